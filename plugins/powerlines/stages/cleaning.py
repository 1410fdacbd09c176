"""Stage 8, cleaning, on labels per input point from here (the index switch): a wire's points lie
on its plan trend, while the foliage it runs through scatters across it (off_their_spans) or
surrounds its curve (in_foliage); a line whose points lie in or along a surface (crown tops, a
roof's rows, an eave) is none; then the wires of a stack one over another (a joint-use pole's
cables), among every candidate."""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from ..core import (
    WIRE_ID_BASE,
    along_a_surface,
    fit_catenary,
    in_a_surface,
    in_foliage,
    make_span,
    off_their_spans,
    sibling_wires,
)
from ..rules import GROW_FROM_M, Rules
from ..state import State, Wires
from ..wire_sets import keep_conductors


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, vu, params, hag, idx = scene.pc, scene.hu, scene.vu, settings.params, scene.hag, scene.candidates
    lines, geo, spans = st.wires.as_tuple()
    tower_pt = st.supports.tower_pt
    labels = st.labels.to_points(st.conductor_of)
    conductor_of, wire_of_input = labels.conductor, labels.wire
    t = time.perf_counter()
    wire_pt = np.flatnonzero(conductor_of >= 0)
    clutter = np.flatnonzero(np.isfinite(hag) & (hag >= GROW_FROM_M) & (conductor_of < 0))
    off_trend = wire_pt[off_their_spans(spans, geo, pc.x[wire_pt] * hu, pc.y[wire_pt] * hu, pc.z[wire_pt] * vu,
                                        conductor_of[wire_pt], wire_of_input[wire_pt], params["max_rms_3d_m"],
                                        clutter_xyz=np.column_stack([pc.x[clutter] * hu, pc.y[clutter] * hu,
                                                                     pc.z[clutter] * vu]))]
    conductor_of[off_trend] = -1
    # where a wire runs through a crown, the crown's points on its curve may be its span's own (and
    # set the span's lateral tolerance): foliage surrounds them, denser than the wire's core
    wire_pt = np.flatnonzero(conductor_of >= 0)
    around = np.flatnonzero(np.isfinite(hag) & (hag >= GROW_FROM_M))
    around_xyz = np.column_stack([pc.x[around] * hu, pc.y[around] * hu, pc.z[around] * vu])
    around_tree = cKDTree(around_xyz) if len(around) else None
    wires = (spans, geo, pc.x[wire_pt] * hu, pc.y[wire_pt] * hu, pc.z[wire_pt] * vu, conductor_of[wire_pt],
             wire_of_input[wire_pt], params["max_rms_3d_m"], around_xyz)
    foliage = wire_pt[in_foliage(*wires, around_tree=around_tree, rules=settings.rules.foliage)]
    # a line whose points lie in a surface (the tops of crowns, a roof's rows) or along one (a sparse
    # roof's scan row or eave) is none
    around_wire = np.where(conductor_of[around] >= 0, conductor_of[around] * WIRE_ID_BASE + wire_of_input[around], -1)
    surfaces = in_a_surface(*wires, around_wire, around_tree=around_tree, rules=settings.rules.surface) | \
        along_a_surface(*wires, around_wire, around_tree=around_tree, rules=settings.rules.along_surface)
    conductor_of[foliage] = -1
    if surfaces:
        kept = [i for i in range(len(geo)) if i not in surfaces]
        lines, geo, spans, conductor_of, wire_of_input = keep_conductors(kept, lines, geo, spans, conductor_of,
                                                                         wire_of_input)
    st.timings["off_trend_s"] = time.perf_counter() - t
    if params["sibling_wires"] and spans:
        # one over another (a joint-use pole's cables), among every candidate: a stack's wires make
        # a ribbon on end that the shape test takes for a surface (searched once the lines in a
        # surface are gone: a facade's scan rows hang one over another under such a line)
        t = time.perf_counter()
        spans, n_stacked = add_stacked_wires(pc, idx[(conductor_of[idx] < 0) & ~tower_pt[idx]], geo, spans,
                                             conductor_of, wire_of_input, params, hu, vu, settings.rules)
        st.counts["n_sibling_wires"] += n_stacked
        st.timings["sibling_wires_s"] = st.timings.get("sibling_wires_s", 0.0) + time.perf_counter() - t
    st.counts.update(n_off_trend_points=len(off_trend), n_foliage_points=len(foliage), n_surface_lines=len(surfaces))
    st.off_trend, st.foliage = off_trend, foliage
    st.around, st.around_xyz, st.around_tree = around, around_xyz, around_tree
    st.wires, st.labels, st.conductor_of = Wires(lines, geo, spans), labels, None
    labels.conductor, labels.wire = conductor_of, wire_of_input
    return st


def add_stacked_wires(pc, pool, geo, spans, conductor_of, wire_of, params, hu, vu, rules=None):
    """``sibling_wires`` over and under the fitted spans among the points ``pool`` (indices into
    ``pc``, on no wire), each added as a further wire of the span's conductor (one over another,
    they are one line in plan): ``conductor_of`` and ``wire_of`` (per point of ``pc``) are
    updated in place. Returns (spans, number added)."""
    siblings = (rules or Rules()).siblings
    if len(pool) < siblings.min_points or not spans:
        return spans, 0
    xyz = np.column_stack([pc.x[pool] * hu, pc.y[pool] * hu, pc.z[pool] * vu])
    # (S_min long, but covering no share of the span: the cables of a stack hide one another
    # over stretches, and a leftover stub of the span's own wire is inside its fit tolerance)
    found = sibling_wires(spans, geo, xyz[:, 0], xyz[:, 1], xyz[:, 2], params["max_rms_3d_m"], params["band_m"],
                          params["s_min_m"], stacked=True, min_cover=0.0,
                          rules=siblings)
    # each conductor's highest wire number so far (its spans' and its points'), found once
    top = np.full(len(geo), -1, np.int64)
    on = conductor_of >= 0
    np.maximum.at(top, conductor_of[on], wire_of[on])
    for sp in spans:
        top[sp.conductor] = max(top[sp.conductor], sp.wire)
    spans = list(spans)
    for k, li, s, off in found:
        top[li] += 1
        spans.append(make_span(li, int(top[li]), 0, s, off, fit_catenary(s, xyz[k, 2]), xyz[k, 2]))
        conductor_of[pool[k]], wire_of[pool[k]] = li, int(top[li])
    return spans, len(found)

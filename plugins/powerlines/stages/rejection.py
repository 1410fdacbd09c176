"""Stage 4, rejection: a conductor in a surface is a roof's scan row or an eave seen from the
street; one in a volume, points of a crown that line up (lines_not_wires). On a line that holds
wires, a span no denser than around it gives its points back (crowded spans)."""

from __future__ import annotations

import time

import numpy as np

from ..core import catenary, core_and_ring, core_ring_contrast, pieces_on_surfaces, span_on_surface
from ..rules import SURFACE_ROWS, WIRE_CONTRAST
from ..state import CandidateLabels, State, Wires
from ..wire_sets import drop_spans, keep_conductors


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, vu, params = scene.pc, scene.hu, scene.vu, settings.params
    idx, off = scene.candidates, scene.off
    lines, geo, spans = st.wires.as_tuple()
    keep, line_of, wire_of_pt = st.labels.as_tuple()
    t = time.perf_counter()
    crowded = []
    not_wires = lines_not_wires(spans, geo, pc.x[idx] * hu, pc.y[idx] * hu, pc.z[idx] * vu, params["max_rms_3d_m"],
                                below=(pc.x[off] * hu, pc.y[off] * hu, pc.z[off] * vu), crowded=crowded)
    fitting = {k for k, sp in enumerate(spans) if sp.rms <= params["max_rms_3d_m"]}
    # a line whose every span is so is none (its spans' pooled contrast may pass on a few dense ones)
    not_wires |= {li for li in {spans[k].conductor for k in crowded}
                  if all(k in crowded for k in fitting if spans[k].conductor == li)}
    crowded = [spans[k] for k in crowded if spans[k].conductor not in not_wires]
    st.timings["not_wires_s"] = time.perf_counter() - t
    if not_wires:
        kept = [i for i in range(len(geo)) if i not in not_wires]
        lines, geo, spans, line_of, wire_of_pt = keep_conductors(kept, lines, geo, spans, line_of, wire_of_pt)
    if crowded:
        # a span no denser than around it, on a line that holds wires: crown points lined up beside them
        spans, line_of, wire_of_pt = drop_spans(crowded, spans, geo, pc.x[keep] * hu, pc.y[keep] * hu, line_of,
                                                wire_of_pt)
    st.counts.update(n_not_wires=len(not_wires), n_crowded_spans=len(crowded))
    st.wires, st.labels = Wires(lines, geo, spans), CandidateLabels(keep, line_of, wire_of_pt)
    return st


def lines_not_wires(spans, geo, px, py, pz, max_rms: float, min_contrast: float = WIRE_CONTRAST, below=None,
                    crowded=None) -> set:
    """Conductors that are not wires seen in the cross-section of their fitted spans, over the
    candidates ``p*``: most span points in a surface (``span_on_surface``: a roof's scan row,
    an eave), or no denser within 0.1 m than 0.2-0.5 m around (under ``min_contrast`` times:
    points of a crown that happen to line up; a wire is a concentration of points, its
    sub-conductors and neighbours sit at a few places around it). ``below``: (x, y, z) of every
    point off the ground, whatever its height: a span that is the top edge of a wall (a truck, a
    fence seen from the street) is in a surface that reaches under the height window. ``crowded``,
    a list, gets the indices (into ``spans``) of the spans that fit and are, on their own, under
    ``min_contrast``."""
    def frame(qx, qy, qz, a, d, lo, hi, reach):
        dx, dy = qx - a[0], qy - a[1]
        s, off = dx * d[0] + dy * d[1], -dx * d[1] + dy * d[0]
        near = np.flatnonzero((s >= lo) & (s <= hi) & (np.abs(off) <= reach))
        return s[near], off[near], qz[near]

    out = set()
    for li, (a, d, _, _) in enumerate(geo):
        numbered = [(k, sp) for k, sp in enumerate(spans) if sp.conductor == li and sp.rms <= max_rms]
        line_spans = [sp for _, sp in numbered]
        if not line_spans:
            continue
        lo, hi = min(sp.s_from for sp in line_spans), max(sp.s_to for sp in line_spans)
        reach = 2.0 + max(abs(sp.offset) + abs(sp.offset_slope) * max(abs(lo), abs(hi)) for sp in line_spans)
        s, off, z = frame(px, py, pz, a, d, lo, hi, reach)
        if below is not None:
            sb, offb, zb = frame(*below, a, d, lo, hi, reach)
        flat = core_n = ring_n = 0
        for k, sp in numbered:
            o, dz = off - sp.offset - sp.offset_slope * s, z - catenary(s, sp.z0, sp.s0, sp.c)
            if span_on_surface(s, o, dz, sp.s_from, sp.s_to) or pieces_on_surfaces(s, o, dz, sp) > 0.5:
                flat += sp.n_points
            elif below is not None and span_on_surface(
                    sb, offb - sp.offset - sp.offset_slope * sb, zb - catenary(sb, sp.z0, sp.s0, sp.c), sp.s_from,
                    sp.s_to, bin_m=SURFACE_ROWS.wall_bin_m, min_run_m=SURFACE_ROWS.wall_run_m,
                    min_tilt_deg=SURFACE_ROWS.wall_min_tilt_deg, max_tilt_deg=SURFACE_ROWS.wall_max_tilt_deg):
                # a wall seen from the side is dense down its scan lines
                flat += sp.n_points
            inside = (s >= sp.s_from) & (s <= sp.s_to)
            core, ring = core_and_ring(np.hypot(o[inside], dz[inside]))
            core_n, ring_n = core_n + core, ring_n + ring
            if crowded is not None and ring and core_ring_contrast(core, ring) < min_contrast:
                crowded.append(k)
        if flat > 0.5 * sum(sp.n_points for sp in line_spans) or core_ring_contrast(core_n, ring_n) < min_contrast:
            out.add(li)
    return out

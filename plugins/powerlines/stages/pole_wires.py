"""Stage 7, pole wires: with the poles known, a wire seen over a few metres where it leaves one
(too short for the short wires' S_min / 2): runs of S_min / 4 leading from a found pole."""

from __future__ import annotations

import time

import numpy as np

from ..core import points_on_spans, wires_from_poles
from ..rules import SPAN_POINTS, STRAIGHT_RUNS
from ..state import CandidateLabels, State, Wires
from ..wire_sets import add_pass
from .more_wires import straight_conductors


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, vu, params = scene.pc, scene.hu, scene.vu, settings.params
    idx, linear, steep, off, low = scene.candidates, scene.linear, scene.steep, scene.off, scene.low
    found, tower_pt, conductor_of = st.supports.found, st.supports.tower_pt, st.conductor_of
    n_pole_wires = 0
    if params["short_wires"] and any(p.kind == "pole" for p in found):
        lines, geo, spans = st.wires.as_tuple()
        keep, line_of, wire_of_pt = st.labels.as_tuple()
        t = time.perf_counter()
        more = np.setdiff1d(idx[linear], keep)  # (the growth dropped none; the rest are in keep)
        n_keep = len(keep)
        keep = np.r_[keep, more]
        line_of, wire_of_pt = np.r_[line_of, np.full(len(more), -1)], np.r_[wire_of_pt, np.full(len(more), -1)]
        free = keep[line_of < 0]
        found4 = pole_wire_pass(pc, free, ~tower_pt[free] & np.isin(free, idx[linear]), off, idx[linear | steep],
                                [p for p in found if p.kind == "pole"], scene.dtm, params, hu, vu)
        if found4 is not None:
            n_before, was, old = len(geo), line_of < 0, {id(sp) for sp in spans}
            lines, geo, spans = add_pass(found4, lines, geo, spans, line_of, wire_of_pt, hu, params)
            n_pole_wires = len(geo) - n_before
            now = was & (line_of >= 0)
            conductor_of[keep[now]] = line_of[now]
        held = np.r_[np.ones(n_keep, bool), line_of[n_keep:] >= 0]
        keep, line_of, wire_of_pt = keep[held], line_of[held], wire_of_pt[held]
        if found4 is not None:
            # the rest of their points, off the run's tolerance or not wire-like (as for the spans
            # found before: next to a pole top a wire point's neighbourhood leans on the pole)
            more = low[(conductor_of[low] < 0) & ~tower_pt[low]]
            m_line, m_wire = points_on_spans([sp for sp in spans if id(sp) not in old], geo, pc.x[more] * hu,
                                             pc.y[more] * hu, pc.z[more] * vu, params["max_rms_3d_m"],
                                             lateral_m=SPAN_POINTS.on_span_m)
            on = m_line >= 0
            keep = np.r_[keep, more[on]]
            line_of, wire_of_pt = np.r_[line_of, m_line[on]], np.r_[wire_of_pt, m_wire[on]]
            conductor_of[more[on]] = m_line[on]
        st.timings["pole_wires_s"] = time.perf_counter() - t
        st.wires, st.labels = Wires(lines, geo, spans), CandidateLabels(keep, line_of, wire_of_pt)
    st.counts["n_pole_wires"] = n_pole_wires
    return st


def pole_wire_pass(pc, free, searched, off_ground, wire_like, poles, dtm, params, hu, vu):
    """``wires_from_poles`` among the points ``free`` (indices into ``pc``; runs drawn from
    those where ``searched``), with ``off_ground`` and the ``wire_like`` points among them for
    the stand-alone test and the ``poles`` found, as a further pass's result for ``add_pass``
    (one conductor and one straight span per run), or None."""
    sub = np.flatnonzero(searched)
    if len(sub) < STRAIGHT_RUNS.min_points:
        return None
    xyz = np.column_stack([pc.x[free] * hu, pc.y[free] * hu, pc.z[free] * vu])
    origin = xyz.min(axis=0)
    base = dtm.sample(np.array([p.x / hu for p in poles]), np.array([p.y / hu for p in poles])) * vu
    axes = np.column_stack([[p.x for p in poles], [p.y for p in poles], base, base + [p.height_m for p in poles]])
    ground = np.column_stack([pc.x[off_ground] * hu, pc.y[off_ground] * hu, pc.z[off_ground] * vu])
    runs = wires_from_poles(xyz[sub] - origin, axes - np.r_[origin, origin[2]], ground - origin,
                            params["s_min_m"] / 4, params["v_max_m"], wire_like=np.isin(off_ground, wire_like))
    if not runs:
        return None
    lines_xy = []
    for run in runs:
        q = xyz[sub[run]]
        d = q[-1, :2] - q[0, :2]
        L = float(np.hypot(*d))
        lines_xy.append((q[0, :2], d / max(L, 1e-9), L, [sub[run]]))
    return straight_conductors(pc, xyz, lines_xy, hu)

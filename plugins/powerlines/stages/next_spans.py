"""Stage 5, next spans: past its last support a wire hangs in a new catenary, seen sparsely
among crowns where the shape test and the Hough had too few of its points (next_spans); between
two pieces of a wire on one catenary, the stretch through a crown (bridge_gaps)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from shapely.geometry import LineString

from ..core import bridge_gaps, make_span, next_spans
from ..rules import Rules
from ..state import CandidateLabels, State, Wires


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, vu, params, low = scene.pc, scene.hu, scene.vu, settings.params, scene.low
    lines, geo, spans = st.wires.as_tuple()
    keep, line_of, wire_of_pt = st.labels.as_tuple()
    n_next = n_bridges = 0
    if params["next_spans"] and spans:
        t = time.perf_counter()
        lines, geo, spans, keep, line_of, wire_of_pt, n_next = add_next_spans(pc, low, keep, lines, geo, spans,
                                                                              line_of, wire_of_pt, params, hu, vu,
                                                                              settings.rules)
        st.timings["next_spans_s"] = time.perf_counter() - t
    if params["bridge_gaps"] and spans:
        t = time.perf_counter()
        lines, geo, spans, keep, line_of, wire_of_pt, n_bridges = add_bridged_gaps(
            pc, low, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu)
        st.timings["bridge_gaps_s"] = time.perf_counter() - t
    st.counts.update(n_next_spans=n_next, n_bridged_gaps=n_bridges)
    st.wires, st.labels = Wires(lines, geo, spans), CandidateLabels(keep, line_of, wire_of_pt)
    return st


def labels_of_low(low, keep, line_of, wire_of_pt, n_points):
    """Each of the points ``low`` (indices into the cloud of ``n_points``): its conductor and wire
    so far (-1: on no wire)."""
    at_low = np.full(n_points, -1, np.int64)
    at_low[low] = np.arange(len(low))
    in_low = at_low[keep] >= 0
    low_line, low_wire = np.full(len(low), -1, np.int64), np.full(len(low), -1, np.int64)
    low_line[at_low[keep[in_low]]], low_wire[at_low[keep[in_low]]] = line_of[in_low], wire_of_pt[in_low]
    return low_line, low_wire


def add_next_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu, rules=None):
    """``next_spans`` of the wires found among the points ``low`` (indices into ``pc``: off the
    ground), added by ``add_found_spans``. Returns what it returns."""
    r = (rules or Rules()).next_spans
    low_line, low_wire = labels_of_low(low, keep, line_of, wire_of_pt, len(pc))
    found = next_spans(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu, low_line < 0,
                       params["max_rms_3d_m"], max_gap_m=2 * params["v_max_m"],
                       reach_m=max(r.reach_m, 8 * params["s_min_m"]), min_span_m=params["s_min_m"], line_of=low_line,
                       wire_of=low_wire, rules=r)
    return add_found_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, found, hu, vu)


def add_bridged_gaps(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu):
    """``bridge_gaps`` of the wires found among the points ``low`` (indices into ``pc``: off the
    ground), added by ``add_found_spans``. Returns what it returns."""
    low_line, low_wire = labels_of_low(low, keep, line_of, wire_of_pt, len(pc))
    found = bridge_gaps(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu, low_line < 0,
                        params["max_rms_3d_m"], max_gap_m=2 * params["s_min_m"], line_of=low_line, wire_of=low_wire)
    return add_found_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, found, hu, vu)


def add_found_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, found, hu, vu):
    """Spans ``found`` past or between a wire's fitted ones ([(line, wire, indices into ``low``, s,
    offsets, fit)]) added as chained spans of those wires; their points join ``keep`` (relabelled
    where they are candidates on no wire) and each conductor's 2D line is stretched over them.
    Returns (lines, geo, spans, keep, line_of, wire_of_pt, number of spans added)."""
    if not found:
        return lines, geo, spans, keep, line_of, wire_of_pt, 0
    spans, geo = list(spans), list(geo)
    number = {}
    for sp in spans:
        number[(sp.conductor, sp.wire)] = max(number.get((sp.conductor, sp.wire), -1), sp.span)
    pos = np.full(len(pc), -1, np.int64)
    pos[keep] = np.arange(len(keep))
    cond = lines["conductors"].copy()
    for li, wire, k, s, off, fit in found:
        number[(li, wire)] += 1
        spans.append(dataclasses.replace(make_span(li, wire, number[(li, wire)], s, off, fit, z=pc.z[low[k]] * vu),
                                         chained=True))
        pts = low[k]
        at = pos[pts]
        line_of[at[at >= 0]], wire_of_pt[at[at >= 0]] = li, wire
        new = pts[at < 0]
        pos[new] = len(keep) + np.arange(len(new))
        keep = np.r_[keep, new]
        line_of, wire_of_pt = np.r_[line_of, np.full(len(new), li)], np.r_[wire_of_pt, np.full(len(new), wire)]
        a, d, t0, t1 = geo[li]
        t0, t1 = min(t0, float(s.min())), max(t1, float(s.max()))
        if (t0, t1) != geo[li][2:]:
            geo[li] = (a, d, t0, t1)
            row = cond.index[li]
            cond.loc[row, "geometry"] = LineString([tuple((a + t0 * d) / hu), tuple((a + t1 * d) / hu)])
            if "length_m" in cond.columns:
                cond.loc[row, "length_m"] = t1 - t0
    cond.attrs.update(lines["conductors"].attrs)
    return {**lines, "conductors": cond}, geo, spans, keep, line_of, wire_of_pt, len(found)

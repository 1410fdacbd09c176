"""Stage 3, more wires: the wire-like points on no wire searched again (second_pass), straight
3D runs of S_min / 2 among what is left (short_wires), phases beside each fitted span
(sibling_wires), candidates the shape test left out that lie on a span, and each span's
catenary continued past its ends (grow_spans)."""

from __future__ import annotations

import time

import geopandas as gpd
import numpy as np
from shapely.geometry import LineString

from ..core import fit_catenary, grow_span_ends, make_span, points_on_spans, short_wires, sibling_wires
from ..rules import MIN_SECOND_PASS, SPAN_POINTS, STRAIGHT_RUNS, Rules
from ..state import CandidateLabels, State, Wires
from ..wire_sets import add_pass, keep_conductors
from .plan_lines import lines_and_wires


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, vu, params, timings = scene.pc, scene.hu, scene.vu, settings.params, st.timings
    idx, linear, steep, off, low = scene.candidates, scene.linear, scene.steep, scene.off, scene.low
    lines, geo, spans = st.wires.as_tuple()
    keep, line_of, wire_of_pt = st.labels.as_tuple()
    free = keep[line_of < 0]
    if params["second_pass"] and len(free) >= MIN_SECOND_PASS:
        # the wire-like points on no wire, searched again: a stretch past a bend in the line whose
        # votes the first line's band took, wires a stronger line outvoted in a tile; what is left
        # is mostly clutter, so a line found there must be mostly wire (half its span points on
        # catenaries that fit)
        t = time.perf_counter()
        counts = {}  # its stage times are second_pass_s; its turned lines count with the first's
        found2 = lines_and_wires(pc, free, scene.hag, settings.cell_m, params, ctx, counts, min_fit_share=0.5,
                                 rules=settings.rules,
                                 optional=True)
        if found2 is not None:
            for k in ("n_lines_realigned", "n_twin_lines_merged"):
                timings[k] = timings.get(k, 0) + counts.get(k, 0)
        lines, geo, spans = add_pass(found2, lines, geo, spans, line_of, wire_of_pt, hu, params)
        timings["second_pass_s"] = time.perf_counter() - t
    n_short = 0
    if params["short_wires"]:
        # what is left may hold wires seen over a few metres only (a mobile scanner's view of a
        # wire across its street): straight 3D runs of S_min / 2, the shortest piece of wire the
        # 3D step fits
        t = time.perf_counter()
        n_free = int((line_of < 0).sum())
        wired = keep[line_of >= 0]
        # the wires of a stack beside a short wire are not clutter around it
        wire_like = np.zeros(len(pc), bool)
        wire_like[idx[linear | steep]] = True
        # a stack's wires one over another make a ribbon on end, whose points the shape test may
        # take for a pole's: they join the search beside a short wire found
        n_keep = len(keep)
        keep = np.r_[keep, idx[steep]]
        line_of, wire_of_pt = np.r_[line_of, np.full(steep.sum(), -1)], np.r_[wire_of_pt, np.full(steep.sum(), -1)]
        found3 = short_wire_pass(pc, keep[line_of < 0], off, idx[steep], wired, params, hu, vu, n_searched=n_free,
                                 rules=settings.rules,
                                 wire_like=wire_like[off])
        n_before = len(geo)
        lines, geo, spans = add_pass(found3, lines, geo, spans, line_of, wire_of_pt, hu, params)
        held = np.r_[np.ones(n_keep, bool), line_of[n_keep:] >= 0]
        keep, line_of, wire_of_pt = keep[held], line_of[held], wire_of_pt[held]
        n_short = len(geo) - n_before
        timings["short_wires_s"] = time.perf_counter() - t
    n_sibling = 0
    if params["sibling_wires"]:
        # a line's phases hang side by side with one sag: beside each span, the points of a phase
        # too sparse to find alone share one offset across it and one height above its catenary
        t = time.perf_counter()
        lines, geo, spans, line_of, wire_of_pt, n_sibling = add_sibling_wires(pc, keep, lines, geo, spans, line_of,
                                                                              wire_of_pt, params, hu, vu,
                                                                              settings.rules)
        timings["sibling_wires_s"] = time.perf_counter() - t

    # candidates the shape test left out that lie on a fitted span are its points too: steep ones
    # (next to a pole top a wire point's neighbourhood leans on the pole), and flat or rough ones
    # right on it (a ribbon's phases or a crown shared their neighbourhood)
    # (steep points a short wire took are on a wire already)
    for more, lateral_m in ((np.setdiff1d(idx[steep], keep), SPAN_POINTS.on_span_m),
                            (idx[~linear & ~steep], SPAN_POINTS.on_span_flat_m)):
        m_line, m_wire = points_on_spans(spans, geo, pc.x[more] * hu, pc.y[more] * hu, pc.z[more] * vu,
                                         params["max_rms_3d_m"], lateral_m=lateral_m)
        on = m_line >= 0
        keep = np.r_[keep, more[on]]
        line_of, wire_of_pt = np.r_[line_of, m_line[on]], np.r_[wire_of_pt, m_wire[on]]

    # a span's catenary continued past its ends picks up its wire where the candidates stopped
    # (under the height window on a slope; next to a tower, where the shape test sees the structure)
    grown = np.zeros(0, np.int64)
    if params["grow_spans"]:
        t = time.perf_counter()
        g_line, g_wire = grow_span_ends(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu,
                                        ~np.isin(low, keep[line_of >= 0]), params["max_rms_3d_m"],
                                        max_gap_m=2 * params["v_max_m"], reach_m=2 * params["s_min_m"],
                                        rules=settings.rules.grow)
        on = g_line >= 0
        grown = low[on]
        # candidates on no wire yet are relabelled in place, the rest appended
        pos = np.full(len(pc), -1, np.int64)
        pos[keep] = np.arange(len(keep))
        at = pos[grown]
        line_of[at[at >= 0]], wire_of_pt[at[at >= 0]] = g_line[on][at >= 0], g_wire[on][at >= 0]
        keep = np.r_[keep, grown[at < 0]]
        line_of, wire_of_pt = np.r_[line_of, g_line[on][at < 0]], np.r_[wire_of_pt, g_wire[on][at < 0]]
        timings["grow_spans_s"] = time.perf_counter() - t
    st.counts.update(n_short_wires=n_short, n_sibling_wires=n_sibling)
    st.grown = grown
    st.wires, st.labels = Wires(lines, geo, spans), CandidateLabels(keep, line_of, wire_of_pt)
    return st


def short_wire_pass(pc, free, off_ground, steep, wired, params, hu, vu, n_searched=None, wire_like=None, rules=None):
    """``short_wires`` among the wire-like points ``free`` (indices into ``pc``; ``off_ground``,
    ``steep``, ``wired``: the points off the ground, of structures and of the wires found;
    ``wire_like``: which of ``off_ground`` are; runs are drawn from the first ``n_searched`` of
    ``free``, the rest only join a stack beside one) as a further pass's result for
    ``add_pass`` (one conductor and one straight span per run), or None."""
    if (len(free) if n_searched is None else n_searched) < STRAIGHT_RUNS.min_points or len(wired) == 0:
        return None
    xyz = np.column_stack([pc.x[free] * hu, pc.y[free] * hu, pc.z[free] * vu])
    origin = xyz.min(axis=0)

    def local(ix):
        return np.column_stack([pc.x[ix] * hu, pc.y[ix] * hu, pc.z[ix] * vu]) - origin

    runs = short_wires(xyz - origin, local(off_ground), local(steep), local(wired), params["s_min_m"] / 2,
                       params["v_max_m"], n_searched=n_searched, wire_like=wire_like,
                       rules=(rules or Rules()).short_wires)
    if not runs:
        return None
    lines_xy = []
    for run in runs:
        q = xyz[run]
        d = q[-1, :2] - q[0, :2]
        L = float(np.hypot(*d))
        lines_xy.append((q[0, :2], d / max(L, 1e-9), L, [run]))
    return straight_conductors(pc, xyz, lines_xy, hu)


def straight_conductors(pc, xyz, lines_xy, hu):
    """A further pass's result for ``add_pass`` from conductors drawn as straight 2D lines, each
    (anchor, unit direction, length, [indices into ``xyz`` of each of its spans' points]): one
    catenary per span."""
    geo, spans, rows, segs = [], [], [], []
    line_of = np.full(len(xyz), -1, np.int64)
    for li, (a, d, L, pieces) in enumerate(lines_xy):
        n_points, offs = 0, []
        for number, run in enumerate(pieces):
            q = xyz[run]
            s, off = (q[:, :2] - a) @ d, (q[:, :2] - a) @ np.array([-d[1], d[0]])
            spans.append(make_span(li, 0, number, s, off, fit_catenary(s, q[:, 2])))
            line_of[run] = li
            n_points += len(run)
            offs.append(off)
        geo.append((a, d, 0.0, L))
        g = LineString([a / hu, (a + L * d) / hu])
        off = np.concatenate(offs)
        rows.append({"conductor": li, "votes": n_points, "n_points": n_points, "length_m": L,
                     "rms_m": float(np.sqrt(np.mean(off ** 2))),
                     "azimuth_deg": float(np.degrees(np.arctan2(d[0], d[1])) % 180.0), "geometry": g})
        segs.append({"conductor": li, "segment": 0, "length_m": L, "geometry": g})
    lines = {"conductors": gpd.GeoDataFrame(rows, geometry="geometry", crs=pc.crs),
             "conductor_segments": gpd.GeoDataFrame(segs, geometry="geometry", crs=pc.crs)}
    return lines, geo, spans, line_of, np.where(line_of >= 0, 0, -1), 0


def add_sibling_wires(pc, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu, rules=None):
    """``sibling_wires`` beside the fitted spans among the wire-like points ``keep`` (indices
    into ``pc``; ``line_of``, ``wire_of_pt``: their conductor and wire so far), added as new
    conductors (pieces beside the spans of one line at one offset make one, a span each). A line
    whose points a sibling takes for the most part was a stretch of it: it is dropped and the
    sibling holds its points. Returns (lines, geo, spans, line_of, wire_of_pt, number added)."""
    siblings = (rules or Rules()).siblings
    min_points = siblings.min_points  # a piece left with fewer is no wire of its own
    if len(keep) < min_points or not spans:
        return lines, geo, spans, line_of, wire_of_pt, 0
    xyz = np.column_stack([pc.x[keep] * hu, pc.y[keep] * hu, pc.z[keep] * vu])
    length = np.array([t1 - t0 for (_, _, t0, t1) in geo] + [0.0])
    found = sibling_wires(spans, geo, xyz[:, 0], xyz[:, 1], xyz[:, 2], params["max_rms_3d_m"], params["band_m"],
                          params["s_min_m"], owner=line_of, owner_length=length[line_of], min_points=min_points,
                          rules=siblings)
    if not found:
        return lines, geo, spans, line_of, wire_of_pt, 0
    taken = np.zeros(len(keep), bool)
    reach = np.zeros(len(geo) + 1)  # per line: the longest piece that took points of it
    for k, _, s, _ in found:
        taken[k] = True
        reach[line_of[k]] = np.maximum(reach[line_of[k]], np.ptp(s))
    owners = line_of[taken & (line_of >= 0)]
    absorbed = {int(li) for li in np.unique(owners)
                if (owners == li).sum() >= 0.5 * (line_of == li).sum() and length[li] <= reach[li]}
    searched = list(geo)
    if absorbed:
        lines, geo, spans, line_of, wire_of_pt = keep_conductors(
            [i for i in range(len(geo)) if i not in absorbed], lines, geo, spans, line_of, wire_of_pt)
    free = np.flatnonzero(line_of < 0)
    at = np.full(len(keep), -1, np.int64)
    at[free] = np.arange(len(free))
    groups = []  # [parent line, offset at its middle, [pieces], their s and offsets]
    for k, li, s, off in found:
        mine = at[k] >= 0  # (points of a line not absorbed stay with it)
        if mine.sum() < min_points:
            continue
        k, s, off = at[k[mine]], s[mine], off[mine]
        o1, o0 = np.polyfit(s, off, 1)
        mid = float(np.mean(s))
        g = next((g for g in groups if g[0] == li and abs(g[1] - (o0 + o1 * mid)) <= params["band_m"]), None)
        if g is None:
            groups.append([li, o0 + o1 * mid, [k], [s], [off]])
        else:
            g[2].append(k), g[3].append(s), g[4].append(off)
    lines_xy = []
    for li, _, pieces, ss, offs in groups:
        if np.ptp(np.concatenate(ss)) < params["s_min_m"]:
            continue  # what the lines kept leave of it is shorter than a conductor's run
        a, d, _, _ = searched[li]  # the parent's frame as searched (dropping absorbed lines renumbers)
        n = np.array([-d[1], d[0]])
        s, off = np.concatenate(ss), np.concatenate(offs)
        o1, o0 = np.polyfit(s, off, 1)
        ends = [a + t * d + (o0 + o1 * t) * n for t in (float(s.min()), float(s.max()))]
        L = float(np.hypot(*(ends[1] - ends[0])))
        lines_xy.append((ends[0], (ends[1] - ends[0]) / max(L, 1e-9), L, pieces))
    n_before = len(geo)
    lines, geo, spans = add_pass(straight_conductors(pc, xyz[free], lines_xy, hu) if lines_xy else None, lines,
                                  geo, spans, line_of, wire_of_pt, hu, params)
    return lines, geo, spans, line_of, wire_of_pt, len(geo) - n_before

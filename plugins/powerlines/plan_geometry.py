"""Plan geometry of the conductors: their lines redrawn, twins merged, lines realigned on their
spans' trends, wires side by side made conductors of their own, how far each wire reaches."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from shapely.geometry import LineString

from .core import SIDE_BY_SIDE_MIN_GAP_M, WIRE_LATERAL_RMS_M, line_fit, span_in_frame
from .rules import ALONG_SLOPE_MAX
from .wire_sets import runs_along, select_conductors


def redrawn_lines(lines, geo, source, held, hu):
    """The Hough's layers for the lines ``geo`` (anchor, direction, from, to; metres) that
    ``ribbon_lines`` redrew: each takes the attributes of its ``source`` line, the points it
    ``held`` as its votes (where redrawn), its own geometry and one segment over its extent."""
    cond, seg = lines["conductors"], lines["conductor_segments"]
    rows, segs = [], []
    for k, ((a, d, t0, t1), src, n_held) in enumerate(zip(geo, source, held)):
        ends = [tuple((a + t * d) / hu) for t in (t0, t1)]
        row = cond.iloc[src].copy()
        row["conductor"] = k
        if n_held is not None:
            for col in ("votes", "n_points"):
                if col in row.index:
                    row[col] = n_held
        row["geometry"] = LineString(ends)
        if "length_m" in row.index:
            row["length_m"] = float(t1 - t0)
        if "azimuth_deg" in row.index:
            row["azimuth_deg"] = float(np.degrees(np.arctan2(d[0], d[1])) % 180.0)
        rows.append(row)
        segs.append({"conductor": k, "segment": 0, "length_m": float(t1 - t0), "geometry": LineString(ends)})
    out_c = gpd.GeoDataFrame(pd.DataFrame(rows).reset_index(drop=True), geometry="geometry", crs=cond.crs)
    out_s = gpd.GeoDataFrame(pd.DataFrame(segs, columns=["conductor", "segment", "length_m", "geometry"]),
                             geometry="geometry", crs=seg.crs)
    out_c.attrs.update(cond.attrs)
    out_s.attrs.update(seg.attrs)
    return {**lines, "conductors": out_c, "conductor_segments": out_s}


def merge_twins(lines, geo, pairs, hu):
    """Each group of lines joined by ``pairs`` (twin_lines) as one: the least-squares line through
    their ends in the frame of the longest, each line's ends weighted by its length (a stub at a
    tower does not turn a long line), over all their extents; the longest line's conductor takes
    it and their segments (moved onto it), the others are dropped. Returns (lines, geo, number of
    lines merged away)."""
    i, j = np.array(pairs, np.int64).reshape(-1, 2).T
    _, group_of = connected_components(sparse.coo_matrix((np.ones(len(i)), (i, j)), shape=(len(geo), len(geo))),
                                       directed=False)
    groups = {}
    for k, g in enumerate(group_of):
        groups.setdefault(int(g), []).append(k)
    geo = list(geo)
    seg = lines["conductor_segments"].copy()
    cond = lines["conductors"].copy()
    keep = []
    for members in groups.values():
        main = max(members, key=lambda k: geo[k][3] - geo[k][2])
        keep.append(main)
        if len(members) < 2:
            continue
        ah, dh, _, _ = geo[main]
        nh = np.array([-dh[1], dh[0]])
        ends = np.array([a + t * d for k in members for a, d, *ts in [geo[k]] for t in ts])
        w = np.repeat([geo[k][3] - geo[k][2] for k in members], 2)
        s, o = (ends - ah) @ dh, (ends - ah) @ nh
        sm, om = (w @ s) / w.sum(), (w @ o) / w.sum()
        slope = float(w @ ((s - sm) * (o - om)) / max(float(w @ (s - sm) ** 2), 1e-12))
        d2 = (dh + slope * nh) / np.hypot(1.0, slope)
        a2 = ah + s.min() * dh + (om + slope * (s.min() - sm)) * nh
        geo[main] = (a2, d2, 0.0, float((s.max() - s.min()) * np.hypot(1.0, slope)))

        def onto(xy, a2=a2, d2=d2):
            p = np.asarray(xy) * hu
            return tuple((a2 + float((p - a2) @ d2) * d2) / hu)
        row = cond.index[main]
        cond.loc[row, "geometry"] = LineString([a2 / hu, (a2 + geo[main][3] * d2) / hu])
        if "azimuth_deg" in cond.columns:
            cond.loc[row, "azimuth_deg"] = float(np.degrees(np.arctan2(d2[0], d2[1])) % 180.0)
        if "length_m" in cond.columns:
            cond.loc[row, "length_m"] = geo[main][3]
        for k in seg.index[seg["conductor"].isin(members)]:
            seg.loc[k, "geometry"] = LineString([onto(c) for c in seg.loc[k, "geometry"].coords])
            seg.loc[k, "conductor"] = main
    keep = sorted(keep)
    out = select_conductors({"conductors": cond, "conductor_segments": seg}, keep)
    for name in ("conductors", "conductor_segments"):
        out[name].attrs.update(lines[name].attrs)
    return {**lines, **out}, [geo[k] for k in keep], len(geo) - len(keep)


def plan_trends(spans, params) -> dict:
    """Per line, the plan trend of its wires: their spans' offset slope along it, pooled over the
    spans that fit and are S_min long, each weighted by its precision. line -> (trend, whether the
    spans agree on it (no bend at a support, no fan of wires), and per span: weight, middle along
    the line, offset there, points; then the trend of the spans' offsets from one span to the next
    along each wire (a common slope, each wire its own intercept, weighted by the points over their
    scatter), None where no wire has two such spans)."""
    pooled = {}  # line -> [(weight of its slope, slope, middle, offset there, points)] per span
    for sp in spans:
        length = sp.s_to - sp.s_from
        if sp.rms <= params["max_rms_3d_m"] and length >= params["s_min_m"] and sp.offset_rms <= WIRE_LATERAL_RMS_M:
            # 1 / var(slope) of a least-squares line through n points spread evenly over the span
            w = sp.n_points * length ** 2 / 12.0 / max(sp.offset_rms, 0.01) ** 2
            mid = 0.5 * (sp.s_from + sp.s_to)
            pooled.setdefault(sp.conductor, []).append((w, sp.offset_slope, mid, sp.offset + sp.offset_slope * mid,
                                                        sp.n_points, sp.wire, sp.n_points / max(sp.offset_rms, 0.01) ** 2))
    out = {}
    for li, rows in pooled.items():
        w, slope, mid, off, n, wire, v = map(np.array, zip(*rows))
        trend = float(w @ slope / w.sum())
        agree = bool(w @ (slope - trend) ** 2 <= 9.0 * max(len(w) - 1, 1))
        sxx = sxy = 0.0
        for k in np.unique(wire):
            on = wire == k
            if on.sum() < 2:
                continue
            ds = mid[on] - v[on] @ mid[on] / v[on].sum()
            sxx += float(v[on] @ ds ** 2)
            sxy += float(v[on] @ (ds * (off[on] - v[on] @ off[on] / v[on].sum())))
        out[li] = (trend, agree, w, mid, off, n, sxy / sxx if sxx > 0 else None)
    return out


def main_wire_spans(spans, max_rms: float) -> list:
    """The spans (those that fit, within ``max_rms``) of each line's main wire: the one whose
    fitting spans hold the most points."""
    held = {}
    for sp in spans:
        if sp.rms <= max_rms:
            held[(sp.conductor, sp.wire)] = held.get((sp.conductor, sp.wire), 0) + sp.n_points
    main = {}
    for (li, w), n in sorted(held.items()):
        if li not in main or n > held[(li, main[li])]:
            main[li] = w
    return [sp for sp in spans if sp.rms <= max_rms and main.get(sp.conductor) == sp.wire]


def realign(lines, geo, spans, params, hu, min_drift_m: float | None = None, max_spans: int | None = None):
    """Lines turned onto the plan trend of their wires: the Hough's line through a wire seen from
    one side (a mobile scanner's view of a line crossing its street) can lean off it by a few
    tenths of a degree, a drift across its length that its band and its crossings inherit. The
    trend is the spans' own (their offset's slope along the line, pooled over the spans that fit
    and are S_min long, each weighted by its precision); a line turns about the middle of its
    spans where that trend drifts more than band_m over the line's length (its band loses the
    wire at one end), lies more than three standard errors off zero and its spans agree on it
    (a line bending at a support, or wires fanning out from a pole, keep the Hough's compromise).
    ``min_drift_m``: the drift that turns a line (default band_m); ``max_spans``: only lines held
    by at most that many such spans. Returns (lines, geo, number turned)."""
    turn = {}
    drift = params["band_m"] if min_drift_m is None else min_drift_m
    for li, (trend, agree, w, mid, off, n, between) in plan_trends(spans, params).items():
        if max_spans is not None and len(w) > max_spans:
            continue
        length = geo[li][3] - geo[li][2]
        # where a wire holds several spans, their offsets from one to the next must drift too: the
        # spans' own slopes, tens of metres each, can share a bias of a few 1e-4 (a sparse scan's
        # pattern along them) that no drift of the wire across the line bears out
        confirmed = between is None or (between * trend > 0 and abs(between) * length > drift)
        if abs(trend) * length > drift and abs(trend) > 3.0 / np.sqrt(w.sum()) and agree and confirmed:
            pivot = float(w @ mid / w.sum())
            # the line moves onto its wire there: the offset most of its points share (another
            # line's wire its lean let into the band is out-numbered)
            at = off + trend * (pivot - mid)
            order = np.argsort(at)
            turn[li] = (trend, pivot, float(at[order][np.searchsorted(np.cumsum(n[order]), 0.5 * n.sum())]))
    if not turn:
        return lines, geo, 0
    geo = list(geo)
    cond, seg = lines["conductors"].copy(), lines["conductor_segments"].copy()
    for li, (slope, mid, off) in turn.items():
        a, d, t0, t1 = geo[li]
        n = np.array([-d[1], d[0]])
        pivot = a + mid * d
        d2 = d + slope * n
        d2 = d2 / np.hypot(*d2)
        centre = pivot + off * n
        geo[li] = (centre - mid * d2, d2, t0, t1)

        def onto(xy):  # the layers follow: each end keeps its place along the line
            s = float((np.asarray(xy) * hu - pivot) @ d)
            return tuple((centre + s * d2) / hu)
        row = cond.index[li]
        cond.loc[row, "geometry"] = LineString([onto(c) for c in cond.loc[row, "geometry"].coords])
        if "azimuth_deg" in cond.columns:
            cond.loc[row, "azimuth_deg"] = float(np.degrees(np.arctan2(d2[0], d2[1])) % 180.0)
        for k in seg.index[seg["conductor"] == li]:
            seg.loc[k, "geometry"] = LineString([onto(c) for c in seg.loc[k, "geometry"].coords])
    for g, src in ((cond, lines["conductors"]), (seg, lines["conductor_segments"])):
        g.attrs.update(src.attrs)
    return {**lines, "conductors": cond, "conductor_segments": seg}, geo, len(turn)


def side_by_side(lines, geo, spans, conductor_of, wire_of, x, y, params, hu, min_gap_m: float | None = None):
    """Conductors whose fitted spans lie in groups side by side across the line, ``min_gap_m`` or
    more apart (the 3D step's cut across a piece): a ribbon's phases 0.3-0.4 m apart share one
    Hough line (its band is band_m), and so do the sub-conductors of a bundle side by side that
    far apart. Each group becomes a conductor of its own in plan (the original's extent, on the
    group's own trend), with its spans and the points nearest its trend (``conductor_of``,
    ``wire_of``: per input point, ``x``, ``y`` in metres); a group along another conductor (a
    phase that line also holds) joins it, as further wires. Sub-conductors closer than
    ``min_gap_m`` in plan (default: the 3D step's own cut, SIDE_BY_SIDE_MIN_GAP_M; a triangle
    bundle's 0.2 m) stay one conductor per phase. Spans are grouped by their offsets about the
    line's plan trend (``plan_trends``, where its spans agree on one), spans more than 1 deg off
    the line (jumpers) left out. Returns (lines, geo, spans, conductor_of, wire_of, number of
    conductors added)."""
    min_gap_m = SIDE_BY_SIDE_MIN_GAP_M if min_gap_m is None else min_gap_m

    fitting = [sp for sp in spans if sp.rms <= params["max_rms_3d_m"]]
    cond, seg = lines["conductors"], lines["conductor_segments"]
    new_geo, new_rows, new_segs, new_spans = list(geo), [], [], []
    conductor_of, wire_of = conductor_of.copy(), wire_of.copy()
    next_wire = {li: int(max([sp.wire for sp in spans if sp.conductor == li], default=-1)) + 1
                 for li in range(len(geo))}
    moved = {}  # original conductor -> [(new index, offset trend (slope, intercept))]
    plan = plan_trends(spans, params)
    for li in range(len(geo)):
        found = _groups_across(fitting, li, plan.get(li, (0.0, False))[:2], min_gap_m, params["s_min_m"])
        if found is None:
            continue
        mine, groups, to_centre = found
        a, d, t0, t1 = geo[li]
        n = np.array([-d[1], d[0]])
        moved[li] = []
        for gi, (g, (o1, o0)) in enumerate(zip(groups, _group_trends(mine, groups, to_centre))):
            d2 = d + o1 * n
            d2 = d2 / np.hypot(*d2)
            a2 = a + o0 * n
            extent = (min(mine[k].s_from for k in g), max(mine[k].s_to for k in g))
            onto_other = [j for j in range(len(geo)) if j != li and
                          runs_along((a2, d2, *extent), geo[j], 0.5 * min_gap_m)]
            if gi > 0 and onto_other:
                moved[li].append((onto_other[0], o1, o0, [mine[k] for k in g]))
                continue
            if gi == 0:
                k_new = li
            else:
                k_new = len(new_geo)
                _copy_rows(cond, seg, li, k_new, new_rows, new_segs)
                new_geo.append(None)
            new_geo[k_new] = (a2, d2, t0, t1)
            moved[li].append((k_new, o1, o0, [mine[k] for k in g]))
    if not moved:
        return lines, geo, spans, conductor_of, wire_of, 0
    cond = pd.concat([cond, pd.DataFrame(new_rows)], ignore_index=True) if new_rows else cond.copy()
    seg = pd.concat([seg, pd.DataFrame(new_segs)], ignore_index=True) if new_segs else seg.copy()
    cond = cond.set_geometry("geometry", crs=lines["conductors"].crs)
    seg = seg.set_geometry("geometry", crs=lines["conductor_segments"].crs)
    for li, parts in moved.items():
        a, d, t0, t1 = geo[li]
        n = np.array([-d[1], d[0]])
        pts = np.flatnonzero(conductor_of == li)
        ps = (x[pts] - a[0]) * d[0] + (y[pts] - a[1]) * d[1]
        po = -(x[pts] - a[0]) * d[1] + (y[pts] - a[1]) * d[0]
        # each point to the group whose trend lies nearest across the line
        near = np.argmin(np.abs(np.column_stack([po - (o1 * ps + o0) for _, o1, o0, _ in parts])), axis=1)
        for k, (k_new, o1, o0, group_spans) in enumerate(parts):
            conductor_of[pts[near == k]] = k_new
            if k_new < len(geo) and k_new != li:  # joins another conductor: its wires numbered on after
                renum = {}
                for sp in group_spans:
                    if sp.wire not in renum:
                        renum[sp.wire] = next_wire[k_new]
                        next_wire[k_new] += 1
                mine_pts = pts[near == k]
                wire_of[mine_pts] = [renum.get(w, renum[group_spans[0].wire]) for w in wire_of[mine_pts]]
                for sp in group_spans:
                    new_spans.append(span_in_frame(sp, geo[li], geo[k_new], k_new, renum[sp.wire]))
                continue
            a2, d2, _, _ = new_geo[k_new]

            def onto(xy, o1=o1, o0=o0):  # a point of the original line onto the group's trend
                p = np.asarray(xy) * hu
                t = float((p - a) @ d)
                return tuple((p + (o0 + o1 * t) * n) / hu)
            rows = cond.index[cond["conductor"] == k_new]
            cond.loc[rows[0], "geometry"] = LineString([onto(c) for c in cond.loc[rows[0], "geometry"].coords])
            cond.loc[rows[0], "azimuth_deg"] = float(np.degrees(np.arctan2(d2[0], d2[1])) % 180.0)
            cond.loc[rows[0], "n_points"] = int((near == k).sum())
            for r in seg.index[seg["conductor"] == k_new]:
                seg.loc[r, "geometry"] = LineString([onto(c) for c in seg.loc[r, "geometry"].coords])
            for sp in group_spans:
                new_spans.append(span_in_frame(sp, geo[li], new_geo[k_new], k_new, sp.wire))
    done = {id(sp) for parts in moved.values() for _, _, _, g in parts for sp in g}
    # the rest (spans that do not fit, groups under S_min) stay on the original conductor, in its new frame
    spans = [span_in_frame(sp, geo[sp.conductor], new_geo[sp.conductor], sp.conductor, sp.wire)
             if sp.conductor in moved else sp for sp in spans if id(sp) not in done] + new_spans
    for g, src in ((cond, lines["conductors"]), (seg, lines["conductor_segments"])):
        g.attrs.update(src.attrs)
    return ({**lines, "conductors": cond, "conductor_segments": seg}, new_geo, spans, conductor_of, wire_of,
            len(new_geo) - len(geo))


def _group_trends(mine, groups, to_centre) -> list:
    """Each group's offset along the line, (slope, intercept): its spans' trends sampled at both ends."""
    trends = []
    for g in groups:
        ss = np.concatenate([[mine[k].s_from, mine[k].s_to] for k in g])
        oo = np.concatenate([[mine[k].offset + mine[k].offset_slope * mine[k].s_from + to_centre[k],
                              mine[k].offset + mine[k].offset_slope * mine[k].s_to + to_centre[k]] for k in g])
        trends.append(line_fit(ss, oo) if np.ptp(ss) > 0 else (0.0, float(np.median(oo))))
    return trends


def _copy_rows(cond, seg, li: int, k_new: int, new_rows: list, new_segs: list) -> None:
    """Conductor ``li``'s row and its segments' rows, copied as conductor ``k_new``'s."""
    row = cond.iloc[li].copy()
    row["conductor"] = k_new
    new_rows.append(row)
    for _, sr in seg[seg["conductor"] == li].iterrows():
        sr = sr.copy()
        sr["conductor"] = k_new
        new_segs.append(sr)


def _groups_across(fitting, li, trend_agree, min_gap_m: float, s_min_m: float):
    """The fitting spans of conductor ``li`` that run along it at one offset each (``mine``), in
    groups side by side across it (``groups``: indices into ``mine``), and per span the shift that
    centres a phase of sub-conductors closer than ``min_gap_m`` (``to_centre``); None when the
    line holds no such groups. ``trend_agree``: the line's plan trend and whether its spans agree
    on it (``plan_trends``)."""
    # spans along the line (within 1 deg, as runs_along) that lie at one offset: a jumper at a
    # tower, a piece there drifting half the gap across, or one whose points are two wires'
    # (scattered across as two wires half the gap apart would be, over the line's own wires'
    # scatter) has its middle between their groups and would chain them into one
    trend, agree = trend_agree
    lean = trend if agree else 0.0
    along = [sp for sp in fitting if sp.conductor == li and abs(sp.offset_slope) <= ALONG_SLOPE_MAX]
    if len(along) < 2:
        return None
    max_scatter = np.hypot(np.median([sp.offset_rms for sp in along]), 0.25 * min_gap_m)
    mine = [sp for sp in along if sp.offset_rms <= max_scatter and
            abs(sp.offset_slope - lean) * (sp.s_to - sp.s_from) <= 0.5 * min_gap_m]
    if len(mine) < 2:
        return None
    # span middles' offsets about the wires' own plan trend: the Hough's line can lie across
    # two phases at a small angle, so that one phase's offset drifts along it by a good part
    # of the gap to the next
    smid = np.array([0.5 * (sp.s_from + sp.s_to) for sp in mine])
    mid = np.array([sp.offset + sp.offset_slope * s for sp, s in zip(mine, smid)]) - lean * smid
    order = np.argsort(mid)
    # runs of span offsets without a gap of half min_gap_m, then neighbouring runs whose
    # middles lie closer than min_gap_m joined
    runs = np.split(order, np.flatnonzero(np.diff(mid[order]) >= 0.5 * min_gap_m) + 1)
    groups = [list(runs[0])]
    for prev, r in zip(runs[:-1], runs[1:]):
        if np.median(mid[r]) - np.median(mid[prev]) < min_gap_m:
            groups[-1] += list(r)
        else:
            groups.append(list(r))
    # a group is a wire along the line: S_min or more, and half the length its spans cover (a piece
    # of a neighbouring wire at the line's end, a tower's arms and jumpers are not)
    cover = sum(sp.s_to - sp.s_from for sp in mine)

    def long_enough(parts):
        return [g for g in parts if sum(mine[k].s_to - mine[k].s_from for k in g) >= max(
            s_min_m, 0.5 * cover / len(parts))]
    groups = long_enough(groups) if len(groups) > 1 else groups
    if not groups:
        return None
    to_centre = np.zeros(len(mine))
    if len(groups) < 2 and np.ptp(mid[groups[0]]) > 0.5 * min_gap_m:
        # one phase whose sub-conductors lie closer than min_gap_m in plan (a triangle
        # bundle): its line runs through the middle of the outermost, not through its points'
        # centroid, which a sub-conductor holding more points pulls off by centimetres (a
        # crossing at 25 deg by 2.4 times as much); each as long as the groups above
        wires = long_enough(runs)
        if len(wires) < 2:
            return None
        centre = 0.5 * (np.median(mid[wires[0]]) + np.median(mid[wires[-1]]))
        for r in runs:
            to_centre[r] = centre - np.median(mid[r])
    return mine, groups, to_centre


def wire_reach_of(cond, conductor_of, pc, hu: float) -> list:
    """Per conductor of ``cond``, how far its wire points (``conductor_of``) reach along it: the
    two ends of their extent in plan (metres), or None where it holds none. The growth and the
    later passes take points past the Hough line's extent (a wire seen again near its pole)."""
    n = len(cond)
    if n == 0:
        return []
    a = np.array([np.asarray(g.coords[0], float)[:2] for g in cond.geometry]) * hu
    d = np.array([np.asarray(g.coords[-1], float)[:2] for g in cond.geometry]) * hu - a
    d /= np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    own = np.flatnonzero((conductor_of >= 0) & (conductor_of < n))
    li = conductor_of[own]
    t = (pc.x[own] * hu - a[li, 0]) * d[li, 0] + (pc.y[own] * hu - a[li, 1]) * d[li, 1]
    t_min, t_max = np.full(n, np.inf), np.full(n, -np.inf)
    np.minimum.at(t_min, li, t)
    np.maximum.at(t_max, li, t)
    return [(a[i] + t_min[i] * d[i], a[i] + t_max[i] * d[i]) if np.isfinite(t_min[i]) else None for i in range(n)]

"""Spans continued: points on a fitted span, span ends grown, the next span past a support,
gaps bridged along one catenary."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..rules import SPAN_POINTS, SURFACE_ROWS, GrowRules, NextSpanRules
from .catenaries import WIRE_HEIGHT_RMS_M, catenary, fit_catenary, fit_tolerance_m, line_fit, median_line_fit
from .clutter import _contrast, _on_spans
from .wires_3d import _longest_run, _refined_trend, peel_catenaries


def span_on_surface(s, off, dz, s_from: float, s_to: float, reach_m: float = SURFACE_ROWS.reach_m,
                    bin_m: float = SURFACE_ROWS.bin_m, min_run_m: float = SURFACE_ROWS.min_run_m,
                    line_m: float = SURFACE_ROWS.line_m, max_tilt_deg: float = SURFACE_ROWS.max_tilt_deg,
                    min_cover: float = SURFACE_ROWS.min_cover, min_tilt_deg: float = 0.0) -> bool:
    """Whether a span lies in a surface: a scan row on a roof or the edge of an eave, which a
    mobile scanner sees as a thin straight line at a range where the surface is too sparse to
    count as one. ``s``, ``off``, ``dz``: candidate points along the line, across it and in
    height, relative to the span (its plan trend and catenary).

    In the cross-section a wire is a point, with its neighbours (sub-conductors, phases of a
    ribbon) at discrete places around it; a surface is a line through it. A span lies in a
    surface when, along some direction within ``max_tilt_deg`` of level, points within
    ``line_m`` of that line fill every ``bin_m`` from the span out to ``min_run_m`` on one
    side, each bin along at least ``min_cover`` of the span's length and denser than the band
    just beside the line (a plane, not the volume of a crown). Four wires 0.4 m apart span
    1.2 m with gaps; a pole or a cross arm holds a few metres of the span, not a third.
    Directions are tried from ``min_tilt_deg`` to ``max_tilt_deg`` either way (90: straight
    down or up, the side of a wall or a truck whose top edge is the span)."""
    near = (s >= s_from) & (s <= s_to) & (np.abs(off) <= reach_m) & (np.abs(dz) <= reach_m)
    s, off, dz = s[near], off[near], dz[near]
    n_sbins = max(int(np.ceil(s_to - s_from)), 1)
    sbin = np.minimum(((s - s_from) // 1.0).astype(np.int64), n_sbins - 1)
    n_bins = int(round(min_run_m / bin_m))
    tilts = np.arange(min_tilt_deg, max_tilt_deg + 1e-9, 5.0)
    for phi in np.radians(np.unique(np.r_[-tilts, tilts])):
        t = off * np.cos(phi) + dz * np.sin(phi)
        n = np.abs(-off * np.sin(phi) + dz * np.cos(phi))
        on, beside = n <= line_m, (n > 2 * line_m) & (n <= 4 * line_m)
        for side in (1.0, -1.0):
            b = np.floor((side * t - bin_m) / bin_m).astype(np.int64)  # bin 0 starts bin_m out
            inb = (b >= 0) & (b < n_bins)
            full = 0
            for k in range(n_bins):
                m = inb & (b == k)
                cover = len(np.unique(sbin[m & on])) / n_sbins
                if cover < min_cover or (m & on).sum() <= (m & beside).sum() / 2:
                    break
                full += 1
            if full == n_bins:
                return True
    return False


def pieces_on_surfaces(s, off, dz, sp, gap_m: float = SURFACE_ROWS.piece_gap_m,
                       lateral_m: float = SURFACE_ROWS.piece_lateral_m) -> float:
    """The share of the span ``sp``'s own points (``s`` along its line, ``off`` across and ``dz``
    over its curve, as for span_on_surface) that lie in pieces, cut where its points leave gaps
    over ``gap_m``, each in a surface of its own: a short wire found along the top edges of two
    roofs a street apart lies in neither surface over its whole length, nor at one tilt."""
    own = (s >= sp.s_from) & (s <= sp.s_to) & (np.abs(off) <= lateral_m) & (np.abs(dz) <= fit_tolerance_m(sp.rms))
    ss = np.sort(s[own])
    if len(ss) < 2:
        return 0.0
    cut = np.flatnonzero(np.diff(ss) > gap_m)
    if not len(cut):
        return 0.0  # one piece: the whole span's test
    on = 0
    for lo, hi in zip(np.r_[0, cut + 1], np.r_[cut, len(ss) - 1]):
        if ss[hi] - ss[lo] >= 1.0 and span_on_surface(s, off, dz, ss[lo], ss[hi]):
            on += hi - lo + 1
    return on / len(ss)


def _spans_by_line(spans, lines, px, py, max_rms: float):
    """Per conductor holding a span that fits (rms <= ``max_rms``): (its index, those spans, the
    points' positions ``s`` along it and ``off`` across it). ``lines`` as for conductors_3d."""
    for li in sorted({sp.conductor for sp in spans if sp.rms <= max_rms}):
        anchor, direction, _, _ = lines[li]
        dx, dy = px - anchor[0], py - anchor[1]
        yield (li, [sp for sp in spans if sp.conductor == li and sp.rms <= max_rms],
               dx * direction[0] + dy * direction[1], -dx * direction[1] + dy * direction[0])


def wire_point_spacing(spans, lines, px, py, line_of, wire_of, max_rms: float, max_gap_m: float) -> float | None:
    """The median distance along the wire between consecutive points of the fitted spans that fit
    (rms <= ``max_rms``), leaving out the gaps over ``max_gap_m`` between their pieces: how densely
    the survey samples its wires. ``p*``: the points, ``line_of``/``wire_of`` their conductor and
    wire (-1: none); None where no span fits."""
    gaps = []
    for li, line_spans, s, _ in _spans_by_line(spans, lines, px, py, max_rms):
        on_line = line_of == li
        for sp in line_spans:
            ss = np.sort(s[on_line & (wire_of == sp.wire) & (s >= sp.s_from) & (s <= sp.s_to)])
            g = np.diff(ss)
            gaps.append(g[g <= max_gap_m])
    gaps = np.concatenate(gaps) if gaps else np.zeros(0)
    return float(np.median(gaps)) if len(gaps) >= 20 else None


def points_on_spans(spans, lines, px, py, pz, max_rms: float, lateral_m: float = SPAN_POINTS.on_span_m):
    """For points outside the 3D step (the candidates the shape test left out: a wire's points
    next to a pole top, whose neighbourhood leans on the pole), the conductor and wire of the
    fitted span each lies on (within its extent, ``lateral_m`` of its plan position and its fit
    tolerance), else -1. ``lines`` as for conductors_3d."""
    line_of = np.full(len(px), -1, np.int64)
    wire_of = np.full(len(px), -1, np.int64)
    best = np.full(len(px), np.inf)
    for li, line_spans, s, off in _spans_by_line(spans, lines, px, py, max_rms):
        r, k = _on_spans(s, off, pz, line_spans, lateral_m, margin_m=0.0)
        hit = np.flatnonzero((k >= 0) & (r < best))
        best[hit], line_of[hit] = r[hit], li
        wire_of[hit] = [line_spans[j].wire for j in k[hit]]
    return line_of, wire_of



def grow_span_ends(spans, lines, px, py, pz, free, max_rms, max_gap_m, reach_m, supports=None,
                   rules: GrowRules | None = None, **overrides):
    """For points outside the 3D step's candidates (under the height window, or left by the shape
    test next to a tower where a wire's neighbourhood leans on the structure): the conductor and
    wire of the fitted span whose catenary, continued past either end, they extend, else -1.

    From each end outward, ``free`` points within ``lateral_m`` in plan and the span's fit
    tolerance are taken while no gap along the line exceeds ``max_gap_m``, up to ``reach_m``, and
    stop at the first whose column (``column_m`` in plan, ``column_dz_m`` up and down) holds more
    points off the catenary than on it, or than the columns of the span's own last ``own_m`` do
    (the median): the pole, arm or crown the wire meets. (Wires hung one over another fill each
    other's columns all along.) ``px, py, pz``: the off-ground points, ``free`` those not on a
    wire yet. ``lines`` as for conductors_3d.

    With ``supports`` (an (n, 2) array of found poles and towers in plan), only the ends of a
    stack's wires (another wire of the line within ``stack_m`` over or under the end) facing a
    support within ``reach_m`` along the line and ``support_m`` across the wire grow, up to
    ``margin_m`` before it, with no column test: in a sparse stack the other wires' few points
    per column make the ratio noise, and the support, once found, tells where the wire ends."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or GrowRules(), **overrides)
    (lateral_m, column_m, column_dz_m, own_m, support_m, margin_m, stack_m) = dataclasses.astuple(r)
    line_of = np.full(len(px), -1, np.int64)
    wire_of = np.full(len(px), -1, np.int64)
    best = np.full(len(px), np.inf)
    if supports is not None:
        supports = np.asarray(supports, float).reshape(-1, 2)
    for li, line_spans, s, off in _spans_by_line(spans, lines, px, py, max_rms):
        if supports is not None:
            anchor, direction, _, _ = lines[li]
            d = supports - anchor
            sup_s, sup_off = d @ direction, d @ [-direction[1], direction[0]]
        for sp in line_spans:
            tol = fit_tolerance_m(sp.rms)
            for end, sign in ((sp.s_to, 1.0), (sp.s_from, -1.0)):
                out = sign * (s - end)
                limit = np.inf
                if supports is not None:
                    ahead_of = sign * (sup_s - end)
                    facing = (ahead_of > 0) & (ahead_of <= reach_m) & (
                        np.abs(sup_off - (sp.offset + sp.offset_slope * sup_s)) <= support_m)
                    if not facing.any() or not _stacked_at(sp, end, sign, line_spans, own_m, stack_m):
                        continue
                    limit = float(ahead_of[facing].min()) - margin_m
                zone = np.flatnonzero((out > -own_m - column_m) & (out <= min(reach_m, limit) + column_m))
                lat = np.abs(off[zone] - (sp.offset + sp.offset_slope * s[zone]))
                zone, lat = zone[lat <= lateral_m + column_m], lat[lat <= lateral_m + column_m]
                dz = pz[zone] - catenary(s[zone], sp.z0, sp.s0, sp.c)
                on = (lat <= lateral_m) & (np.abs(dz) <= tol)
                # the gaps along the wire count its points on a wire already too (another span's,
                # a candidate's), then the free ones up to the first gap are taken
                ahead = np.flatnonzero(on & (out[zone] > 0) & (out[zone] <= limit))
                ahead = ahead[np.argsort(out[zone[ahead]])]
                steps = np.diff(np.r_[0.0, out[zone[ahead]]])
                ahead = ahead[: int(np.argmax(np.r_[steps, np.inf] > max_gap_m))]
                cand = ahead[free[zone[ahead]]]
                if not len(cand):
                    continue
                if np.isfinite(limit):
                    taken = zone[cand]
                else:
                    tree = cKDTree(np.column_stack([s[zone], off[zone]]))

                    def columns(ks):  # (points on the catenary, points off it) in the column of each, in turn
                        for k in ks:
                            nb = np.asarray(tree.query_ball_point((s[zone[k]], off[zone[k]]), column_m))
                            nb = nb[np.abs(dz[nb] - dz[k]) <= column_dz_m]
                            yield int(on[nb].sum()), int((~on[nb]).sum())

                    own = np.flatnonzero(on & (out[zone] <= 0) & (out[zone] > -own_m))
                    ratio = max(1.0, float(np.median([b / a for a, b in columns(own)]))) if len(own) >= 3 else 1.0
                    taken = []
                    for k, (n_on, n_off) in zip(cand, columns(cand)):
                        if n_off > ratio * n_on:
                            break
                        taken.append(zone[k])
                    taken = np.asarray(taken, np.int64)
                r = np.abs(pz[taken] - catenary(s[taken], sp.z0, sp.s0, sp.c))
                better = r < best[taken]
                best[taken[better]] = r[better]
                line_of[taken[better]], wire_of[taken[better]] = li, sp.wire
    return line_of, wire_of


def _stacked_at(sp, end, sign, line_spans, own_m: float, stack_m: float,
                across_m: float = SPAN_POINTS.stack_across_m) -> bool:
    """Whether another wire of the line hangs over or under span ``sp`` near its ``end`` (within
    ``stack_m`` in height and ``across_m`` in plan, along its last ``own_m``): a stack."""
    s = np.linspace(end - sign * own_m, end, 5)
    for other in line_spans:
        if other.wire == sp.wire:
            continue
        inside = (s >= other.s_from) & (s <= other.s_to)
        if not inside.any():
            continue
        si = s[inside]
        dz = np.abs(catenary(si, other.z0, other.s0, other.c) - catenary(si, sp.z0, sp.s0, sp.c))
        doff = np.abs(other.offset + other.offset_slope * si - sp.offset - sp.offset_slope * si)
        if np.any((dz <= stack_m) & (doff <= across_m)):
            return True
    return False



def next_spans(spans, lines, px, py, pz, free, max_rms: float, max_gap_m: float, min_span_m: float,
               line_of=None, wire_of=None, rules: NextSpanRules | None = None, **overrides) -> list:
    """The spans of a found wire beyond its last one: past a support the wire hangs on in a new
    catenary that ``grow_span_ends`` (the old one continued) leaves, and where the survey sees it
    sparsely among crowns (a mobile scan's wire past the last pole it passes) the shape test and
    the Hough have too few of its points.

    From each end of a wire's spans that fit (rms <= ``max_rms``) where no more of the wire follows
    within ``max_gap_m`` (``_span_ends``: past its outermost spans, and into the holes inside it,
    up to where its next fitted span begins; not into a hole where one of its spans was fitted and
    did not fit), the points ``p*``
    (off the ground, metres; ``free``: on no wire yet) within ``lateral_m`` of its plan trend
    continued, up to ``reach_m`` on and ``max_rise_m`` up or down from its end height, are
    searched for catenaries (``peel_catenaries``: thin, gentle, ``min_span_m`` long, no gap over
    ``max_gap_m``). One is that wire's next span when it fits as closely as the span it continues
    (rms at most twice that span's, or ``WIRE_HEIGHT_RMS_M``), its points are not bunched (at most
    half within ``min_span_m`` / 4: a pole's and a crown's blob), it starts within ``max_gap_m`` of the end,
    meets the end within ``max_step_m`` in height (they hang on the same support), is thin across
    (its points' median distance from their plan trend at most ``lateral_m`` / 4), and is a
    concentration of points (within 0.1 m of it ``min_contrast`` times denser than 0.2-0.5 m
    around, among all ``p*``: a crown's points lined up are not). Its far end is searched again,
    up to ``max_rounds`` spans on. ``lines`` as for conductors_3d. With ``line_of``/``wire_of``
    (each p*'s conductor and wire, -1: none), a wire's end is its farthest point on that catenary
    (``grow_span_ends`` carries a wire past its span's end, a sparse one with gaps between).
    Returns [(line, wire, indices into p*, s, offsets across, fit)] per span found."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or NextSpanRules(), **overrides)
    (reach_m, min_points, lateral_m, max_step_m, max_rise_m, min_contrast, max_rounds) = dataclasses.astuple(r)
    found = []
    taken = ~np.asarray(free, bool).copy()
    tree = None
    for li, line_spans, s, off in _spans_by_line(spans, lines, px, py, max_rms):
        for wire in sorted({sp.wire for sp in line_spans}):
            mine = [sp for sp in line_spans if sp.wire == wire]
            ours = (line_of == li) & (wire_of == wire) if line_of is not None else None
            failed = [sp for sp in spans if sp.conductor == li and sp.wire == wire and sp.rms > max_rms]
            for sp, sign, hole in _span_ends(mine, max_gap_m):
                end = sp.s_to if sign > 0 else sp.s_from
                hole_end = end + sign * hole  # where the wire's next fitted span begins (inf: none)
                lo, hi = min(end, hole_end), max(end, hole_end)
                if np.isfinite(hole) and any(min(q.s_to, hi) > max(q.s_from, lo) for q in failed):
                    continue  # the 3D step fitted its points there and found no wire's catenary
                if ours is not None:
                    past = ours & (s > lo) & (s < hi) & \
                        (np.abs(pz - catenary(s, sp.z0, sp.s0, sp.c)) <= fit_tolerance_m(sp.rms))
                    if past.any():
                        end = float(s[past].max() if sign > 0 else s[past].min())
                z_end = float(catenary(end, sp.z0, sp.s0, sp.c))
                o0, o1 = sp.offset, sp.offset_slope
                # as thin in height as the wire it continues: a pole's or a crown's points lined up
                # with the wire's few past the support fit a catenary, loosely
                thin_m = max(2 * sp.rms, WIRE_HEIGHT_RMS_M)
                for _ in range(max_rounds):
                    stop = end + sign * min(reach_m, sign * (hole_end - end))
                    out = sign * (s - end)
                    zone = np.flatnonzero((out > 0) & (sign * (stop - s) > 0) & ~taken &
                                          (np.abs(off - o0 - o1 * s) <= lateral_m) & (np.abs(pz - z_end) <= max_rise_m))
                    if len(zone) < min_points:
                        break
                    hit = None
                    for part, fit in peel_catenaries(s[zone], pz[zone], off[zone], min_points, min_span_m, max_rms,
                                                     gap_m=max_gap_m):
                        k = zone[part]
                        near = float(np.min(sign * (s[k] - end)))
                        step = abs(float(catenary(end, *fit[:3])) - z_end)
                        if near > max_gap_m or step > max_step_m:
                            continue
                        if fit[3] > thin_m or _clumped(s[k], min_span_m / 4):
                            continue
                        # thin across: a wire's points hug their trend, clutter (a cross arm, a
                        # crown's edge) spreads over the band searched (median lateral_m / 2)
                        o1_, o0_ = line_fit(s[k], off[k])
                        if np.median(np.abs(off[k] - o1_ * s[k] - o0_)) > lateral_m / 4:
                            continue
                        if tree is None:
                            tree = cKDTree(np.column_stack([px, py, pz]))
                        if _contrast(tree, k, s, off, pz, fit) < min_contrast:
                            continue
                        if hit is None or near < hit[2]:
                            hit = (k, fit, near)
                    if hit is None:
                        break
                    k, fit = _span_grown(hit[0], hit[1], (s, off, pz), (end, stop, sign), ~taken, lateral_m,
                                         max_gap_m, thin_m)
                    o1, o0 = line_fit(s[k], off[k])  # the next search follows this span's own trend
                    found.append((li, wire, k, s[k], off[k], fit))
                    taken[k] = True
                    end = float(s[k].max() if sign > 0 else s[k].min())
                    z_end = float(catenary(end, *fit[:3]))
    return found


def _span_grown(k, fit, band, reach, free, lateral_m: float, max_gap_m: float, thin_m: float):
    """A next span's points ``k`` (fitted by ``fit``) grown along its own trend and catenary up
    to three times (past a support a wire turns a little, and the end's trend continued loses it
    across a long span): the points of ``band`` (along, across, height) that are ``free``, past
    the end and short of the stop of ``reach`` (end, stop, sign), within ``lateral_m`` of the
    span's trend and its fit's tolerance, in the longest run without a gap over ``max_gap_m``
    holding all of ``k``, kept while the refit is at most ``thin_m`` rms. Returns (k, fit)."""
    s, off, pz = band
    end, stop, sign = reach
    for _refit in range(3):
        o1, o0 = line_fit(s[k], off[k])
        more = np.flatnonzero((sign * (s - end) > 0) & (sign * (stop - s) > 0) & free &
                              (np.abs(off - o0 - o1 * s) <= lateral_m) &
                              (np.abs(pz - catenary(s, *fit[:3])) <= fit_tolerance_m(fit[3])))
        run = _longest_run(s, more, max_gap_m)
        if len(run) <= len(k) or not np.isin(k, run).all():
            break
        refit = fit_catenary(s[run], pz[run])
        if refit[3] > thin_m:
            break
        k, fit = run, refit
    return k, fit


def _clumped(s, window_m: float, share: float = SPAN_POINTS.clump_share) -> bool:
    """More than ``share`` of the positions ``s`` within one window of ``window_m``: a pole's or a
    crown's blob with a few points either side, not a wire's points spread along it."""
    ss = np.sort(s)
    return bool((np.searchsorted(ss, ss + window_m, side="right") - np.arange(len(ss))).max() > share * len(ss))


def _span_ends(spans, min_hole_m: float):
    """The ends of one wire's spans that open onto no more of it: (span, direction along the line,
    length of the hole up to its next span that way, inf past the last). Both ends of the whole
    wire, and the ends of holes longer than ``min_hole_m`` inside it (the wire's points were too
    few there for the 3D step, as past its last span)."""
    out = []
    for sign in (1.0, -1.0):
        for sp in spans:
            end = sp.s_to if sign > 0 else sp.s_from
            ahead = [sign * ((q.s_from if sign > 0 else q.s_to) - end) for q in spans
                     if q is not sp and sign * ((q.s_to if sign > 0 else q.s_from) - end) > 0]
            hole = min(ahead) if ahead else np.inf
            if hole > min_hole_m:
                out.append((sp, sign, hole))
    return out


def _robust_trend(sp, s, off, z, own):
    """((slope, offset), lateral tolerance) of the span ``sp``'s plan trend from its wire's points
    (``own``) on its catenary (``s`` along its line, ``off`` across, heights ``z``), started from
    their least-median line: a crown's points clumped at one end of a short piece tilt a
    least-squares trend (and widen its tolerance) enough to hide that the wire's pieces either
    side of the crown line up. The stored trend where fewer than 3 points."""
    on = own & (s >= sp.s_from) & (s <= sp.s_to) & \
        (np.abs(z - catenary(s, sp.z0, sp.s0, sp.c)) <= fit_tolerance_m(sp.rms))
    if on.sum() < 3:
        return (sp.offset_slope, sp.offset), sp.lateral_tol
    o1, o0, tol = _refined_trend(s[on], off[on], *median_line_fit(s[on], off[on]))
    return (o1, o0), tol


def bridge_gaps(spans, lines, px, py, pz, free, max_rms: float, max_gap_m: float, min_gap_m: float = 1.0,
                sample_m: float = SPAN_POINTS.gap_sample_m, line_of=None, wire_of=None) -> list:
    """The stretches of a wire between two of its fitted pieces along one line that one catenary
    explains: where the wire runs through a crown, the shape test and the Hough lose it, the 3D
    step fits the pieces either side, and ``grow_span_ends`` stops at the foliage. Two spans
    (rms <= ``max_rms``) are one wire across a gap of ``min_gap_m`` to ``max_gap_m`` when their
    plan trends meet mid-gap (within the tighter of their lateral tolerances: a wire a little
    askew to its 2D line moves across it over the gap; with each point's ``line_of`` and
    ``wire_of``, the trends are refitted robustly to each span's own points) and one catenary fits
    both their curves (sampled every ``sample_m``) as closely as their own points fit them (the
    mean of their rms): at a support the two hang in different catenaries and do not. The gap's
    ``free`` points (``p*``: off the ground, metres) on that catenary (within its points' tolerance,
    3 x that rms, and the lateral tolerance of the trend between the two ends) are the wire's.
    Returns [(line, wire, indices into p*, s, offsets across, fit)] per gap bridged, with fit the
    joint (z0, s0, c, rms)."""
    found = []
    taken = ~np.asarray(free, bool).copy()
    for li, line_spans, s, off in _spans_by_line(spans, lines, px, py, max_rms):
        line_spans = sorted(line_spans, key=lambda q: q.s_from)
        trends = {id(q): ((q.offset_slope, q.offset), q.lateral_tol) if wire_of is None else
                  _robust_trend(q, s, off, pz, (line_of == li) & (wire_of == q.wire)) for q in line_spans}
        for a in line_spans:
            (a1, a0), lat_a = trends[id(a)]
            oa = a0 + a1 * a.s_to
            best = None  # (gap, the next piece, its offset at the gap, the lateral tolerance)
            for b in line_spans:
                gap = b.s_from - a.s_to
                (b1, b0), lat_b = trends[id(b)]
                ob = b0 + b1 * b.s_from
                lat = min(lat_a, lat_b)
                # the trends meet mid-gap: a wire a little askew to the line moves across it over the gap
                mid = 0.5 * (a.s_to + b.s_from)
                if min_gap_m <= gap <= max_gap_m and abs(a0 + a1 * mid - b0 - b1 * mid) <= lat and \
                        (best is None or gap < best[0]):
                    best = (gap, b, ob, lat)
            if best is None:
                continue
            _, b, ob, lat = best
            # nothing of this wire's already in the gap (another piece, a span grown into it)
            if any(q is not a and q is not b and q.s_to > a.s_to and q.s_from < b.s_from and
                   abs(q.offset + q.offset_slope * 0.5 * (a.s_to + b.s_from) - oa) <= lat for q in line_spans):
                continue
            sa, sb = np.arange(a.s_from, a.s_to, sample_m), np.arange(b.s_from, b.s_to, sample_m)
            if len(sa) + len(sb) < 6:
                continue
            z0, s0, c, joint = fit_catenary(np.r_[sa, sb], np.r_[catenary(sa, a.z0, a.s0, a.c),
                                                                catenary(sb, b.z0, b.s0, b.c)])
            noise = 0.5 * (a.rms + b.rms)
            if joint > noise:
                continue
            trend = oa + (ob - oa) * (s - a.s_to) / (b.s_from - a.s_to)
            k = np.flatnonzero((s > a.s_to) & (s < b.s_from) & ~taken & (np.abs(off - trend) <= lat) &
                               (np.abs(pz - catenary(s, z0, s0, c)) <= 3 * noise))
            if len(k) < 3:
                continue
            taken[k] = True
            found.append((li, a.wire, k, s[k], off[k], (z0, s0, c, noise)))
    return found

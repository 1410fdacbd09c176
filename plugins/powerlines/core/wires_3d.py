"""The 3D step: wires along each plan line split by height and continuity, a catenary per span,
ribbons of wires side by side redrawn, twin lines, catenaries peeled one at a time."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..rules import (ALONE_AROUND_M, ALONE_MAX_AROUND, ALONE_MAX_NEAR, ALONE_NEAR_M, ALONE_REACH_M, ALONE_ROUNDS,
                     FIT_SEARCH, SPAN_CUTS, SPAN_POINTS, STANDS_CLEAR_MAX, PeelRules, RibbonRules, WireRules)
from .bundles import _chain_pieces, split_bundles
from .catenaries import (
    ISOLATION_M,
    SIDE_BY_SIDE_MIN_GAP_M,
    WIDE_GAP_LINKS,
    WIRE_LATERAL_FLOOR_M,
    WIRE_LATERAL_RMS_M,
    Span,
    catenary,
    fit_catenary,
    fit_tolerance_m,
    kink_cut,
    line_fit,
    split_spans,
)
from .clutter import _on_spans



def conductors_3d(lines, px, py, pz, band: float, z_link: float, s_link: float, min_span: float, ground_z=None,
                  only=None, rules: WireRules | None = None, **overrides):
    """Wires and their catenary spans along each 2D line (of those in ``only``, if given: a line's
    result depends on the points ``band_owner`` gives it and nothing else).

    ``lines``: [(anchor, direction, t_from, t_to)]; p*: candidate 3D points; ``ground_z``: the
    ground's height under each (optional: links heights about its slope along the line). Returns
    (spans, line_of, wire_of): per point the line and the wire it belongs to (-1: none).

    A line's band reaches ``reach`` (default: ``band``) past the ends of its 2D extent, and each
    point belongs to the nearest line that reaches it: a short line of another heading (a crossing
    structure, a tile's stub) does not take the points of a long line it would meet if it were
    extended. Once a line's catenaries are fitted, its points within their tolerance are wire
    points even where their piece was too small to fit on its own.

    ``min_span`` is the granularity of the cuts at attachment points; a piece of wire between
    cuts or occlusions is fitted when at least ``min_piece`` long (default ``min_span / 2``): a
    span's end at a tower, a wire seen in stretches from a street.
    """
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or WireRules(), **overrides)
    (min_points, max_rms, off_link, reach, peel, min_piece) = dataclasses.astuple(r)
    r = dataclasses.replace(r, reach=band if reach is None else reach,
                            min_piece=min_span / 2 if min_piece is None else min_piece)
    spans: list[Span] = []
    line_of = np.full(len(px), -1, np.int64)
    wire_of_point = np.full(len(px), -1, np.int64)
    out = (spans, line_of, wire_of_point)
    owner = band_owner(lines, px, py, band, r.reach)
    for li, (anchor, direction, _, _) in enumerate(lines):
        if only is not None and li not in only:
            continue
        normal = np.array([-direction[1], direction[0]])
        cand = np.flatnonzero(owner == li)
        if len(cand) < min_points:
            continue
        d = np.column_stack([px[cand], py[cand]]) - anchor
        off = d @ normal
        s = d @ direction
        z = pz[cand]
        # height, continuity and lateral position: link points close along the line, in height and
        # across it (within ALS scatter across a wire; sub-conductors of a bundle, closer than that,
        # are told apart afterwards by split_bundles)
        # heights linked about the ground's trend along the line: wires on a hillside climb with the
        # towers, and a sparse wire's points a few metres apart on a 25 % slope differ by > z_link
        slope_z = line_fit(s, ground_z[cand])[0] if ground_z is not None else 0.0
        scaled = np.column_stack([s / s_link, (z - slope_z * s) / z_link, off / off_link])
        pairs = cKDTree(scaled).query_pairs(1.0, output_type="ndarray")
        g = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(cand), len(cand))) \
            if len(pairs) else sparse.coo_matrix((len(cand), len(cand)))
        _, lab = connected_components(g, directed=False)
        lab = split_bundles(s, off, lab, min_points, z=z)
        wire_of = _chain_pieces(s, z, lab, min_points, gap_max=6 * s_link, z_tol=z_link)
        next_wire = int(wire_of.max()) + 1 if len(wire_of) else 0
        for k in np.flatnonzero(wire_of >= 0):
            m = lab == k
            if s[m].max() - s[m].min() < r.min_piece:
                continue
            next_wire = _fit_pieces((s[m], z[m], cand[m], off[m]), li, int(wire_of[k]), next_wire, out, min_span,
                                    s_link, r)
        good = [sp for sp in spans if sp.conductor == li and sp.rms <= max_rms]
        _sparse_wires(li, (cand, s, off, z), good, next_wire, out, min_span, s_link, r)
        _pick_up(li, good, cand, s, z, off, line_of, wire_of_point)
    return spans, line_of, wire_of_point


def _fit_pieces(piece, li, wire, next_wire: int, out, min_span: float, s_link: float, r: WireRules) -> int:
    """One wire's ``piece`` (along, height, point indices, across) of line ``li`` fitted span by
    span for ``conductors_3d``: cut at attachment points, a piece no catenary fits peeled or cut
    again; the spans and the points on them go to ``out`` (spans, line_of, wire_of_point).
    Returns the next free wire number."""
    spans, line_of, wire_of_point = out
    min_points, max_rms, min_piece = r.min_points, r.max_rms, r.min_piece
    sk, zk, ik, ok_ = piece
    n_spans = [0]

    def emit(sel, wire, fit):
        spans.append(make_span(li, wire, n_spans[0], sk[sel], ok_[sel], fit, z=zk[sel]))
        n_spans[0] += 1
        z0, s0, c, rms = fit
        if rms <= max_rms:  # points of a span that is not a wire are not wire points
            resid = np.abs(catenary(sk[sel], z0, s0, c) - zk[sel])
            on = ik[sel][resid <= fit_tolerance_m(rms)]
            line_of[on], wire_of_point[on] = li, wire

    pieces = [(sk.min(), sk.max() + 1e-9)]
    cuts = split_spans(sk, zk, min_span)
    if cuts:
        pieces = list(zip([sk.min()] + cuts, cuts + [sk.max() + 1e-9]))
    while pieces:
        lo_s, hi_s = pieces.pop(0)
        sel = (sk >= lo_s) & (sk < hi_s)
        if sel.sum() < min_points or sk[sel].max() - sk[sel].min() < min_piece:
            continue
        fit = fit_catenary(sk[sel], zk[sel])
        if fit[3] > max_rms and r.peel:
            # one catenary does not fit: wires stacked closer than z_link (a mobile scan's
            # distribution line) or clutter linked to a wire: its catenaries one at a time
            found = peel_catenaries(sk[sel], zk[sel], ok_[sel], min_points, min_span, max_rms, gap_m=s_link)
            if found:
                where = np.flatnonzero(sel)
                for i, (part, part_fit) in enumerate(found):
                    emit(where[part], wire if i == 0 else next_wire, part_fit)
                    next_wire += i > 0
                continue
        if fit[3] > max_rms:
            # one catenary does not fit: look again for an attachment point, more sensitively
            finer = split_spans(sk[sel], zk[sel], min_span, min_drop=SPAN_CUTS.fine_min_drop)
            if not finer:  # no slope evidence (points missing at the pole): the widest gap
                ss_ = np.sort(sk[sel])
                gaps = np.diff(ss_)
                ok = (ss_[:-1] - ss_[0] >= min_span) & (ss_[-1] - ss_[1:] >= min_span) & (gaps >= 1.0)
                if ok.any():
                    g = int(np.argmax(np.where(ok, gaps, -1)))
                    finer = [float(ss_[g] + gaps[g] / 2)]
            if finer:
                edges = [lo_s] + finer + [hi_s]
                pieces = list(zip(edges[:-1], edges[1:])) + pieces
                continue
        if hi_s - lo_s >= 2 * min_span:
            cut = kink_cut(sk[sel], zk[sel], min_span)
            if cut is not None:  # two spans, one attachment between them
                pieces = [(lo_s, cut), (cut, hi_s)] + pieces
                continue
        emit(np.flatnonzero(sel), wire, fit)
    return next_wire


def _sparse_wires(li, band, good: list, next_wire: int, out, min_span: float, s_link: float, r: WireRules) -> None:
    """What the pieces of a line that holds a wire (``good``: its fitted spans, extended here)
    left, searched for catenaries as a whole for ``conductors_3d`` (``band``: the line's candidate
    indices, along, across, height; ``out`` as ``_fit_pieces``'): the sparse stretches of a mobile
    scan, a wire linked to clutter under it, across gaps twice the link's (occlusions); then
    across WIDE_GAP_LINKS for a thin wire (an earth wire over the phases) that the survey hit in
    stretches several V_max apart, kept where nothing else of the band lies around its points (a
    facade's scan rows, a crown's edge have their neighbours there)."""
    spans, line_of, wire_of_point = out
    cand, s, off, z = band
    for gap_m, wide in ((2 * s_link, False), (WIDE_GAP_LINKS * s_link, True)):
        free = np.flatnonzero(line_of[cand] < 0)
        if not (good and r.peel and len(free) >= r.min_points):
            continue
        xyz = np.column_stack([s, off, z]) if wide else None
        for part, fit in peel_catenaries(s[free], z[free], off[free], r.min_points, min_span, r.max_rms,
                                         gap_m=gap_m):
            sel = free[part]
            if wide:
                # (one without a gap over the first search's is what that search turned down)
                if np.diff(np.sort(s[sel])).max() <= 2 * s_link or not stands_clear(xyz, sel, ISOLATION_M):
                    continue
                sel, fit, gone = _whole_sparse_wire(sel, fit, xyz, line_of[cand] >= 0, wire_of_point[cand],
                                                    r.max_rms, ISOLATION_M)
                if gone:  # stretches of it dense enough to have been fitted alone
                    spans[:] = [sp for sp in spans if not (sp.conductor == li and sp.wire in gone)]
                    good[:] = [sp for sp in good if sp.wire not in gone]
            spans.append(make_span(li, next_wire, 0, s[sel], off[sel], fit, z=z[sel]))
            line_of[cand[sel]], wire_of_point[cand[sel]] = li, next_wire
            next_wire += 1
            good.append(spans[-1])


def _whole_sparse_wire(run, fit, xyz, wired, wire_of, max_rms: float, radius_m: float,
                       max_slope: float = FIT_SEARCH.sparse_max_slope, share: float = FIT_SEARCH.sparse_wire_share):
    """A sparse wire found from its longest run (indices ``run`` into a line's band ``xyz``:
    along, across, height; ``fit`` its catenary) with the rest of its points past gaps wider
    still: the band's points on that catenary where it hangs gently (slope at most
    ``max_slope``) that are on no wire (``wired``) and have no point off it within ``radius_m``,
    and the wires (``wire_of``) with ``share`` of their points on it, whole. Returns (indices,
    refitted catenary, those wires); the run alone where the whole fits worse than ``max_rms``."""
    s, z = xyz[:, 0], xyz[:, 2]
    gentle = np.abs(np.sinh((s - fit[1]) / fit[2])) <= max_slope
    on = gentle & (np.abs(catenary(s, *fit[:3]) - z) <= fit_tolerance_m(fit[3]))
    gone = [int(w) for w in np.unique(wire_of[on & wired]) if w >= 0 and np.mean(on[wire_of == w]) >= share]
    take = on & (~wired | np.isin(wire_of, gone))
    rest = np.flatnonzero(~take)
    if len(rest):  # (a point with clutter around it is the clutter's)
        crowded = cKDTree(xyz[rest]).query_ball_point(xyz[take], radius_m, return_length=True) > 0
        take[np.flatnonzero(take)[crowded]] = False
    gone = [w for w in gone if np.all(take[wire_of == w])]  # a wire joins whole or not at all
    take &= ~wired | np.isin(wire_of, gone)
    take[run] = True
    whole = np.flatnonzero(take)
    whole_fit = fit_catenary(s[whole], z[whole])
    if whole_fit[3] > max_rms:
        return run, fit, []
    return whole, whole_fit, gone


def stands_clear(xyz, run, radius_m: float, max_around: float = STANDS_CLEAR_MAX) -> bool:
    """Whether the points ``run`` (indices into ``xyz``) have on average at most ``max_around``
    other points of ``xyz`` within ``radius_m`` each."""
    others = np.setdiff1d(np.arange(len(xyz)), run)
    if not len(others):
        return True
    around = cKDTree(xyz[others]).query_ball_point(xyz[run], radius_m, return_length=True)
    return float(np.mean(around)) <= max_around


def alone_beside_wires(xyz, wire, free, reach_m: float = ALONE_REACH_M, near_m: float = ALONE_NEAR_M,
                       max_near: int = ALONE_MAX_NEAR, around_m: float = ALONE_AROUND_M,
                       max_around: int = ALONE_MAX_AROUND, rounds: int = ALONE_ROUNDS, tree=None):
    """The points ``free`` (mask over ``xyz``, metres) within ``reach_m`` of a point of ``wire``
    (mask) that stand alone in the air: at most ``max_near`` other points that are not wire within
    ``near_m`` and ``max_around`` within ``around_m``. They are the wire points its fits left out
    (a sparse scan's points off the catenary's tolerance) and a wire hanging beside it closer than
    the 2D step tells apart; a crown's or a pole's points have many others around them. Taken
    points are wire for the next of ``rounds`` (a run of them off a wire's end). ``tree``: a
    cKDTree of ``xyz`` where the caller has one. Returns (taken indices, for each the ``wire``
    point it was taken through)."""
    wire = np.asarray(wire, bool).copy()
    root = np.where(wire, np.arange(len(xyz)), -1)
    if not wire.any() or not np.any(free & ~wire):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    tree = cKDTree(xyz) if tree is None else tree
    for _ in range(rounds):
        on = np.flatnonzero(wire)
        wires = cKDTree(xyz[on])
        cand = np.flatnonzero(free & ~wire)
        d, j = wires.query(xyz[cand], distance_upper_bound=reach_m)
        near = np.isfinite(d)
        cand, j = cand[near], j[near]
        if not len(cand):
            break
        # others that are not wire (the point itself is one of the tree's)
        alone = (tree.query_ball_point(xyz[cand], near_m, return_length=True)
                 - wires.query_ball_point(xyz[cand], near_m, return_length=True) - 1 <= max_near)
        alone &= (tree.query_ball_point(xyz[cand], around_m, return_length=True)
                  - wires.query_ball_point(xyz[cand], around_m, return_length=True) - 1 <= max_around)
        if not alone.any():
            break
        wire[cand[alone]] = True
        root[cand[alone]] = root[on[j[alone]]]
    taken = np.flatnonzero(wire & (root != np.arange(len(xyz))))
    return taken, root[taken]



def ribbon_lines(lines, px, py, band_m, min_length_m, max_gap_m, rules: RibbonRules | None = None, **overrides):
    """The Hough's lines over a ribbon redrawn one per wire: wires side by side closer than twice
    ``band_m`` (a horizontal three-phase line 0.3-0.4 m apart) put several into one band, and the
    Hough draws a line between two of them, leaning from one to the next over the corridor
    (a 0.03 deg lean is 0.3 m over 600 m); which ones it joins changes from tile to tile.

    ``lines``: [(anchor, direction, t_from, t_to)] in metres; p*: the candidates (metres). Lines
    within ``max_angle_deg`` of one another and within twice ``band_m`` across, overlapping
    along, form a group; its band's points, in the frame of its longest line, are turned by the
    angle (within ``search_deg``, ``step_deg`` steps) that stacks their offsets across most
    sharply (wires side by side are parallel and straight in plan: the sum of squared counts of
    ``bin_m`` bins). Peaks of that histogram holding ``min_points`` within ``peak_m``, their points
    running ``min_length_m`` along (gaps under ``max_gap_m``), are the wires in plan; peaks closer
    than ``min_gap_m`` are one (a bundle's sub-conductors stay one conductor per phase, as
    ``split_bundles`` keeps them). Only lines ``4 * min_length_m`` or longer take part (a tower's
    members stay out), a wire runs along half the longest line or more, and a group is redrawn
    where it holds ``min_wires`` wires or more (two side by side the 3D step tells apart, as a
    bundle's pair) that hold ``min_share`` of its band's points (an airborne survey's scatter
    across a wire, as wide as the gaps between them, leaves the Hough's lines as good as any)
    and its lines are not already one per wire, each within ``match_m`` of it at both ends. A
    line reaching out of the ribbon stays.

    Returns (lines, source, points) with each group redrawn (source: per returned line, the index
    of the input line nearest it, whose attributes it takes; points: how many of the band's points
    a redrawn line holds, None for a line left as it was), or None where no group changed."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or RibbonRules(), **overrides)
    (min_gap_m, max_angle_deg, search_deg, step_deg, bin_m, peak_m, min_points, match_m, min_wires,
     min_share) = dataclasses.astuple(r)
    n = len(lines)
    if n == 0:
        return None
    dirs = np.array([d for _, d, _, _ in lines])
    pairs = []
    cos_lim = np.cos(np.radians(max_angle_deg))
    long_ = [lines[k][3] - lines[k][2] >= 4 * min_length_m for k in range(n)]  # (a tower's members stay out)
    for i in range(n):
        a, d, t0, t1 = lines[i]
        nrm = np.array([-d[1], d[0]])
        for j in range(i + 1, n):
            if not (long_[i] and long_[j]) or abs(float(dirs[i] @ dirs[j])) < cos_lim:
                continue
            b, e, u0, u1 = lines[j]
            ends = np.array([b + u0 * e, b + u1 * e])
            along = np.sort((ends - a) @ d)
            if along[1] < t0 or along[0] > t1:
                continue
            if np.abs((ends - a) @ nrm).max() <= 2 * band_m:
                pairs.append((i, j))
    i, j = np.array(pairs, np.int64).reshape(-1, 2).T
    _, group_of = connected_components(sparse.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)), directed=False)
    groups = {}
    for k in range(n):
        groups.setdefault(int(group_of[k]), []).append(k)
    out, source, held, changed = [], [], [], False
    pts = np.column_stack([px, py])
    for members in groups.values():
        redrawn = _ribbon_group(lines, members, pts, band_m, min_length_m, max_gap_m, r) if long_[members[0]] else None
        if redrawn is None:
            out += [lines[k] for k in members]
            source += members
            held += [None] * len(members)
        else:
            changed = True
            out += [ln for ln, _, _ in redrawn]
            source += [k for _, k, _ in redrawn]
            held += [m for _, _, m in redrawn]
    return (out, source, held) if changed else None


def _ribbon_group(lines, members, pts, band_m, min_length_m, max_gap_m, r: RibbonRules):
    """One group of ``ribbon_lines``: [(line, source index, points held or None)] redrawn, or
    None (left as it is)."""
    min_gap_m, min_points, min_wires, min_share = r.min_gap_m, r.min_points, r.min_wires, r.min_share
    main = max(members, key=lambda k: lines[k][3] - lines[k][2])
    a, d, _, _ = lines[main]
    longest = lines[main][3] - lines[main][2]
    nrm = np.array([-d[1], d[0]])
    inside = np.zeros(len(pts), bool)
    for k in members:
        b, e, u0, u1 = lines[k]
        rel = pts - b
        t = rel @ e
        inside |= (np.abs(rel @ np.array([-e[1], e[0]])) <= band_m) & (t >= u0 - band_m) & (t <= u1 + band_m)
    if inside.sum() < 2 * min_points:
        return None
    rel = pts[inside] - a
    s, o = rel @ d, rel @ nrm
    oc = _turned_offsets(s, o, r)
    wires = _ribbon_peaks(s, oc, longest, max_gap_m, min_length_m, r)
    if not wires:
        return None
    wires.sort()
    # peaks closer than min_gap_m are one wire (a bundle's), at their points' weighted middle
    merged = [[wires[0]]]
    for w in wires[1:]:
        if w[0] - merged[-1][-1][0] < min_gap_m:
            merged[-1].append(w)
        else:
            merged.append([w])
    if len(merged) < min_wires:
        return None
    centres = [sum(c * m for c, m in g) / sum(m for _, m in g) for g in merged]
    on_wires = np.abs(oc[:, None] - np.array([c for g in merged for c, _ in g])[None, :]).min(axis=1) <= r.peak_m
    if on_wires.mean() < min_share:
        return None
    # each wire's own line: its points (within peak_m, or within half the gap to its neighbours
    # for a merged bundle) refitted along the turned frame
    peak_m = r.peak_m
    redrawn = []
    for g, c in zip(merged, centres):
        half = max(peak_m, 0.5 * (g[-1][0] - g[0][0]) + peak_m)
        mine = np.abs(oc - c) <= half
        runs = _runs(s[mine], max_gap_m, min_length_m)
        if not runs:
            continue
        t0, t1 = min(q[0] for q in runs), max(q[1] for q in runs)
        on = mine & (s >= t0) & (s <= t1)
        slope, icpt = line_fit(s[on], o[on])
        d2 = (d + slope * nrm) / np.hypot(1.0, slope)
        a2 = a + t0 * d + (icpt + slope * t0) * nrm
        redrawn.append(((a2, d2, 0.0, float((t1 - t0) * np.hypot(1.0, slope))), (slope, icpt, t0, t1),
                        int(on.sum())))
    if not redrawn:
        return None
    # each input line's offsets at its ends, in the group's frame
    def ends_of(k):
        b, e, u0, u1 = lines[k]
        p = np.array([b + u0 * e, b + u1 * e]) - a
        return p @ d, p @ nrm
    matched = set()
    for k in members:
        ss, oo = ends_of(k)
        hit = [w for w, (_, (sl, ic, _, _), _) in enumerate(redrawn)
               if np.all(np.abs(oo - (sl * ss + ic)) <= r.match_m)]
        if len(hit) != 1 or hit[0] in matched:
            break
        matched.add(hit[0])
    else:
        if len(matched) == len(redrawn) == len(members):
            return None
    def offset_at(k, at):  # input line k's offset where it passes along-position ``at``
        b, e, _, _ = lines[k]
        t = (at - float((b - a) @ d)) / max(float(e @ d), 1e-9)
        return float((b - a) @ nrm) + t * float(e @ nrm)

    out = []
    for ln, (sl, ic, t0, t1), held in redrawn:
        mid = 0.5 * (t0 + t1)
        out.append((ln, min(members, key=lambda k: abs(offset_at(k, mid) - (sl * mid + ic))), held))
    # a line reaching out of the ribbon (another wire beside it, under min_length_m of it in
    # the band) stays
    for k in members:
        ss, oo = ends_of(k)
        across = np.array([sl * ss + ic for _, (sl, ic, _, _), _ in redrawn])
        if np.any(oo < across.min(axis=0) - 0.5 * min_gap_m) or np.any(oo > across.max(axis=0) + 0.5 * min_gap_m):
            out.append((lines[k], k, None))
    return out


def _turned_offsets(s, o, r: RibbonRules):
    """The offsets ``o`` across a ribbon group's frame turned about the middle of ``s`` by the
    angle (within ``r.search_deg``, ``r.step_deg`` steps) that stacks them most sharply (the sum
    of squared counts of ``r.bin_m`` bins): wires side by side are parallel and straight in plan."""
    sc = s - np.median(s)  # turn about the middle: the offsets stay where they are there
    best, best_phi = -1.0, 0.0
    for phi in np.radians(np.arange(-r.search_deg, r.search_deg + r.step_deg / 2, r.step_deg)):
        turned = o - phi * sc
        h = np.bincount(((turned - turned.min()) / r.bin_m).astype(np.int64))
        score = float(h @ h)
        if score > best:
            best, best_phi = score, phi
    return o - best_phi * sc


def _ribbon_peaks(s, oc, longest: float, max_gap_m: float, min_length_m: float, r: RibbonRules) -> list:
    """(centre, points) of the peaks of the turned offsets ``oc`` that hold a wire: ``r.min_points``
    within ``r.peak_m``, running along half the ``longest`` line or more in runs of
    ``min_length_m`` (gaps under ``max_gap_m``): not a stub of an arm or a jumper."""
    bin_m, peak_m = r.bin_m, r.peak_m
    lo, hi = float(oc.min()) - 2 * bin_m, float(oc.max()) + 2 * bin_m
    nb = int(np.ceil((hi - lo) / bin_m)) + 1
    h = np.bincount(((oc - lo) / bin_m).astype(np.int64).clip(0, nb - 1), minlength=nb).astype(float)
    hs = np.convolve(h, [1.0, 2.0, 1.0], mode="same")
    peaks = [i for i in range(1, nb - 1) if hs[i] > 0 and hs[i] >= hs[i - 1] and hs[i] > hs[i + 1]]
    wires = []
    for i in peaks:
        c = lo + (i + 0.5) * bin_m
        near = np.abs(oc - c) <= peak_m
        if near.sum() < r.min_points:
            continue
        c = float(np.median(oc[near]))
        near = np.abs(oc - c) <= peak_m
        runs = _runs(s[near], max_gap_m, min_length_m)
        if sum(q[1] - q[0] for q in runs) < 0.5 * longest:
            continue
        wires.append((c, int(near.sum())))
    return wires


def _runs(t, max_gap_m: float, min_length_m: float) -> list:
    """(first, last) of the runs of the positions ``t`` with every gap under ``max_gap_m``, at
    least ``min_length_m`` long."""
    if len(t) < 2:
        return []
    t = np.sort(t)
    cut = np.flatnonzero(np.diff(t) >= max_gap_m)
    firsts, lasts = np.r_[t[0], t[cut + 1]], np.r_[t[cut], t[-1]]
    return [(float(f), float(g)) for f, g in zip(firsts, lasts) if g - f >= min_length_m]


def twin_lines(spans, lines, max_rms: float, min_span_m: float, band_m: float,
               across_m: float = 0.5 * SIDE_BY_SIDE_MIN_GAP_M,
               max_angle_deg: float = FIT_SEARCH.twin_max_angle_deg) -> list[tuple[int, int]]:
    """Pairs of lines (i < j; ``lines``: [(anchor, direction, t_from, t_to)]) whose bands share a
    wire: the Hough can draw a ribbon's lines between its phases, a few tenths of a metre either
    side of the middle one, and each band then holds the points on its side of that wire (two
    conductors along it, each leaning with the boundary between the bands). Lines nearly parallel
    and within two bands (``band_m``) of each other are compared: they are twins where a span of
    each (fitting, ``min_span_m`` long, thin across) overlaps the other's by ``min_span_m`` on the
    same plan trend (within ``across_m``) and the same catenary (within their fit tolerance) at
    both ends and the middle of the overlap."""
    good = {}
    for sp in spans:
        if sp.rms <= max_rms and sp.s_to - sp.s_from >= min_span_m and sp.offset_rms <= WIRE_LATERAL_RMS_M:
            good.setdefault(sp.conductor, []).append(sp)
    cos_min = np.cos(np.radians(max_angle_deg))
    pairs = []
    keys = sorted(good)
    for x, i in enumerate(keys):
        ai, di, _, _ = lines[i]
        ni = np.array([-di[1], di[0]])
        for j in keys[x + 1:]:
            aj, dj, tj0, tj1 = lines[j]
            if abs(float(di @ dj)) < cos_min or \
                    min(abs(float((aj + t * dj - ai) @ ni)) for t in (tj0, tj1)) > 2 * band_m:
                continue
            if any(_same_wire(p, span_in_frame(q, lines[j], lines[i], i, q.wire), min_span_m, across_m)
                   for p in good[i] for q in good[j]):
                pairs.append((i, j))
    return pairs


def _same_wire(p: Span, q: Span, min_overlap_m: float, across_m: float) -> bool:
    lo, hi = max(p.s_from, q.s_from), min(p.s_to, q.s_to)
    if hi - lo < min_overlap_m:
        return False
    s = np.array([lo, 0.5 * (lo + hi), hi])
    across = np.abs((p.offset + p.offset_slope * s) - (q.offset + q.offset_slope * s))
    height = np.abs(catenary(s, p.z0, p.s0, p.c) - catenary(s, q.z0, q.s0, q.c))
    return bool((across <= across_m).all() and (height <= fit_tolerance_m(max(p.rms, q.rms))).all())


def band_owner(lines, px, py, band: float, reach: float) -> np.ndarray:
    """Per point, the 2D line whose band holds it (-1: none): the nearest line that reaches it,
    ``reach`` past the ends of its extent, if within ``band`` of it (bands of neighbouring lines
    overlap)."""
    owner = np.full(len(px), -1)
    best = np.full(len(px), np.inf)
    for li, (anchor, direction, t0, t1) in enumerate(lines):
        normal = np.array([-direction[1], direction[0]])
        d = np.abs((px - anchor[0]) * normal[0] + (py - anchor[1]) * normal[1])
        along = (px - anchor[0]) * direction[0] + (py - anchor[1]) * direction[1]
        beyond = np.maximum(np.maximum(t0 - along, along - t1), 0.0)
        score = np.where(beyond <= reach, d, np.inf)
        closer = score < best
        owner[closer], best[closer] = li, score[closer]
    owner[best > band] = -1
    return owner


def make_span(line: int, wire: int, number: int, s, off, fit, z=None) -> Span:
    """The Span of a catenary ``fit`` (z0, s0, c, rms) to points at ``s`` along the line and
    ``off`` across it: its extent, sag below the chord and plan position (a straight trend).

    With the points' heights ``z``, the plan trend and the lateral tolerance come from the points
    on the catenary (within its fit tolerance) alone: foliage the wire runs through, linked to its
    piece, scatters across it and must neither pull the trend nor widen what is taken as wire."""
    z0, s0, c, rms = fit
    a, b = float(s.min()), float(s.max())
    ss = np.linspace(a, b, 200)
    chord = catenary(a, z0, s0, c) + (catenary(b, z0, s0, c) - catenary(a, z0, s0, c)) * (ss - a) / (b - a)
    sag = float(np.max(chord - catenary(ss, z0, s0, c)))
    o1, o0 = line_fit(s, off) if len(s) >= 3 else (0.0, float(np.median(off)))
    o_rms = float(np.sqrt(np.mean((off - o1 * s - o0) ** 2)))
    lateral_tol = np.inf
    if z is not None:
        dz = z - catenary(s, z0, s0, c)
        on = np.abs(dz) <= fit_tolerance_m(rms)
        if on.sum() >= 3:
            o1, o0, lateral_tol = _refined_trend(s[on], off[on], *line_fit(s[on], off[on]))
    return Span(line, wire, number, s0, c, z0, a, b, rms, len(s), sag, float(o0), float(o1), o_rms, lateral_tol)


def thin_across(sp: Span) -> bool:
    """Whether a span's points are a wire's across its line: their lateral rms about its plan
    trend within WIRE_LATERAL_RMS_M or, where foliage the wire runs into is linked to its piece
    (a crown at a pole, under a low line), the points on its catenary within that in robust
    sigma (its lateral tolerance, 3 sigma, within 3 WIRE_LATERAL_RMS_M). A crown's edge lined up
    along a street scatters across the line either way."""
    return sp.offset_rms <= WIRE_LATERAL_RMS_M or sp.lateral_tol <= 3 * WIRE_LATERAL_RMS_M


def _refined_trend(s, off, o1: float, o0: float) -> tuple[float, float, float]:
    """(slope, offset, lateral tolerance) of a wire's plan trend ``off = o1·s + o0`` refitted
    twice to the points within 3 robust sigma of it (the tolerance, at least
    WIRE_LATERAL_FLOOR_M): crown points linked to the wire neither pull it nor widen it."""
    for refit in (True, True, False):
        r = np.abs(off - o1 * s - o0)
        tol = max(3 * 1.4826 * float(np.median(r)), WIRE_LATERAL_FLOOR_M)
        if refit and (r <= tol).sum() >= 3:
            o1, o0 = line_fit(s[r <= tol], off[r <= tol])
    return o1, o0, tol


def span_in_frame(sp: Span, line_from, line_to, conductor: int, wire: int) -> Span:
    """The span ``sp`` of line ``line_from`` re-expressed along ``line_to`` (both (anchor,
    direction, t0, t1), within a few degrees of each other): the same catenary and plan trend,
    as the span ``wire`` of ``conductor``."""
    import dataclasses

    (ag, dg, _, _), (ah, dh, _, _) = line_from, line_to
    nh = np.array([-dh[1], dh[0]])
    cos, sin = float(dg @ dh), float(dg @ nh)
    c0, o0 = float((ag - ah) @ dh), float((ag - ah) @ nh)
    slope = sin / cos + sp.offset_slope
    ends = sorted((c0 + sp.s_from * cos, c0 + sp.s_to * cos))
    return dataclasses.replace(sp, conductor=conductor, wire=wire, s0=c0 + sp.s0 * cos, c=sp.c * abs(cos),
                               s_from=ends[0], s_to=ends[1], offset_slope=slope,
                               offset=o0 + sp.offset * cos - c0 * slope)



def peel_catenaries(s, z, off, min_points, min_span, max_rms, gap_m, rules: PeelRules | None = None, **overrides):
    """Catenaries in a piece of (along-line, height) points that no single one fits, strongest
    first: a parabola through three points (a catenary's first-order form) with the most points
    within ``tol_m``, its points' longest run without a gap over ``gap_m``, a catenary refitted
    to them; kept when its points are thin across the line (``off``: lateral rms within
    ``lateral_tol_m`` about a straight trend, a crown's points lined up in (s, z) are not), it
    fits within ``max_rms``, spans ``min_span`` and hangs gently (slope at most ``max_slope``);
    its points are removed and the rest searched again. The ``max_tries`` best-supported
    parabolas are tried before giving up (RANSAC, seeded: reproducible).
    Returns [(indices into s, (z0, s0, c, rms))]."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or PeelRules(), **overrides)
    (tol_m, lateral_tol_m, max_slope, n_samples, max_tries, seed) = dataclasses.astuple(r)
    rng = np.random.default_rng(seed)
    left = np.arange(len(s))
    found = []
    while len(left) >= min_points:
        ls, lz, lo_ = s[left], z[left], off[left]
        tri = np.sort(rng.integers(0, len(left), (n_samples, 3)), axis=1)
        tri[n_samples // 2:] = _local_triples(ls, lz, n_samples - n_samples // 2, min_span, max_slope, rng)
        # each triple in order along the line (the points come in the survey's order, not along it)
        tri = np.take_along_axis(tri, np.argsort(ls[tri], axis=1, kind="stable"), axis=1)
        s1, s2, s3 = (ls[tri[:, i]] for i in range(3))
        z1, z2, z3 = (lz[tri[:, i]] for i in range(3))
        with np.errstate(divide="ignore", invalid="ignore"):
            d12, d23 = (z2 - z1) / (s2 - s1), (z3 - z2) / (s3 - s2)
            a2 = (d23 - d12) / (s3 - s1)
            a1 = d12 - a2 * (s1 + s2)
            a0 = z1 - a1 * s1 - a2 * s1 * s1
            # a wire hangs (curvature >= 0, a little slack for noise) and gently around its points
            lo, hi = np.maximum(s1 - min_span, ls.min()), np.minimum(s3 + min_span, ls.max())
            ok = np.isfinite(a0) & (s3 - s1 >= min_span / 2) & (a2 >= -1e-3) & \
                (np.abs(2 * a2 * lo + a1) <= max_slope) & (np.abs(2 * a2 * hi + a1) <= max_slope)
        if not ok.any():
            break
        a2, a1, a0 = a2[ok], a1[ok], a0[ok]
        votes = np.zeros(len(a2), np.int64)
        for i in range(0, len(ls), 4096):  # (samples x points) in blocks: bounded memory
            b = slice(i, i + 4096)
            pred = (a2[:, None] * ls[None, b] + a1[:, None]) * ls[None, b] + a0[:, None]
            votes += np.count_nonzero(np.abs(pred - lz[None, b]) <= tol_m, axis=1)
        hit = None
        rejected = np.zeros(len(ls), bool)  # inliers of hypotheses already turned down
        tries = 0
        for best in np.argsort(-votes, kind="stable"):
            if votes[best] < min_points or tries >= max_tries:
                break
            inl = np.flatnonzero(np.abs((a2[best] * ls + a1[best]) * ls + a0[best] - lz) <= tol_m)
            # variants of a turned-down hypothesis (a flat band of clutter draws many samples)
            # would use up the tries before a weaker wire is looked at
            if rejected[inl].mean() > 0.5:
                continue
            tries += 1
            rejected[inl] = True
            # local optimisation: a parabola refitted to the longest run of inliers, recounted
            # (three points a few metres apart leave the curvature loose; the run fixes it)
            for _ in range(3):
                run = _longest_run(ls, inl, gap_m)
                if len(run) < 3 or np.ptp(ls[run]) < min_span / 2:
                    break
                c2, c1, c0 = np.polyfit(ls[run], lz[run], 2)
                more = np.flatnonzero(np.abs((c2 * ls + c1) * ls + c0 - lz) <= tol_m)
                if len(more) <= len(inl):
                    break
                inl = more
            # the longest run of them along the line (another wire's crossing or clutter elsewhere)
            run = _longest_run(ls, inl, gap_m)
            if len(run) < min_points or np.ptp(ls[run]) < min_span:
                continue
            # a wire is thin across the line too (points of crowns lined up in (s, z) are not):
            # its run without the points off its plan trend (robust: twice, about the median)
            thin = np.ones(len(run), bool)
            for _ in range(2):
                o1, o0 = line_fit(ls[run][thin], lo_[run][thin])
                r = lo_[run] - o1 * ls[run] - o0
                mad = np.median(np.abs(r[thin] - np.median(r[thin])))
                thin = np.abs(r - np.median(r[thin])) <= max(3 * 1.4826 * mad, WIRE_LATERAL_FLOOR_M)
            if thin.sum() < max(min_points, len(run) // 2) or np.sqrt(np.mean(r[thin] ** 2)) > lateral_tol_m:
                continue
            run = run[thin]
            if np.ptp(ls[run]) < min_span:
                continue
            fit = fit_catenary(ls[run], lz[run])
            z0, s0, c, rms = fit
            slope = np.abs(np.sinh((np.array([ls[run].min(), ls[run].max()]) - s0) / c))
            if rms <= max_rms and np.all(slope <= max_slope):
                o1, o0 = line_fit(ls[run], lo_[run])
                hit = run, fit, (o1, o0, float(np.sqrt(np.mean((lo_[run] - o1 * ls[run] - o0) ** 2))))
                break
        if hit is None:
            break
        run, (z0, s0, c, rms), (o1, o0, o_rms) = hit
        r = np.abs(catenary(ls, z0, s0, c) - lz)
        on = (r <= fit_tolerance_m(rms)) & (ls >= ls[run].min()) & (ls <= ls[run].max()) & \
            (np.abs(lo_ - o1 * ls - o0) <= fit_tolerance_m(o_rms))
        found.append((left[on], hit[1]))
        left = left[~on]
    return found


def _longest_run(s, idx, gap_m: float) -> np.ndarray:
    """The longest run of the points ``idx`` along ``s`` without a gap over ``gap_m``."""
    order = idx[np.argsort(s[idx])]
    return max(np.split(order, np.flatnonzero(np.diff(s[order]) > gap_m) + 1), key=len)


def _local_triples(s, z, n: int, min_span: float, max_slope: float, rng, draws: int = FIT_SEARCH.triple_draws,
                   chord_tol_m: float = FIT_SEARCH.triple_chord_m):
    """Point triples (indices) for catenary hypotheses drawn along the line: a first point, a
    third min_span/2 to min_span further on that a wire could reach from it (slope ≤ max_slope),
    a second between them near their chord. Where a wire is a few percent of a band's points
    (a sparse wire over a tree), uniform triples almost never hold three of its points."""
    order = np.argsort(s, kind="stable")
    ss, zz = s[order], z[order]
    i = rng.integers(0, len(s), n)
    lo = np.searchsorted(ss, ss[i] + min_span / 2)
    hi = np.searchsorted(ss, ss[i] + min_span)
    width = hi - lo
    k = lo[:, None] + (rng.random((n, draws)) * np.maximum(width, 1)[:, None]).astype(np.int64)
    k = np.minimum(k, len(s) - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.abs(zz[k] - zz[i][:, None]) / (ss[k] - ss[i][:, None])
    ok = (width[:, None] > 0) & (slope <= max_slope)
    # the most level of the draws: a wire is, locally, and clutter around it mostly is not
    k = k[np.arange(n), np.argmin(np.where(ok, slope, np.inf), axis=1)]
    found = ok.any(axis=1)
    j = i[:, None] + 1 + (rng.random((n, draws)) * np.maximum(k - i - 1, 1)[:, None]).astype(np.int64)
    j = np.minimum(j, len(s) - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        chord = zz[i][:, None] + (zz[k] - zz[i])[:, None] * (ss[j] - ss[i][:, None]) / (ss[k] - ss[i])[:, None]
    resid = np.abs(zz[j] - chord)
    near = resid <= chord_tol_m
    j = j[np.arange(n), np.argmin(np.where(near, resid, np.inf), axis=1)]
    found &= near.any(axis=1) & (k > i + 1)
    out = np.sort(order[np.column_stack([i, j, k])], axis=1)
    # where no such triple exists, a uniform one
    out[~found] = np.sort(rng.integers(0, len(s), ((~found).sum(), 3)), axis=1)
    return out


def _pick_up(li, line_spans, cand, s, z, off, line_of, wire_of_point, lateral_m: float = SPAN_POINTS.pick_up_m):
    """Points of a line's band not yet on a wire that lie on one of its fitted spans (within the
    span's extent, ``lateral_m`` of its plan position and its fit tolerance): pieces of a wire
    too small to fit alone (sparse stretches, a sub-conductor seen a few times)."""
    free = line_of[cand] < 0
    if not line_spans or not free.any():
        return
    _, k = _on_spans(s[free], off[free], z[free], line_spans, lateral_m, margin_m=0.5)
    got = k >= 0
    fi = cand[free][got]
    line_of[fi], wire_of_point[fi] = li, [line_spans[j].wire for j in k[got]]

"""What is no wire: foliage around a wire's curve, points off a span's plan trend, lines in or
along a surface."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..rules import CORE_M, RING_FROM_M, RING_TO_M, SPAN_POINTS, AlongSurfaceRules, FoliageRules, SurfaceRules
from .catenaries import WIRE_ID_BASE, catenary, fit_tolerance_m, line_fit


def _contrast(tree, k, s, off, z, fit) -> float:
    """How much denser the points of ``tree`` (all the points, at ``s`` along the line, ``off``
    across it, height ``z``) are within 0.1 m of the span of the points ``k`` (its catenary
    ``fit``, its own plan trend) than 0.2-0.5 m around it, per unit of cross-section area: a wire
    is a concentration of points, a crown's points lined up are not."""
    o1, o0 = line_fit(s[k], off[k])
    near = np.unique(np.concatenate(tree.query_ball_point(tree.data[k], 0.5)))
    near = near[(s[near] >= s[k].min()) & (s[near] <= s[k].max())]
    return core_ring_contrast(*core_and_ring(np.hypot(off[near] - o0 - o1 * s[near],
                                                      z[near] - catenary(s[near], *fit[:3]))))


def core_and_ring_masks(r) -> tuple[np.ndarray, np.ndarray]:
    """Of points at distances ``r`` from a wire in its cross-section: which lie within 0.1 m (its
    core) and which 0.2-0.5 m (the ring around it)."""
    return r <= CORE_M, (r > RING_FROM_M) & (r <= RING_TO_M)


def core_and_ring(r) -> tuple[int, int]:
    """How many of the points at distances ``r`` lie in the core and in the ring
    (``core_and_ring_masks``)."""
    core, ring = core_and_ring_masks(r)
    return int(core.sum()), int(ring.sum())


def core_ring_contrast(core, ring):
    """The core's density over the ring's, per unit of cross-section area (both x pi); counts or
    arrays of counts (the areas over pi written out: CORE_M², RING_TO_M² - RING_FROM_M²)."""
    return (core / 0.01) / np.maximum(ring / (0.25 - 0.04), 1e-9)


def off_their_spans(spans, lines, px, py, pz, line_of, wire_of, max_rms: float, clutter_xyz=None,
                    clutter_m: float = SPAN_POINTS.clutter_m, margin_m: float = SPAN_POINTS.clutter_margin_m) -> np.ndarray:
    """Per wire point (``line_of``, ``wire_of`` its conductor and wire; -1: none): whether it lies
    farther across from the plan trend of its wire's span than that span's lateral tolerance (the
    span at its position, within ``margin_m`` of its extent, with the least height residual) and,
    with ``clutter_xyz`` (the points off the ground on no wire), has one of those within
    ``clutter_m``. Foliage the wire runs through lies on its catenary in height but scattered
    across it, among more foliage; a wire point off the trend with nothing around it is the
    tail of the wire's own scatter (a long span swings in the wind). A point on no span of its
    wire (a short wire's) is kept. ``lines`` as for conductors_3d."""
    off_trend = np.zeros(len(px), bool)
    for li in np.unique(line_of[line_of >= 0]):
        anchor, direction, _, _ = lines[li]
        for wire in np.unique(wire_of[line_of == li]):
            wire_spans = [sp for sp in spans if sp.conductor == li and sp.wire == wire and sp.rms <= max_rms
                          and np.isfinite(sp.lateral_tol)]
            if not wire_spans:
                continue
            m = np.flatnonzero((line_of == li) & (wire_of == wire))
            dx, dy = px[m] - anchor[0], py[m] - anchor[1]
            s, off = dx * direction[0] + dy * direction[1], -dx * direction[1] + dy * direction[0]
            best = np.full(len(m), np.inf)
            far = np.zeros(len(m), bool)
            for sp in wire_spans:
                at = (s >= sp.s_from - margin_m) & (s <= sp.s_to + margin_m)
                r = np.where(at, np.abs(pz[m] - catenary(s, sp.z0, sp.s0, sp.c)), np.inf)
                nearer = r < best
                best[nearer] = r[nearer]
                far[nearer] = np.abs(off[nearer] - sp.offset - sp.offset_slope * s[nearer]) > sp.lateral_tol
            off_trend[m[far]] = True
    if clutter_xyz is not None and off_trend.any():
        k = np.flatnonzero(off_trend)
        if len(clutter_xyz):
            d = cKDTree(clutter_xyz).query(np.column_stack([px[k], py[k], pz[k]]), distance_upper_bound=clutter_m)[0]
            off_trend[k[~np.isfinite(d)]] = False
        else:
            off_trend[k] = False
    return off_trend



def in_foliage(spans, lines, px, py, pz, line_of, wire_of, max_rms, around_xyz, around_tree=None,
               rules: FoliageRules | None = None, **overrides) -> np.ndarray:
    """Per wire point (``line_of``, ``wire_of`` its conductor and wire; -1: none): whether it lies
    where its wire runs through foliage that hides it. Within ``window_m`` along the wire, the
    points ``around_xyz`` (all those off the ground) 0.2-0.5 m from its spans' curve are no
    sparser than within 0.1 m of it (``core_ring_contrast`` under ``min_contrast``) and surround it
    on ``min_sides`` or more of 8 sides in its cross-section. A crown's points on the wire's curve
    pass the off-trend test where they are the span's own (they set its lateral tolerance); a
    wire beside other wires or a pole has points on a few sides only, and a wall or roof 0.2 m or
    more away spans at most 4 (an arc of 2 arccos(0.2 / 0.5) = 132 degrees). A point on no
    fitting span of its wire is kept. ``lines`` as for conductors_3d; ``around_tree``: a k-d tree
    of ``around_xyz`` already built."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or FoliageRules(), **overrides)
    (window_m, min_contrast, min_sides, margin_m) = dataclasses.astuple(r)
    foliage = np.zeros(len(px), bool)
    if not len(around_xyz) or not (line_of >= 0).any():
        return foliage
    tree = around_tree if around_tree is not None else cKDTree(around_xyz)
    for li, wire, m, wire_spans, near in _wires_and_around(spans, px, py, pz, line_of, wire_of, max_rms, tree,
                                                           window_m + 0.5):
        anchor, direction, _, _ = lines[li]
        q = around_xyz[near]

        def frame(x, y, z):
            return _span_frame(x, y, z, anchor, direction, wire_spans, margin_m)

        s_q, lat_q, dz_q = frame(q[:, 0], q[:, 1], q[:, 2])
        ok = np.isfinite(dz_q)
        s_q, lat_q, dz_q = s_q[ok], lat_q[ok], dz_q[ok]
        order = np.argsort(s_q)
        s_q, lat_q, dz_q = s_q[order], lat_q[order], dz_q[order]
        core, ring = core_and_ring_masks(np.hypot(lat_q, dz_q))
        side = (np.floor((np.arctan2(dz_q, lat_q) + np.pi) / (np.pi / 4)).astype(np.int64)) % 8
        counts = np.zeros((len(core) + 1, 9))  # cumulative: core, then ring points on each side
        counts[1:, 0] = np.cumsum(core)
        for k in range(8):
            counts[1:, 1 + k] = np.cumsum(ring & (side == k))
        s_m, _, dz_m = frame(px[m], py[m], pz[m])
        lo = np.searchsorted(s_q, s_m - window_m)
        hi = np.searchsorted(s_q, s_m + window_m, side="right")
        c = counts[hi] - counts[lo]
        contrast = core_ring_contrast(c[:, 0], c[:, 1:].sum(axis=1))
        sides = (c[:, 1:] > 0).sum(axis=1)
        foliage[m] = np.isfinite(dz_m) & (contrast < min_contrast) & (sides >= min_sides)
    return foliage


def _wires_and_around(spans, px, py, pz, line_of, wire_of, max_rms: float, tree, radius_m: float):
    """For each wire (line and number) of the points ``px, py, pz`` (``line_of``, ``wire_of``; -1:
    none) with fitting spans: (line, wire, its points, its fitting spans, the indices of the points
    of ``tree`` within ``radius_m`` of its points)."""
    for li in np.unique(line_of[line_of >= 0]):
        for wire in np.unique(wire_of[line_of == li]):
            wire_spans = [sp for sp in spans if sp.conductor == li and sp.wire == wire and sp.rms <= max_rms]
            if not wire_spans:
                continue
            m = np.flatnonzero((line_of == li) & (wire_of == wire))
            near = np.unique(np.concatenate(tree.query_ball_point(np.column_stack([px[m], py[m], pz[m]]),
                                                                  radius_m)).astype(np.int64))
            yield int(li), int(wire), m, wire_spans, near


def _span_frame(x, y, z, anchor, direction, wire_spans, margin_m: float):
    """Points' position along a line, and their offset across and up from the nearest (in
    height) of a wire's spans there (inf where none reaches within ``margin_m``)."""
    dx, dy = x - anchor[0], y - anchor[1]
    s, off = dx * direction[0] + dy * direction[1], -dx * direction[1] + dy * direction[0]
    lat, dz = np.full(len(s), np.inf), np.full(len(s), np.inf)
    for sp in wire_spans:
        at = (s >= sp.s_from - margin_m) & (s <= sp.s_to + margin_m)
        h = np.where(at, z - catenary(s, sp.z0, sp.s0, sp.c), np.inf)
        nearer = np.abs(h) < np.abs(dz)
        dz[nearer] = h[nearer]
        lat[nearer] = (off - sp.offset - sp.offset_slope * s)[nearer]
    return s, lat, dz



def in_a_surface(spans, lines, px, py, pz, line_of, wire_of, max_rms, around_xyz, around_wire, around_tree=None,
                 rules: SurfaceRules | None = None, **overrides) -> set:
    """Lines (indices into ``lines``) whose wires lie in a surface, not in free space: pooled
    over the line's wires, the points ``around_xyz`` (all those off the ground) are within 0.1 m
    of each wire's spans less than ``min_contrast`` times as dense as 0.2-0.5 m around them
    (``core_ring_contrast``). Other wires' points are left out (``around_wire``: each point's
    wire as ``line * WIRE_ID_BASE + wire``, -1 for none): a stack's wires sit in one another's
    ring. A surface through the curve alone gives 7 (its trace crosses the ring three times as
    far as the core); a wire lying along one, half again that or more. The tops of crowns lined
    up in the Hough fit a catenary and pass ``in_foliage`` (nothing above them); a real wire
    through a crown is in it over a few stretches only. ``px, py, pz, line_of, wire_of``: the
    wire points, and ``around_tree``, as for ``in_foliage``."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or SurfaceRules(), **overrides)
    (min_contrast, reach_m, margin_m) = dataclasses.astuple(r)
    if not len(around_xyz) or not (line_of >= 0).any():
        return set()
    core_n, ring_n = {}, {}
    tree = around_tree if around_tree is not None else cKDTree(around_xyz)
    for li, wire, _, wire_spans, near in _wires_and_around(spans, px, py, pz, line_of, wire_of, max_rms, tree,
                                                           reach_m):
        anchor, direction, _, _ = lines[li]
        near = near[(around_wire[near] < 0) | (around_wire[near] == li * WIRE_ID_BASE + wire)]
        _, lat, dz = _span_frame(*around_xyz[near].T, anchor, direction, wire_spans, margin_m)
        core, ring = core_and_ring(np.hypot(lat, dz)[np.isfinite(dz)])
        core_n[li], ring_n[li] = core_n.get(li, 0) + core, ring_n.get(li, 0) + ring
    return {li for li in core_n if core_n[li] + ring_n[li] and core_ring_contrast(core_n[li], ring_n[li]) < min_contrast}



def along_a_surface(spans, lines, px, py, pz, line_of, wire_of, max_rms, around_xyz, around_wire, around_tree=None,
                    rules: AlongSurfaceRules | None = None, **overrides) -> set:
    """Lines (indices into ``lines``) each of whose wires lies along a surface reaching out from
    it: on one side, ``inner_m`` to ``reach_m`` across, the points ``around_xyz`` (off the
    ground; those on other wires left out, ``around_wire`` as for ``in_a_surface``) lie in a
    plane through the wire's curve: at least ``min_share`` of those within ``slab_m`` of the
    plane are within ``tol_m`` of it, they fill ``min_fill`` of the ``bin_m`` bins across (a
    surface, not the unfound wires of a ribbon at a few offsets) and ``min_cover`` of the wire's
    length in 1 m bins along. The plane's tilt is the densest in a histogram of the points'
    elevation angles seen from the wire, within ``max_slope_deg`` of level (a facade a cable is
    fixed to is no roof). A sparse roof's scan row or eave lines up in the Hough and fits a
    catenary; the 0.2-0.5 m ring of ``in_a_surface`` is too sparse there to tell it, and so is
    each 0.25 m bin of ``span_on_surface`` alone (their union covers the wire). A crown scatters
    about any plane (a fifth of its points in the slab are that close), and a roof or hedge a
    long wire passes covers a stretch of it only."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or AlongSurfaceRules(), **overrides)
    (reach_m, inner_m, tol_m, slab_m, max_slope_deg, min_share, bin_m, min_fill, min_cover, min_points,
     margin_m) = dataclasses.astuple(r)
    if not len(around_xyz) or not (line_of >= 0).any():
        return set()
    tree = around_tree if around_tree is not None else cKDTree(around_xyz)
    flat_wires, all_wires = {}, {}
    edges = np.arange(-max_slope_deg, max_slope_deg + 2.0, 2.0)
    n_across = np.ceil((reach_m - inner_m) / bin_m)
    for li, wire, m, wire_spans, near in _wires_and_around(spans, px, py, pz, line_of, wire_of, max_rms, tree,
                                                           reach_m):
        all_wires[li] = all_wires.get(li, 0) + 1
        anchor, direction, _, _ = lines[li]
        near = near[around_wire[near] < 0]
        s, lat, dz = _span_frame(*around_xyz[near].T, anchor, direction, wire_spans, margin_m)
        s_w = _span_frame(px[m], py[m], pz[m], anchor, direction, wire_spans, margin_m)[0]
        s_lo, n_along = np.floor(s_w.min()), int(np.floor(s_w.max()) - np.floor(s_w.min())) + 1
        for side in (-1.0, 1.0):
            q = np.isfinite(dz) & (side * lat >= inner_m) & (side * lat <= reach_m)
            a, h, sq = side * lat[q], dz[q], s[q]
            ang = np.degrees(np.arctan2(h, a))
            if np.sum(np.abs(ang) <= max_slope_deg) < min_points:
                continue
            votes = np.convolve(np.histogram(ang, bins=edges)[0], np.ones(3), "same")
            k = np.tan(np.radians(edges[np.argmax(votes)] + 1.0))  # the densest bin's middle
            dist = np.abs(h - k * a) / np.hypot(1.0, k)
            inl = dist <= tol_m
            if inl.sum() < min_points or inl.sum() < min_share * (dist <= slab_m).sum():
                continue
            fill = len(np.unique(np.floor((a[inl] - inner_m) / bin_m))) / n_across
            along = np.unique(np.floor(sq[inl]) - s_lo)
            cover = np.sum((along >= 0) & (along < n_along)) / n_along
            if fill >= min_fill and cover >= min_cover:
                flat_wires[li] = flat_wires.get(li, 0) + 1
                break
    return {li for li, n in flat_wires.items() if n == all_wires[li]}


def _on_spans(s, off, z, spans, lateral_m: float, margin_m: float):
    """Per point (``s`` along a line, ``off`` across it, height ``z``): the residual to the
    nearest of the line's ``spans`` it lies on - within the span's extent (± ``margin_m``),
    ``lateral_m`` of its plan position and its fit tolerance (3 rms, at least 0.15) - and that
    span's index in ``spans`` (-1: none)."""
    best_r = np.full(len(s), np.inf)
    best_k = np.full(len(s), -1)
    for k, sp in enumerate(spans):
        near = np.flatnonzero((s >= sp.s_from - margin_m) & (s <= sp.s_to + margin_m))
        near = near[np.abs(off[near] - (sp.offset + sp.offset_slope * s[near])) <= lateral_m]
        r = np.abs(catenary(s[near], sp.z0, sp.s0, sp.c) - z[near])
        ok = (r <= fit_tolerance_m(sp.rms)) & (r < best_r[near])
        best_r[near[ok]], best_k[near[ok]] = r[ok], k
    return best_r, best_k


# a flank's rows come a scan-angle step apart (0.3 m on the Oakland scans looked at), and foliage
# leaves some out: rows up to 1.5 m apart are one flank's
FLANK_ROW_GAP_M = 1.5
# its rows start and end at the crown's edge, ragged by a metre or two
FLANK_EDGE_M = 2.0
# more levels than a street pole or a tower carries on one span, sub-conductors included (the
# deepest stacks on the bench's scenes and AHN4: 3 within 1.5 m of one another, 6 in all)
FLANK_MIN_ROWS = 7


def flank_rows(spans, max_gap_m: float = FLANK_ROW_GAP_M, edge_m: float = FLANK_EDGE_M,
               min_rows: int = FLANK_MIN_ROWS) -> list:
    """The spans that are rows of a surface seen side-on, not wires (#77). A profile scanner
    passing a crown's or a hedge's flank leaves a row of points at each step of its scan angle,
    one above the other up the flank, and the 3D step fits each row as a wire level of one plan
    line; the rows start and end together, at the flank's edges. Wires on one span keep
    clearances and a support carries a few levels. Levels of one conductor are linked where both
    their ends lie within ``edge_m`` along the line and their heights (at the middle of their
    common stretch) within ``max_gap_m``; groups of at least ``min_rows`` are a flank's. Returns
    the indices into ``spans`` of those levels' spans."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    levels: dict = {}
    for k, sp in enumerate(spans):
        levels.setdefault((sp.conductor, sp.wire), []).append(k)
    by_line: dict = {}
    for key, ks in levels.items():
        by_line.setdefault(key[0], []).append(ks)
    gone = []
    for groups in by_line.values():
        if len(groups) < min_rows:
            continue
        lo = np.array([min(spans[k].s_from for k in ks) for ks in groups])
        hi = np.array([max(spans[k].s_to for k in ks) for ks in groups])
        i, j = np.triu_indices(len(groups), 1)
        together = (np.abs(lo[i] - lo[j]) <= edge_m) & (np.abs(hi[i] - hi[j]) <= edge_m)
        i, j = i[together], j[together]
        mid = 0.5 * (np.maximum(lo[i], lo[j]) + np.minimum(hi[i], hi[j]))
        linked = np.abs(_level_height(spans, groups, i, mid) - _level_height(spans, groups, j, mid)) <= max_gap_m
        g = coo_matrix((np.ones(int(linked.sum())), (i[linked], j[linked])), shape=(len(groups),) * 2)
        _, comp = connected_components(g, directed=False)
        for c in np.flatnonzero(np.bincount(comp) >= min_rows):
            gone += [k for m in np.flatnonzero(comp == c) for k in groups[m]]
    return sorted(gone)


def _level_height(spans, groups, which, s) -> np.ndarray:
    """Height of level ``groups[which[n]]`` at ``s[n]`` along its line: its span there (or the
    nearest one's end)."""
    out = np.empty(len(which))
    for n, (m, sn) in enumerate(zip(which, s)):
        sps = [spans[k] for k in groups[m]]
        sp = min(sps, key=lambda q: max(q.s_from - sn, sn - q.s_to, 0.0))
        out[n] = catenary(np.clip(sn, sp.s_from, sp.s_to), sp.z0, sp.s0, sp.c)
    return out

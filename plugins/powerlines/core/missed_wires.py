"""Wires the plan lines missed: straight 3D runs (short wires), runs leading from a pole,
sibling phases beside a fitted span."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ..rules import RING_FROM_M, RING_TO_M, STRAIGHT_RUNS, ShortWireRules, SiblingRules
from .catenaries import MAX_NEIGHBOUR_PAIRS, N_BEST_LINES, catenary, fit_catenary, fit_tolerance_m, line_fit
from .spans import _spans_by_line
from .wires_3d import _longest_run


def straight_wires(xyz: np.ndarray, min_length_m: float, max_gap_m: float, tol_m: float = STRAIGHT_RUNS.tol_m,
                   min_points: int = STRAIGHT_RUNS.min_points, max_slope: float = STRAIGHT_RUNS.max_slope,
                   link_m: float = 1.0, n_samples: int = STRAIGHT_RUNS.n_samples, seed: int = 0) -> list[np.ndarray]:
    """Straight 3D runs of points (indices into ``xyz``, metres): wires seen over
    a few metres only, such as a mobile scanner's view of a wire crossing its street, too short
    for the 2D Hough's S_min and not collinear in plan with their neighbours (wires fanning out
    from a pole at several heights). Over a few metres a wire's sag is millimetres, so a
    straight line is its model.

    Per connected set (points ``link_m`` apart), sequential RANSAC: the line through two sampled
    points with the most points within ``tol_m`` (where its run is too short, the next best
    through other points, up to ``N_BEST_LINES``), its longest run without a gap of
    ``max_gap_m``, refitted (principal axis) and its points taken again; kept when the run is at
    least ``min_length_m`` long, holds ``min_points`` and rises at most ``max_slope``. Its points
    leave the set, kept or too steep (a pole), and the rest is searched again (strongest first
    within each set) until the best run is too short or too sparse."""
    from scipy.sparse.csgraph import connected_components as components

    n = len(xyz)
    if n < min_points:
        return []
    pairs = cKDTree(xyz).query_pairs(link_m, output_type="ndarray")
    g = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, comp = components(g, directed=False)
    out = []
    sizes = np.bincount(comp)
    for k in np.flatnonzero(sizes >= min_points):
        left = np.flatnonzero(comp == k)
        # a set's points in the order of their coordinates and its own random stream: a tile of a
        # survey that holds the set whole draws as a run on the whole does
        cm = np.round(xyz[left] - xyz[left].min(axis=0), 3)
        left = left[np.lexsort(cm.T[::-1])]
        rng = np.random.default_rng([seed, len(left)])
        # each point's neighbourhood searched once per set, where that fits in memory
        tree = cKDTree(xyz[left])
        near = SetNeighbours(tree, min_length_m / 2) if (tree.count_neighbors(tree, min_length_m / 2) - len(left)) \
            // 2 <= MAX_NEIGHBOUR_PAIRS else None
        while len(left) >= min_points and np.linalg.norm(np.ptp(xyz[left], axis=0)) >= min_length_m:
            run = _best_straight_run(xyz[left], min_length_m, max_gap_m, tol_m, n_samples, rng,
                                     near.of if near is not None else None)
            if run is None or len(run) < min_points:
                break
            q = xyz[left[run]]
            d = q[-1] - q[0]
            if abs(d[2]) <= max_slope * np.hypot(d[0], d[1]):
                out.append(left[run])
            # a steep run (a pole, a trunk) leaves the set too: wires held on it come next
            left = np.delete(left, run)
            if near is not None:
                near.remove(run)
    return out



def short_wires(xyz, off_ground, steep, wired, min_length_m, max_gap_m, n_searched: int | None = None,
                wire_like: np.ndarray | None = None, rules: ShortWireRules | None = None, **overrides) -> list[np.ndarray]:
    """The ``straight_wires`` runs (within ``tol_m``) of ``xyz`` (wire-like points on no wire)
    that are wires seen over a few metres, given the points off the ground (``wire_like``: which
    of them are), those of structures (``steep``: poles, tower bodies) and those of the wires
    found (``wired``), all (n, 3) in one frame. Runs are drawn from the first ``n_searched``
    points of ``xyz``; the rest (a stack's ribbon on end that the shape test took for a pole's)
    only join a stack beside a run kept. A run of ``min_length_m`` is kept when
    * it stands alone in its cross-section: the points 0.2-0.5 m from it (over its length)
      number under ``max_around`` times its own, not counting wire-like ones in its vertical or
      horizontal plane (within 2 ``tol_m``: the wires of a stack or a ribbon beside it). A scan
      row on a facade has the next rows there, a roof's eave the roof rising from it;
    * it joins the wires found at a support: one end within ``reach_m`` of them (a pole's cross
      arm and insulators), and leads away from them at 30 degrees or more (its other end half
      its length farther; a cross arm lies along under them);
    * it is not a tower's arm: the end nearer the wires found is the one at a structure (more
      ``steep`` points within ``structure_m`` than at the other). A wire across the street leaves
      the pole where the line's wires are held; an arm reaches from the tower's body out to
      where the conductors hang under its tip.
    Wires one over another (cables from a pole to a house) may be seen over less: two or more
    runs of half ``min_length_m``, parallel within ``max_stack_deg`` and within ``stack_m`` of
    each other, each standing alone, are kept when one of them joins the wires found. Beside
    each run kept (within ``stack_m`` of its axis, along it), the rest of its stack is runs of
    half its length as parallel, standing alone, searched among all of ``xyz``."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or ShortWireRules(), **overrides)
    (max_around, reach_m, structure_m, stack_m, max_stack_deg, tol_m) = dataclasses.astuple(r)
    if not len(wired):
        return []
    runs = straight_wires(xyz[:n_searched], min_length_m, max_gap_m, tol_m=tol_m)
    every, wires = _Around(off_ground, wire_like, 2 * tol_m), cKDTree(wired)
    structure = cKDTree(steep) if len(steep) else None
    kept = [run for run in runs if _stands_alone(xyz[run], every, max_around) and
            _joins(xyz[run], wires, structure, reach_m, structure_m)]
    taken = np.zeros(len(xyz), bool)
    for run in kept:
        taken[run] = True
    cos_max = np.cos(np.radians(max_stack_deg))
    # stacks of wires seen over less than min_length
    rest = np.flatnonzero(~taken[:n_searched])
    short = [rest[r] for r in straight_wires(xyz[rest], min_length_m / 2, max_gap_m, tol_m=tol_m)]
    short = [r for r in short if _stands_alone(xyz[r], every, max_around)]
    for group in _stacks([xyz[r] for r in short], stack_m, cos_max):
        if len(group) >= 2 and any(_joins(xyz[short[i]], wires, structure, reach_m, structure_m) for i in group):
            for i in group:
                kept.append(short[i])
                taken[short[i]] = True
    tree = cKDTree(xyz) if kept else None
    for run in list(kept):  # (a wire found beside one vouches for no other: it is shorter)
        q = xyz[run]
        length = float(np.linalg.norm(q[-1] - q[0]))
        u = (q[-1] - q[0]) / max(length, 1e-9)
        near = np.asarray(tree.query_ball_point((q[0] + q[-1]) / 2, length / 2 + stack_m), np.int64)
        t, r = _along_axis(xyz[near], q[0], u)
        beside = near[~taken[near] & (t >= 0) & (t <= length) & (r <= stack_m)]
        for sub in straight_wires(xyz[beside], length / 2, max_gap_m, tol_m=tol_m,
                                  min_points=STRAIGHT_RUNS.stack_min_points):
            p = xyz[beside[sub]]
            d = p[-1] - p[0]
            if abs(d @ u) >= cos_max * np.linalg.norm(d) and _stands_alone(p, every, max_around):
                taken[beside[sub]] = True
                # the rest of a run kept (its points the search could not draw from) joins it
                k = next((k for k, r in enumerate(kept) if _on_axis(xyz[r], p, 2 * tol_m)), None)
                if k is None:
                    kept.append(beside[sub])
                else:
                    both = np.r_[kept[k], beside[sub]]
                    kept[k] = both[np.argsort((xyz[both] - xyz[both[0]]) @ (xyz[kept[k][-1]] - xyz[kept[k][0]]))]
    return kept


def _on_axis(q, p, tol_m: float) -> bool:
    """Whether every point of ``p`` lies within ``tol_m`` of the axis of the run ``q``."""
    u = (q[-1] - q[0]) / max(float(np.linalg.norm(q[-1] - q[0])), 1e-9)
    return bool(np.all(_along_axis(p, q[0], u)[1] <= tol_m))


def _joins(q, wires_tree, structure_tree, reach_m: float, structure_m: float) -> bool:
    """Whether the run ``q`` joins the wires found at a support and is no tower's arm (see
    short_wires)."""
    ends = q[[0, -1]]
    to_wires = wires_tree.query(ends)[0]
    at_structure = [len(structure_tree.query_ball_point(e, structure_m)) if structure_tree is not None else 0
                    for e in ends]
    nearer = int(np.argmin(to_wires))
    leaves = to_wires[1 - nearer] - to_wires[nearer] >= 0.5 * float(np.linalg.norm(q[-1] - q[0]))
    return to_wires[nearer] <= reach_m and leaves and at_structure[nearer] > at_structure[1 - nearer]


def wires_from_poles(xyz: np.ndarray, poles: np.ndarray, off_ground: np.ndarray, min_length_m: float,
                     max_gap_m: float, wire_like: np.ndarray | None = None,
                     reach_m: float = STRAIGHT_RUNS.pole_reach_m, head_m: float = STRAIGHT_RUNS.pole_head_m,
                     max_around: float = STRAIGHT_RUNS.pole_max_around,
                     tol_m: float = STRAIGHT_RUNS.tol_m) -> list[np.ndarray]:
    """The straight runs (``straight_wires``, ``tol_m``) of at least ``min_length_m`` among
    ``xyz`` (wire-like points on no wire or support) that lead from a pole found: a wire seen
    over a few metres where it leaves its pole, too short for ``short_wires`` (which has only
    the wires found to go by). ``poles``: (k, 4) of x, y, base and top height (z) of each pole;
    ``off_ground``, ``wire_like``: as short_wires, for its stand-alone test; all in one frame,
    metres. A run is continued along its own axis across gaps under ``max_gap_m`` (the view
    blocked for a metre or two) and kept when
    * it stands alone in its cross-section (see short_wires);
    * its nearer end lies within ``reach_m`` of a pole's axis in plan, its farther end farther
      by half its length (it leads away; a run along the street past the pole does not) and at
      least twice ``min_length_m`` out (farther than a street light's or a bracket's arm reaches);
    * continued toward that pole, it passes within ``head_m`` of the axis (a cross arm's reach)
      between 1 m over its base and its top: where a wire is held.
    Returns the runs, indices into ``xyz`` sorted along each."""
    if not len(poles) or len(xyz) < STRAIGHT_RUNS.min_points:
        return []
    axes = cKDTree(poles[:, :2])
    # only points a run reaching a pole may hold
    near = np.flatnonzero(axes.query(xyz[:, :2], distance_upper_bound=reach_m + 2 * min_length_m)[0] < np.inf)
    if len(near) < STRAIGHT_RUNS.min_points:
        return []
    runs = [near[r] for r in straight_wires(xyz[near], min_length_m, max_gap_m, tol_m=tol_m)]
    every = _Around(off_ground, wire_like, 2 * tol_m)
    taken = np.zeros(len(xyz), bool)
    kept = []
    for r in runs:
        if taken[r].any():
            continue
        q = xyz[r]
        u = (q[-1] - q[0]) / max(float(np.linalg.norm(q[-1] - q[0])), 1e-9)
        pool = near[~taken[near]]
        run, length = _refined_run(xyz[pool], q.mean(axis=0), u, max_gap_m, tol_m)
        run = pool[run] if len(run) >= len(r) else r
        if _leads_from_pole(xyz[run], poles, reach_m, head_m, 2 * min_length_m) and \
                _stands_alone(xyz[run], every, max_around):
            kept.append(run)
            taken[run] = True
    return kept


def _leads_from_pole(q, poles, reach_m: float, head_m: float, out_m: float) -> bool:
    """Whether the run ``q`` (points in order along it) leads from one of the ``poles`` out to
    ``out_m`` from its axis (see wires_from_poles)."""
    ends = q[[0, -1]]
    d = np.hypot(ends[:, None, 0] - poles[None, :, 0], ends[:, None, 1] - poles[None, :, 1])
    length = float(np.linalg.norm(ends[1] - ends[0]))
    for k in np.flatnonzero((d.min(axis=0) <= reach_m) & (np.abs(d[0] - d[1]) >= 0.5 * length) &
                            (d.max(axis=0) >= out_m)):
        near_end = int(np.argmin(d[:, k]))
        a, b = ends[near_end], ends[1 - near_end]
        u = (a - b) / max(length, 1e-9)  # toward the pole
        h = float(np.hypot(u[0], u[1]))
        if h < 1e-6:
            continue
        # where the run's line comes nearest the axis in plan
        t = max(0.0, float((poles[k, :2] - a[:2]) @ u[:2]) / (h * h))
        at = a + t * u
        if np.hypot(*(at[:2] - poles[k, :2])) <= head_m and poles[k, 2] + 1.0 <= at[2] <= poles[k, 3]:
            return True
    return False


def _stacks(runs, stack_m: float, cos_max: float) -> list[list[int]]:
    """Groups of the runs (points in order along each) that lie one beside another: parallel
    (cosine of their angle at least ``cos_max``), the middle of one within ``stack_m`` of the
    other's axis, overlapping along it over half the shorter's length."""
    from scipy.sparse.csgraph import connected_components as components

    n = len(runs)
    ends = [(q[0], q[-1]) for q in runs]
    link = np.zeros((n, n), bool)
    for i in range(n):
        a, b = ends[i]
        li = float(np.linalg.norm(b - a))
        u = (b - a) / max(li, 1e-9)
        for j in range(i + 1, n):
            c, d = ends[j]
            lj = float(np.linalg.norm(d - c))
            if abs((d - c) @ u) < cos_max * lj:
                continue
            rel = (c + d) / 2 - a
            t = rel @ u
            tc, td = sorted(((c - a) @ u, (d - a) @ u))
            if np.linalg.norm(rel - t * u) <= stack_m and min(li, td) - max(0.0, tc) >= 0.5 * min(li, lj):
                link[i, j] = True
    _, lab = components(sparse.coo_matrix(link), directed=False)
    return [list(np.flatnonzero(lab == k)) for k in range(lab.max() + 1)] if n else []


class _Around:
    """The points off the ground around a run (see short_wires), and which of them are wire-like."""

    def __init__(self, xyz, wire_like, plane_m: float):
        self.tree, self.plane_m = cKDTree(xyz), plane_m
        self.wire_like = np.zeros(len(xyz), bool) if wire_like is None else np.asarray(wire_like, bool)


def _stands_alone(q, around: _Around, max_around: float) -> bool:
    """Whether the run ``q`` (its points in order along it) has under ``max_around`` times its
    own points 0.2-0.5 m from its axis over its length (see short_wires), not counting the
    wire-like ones in its vertical or horizontal plane (within ``around.plane_m``: two wires'
    points each scatter up to a run's tolerance from their axes). The wires of a stack hang
    one over another, a ribbon's side by side; a roof's next scan rows rise away from its eave."""
    length = float(np.linalg.norm(q[-1] - q[0]))
    u = (q[-1] - q[0]) / max(length, 1e-9)
    near = np.unique(np.concatenate(around.tree.query_ball_point(q, RING_TO_M))).astype(np.int64)
    rel = around.tree.data[near] - q[0]
    t = rel @ u
    r = np.linalg.norm(rel - t[:, None] * u, axis=1)
    across = np.array([-u[1], u[0], 0.0]) / max(float(np.hypot(u[0], u[1])), 1e-9)
    # (the vertical plane's distance along ``across``; the horizontal plane's in height, as the
    # run is near level)
    up = rel[:, 2] - t * u[2]
    stacked = around.wire_like[near] & ((np.abs(rel @ across) <= around.plane_m) | (np.abs(up) <= around.plane_m))
    ring = (r > RING_FROM_M) & (r <= RING_TO_M)
    return int((ring & (t >= 0) & (t <= length) & ~stacked).sum()) < max_around * len(q)



def sibling_wires(spans, lines, px, py, pz, max_rms, min_sep_m, min_span_m, owner=None, owner_length=None,
                  stacked: bool = False, rules: SiblingRules | None = None, **overrides) -> list:
    """Wires hanging beside a fitted span, too sparse for the Hough and the 3D step to find alone
    (a mobile scanner's view of the far phase of a line crossing its street, 10-45 m away): the
    phases of one line hang side by side, parallel, with nearly the same sag, so beside each
    span (``min_sep_m``-``max_sep_m`` across, within ``max_dz_m`` in height) the points of
    another phase share one lateral offset and one height offset from its catenary.

    Per span that fits (rms <= ``max_rms``) at least ``min_span_m`` long: the points ``p*`` (those on no wire, in metres) are
    binned by (offset across, height above the catenary) at ``bin_m``; the fullest 2x2 window
    whose points, refitted as a catenary of their own (at most ``max_rms``), number
    ``min_points`` within ``tol_m`` of its plan trend and curve, reach ``min_span_m`` along it
    (the method's S_min: the leftover points of a found wire near its tower are no wire of their
    own) and occupy ``min_cover`` of the span's ``cover_bin_m`` steps is a wire, its points
    taken; up to ``max_rounds`` per span.
    With ``owner`` (the line each point is on, -1: none) and ``owner_length`` (that line's
    length), the points of lines shorter than the span's own line are searched too: the stretch
    of a sparse phase the Hough found alone near its pole.
    With ``stacked``, the wires searched are over or under the span instead (within
    ``min_sep_m`` across, out of its fit tolerance in height: 3 rms, at least ``tol_m``): the
    cables of a joint-use pole hang one over another with one sag, a ribbon on end that the
    shape test takes for a surface, and the 3D step may keep one of them. Such a wire stands
    alone but in its vertical plane (``plane_m``): under ``max_around`` times its points lie
    0.2-0.5 m from it elsewhere (as short_wires asks; a slice through the crowns under a line
    has the rest of the crowns around it).
    Returns [(indices into p*, line index, s of those points, offset across)] per wire found.
    ``lines`` as for conductors_3d."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or SiblingRules(), **overrides)
    (max_sep_m, max_dz_m, bin_m, tol_m, min_points, min_cover, cover_bin_m, max_rounds, max_around,
     plane_m) = dataclasses.astuple(r)
    found = []
    taken = np.zeros(len(px), bool)
    if owner is None:
        owner, owner_length = np.full(len(px), -1), np.zeros(len(px))
    for li, line_spans, s, off in _spans_by_line(spans, lines, px, py, max_rms):
        open_ = (owner < 0) | ((owner != li) & (owner_length < lines[li][3] - lines[li][2]))
        for sp in line_spans:
            length = sp.s_to - sp.s_from
            if length < max(min_span_m, 2 * cover_bin_m):
                continue
            near = np.flatnonzero((s >= sp.s_from) & (s <= sp.s_to) & ~taken & open_)
            across = off[near] - (sp.offset + sp.offset_slope * s[near])
            dz = pz[near] - catenary(s[near], sp.z0, sp.s0, sp.c)
            if stacked:
                zone = (np.abs(across) < min_sep_m) & (np.abs(dz) > fit_tolerance_m(sp.rms, tol_m)) & (np.abs(dz) <= max_dz_m)
            else:
                zone = (np.abs(across) >= min_sep_m) & (np.abs(across) <= max_sep_m) & (np.abs(dz) <= max_dz_m)
            near, across, dz = near[zone], across[zone], dz[zone]
            n_steps = int(np.ceil(length / cover_bin_m))
            for _ in range(max_rounds):
                if len(near) < min_points:
                    break
                ia = np.floor(across / bin_m).astype(np.int64)
                iz = np.floor(dz / bin_m).astype(np.int64)
                ia -= ia.min()
                iz -= iz.min()
                grid = np.zeros((ia.max() + 2, iz.max() + 2))
                np.add.at(grid, (ia, iz), 1.0)
                window = grid[:-1, :-1] + grid[1:, :-1] + grid[:-1, 1:] + grid[1:, 1:]
                ka, kz = np.unravel_index(int(np.argmax(window)), window.shape)
                if window[ka, kz] < min_points:
                    break
                pick = np.flatnonzero((ia >= ka) & (ia <= ka + 1) & (iz >= kz) & (iz <= kz + 1))
                k = near[pick]
                ok = False
                for _refit in range(2):  # the picked points' own catenary and trend, their points again
                    fit = fit_catenary(s[k], pz[k])
                    o1, o0 = line_fit(s[k], off[k]) if len(k) >= 3 else (0.0, float(np.median(off[k])))
                    r_z = np.abs(pz[near] - catenary(s[near], *fit[:3]))
                    r_o = np.abs(off[near] - o1 * s[near] - o0)
                    pick = np.flatnonzero((r_z <= fit_tolerance_m(fit[3], tol_m)) & (r_o <= tol_m))
                    k = near[pick]
                    ok = len(k) >= min_points and fit[3] <= max_rms
                    if not ok:
                        break
                cover = len(np.unique(np.floor((s[k] - sp.s_from) / cover_bin_m))) / n_steps if ok else 0.0
                if (ok and cover >= min_cover and np.ptp(s[k]) >= min_span_m
                        and fit_catenary(s[k], pz[k])[3] <= max_rms
                        and (not stacked or _alone_in_its_plane(k, s, off, pz, fit, (o1, o0), max_around, plane_m))):
                    found.append((k, li, s[k], off[k]))
                    taken[k] = True
                # the window's points leave the search either way: the next round looks elsewhere
                gone = np.zeros(len(near), bool)
                gone[pick] = True
                gone[(ia >= ka) & (ia <= ka + 1) & (iz >= kz) & (iz <= kz + 1)] = True
                near, across, dz = near[~gone], across[~gone], dz[~gone]
    return found


def _alone_in_its_plane(k, s, off, z, fit, trend, max_around: float, plane_m: float) -> bool:
    """Whether the wire of the points ``k`` (its catenary ``fit``, its plan ``trend`` (slope,
    intercept) of ``off`` over ``s``) has under ``max_around`` times its points 0.2-0.5 m from it
    over its extent among the points (``s``, ``off``, ``z``), leaving out those in its vertical
    plane (within ``plane_m`` across: the other wires of its stack)."""
    within = np.flatnonzero((s >= s[k].min()) & (s <= s[k].max()))
    across = off[within] - trend[0] * s[within] - trend[1]
    r = np.hypot(across, z[within] - catenary(s[within], *fit[:3]))
    return int(((r > RING_FROM_M) & (r <= RING_TO_M) & (np.abs(across) > plane_m)).sum()) < max_around * len(k)


def _best_straight_run(p, min_length_m, max_gap_m, tol_m, n_samples, rng, neighbours=None):
    """The most populous straight run in ``p`` (see straight_wires), its indices sorted along it,
    or None when none reaches ``min_length_m``. ``neighbours(i)``: the points of ``p`` within
    min_length / 2 of its points ``i`` as ``ball_pairs`` gives them (default: searched here)."""
    n = len(p)
    # pairs drawn locally (the second point within min_length / 2 of the first): a wire of 20
    # points in a set of thousands (linked to a crown) is then drawn as often as the crown
    i = rng.integers(0, n, min(max(n_samples, n), 4 * n_samples))
    # (sample, neighbour) pairs, grouped by sample, each sample's neighbours in index order
    sid, flat = neighbours(i) if neighbours is not None else ball_pairs(cKDTree(p), p[i], min_length_m / 2)
    first = np.searchsorted(sid, np.arange(len(i)))
    size = np.diff(np.r_[first, len(sid)])
    j = flat[first + np.array([int(rng.integers(0, m)) for m in size], np.int64)]
    d = p[j] - p[i]
    length = np.linalg.norm(d, axis=1)
    ok = length >= min_length_m / 8
    if not ok.any():
        return None
    i, d = i[ok], d[ok] / length[ok, None]
    # each line's support counted where its pair was drawn (within min_length / 2 of its first
    # point), all lines at once over their neighbourhoods
    mine = ok[sid]
    sid, flat = (np.cumsum(ok) - 1)[sid[mine]], flat[mine]
    rel = p[flat] - p[i][sid]
    t = np.einsum("ij,ij->i", rel, d[sid])
    counts = np.bincount(sid, weights=(np.einsum("ij,ij->i", rel, rel) - t * t) <= tol_m * tol_m, minlength=len(i))
    # the best-supported lines in turn: the best may be a short dense bit (a cross arm, a pole
    # top) whose run is too short, and the wires beside it must still be drawn; a line drawn from
    # a point of a run that failed is not tried (lines through the arm at other angles)
    spent, tried = np.zeros(n, bool), 0
    for m in np.argsort(-counts, kind="stable"):
        if spent[i[m]]:
            continue
        run, length = _refined_run(p, p[i[m]], d[m], max_gap_m, tol_m)
        if length >= min_length_m:
            return run
        spent[run] = spent[i[m]] = True
        tried += 1
        if tried == N_BEST_LINES:
            break
    return None


def ball_pairs(tree, q, radius):
    """(k, index) of each point of ``tree`` within ``radius`` of the point ``q[k]``, grouped by
    k, indices ascending."""
    near = tree.query_ball_point(q, radius)  # (several points: each list sorted)
    sid = np.repeat(np.arange(len(q)), [len(x) for x in near])
    return sid, (np.concatenate(near).astype(np.int64) if len(sid) else np.zeros(0, np.int64))


class SetNeighbours:
    """The neighbours within ``radius`` of each point of a set (``tree``), searched once
    (``straight_wires`` draws from the set a run at a time, and the neighbourhoods barely
    change): ``of(i)`` gives them among the points still alive (renumbered in order) as
    ``ball_pairs`` does."""

    def __init__(self, tree, radius):
        n = tree.n
        pairs = tree.query_pairs(radius, output_type="ndarray")
        rows = np.r_[pairs[:, 0], pairs[:, 1], np.arange(n)]
        cols = np.r_[pairs[:, 1], pairs[:, 0], np.arange(n)]
        order = np.lexsort((cols, rows))
        self.flat = cols[order]
        self.start = np.r_[0, np.cumsum(np.bincount(rows, minlength=n))]
        self.alive = np.ones(n, bool)

    def remove(self, positions):
        """Take the alive points at these positions (in the alive order) out."""
        self.alive[np.flatnonzero(self.alive)[positions]] = False

    def of(self, i):
        at = np.flatnonzero(self.alive)[i]
        size = self.start[at + 1] - self.start[at]
        sid = np.repeat(np.arange(len(i)), size)
        cols = self.flat[np.repeat(self.start[at] - np.cumsum(size) + size, size) + np.arange(int(size.sum()))]
        keep = self.alive[cols]
        pos = np.cumsum(self.alive) - 1
        return sid[keep], pos[cols[keep]]


def _refined_run(p, a, u, max_gap_m, tol_m):
    """(indices of the run along the line through ``a`` along ``u``, refitted twice to its points
    and sorted along it; its length in metres)."""
    for _ in range(2):
        t, run = _run_along(p, a, u, tol_m, max_gap_m)
        if len(run) < 3:
            return run, 0.0
        a = p[run].mean(axis=0)
        u = np.linalg.svd(p[run] - a, full_matrices=False)[2][0]
    t, run = _run_along(p, a, u, tol_m, max_gap_m)
    if len(run) < 2:
        return run, 0.0
    return run[np.argsort(t[run])], float(t[run].max() - t[run].min())


def _along_axis(p, a, u):
    """(position along, distance from) the line through ``a`` along unit ``u`` of the points ``p``."""
    rel = p - a
    t = rel @ u
    return t, np.linalg.norm(rel - t[:, None] * u, axis=1)


def _run_along(p, a, u, tol_m, max_gap_m):
    """(positions along the line through ``a`` along unit ``u``, the longest run of the points
    of ``p`` within ``tol_m`` of it without a gap of ``max_gap_m``)."""
    t, r = _along_axis(p, a, u)
    on = np.flatnonzero(r <= tol_m)
    return t, (_longest_run(t, on, max_gap_m) if len(on) >= 2 else on)

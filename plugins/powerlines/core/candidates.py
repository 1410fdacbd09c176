"""Candidates: the height window's top, the density of the surfaces around each point, the
eigenvalue shape test (linear, planar, rugged, steep), ribbons and tubes of wires side by side."""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from toolbox.neighbourhoods import neighbourhood_covariances, principal_axes, symmetric3_eigenvalues

from ..rules import CANDIDATES, ROBUST_FIT
from .catenaries import line_fit

MAX_DENSITY_NEIGHBOURS = 256  # bounds the neighbourhoods' memory on very dense (mobile) scans


DENSITY_BLOCK_M = 5.0  # the density's window moves in blocks of this size (cells of 1 m inside)


def height_window_top(hag, xyz, link_m: float, quantile: float = CANDIDATES.window_quantile,
                      min_links: int = CANDIDATES.window_min_links) -> float:
    """Highest height above ground the candidates reach, birds and lone returns left out.

    Above the 99.95th percentile of ``hag`` only points with ``min_links`` others within ``link_m``
    (3D, the method's V_max: a wire's run) count: an earth wire over a stack is fewer points than the
    percentile leaves out, but each point of it has neighbours along it, as a tower top has.
    """
    hag = np.asarray(hag, float)
    if not len(hag):
        return 12.0
    top = float(np.percentile(hag, quantile))
    near = np.flatnonzero(hag >= top - link_m)  # the points above it and what links them from below
    high = hag[near] > top
    if high.any():
        tree = cKDTree(xyz[near])
        links = tree.query_ball_point(xyz[near[high]], link_m, return_length=True) - 1
        linked = hag[near[high]][links >= min_links]
        if len(linked):
            top = max(top, float(linked.max()))
    return top + 1.0


def local_surface_density(x, y, weight=None, radius_m: float = CANDIDATES.density_radius_m,
                          cell_m: float = CANDIDATES.density_cell_m,
                          block_m: float = DENSITY_BLOCK_M) -> np.ndarray:
    """Per point: the points (``weight``: those that count, e.g. first returns) per occupied
    ``cell_m`` square in the blocks of ``block_m`` within ``radius_m`` (rounded up to whole
    blocks) of its block: the survey's surface density as one run over a small file measures it,
    made local so that strips, overlaps and a mobile scanner's falling range count where they
    are. Cells and blocks sit on multiples of their size and every sum is an integer, so a point
    gets the same value in any piece of the survey that holds its window: a tiled run decides as
    the whole does. Units: those of x, y."""
    cell, block_cells = cell_m, int(round(block_m / cell_m))
    radius_blocks = int(np.ceil(radius_m / block_m))
    n = len(x)
    if n == 0:
        return np.zeros(0)
    c = np.floor(np.asarray(x) / cell).astype(np.int64)
    r = np.floor(np.asarray(y) / cell).astype(np.int64)
    bc, br = np.floor_divide(c, block_cells), np.floor_divide(r, block_cells)
    bc -= bc.min()
    br -= br.min()
    cols, rows = int(bc.max()) + 1, int(br.max()) + 1
    block = br * cols + bc
    w = None if weight is None else np.asarray(weight, np.float64)
    points = np.bincount(block, weights=w, minlength=rows * cols).round().reshape(rows, cols)
    # occupied cells per block: distinct cells, each counted once (in the block of its first point)
    c -= c.min()
    _, first = np.unique((r - r.min()) * (int(c.max()) + 1) + c, return_index=True)
    occupied = np.bincount(block[first], minlength=rows * cols).astype(np.float64).reshape(rows, cols)

    def window_sum(g):  # box sums through an integral image (exact: integer-valued floats)
        h = radius_blocks
        s = np.zeros((rows + 1, cols + 1))
        s[1:, 1:] = g.cumsum(0).cumsum(1)
        r0, r1 = np.clip(np.arange(rows) - h, 0, rows), np.clip(np.arange(rows) + h + 1, 0, rows)
        c0, c1 = np.clip(np.arange(cols) - h, 0, cols), np.clip(np.arange(cols) + h + 1, 0, cols)
        return s[r1][:, c1] - s[r0][:, c1] - s[r1][:, c0] + s[r0][:, c0]

    density = window_sum(points) / np.maximum(window_sum(occupied), 1.0)
    return density.ravel()[block] / (cell * cell)


def shape_classes(xyz: np.ndarray, neighbours: int = CANDIDATES.neighbours, rugged_share: float = CANDIDATES.rugged_share,
                  planar_share: float = CANDIDATES.planar_share, surface_density: float | None = None,
                  max_axis_slope: float = CANDIDATES.max_axis_slope):
    """(linear, planar, rugged, steep) masks from the normalised eigenvalues of each
    k-neighbourhood; steep: otherwise linear along a steep axis (poles, tower legs, and wire
    points whose neighbourhood leans on a pole top).

    Roofs and crowns are surfaces *as dense as the survey's*: with ``surface_density`` (points per
    square unit, one value or one per point: ``local_surface_density``) a planar or rugged
    neighbourhood also needs half that density within radius 1, which parallel wires (flat or
    tent-shaped, but sparse) never have."""
    n = len(xyz)
    if n < 4:
        return np.ones(n, bool), np.zeros(n, bool), np.zeros(n, bool)
    k = min(neighbours, n)
    tree = cKDTree(xyz)
    # "at least `need` points within 1" (roofs and crowns are surfaces as dense as the survey's;
    # parallel wires, flat or tent-shaped, are sparse) is "the need-th nearest, itself included,
    # within 1". When need > k one search bounded at 1 answers it and gives the k-neighbourhoods
    # of every point with k neighbours within 1 (most points); an unbounded one the rest's.
    # (Two searches, k for all and need for the dense ones, took 1.5x as long on the corridor.)
    # A point's neighbourhood (used below) is its first max(k, need) neighbours within 1.
    need = np.zeros(n, np.int64)
    if surface_density is not None:
        need = np.ceil(0.5 * np.pi * np.broadcast_to(np.asarray(surface_density, np.float64), (n,))).astype(np.int64)
    width = int(min(max(k, need.max()), n, MAX_DENSITY_NEIGHBOURS))
    if width > k:
        dist, idx = tree.query(xyz, k=width, distance_upper_bound=1.0 + 1e-9, workers=-1)
        far = np.flatnonzero(~np.isfinite(dist[:, k - 1]))
        if len(far):
            dist[far, :k], idx[far, :k] = tree.query(xyz[far], k=k, workers=-1)
        beyond = np.arange(width)[None, :] >= np.maximum(need, k)[:, None]
        if beyond.any():
            dist[beyond], idx[beyond] = np.inf, n
    else:
        dist, idx = tree.query(xyz, k=k, workers=-1)
        dist, idx = dist.reshape(n, k), idx.reshape(n, k)
    cov = neighbourhood_covariances(xyz, idx[:, :k])
    ev = symmetric3_eigenvalues(cov)
    share = ev / (ev.sum(axis=1, keepdims=True) + 1e-12)
    rugged = share[:, 0] >= rugged_share
    planar = ~rugged & (share[:, 1] >= planar_share)
    for mask in (planar, rugged):
        p = np.flatnonzero(mask & (need > 1))
        if len(p):
            within = need[p] <= width
            ok = np.zeros(len(p), bool)
            ok[within] = dist[p[within], need[p[within]] - 1] <= 1.0
            if (~within).any():  # denser than the neighbourhoods reach: count
                ok[~within] = tree.query_ball_point(xyz[p[~within]], r=1.0, return_length=True,
                                                    workers=-1) >= need[p[~within]]
            mask[p] = ok
    if planar.any():
        planar &= ~ribbons(xyz, idx, dist, planar, ~rugged)
    if rugged.any():
        rugged &= ~tubes(xyz, idx, dist, rugged, ~planar)
    linear = ~rugged & ~planar
    # wires hang nearly level; a linear set along a steep axis is a pole or a tower leg
    li = np.flatnonzero(linear)
    axis_z = np.abs(principal_axes(cov[li], ev[li, 2])[:, 2])
    steep = np.zeros(n, bool)
    steep[li[axis_z > max_axis_slope / np.hypot(1.0, max_axis_slope)]] = True
    linear &= ~steep
    # edges of roofs (and of crowns) are locally linear: a wire never touches a surface (a surface
    # point closer than ``reach``). The k-neighbourhoods answer it wherever the k-th neighbour is
    # at least that far (every closer point is among them); a search for the rest only
    for surface, reach in ((planar, 1.0), (rugged, 0.5)):
        if surface.any() and linear.any():
            li = np.flatnonzero(linear)
            touches = np.any(np.r_[surface, False][idx[li]] & (dist[li] < reach), axis=1)  # index n: none found
            open_ = np.flatnonzero(~touches & (dist[li, -1] < reach))
            if len(open_):
                d, _ = cKDTree(xyz[surface]).query(xyz[li[open_]], k=1, distance_upper_bound=reach, workers=-1)
                touches[open_] = np.isfinite(d)
            linear[li[touches]] = False
    return linear, planar, rugged, steep & ~planar & ~rugged


def ribbons(xyz, idx, dist, planar, smooth, link: float = 1.0, bin_m: float = CANDIDATES.ribbon_bin_m,
            max_band_m: float = CANDIDATES.ribbon_max_band_m, min_points: int = CANDIDATES.min_set_points,
            floor_share: float = CANDIDATES.ribbon_floor_share, piece_m: float = CANDIDATES.piece_m):
    """Planar points that belong to a ribbon of wires side by side (a compact line's phases, a
    bundle): locally flat like a roof, but the set they form (with the ``smooth`` points linked
    to them within ``link``, through the k-neighbourhoods ``idx``/``dist``), projected across its
    main axis in plan, falls into two or more bands no wider than ``max_band_m`` with empty space
    between them, where a roof fills its width. Bins holding under ``floor_share`` of the fullest
    bin count as empty (a cross arm or an insulator joins the wires at a pole)."""
    n = len(xyz)
    lab = _linked_sets(idx, dist, smooth, link)
    out = np.zeros(n, bool)
    for k in np.unique(lab[planar]):
        comp = np.flatnonzero(lab == k)
        if len(comp) < min_points:
            continue
        if is_ribbon(xyz[comp], bin_m, max_band_m, floor_share):
            out[comp] = True
            continue
        # a ribbon linked to a crown or to a crossing line is a ribbon where it runs alone:
        # the set judged again piece by piece along its main axis
        for m in _pieces_along(xyz, comp, piece_m):
            if len(m) >= min_points and planar[m].any() and is_ribbon(xyz[m], bin_m, max_band_m, floor_share):
                out[m] = True
    return out & planar


def tubes(xyz, idx, dist, rugged, smooth, link: float = 1.0, max_width_m: float = CANDIDATES.tube_max_width_m,
          min_points: int = CANDIDATES.min_set_points, piece_m: float = CANDIDATES.piece_m,
          min_length_m: float = CANDIDATES.tube_min_length_m):
    """Rugged points that belong to a bundle of sub-conductors (a triangle or a square of wires
    0.4-0.6 m apart): volumetric in a small neighbourhood, but the set they form (with the
    ``smooth`` points linked to them within ``link``), taken in ``piece_m`` pieces along its main
    axis, is a tube: across the axis in plan and in height about a straight trend it stays within
    ``max_width_m`` (2nd-98th percentile) over at least ``min_length_m``; a crown is metres
    across."""
    n = len(xyz)
    lab = _linked_sets(idx, dist, smooth, link)
    out = np.zeros(n, bool)
    for k in np.unique(lab[rugged & smooth]):
        comp = np.flatnonzero(lab == k)
        if len(comp) < min_points:
            continue
        for m in _pieces_along(xyz, comp, piece_m):
            if len(m) < min_points or not rugged[m].any():
                continue
            q = xyz[m, :2] - xyz[m, :2].mean(axis=0)
            _, _, vq = np.linalg.svd(q, full_matrices=False)
            a, across = q @ vq[0], q @ vq[1]
            if np.ptp(a) < min_length_m:
                continue
            slope, icpt = line_fit(a, xyz[m, 2])
            up = xyz[m, 2] - slope * a - icpt
            width = [np.subtract(*np.percentile(v, [98, 2])) for v in (across, up)]
            if max(width) <= max_width_m:
                out[m] = True
    return out & rugged


def _linked_sets(idx, dist, smooth, link: float) -> np.ndarray:
    """Connected sets of the ``smooth`` points through their k-neighbourhoods (``idx``/``dist``)
    within ``link``; -1 for the others."""
    n = len(idx)
    ok = (dist < link) & np.r_[smooth, False][idx] & smooth[:, None]
    rows = np.repeat(np.arange(n), idx.shape[1])[ok.ravel()]
    cols = idx.ravel()[ok.ravel()]
    g = sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    return np.where(smooth, lab, -1)


def _pieces_along(xyz, comp, piece_m: float) -> list[np.ndarray]:
    """The points ``comp`` in ``piece_m`` pieces along their main axis in plan."""
    p = xyz[comp, :2] - xyz[comp, :2].mean(axis=0)
    _, _, vt = np.linalg.svd(p, full_matrices=False)
    along = p @ vt[0]
    piece = ((along - along.min()) / piece_m).astype(np.int64)
    return np.split(comp[np.argsort(piece, kind="stable")], np.cumsum(np.bincount(piece))[:-1])


def is_ribbon(xyz, bin_m, max_band_m, floor_share) -> bool:
    """Points that, across their main axis in plan, fall into two or more bands no wider than
    ``max_band_m`` with empty bins (under ``floor_share`` of the fullest) between them: wires side
    by side; or, within one such band in plan, into two or more such bands in height about their
    trend along it: wires one above another (a joint-use pole's communication cables). A roof
    fills its width, a facade its height; terraced roofs are wide in plan."""
    q = xyz[:, :2] - xyz[:, :2].mean(axis=0)
    _, _, vq = np.linalg.svd(q, full_matrices=False)
    along, across = q @ vq[0], q @ vq[1]
    if _bands(across, bin_m, max_band_m, floor_share):
        return True
    if np.subtract(*np.percentile(across, [98, 2])) > max_band_m:
        return False
    # the trend of wires one above another: the median of pairwise slopes (Theil-Sen), most pairs
    # lying along one wire; a least-squares line through a sparse stack leans towards whichever
    # wire has more points at each end, and smears the bands
    slope = _theil_sen_slope(along, xyz[:, 2])
    r = xyz[:, 2] - slope * along
    return _bands(r - np.median(r), bin_m, max_band_m, floor_share)


def _theil_sen_slope(x, y, max_pairs: int = ROBUST_FIT.theil_sen_max_pairs) -> float:
    """The median slope of pairs of points at least a quarter of their extent apart along ``x``
    (Theil 1950, Sen 1968): all pairs up to ``max_pairs``, else that many drawn (seeded)."""
    n = len(x)
    rng = np.random.default_rng(0)
    i, j = np.triu_indices(n, 1) if n * (n - 1) // 2 <= max_pairs else rng.integers(0, n, (2, max_pairs))
    far = np.abs(x[j] - x[i]) >= max(0.25 * float(np.ptp(x)), 1e-9)
    if not far.any():  # (all at one place along: no slope to tell)
        return line_fit(x, y)[0]
    return float(np.median((y[j[far]] - y[i[far]]) / (x[j[far]] - x[i[far]])))


def _bands(values, bin_m, max_band_m, floor_share) -> bool:
    """Whether ``values`` fall into two or more bands no wider than ``max_band_m`` with empty
    bins (under ``floor_share`` of the fullest) between them."""
    counts = np.bincount(((values - values.min()) / bin_m).astype(np.int64))
    full = counts >= floor_share * counts.max()
    # runs of full bins: their widths, and whether there are at least two
    edges = np.flatnonzero(np.diff(np.r_[0, full.astype(np.int8), 0]))
    widths = (edges[1::2] - edges[::2]) * bin_m
    return len(widths) >= 2 and widths.max() <= max_band_m

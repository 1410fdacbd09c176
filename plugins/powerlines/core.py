"""Power-line pre-classification and the 3D conductor step (pure numpy/scipy).

* ``shape_classes``: eigenvalue shape of each candidate's neighbourhood: linear (wires),
  planar (roofs: a flat 2D patch) or rugged (vegetation: volumetric scatter). It stands in for the
  planar/rugged pre-classification the method ran in LAStools.
* ``conductors_3d``: beyond the method's 2D limit — the 3D points near a 2D line are split by
  height and continuity (so wires stacked in plan come apart), each wire into spans at its
  attachment points (the highest points between sags), and a catenary
  z = z0 + c·(cosh((s - s0)/c) - 1) is fitted per span in its vertical plane; where one does
  not fit (wires stacked closer than the height link, clutter linked to a wire),
  ``peel_catenaries`` takes them out one at a time.
* ``short_wires``: wires seen over a few metres only (a mobile scan's wires across the street),
  straight 3D runs that leave the wires found at a support.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from toolbox.neighbourhoods import neighbourhood_covariances, principal_axes, symmetric3_eigenvalues


MAX_DENSITY_NEIGHBOURS = 256  # bounds the neighbourhoods' memory on very dense (mobile) scans


DENSITY_BLOCK_M = 5.0  # the density's window moves in blocks of this size (cells of 1 m inside)


def height_window_top(hag, xyz, quantile: float = 99.95, link_m: float = 2.5, min_links: int = 2) -> float:
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


def local_surface_density(x, y, weight=None, radius_m: float = 200.0, cell_m: float = 1.0,
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


def shape_classes(xyz: np.ndarray, neighbours: int = 12, rugged_share: float = 0.04, planar_share: float = 0.2,
                  surface_density: float | None = None, max_axis_slope: float = 0.7):
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


def ribbons(xyz, idx, dist, planar, smooth, link: float = 1.0, bin_m: float = 0.05, max_band_m: float = 0.4,
            min_points: int = 20, floor_share: float = 0.05, piece_m: float = 10.0):
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
        if _is_ribbon(xyz[comp], bin_m, max_band_m, floor_share):
            out[comp] = True
            continue
        # a ribbon linked to a crown or to a crossing line is a ribbon where it runs alone:
        # the set judged again piece by piece along its main axis
        for m in _pieces_along(xyz, comp, piece_m):
            if len(m) >= min_points and planar[m].any() and _is_ribbon(xyz[m], bin_m, max_band_m, floor_share):
                out[m] = True
    return out & planar


def tubes(xyz, idx, dist, rugged, smooth, link: float = 1.0, max_width_m: float = 1.0, min_points: int = 20,
          piece_m: float = 10.0, min_length_m: float = 5.0):
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


def _is_ribbon(xyz, bin_m, max_band_m, floor_share) -> bool:
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


def _theil_sen_slope(x, y, max_pairs: int = 4000) -> float:
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


# a wire is thin across its line: its points' lateral rms about a straight plan trend (ALS and
# mobile scans alike: 0.04-0.1 m; a crown's edge lined up along a street is wider)
WIRE_LATERAL_RMS_M = 0.15
# the least lateral tolerance of a wire's points about its trend, whatever their measured
# scatter: a few centimetres of ranging noise on either side
WIRE_LATERAL_FLOOR_M = 0.05
# the least distance across the line at which the 3D step tells side-by-side wires apart (a
# triangle bundle's 0.2 m stays one piece, a ribbon's 0.3 m does not)
SIDE_BY_SIDE_MIN_GAP_M = 0.25
# the least rms about its catenary that a wire's span may have, whatever the fit of the span it
# continues (ALS and mobile scans fit 0.02-0.05 m)
WIRE_HEIGHT_RMS_M = 0.08
# a sparse wire's visible stretches may lie this many of the 3D step's links apart (AHN4's
# earth wires: hit in stretches of 10-40 m, up to 26 m apart, where links are 6.4 m)
WIDE_GAP_LINKS = 5.0
# the radius within which a sparse wire has no other point of its band (its own points aside)
ISOLATION_M = 0.5
# a wire's id over all lines: line * WIRE_ID_BASE + wire
WIRE_ID_BASE = 1 << 20
# below this core-to-ring contrast (1.5 times a surface's 7) a line's points are a surface's
SURFACE_CONTRAST = 10.5
# how many of a set's best-supported lines (through distinct points) straight_wires tries before
# it leaves the set: a cross arm or a pole top's several angles come before a wire beside them
N_BEST_LINES = 5
# (pairs of points within min_length / 2 a set's neighbourhoods are kept for: 16 bytes each)
MAX_NEIGHBOUR_PAIRS = 20_000_000


@dataclass
class Span:
    conductor: int  # index of the 2D line
    wire: int  # index of the wire (height level) along that line
    span: int
    s0: float
    c: float
    z0: float
    s_from: float
    s_to: float
    rms: float
    n_points: int
    sag: float
    offset: float = 0.0  # the wire's lateral offset from the 2D line at s = 0 (side-by-side conductors)
    offset_slope: float = 0.0  # its change per unit along the line (wires not quite parallel to it)
    offset_rms: float = 0.0  # its points' lateral scatter about that straight trend (a wire is thin)
    lateral_tol: float = np.inf  # how far across from that trend a point of this wire lies (3 robust sigma)
    chained: bool = False  # found past another span's end (next_spans): it may stop where the view does


def line_fit(x, y) -> tuple[float, float]:
    """(slope, intercept) of the least-squares line y = slope·x + intercept: ``np.polyfit(x, y, 1)``
    in closed form about the mean (polyfit's general machinery cost 150 µs a call, 150 calls per
    AHN4 run). A slope of 0 when all x are equal."""
    xm, ym = float(np.mean(x)), float(np.mean(y))
    dx = x - xm
    sxx = float(dx @ dx)
    slope = float(dx @ (y - ym)) / sxx if sxx > 0 else 0.0
    return slope, ym - slope * xm


def median_line_fit(x, y, max_pairs: int = 256, max_points: int = 512) -> tuple[float, float]:
    """(slope, intercept) of the line through two of the points that leaves the smallest median
    absolute residual (least median of squares, Rousseeuw 1984): a wire's plan trend where up to
    half of what was linked to it is a crown's scatter, which pulls a least-squares line (a clump
    at one end tilts it). Pairs at least a quarter of the points' extent apart; all of them up to
    ``max_pairs``, else that many drawn (seeded); residuals counted on at most ``max_points``."""
    n = len(x)
    if n < 3:
        return line_fit(x, y)
    order = np.argsort(x, kind="stable")
    ev = order[::-(-n // max_points)]
    rng = np.random.default_rng(0)
    i, j = np.triu_indices(n, 1) if n * (n - 1) // 2 <= 4 * max_pairs else rng.integers(0, n, (2, 4 * max_pairs))
    far = np.abs(x[j] - x[i]) >= 0.25 * float(np.ptp(x))
    i, j = i[far], j[far]
    if len(i) > max_pairs:
        pick = rng.choice(len(i), max_pairs, replace=False)
        i, j = i[pick], j[pick]
    if not len(i):
        return line_fit(x, y)
    slope = (y[j] - y[i]) / (x[j] - x[i])
    icpt = y[i] - slope * x[i]
    med = np.median(np.abs(y[ev][None, :] - slope[:, None] * x[ev][None, :] - icpt[:, None]), axis=1)
    k = int(np.argmin(med))
    return float(slope[k]), float(icpt[k])


def parabola_fit(x, y) -> tuple[float, float, float]:
    """(a2, a1, a0) of the least-squares parabola y = a2·x² + a1·x + a0 (``np.polyfit(x, y, 2)``;
    x should be centred), by the 3x3 normal equations."""
    x2 = x * x
    m = np.array([[x2 @ x2, x2 @ x, x2.sum()], [x2 @ x, x2.sum(), x.sum()], [x2.sum(), x.sum(), float(len(x))]])
    try:
        return tuple(float(v) for v in np.linalg.solve(m, np.array([x2 @ y, x @ y, y.sum()])))
    except np.linalg.LinAlgError:  # fewer than 3 distinct x: a straight line
        slope, icpt = line_fit(x, y)
        return 0.0, slope, icpt


def catenary(s, z0, s0, c):
    with np.errstate(over="ignore"):
        return z0 + c * (np.cosh((s - s0) / c) - 1.0)


def fit_catenary(s, z):
    """Least-squares catenary through (s, z); returns (z0, s0, c, rms). Started from the parabola
    through the points (a catenary's first-order form: z0 + (s - s0)^2 / 2c)."""
    from scipy.optimize import least_squares, leastsq

    span = max(float(s.max() - s.min()), 1.0)
    sm = float(s.mean())
    k, b, a = parabola_fit(s - sm, z)
    if k > 1e-7:
        c0 = 1.0 / (2.0 * k)
        s00 = sm - b / (2.0 * k)
        z00 = a - b * b / (4.0 * k)
    else:  # (nearly) straight: a very tight wire
        c0, s00, z00 = 50.0 * span, float(s[np.argmin(z)]), float(z.min())
    c0 = float(np.clip(c0, 1.0, 1e7))

    # MINPACK asks for the Jacobian at the point whose residuals it has just had, and scipy's
    # leastsq tries both functions at the start point first: the residuals, robust weights and
    # Jacobian of the last point are kept (and the Jacobian built in one preallocated array, in
    # MINPACK's column order): per evaluation a few numpy calls on a few hundred points, whose
    # overhead is most of the cost (36 AHN4 spans 51 -> 39 ms, the same curves to 1e-5 m)
    last = {}
    jac_out = np.empty((3, len(s)))

    # The robust soft-L1 cost sum(f² ρ((r/f)²)), ρ(t) = 2(√(1+t) − 1), f = 0.1 m, written as plain
    # least squares of r̃ = r·w, w = √(2/(q+1)), q = √(1+(r/f)²) (Σ r̃² is exactly that cost), so that
    # MINPACK's Levenberg-Marquardt minimises it: the same curves as scipy's trust-region solver
    # with loss="soft_l1" at 60 % of its time (to 0.1 mm on 95 of 99 AHN4 and corridor spans; the
    # other 4, nearly straight pieces where both stop at the cap, within 3 mm).
    def model(p):
        key = (float(p[0]), float(p[1]), float(p[2]))
        if last.get("key") != key:
            c = np.exp(p[2])
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # c underflows on hopeless pieces
                u = (s - p[1]) / c
                ch = np.cosh(u)
                r = p[0] + c * (ch - 1.0) - z  # = catenary(s, p0, p1, c) - z, operation for operation
                q = r / 0.1
                np.hypot(q, 1.0, out=q)  # sqrt(1 + q²) without overflow: a far point must not weigh 0
                w = np.sqrt(2.0 / (q + 1.0))
            last.clear()
            last.update(key=key, c=c, u=u, ch=ch, r=r, q=q, w=w)
        return last

    def res(p):  # a copy: scipy's robust-loss path scales residuals in place
        return model(p)["r"].copy()

    def jac(p):  # analytic: 3-4x fewer model evaluations than finite differences
        m = model(p)
        c, u, ch = m["c"], m["u"], m["ch"]
        with np.errstate(over="ignore", invalid="ignore"):
            sh = np.sinh(u)
            return np.column_stack([np.ones_like(s), -sh, c * (ch - 1.0 - u * sh)])

    def res_robust(p):
        m = model(p)
        r = m["r"]
        with np.errstate(invalid="ignore"):  # an overflowed trial step stays infinite: rejected
            return np.where(np.isfinite(r), r * m["w"], r)

    def jac_robust(p):  # rows: d r̃ / d(z0, s0, log c)
        m = model(p)
        if "jac" not in m:
            c, u, ch, q, w = m["c"], m["u"], m["ch"], m["q"], m["w"]
            with np.errstate(over="ignore", invalid="ignore"):
                g = w * (q + 1.0) / (2.0 * q)  # d r̃ / d r = w (1 - (q - 1) / 2q)
                sh = np.sinh(u)
                jac_out[0] = g
                np.multiply(sh, g, out=jac_out[1])
                np.negative(jac_out[1], out=jac_out[1])
                np.multiply(u, sh, out=jac_out[2])  # c (cosh u - 1) - (s - s0) sinh u = c (cosh u - 1 - u sinh u)
                np.subtract(ch - 1.0, jac_out[2], out=jac_out[2])
                jac_out[2] *= c * g
            m["jac"] = True
        return jac_out

    # 50 evaluations settle every well-posed span; short, tight pieces whose c is barely
    # determined crawl along a flat valley without converging, for an rms that changes by a
    # millimetre (a trial step to a tiny c makes cosh overflow: the solver rejects that step, and
    # must not print a warning to the user)
    with np.errstate(over="ignore", invalid="ignore"):
        x0 = np.array([z00, s00, np.log(c0)])
        if len(s) >= 3:
            # MINPACK's lmder called as least_squares(method="lm", max_nfev=50) calls it (the same
            # tolerances, factor, scaling: the same steps), through leastsq: scipy's generic
            # wrapper cost more per evaluation than the model (99 spans 140-156 -> 90 ms)
            x = leastsq(res_robust, x0, Dfun=jac_robust, col_deriv=True, full_output=True, ftol=1e-8, xtol=1e-8,
                        gtol=1e-8, maxfev=50, factor=100.0, diag=None)[0]
        else:
            x = least_squares(res, x0, jac=jac, loss="soft_l1", f_scale=0.1, max_nfev=50).x
    z0, s0, lc = x
    r = res(x)
    # RMS over the inliers: poles and insulators joined to a wire must not condemn its fit
    mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    inl = np.abs(r) <= max(3 * mad, 0.15)
    with np.errstate(over="ignore"):  # a hopeless piece's residuals may be huge: its rms is then inf
        rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else np.inf
    return float(z0), float(s0), float(np.exp(lc)), rms


def split_spans(s, z, min_span: float, window_m: float = 10.0, min_drop: float = 0.02, min_c_m: float = 100.0):
    """Cut positions along a wire at its attachment points. Along one catenary the slope only
    grows; where the slope drops (rising on the left, falling on the right) the wire passes an
    attachment point; so does a rise in slope far steeper than a catenary's (see below). Slopes
    come from least-squares lines over ``window_m`` on each side."""
    if s.max() - s.min() < 2 * min_span:
        return []
    order = np.argsort(s)
    s, z = s[order], z[order]
    step = 1.0
    # candidate positions on a grid centred on the wire: mirror-symmetric, so a line taken the
    # other way round gives the same cuts
    centre = 0.5 * (s.min() + s.max())
    half = np.floor((0.5 * (s.max() - s.min()) - min_span) / step)
    pos = centre + step * np.arange(-half, half + 1)
    lo = np.searchsorted(s, pos - window_m)
    mid = np.searchsorted(s, pos)
    hi = np.searchsorted(s, pos + window_m)
    # prefix sums for least-squares slopes over index ranges
    cs, cz = np.r_[0, np.cumsum(s)], np.r_[0, np.cumsum(z)]
    css, csz = np.r_[0, np.cumsum(s * s)], np.r_[0, np.cumsum(s * z)]

    def slope(i, j):
        n = j - i
        with np.errstate(invalid="ignore", divide="ignore"):
            sx, sz = cs[j] - cs[i], cz[j] - cz[i]
            sxx, sxz = css[j] - css[i], csz[j] - csz[i]
            return np.where(n >= 5, (n * sxz - sx * sz) / (n * sxx - sx * sx), np.nan)

    left, right = slope(lo, mid), slope(mid, hi)
    drop = left - right
    # a catenary's slope grows by window / c between the two windows; a jump far beyond what
    # the slackest wire (c >= min_c_m) gives is a kink at an attachment point too (a span
    # climbing an embankment from a pole at its foot)
    kink = np.where(drop > 0, drop, -drop - window_m / min_c_m)  # how far past each threshold
    cand = np.isfinite(drop) & ((drop > min_drop) | (-drop > window_m / min_c_m))
    cuts = []
    for i in np.flatnonzero(cand)[np.argsort(-kink[cand])]:
        if all(abs(pos[i] - c) >= min_span for c in cuts):
            cuts.append(float(pos[i]))
    return sorted(cuts)


def kink_cut(s, z, min_span: float, step_m: float = 1.0, min_gain: float = 1.5, min_drop: float = 0.02):
    """Where along a piece of wire that one catenary fits, two fit it markedly better: an
    attachment the wire runs through that ``split_spans``' slope windows missed (a suspension
    tower hiding the wire's points; 60 m spans' small kinks). Parabolas (a catenary's first-order form) left and
    right of each cut ``step_m`` apart, at least ``min_span`` from the ends; the best cut counts
    when it lowers the rms ``min_gain`` times, the slope drops there by ``min_drop`` (rising into
    it, falling after it: a catenary's slope only grows) and both sides meet there (within 3 of
    their rms: one wire, attached). Returns the cut or None."""
    if s.max() - s.min() < 2 * min_span or len(s) < 12:
        return None
    order = np.argsort(s)
    s, z = s[order], z[order]
    centre, half = 0.5 * (s[0] + s[-1]), 0.5 * (s[-1] - s[0])
    u = (s - centre) / half  # conditioning: in [-1, 1]
    pos = centre + step_m * np.arange(-np.floor((half - min_span) / step_m), np.floor((half - min_span) / step_m) + 1)
    k = np.searchsorted(s, pos)
    pw = np.column_stack([u ** i for i in range(5)])  # u^0..u^4
    pz = np.column_stack([z * u ** i for i in range(3)])  # z u^0..u^2
    cp = np.vstack([np.zeros((1, 5)), np.cumsum(pw, axis=0)])
    cz = np.vstack([np.zeros((1, 3)), np.cumsum(pz, axis=0)])
    cz2 = np.r_[0.0, np.cumsum(z * z)]

    def fits(i, j):  # parabola coefficients and SSE over the index ranges [i, j)
        m = cp[j] - cp[i]
        A = np.stack([m[:, 0:3], m[:, 1:4], m[:, 2:5]], axis=1)
        b = cz[j] - cz[i]
        ok = (j - i) >= 6
        A[~ok] = np.eye(3)
        with np.errstate(all="ignore"):
            coef = np.linalg.solve(A, b[..., None])[..., 0]
        sse = (cz2[j] - cz2[i]) - np.einsum("ij,ij->i", coef, b)
        return coef, np.where(ok, np.maximum(sse, 0.0), np.inf)

    n = len(s)
    _, sse1 = fits(np.array([0]), np.array([n]))
    cl, sl = fits(np.zeros_like(k), k)
    cr, sr = fits(k, np.full_like(k, n))
    sse2 = sl + sr
    best = int(np.argmin(sse2))
    if not np.isfinite(sse2[best]) or sse2[best] * min_gain ** 2 > sse1[0]:
        return None
    # cuts in one gap split the points alike: the attachment is where the two sides meet
    same = np.flatnonzero(k == k[best])
    ub = (pos[same] - centre) / half
    basis = np.column_stack([np.ones_like(ub), ub, ub * ub])
    gap = np.abs(basis @ cl[best] - basis @ cr[best])
    at = int(np.argmin(gap))
    ub = ub[at]
    slope_l = (cl[best][1] + 2 * cl[best][2] * ub) / half
    slope_r = (cr[best][1] + 2 * cr[best][2] * ub) / half
    rms2 = np.sqrt(sse2[best] / n)
    if slope_l - slope_r < min_drop or gap[at] > 3 * rms2:
        return None
    return float(pos[same[at]])


def conductors_3d(lines, px, py, pz, band: float, z_link: float, s_link: float, min_span: float,
                  min_points: int = 20, max_rms: float = np.inf, off_link: float = 0.25, reach: float | None = None,
                  ground_z=None, peel: bool = True, min_piece: float | None = None, only=None):
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
    if reach is None:
        reach = band
    if min_piece is None:
        min_piece = min_span / 2
    spans: list[Span] = []
    line_of = np.full(len(px), -1, np.int64)
    wire_of_point = np.full(len(px), -1, np.int64)
    owner = band_owner(lines, px, py, band, reach)
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
        # are told apart afterwards by _split_bundles)
        # heights linked about the ground's trend along the line: wires on a hillside climb with the
        # towers, and a sparse wire's points a few metres apart on a 25 % slope differ by > z_link
        slope_z = line_fit(s, ground_z[cand])[0] if ground_z is not None else 0.0
        scaled = np.column_stack([s / s_link, (z - slope_z * s) / z_link, off / off_link])
        pairs = cKDTree(scaled).query_pairs(1.0, output_type="ndarray")
        g = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(cand), len(cand))) \
            if len(pairs) else sparse.coo_matrix((len(cand), len(cand)))
        _, lab = connected_components(g, directed=False)
        lab = _split_bundles(s, off, lab, min_points, z=z)
        wire_of = _chain_pieces(s, z, lab, min_points, gap_max=6 * s_link, z_tol=z_link)
        next_wire = int(wire_of.max()) + 1 if len(wire_of) else 0
        for k in np.flatnonzero(wire_of >= 0):
            m = lab == k
            if s[m].max() - s[m].min() < min_piece:
                continue
            wire = int(wire_of[k])
            sk, zk, ik, ok_ = s[m], z[m], cand[m], off[m]
            n_spans = [0]

            def emit(sel, wire, fit):
                spans.append(_span(li, wire, n_spans[0], sk[sel], ok_[sel], fit, z=zk[sel]))
                n_spans[0] += 1
                z0, s0, c, rms = fit
                if rms <= max_rms:  # points of a span that is not a wire are not wire points
                    resid = np.abs(catenary(sk[sel], z0, s0, c) - zk[sel])
                    on = ik[sel][resid <= max(3 * rms, 0.15)]
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
                if fit[3] > max_rms and peel:
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
                    finer = split_spans(sk[sel], zk[sel], min_span, min_drop=0.005)
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
        good = [sp for sp in spans if sp.conductor == li and sp.rms <= max_rms]
        # a line that holds a wire: what its pieces left (the sparse stretches of a mobile scan, a
        # wire linked to clutter under it) searched for catenaries as a whole, across gaps twice the
        # link's (occlusions); then across WIDE_GAP_LINKS for a thin wire (an earth wire over the
        # phases) that the survey hit in stretches several V_max apart, kept where nothing else of
        # the band lies around its points (a facade's scan rows, a crown's edge have their
        # neighbours there)
        for gap_m, wide in ((2 * s_link, False), (WIDE_GAP_LINKS * s_link, True)):
            free = np.flatnonzero(line_of[cand] < 0)
            if not (good and peel and len(free) >= min_points):
                continue
            xyz = np.column_stack([s, off, z]) if wide else None
            for part, fit in peel_catenaries(s[free], z[free], off[free], min_points, min_span, max_rms,
                                             gap_m=gap_m):
                sel = free[part]
                if wide:
                    # (one without a gap over the first search's is what that search turned down)
                    if np.diff(np.sort(s[sel])).max() <= 2 * s_link or not _stands_clear(xyz, sel, ISOLATION_M):
                        continue
                    sel, fit, gone = _whole_sparse_wire(sel, fit, xyz, line_of[cand] >= 0, wire_of_point[cand],
                                                        max_rms, ISOLATION_M)
                    if gone:  # stretches of it dense enough to have been fitted alone
                        spans[:] = [sp for sp in spans if not (sp.conductor == li and sp.wire in gone)]
                        good = [sp for sp in good if sp.wire not in gone]
                spans.append(_span(li, next_wire, 0, s[sel], off[sel], fit, z=z[sel]))
                line_of[cand[sel]], wire_of_point[cand[sel]] = li, next_wire
                next_wire += 1
                good.append(spans[-1])
        _pick_up(li, good, cand, s, z, off, line_of, wire_of_point)
    return spans, line_of, wire_of_point


def _whole_sparse_wire(run, fit, xyz, wired, wire_of, max_rms: float, radius_m: float, max_slope: float = 0.5,
                       share: float = 0.9):
    """A sparse wire found from its longest run (indices ``run`` into a line's band ``xyz``:
    along, across, height; ``fit`` its catenary) with the rest of its points past gaps wider
    still: the band's points on that catenary where it hangs gently (slope at most
    ``max_slope``) that are on no wire (``wired``) and have no point off it within ``radius_m``,
    and the wires (``wire_of``) with ``share`` of their points on it, whole. Returns (indices,
    refitted catenary, those wires); the run alone where the whole fits worse than ``max_rms``."""
    s, z = xyz[:, 0], xyz[:, 2]
    gentle = np.abs(np.sinh((s - fit[1]) / fit[2])) <= max_slope
    on = gentle & (np.abs(catenary(s, *fit[:3]) - z) <= max(3 * fit[3], 0.15))
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


def _stands_clear(xyz, run, radius_m: float, max_around: float = 0.5) -> bool:
    """Whether the points ``run`` (indices into ``xyz``) have on average at most ``max_around``
    other points of ``xyz`` within ``radius_m`` each."""
    others = np.setdiff1d(np.arange(len(xyz)), run)
    if not len(others):
        return True
    around = cKDTree(xyz[others]).query_ball_point(xyz[run], radius_m, return_length=True)
    return float(np.mean(around)) <= max_around


def alone_beside_wires(xyz, wire, free, reach_m: float = 0.5, near_m: float = 0.4, max_near: int = 2,
                       around_m: float = 1.0, max_around: int = 8, rounds: int = 3, tree=None):
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


def ribbon_lines(lines, px, py, band_m: float, min_length_m: float, max_gap_m: float,
                 min_gap_m: float = SIDE_BY_SIDE_MIN_GAP_M, max_angle_deg: float = 0.5, search_deg: float = 0.2,
                 step_deg: float = 0.005, bin_m: float = 0.02, peak_m: float = 0.06, min_points: int = 20,
                 match_m: float = 0.05, min_wires: int = 3, min_share: float = 0.75):
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
    ``_split_bundles`` keeps them). Only lines ``4 * min_length_m`` or longer take part (a tower's
    members stay out), a wire runs along half the longest line or more, and a group is redrawn
    where it holds ``min_wires`` wires or more (two side by side the 3D step tells apart, as a
    bundle's pair) that hold ``min_share`` of its band's points (an airborne survey's scatter
    across a wire, as wide as the gaps between them, leaves the Hough's lines as good as any)
    and its lines are not already one per wire, each within ``match_m`` of it at both ends. A
    line reaching out of the ribbon stays.

    Returns (lines, source, points) with each group redrawn (source: per returned line, the index
    of the input line nearest it, whose attributes it takes; points: how many of the band's points
    a redrawn line holds, None for a line left as it was), or None where no group changed."""
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
        redrawn = _ribbon_group(lines, members, pts, band_m, min_length_m, max_gap_m, min_gap_m, search_deg,
                                step_deg, bin_m, peak_m, min_points, match_m, min_wires, min_share) \
            if long_[members[0]] else None
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


def _ribbon_group(lines, members, pts, band_m, min_length_m, max_gap_m, min_gap_m, search_deg, step_deg, bin_m,
                  peak_m, min_points, match_m, min_wires, min_share):
    """One group of ``ribbon_lines``: [(line, source index, points held or None)] redrawn, or
    None (left as it is)."""
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
    sc = s - np.median(s)  # turn about the middle: the offsets stay where they are there
    best, best_phi = -1.0, 0.0
    for phi in np.radians(np.arange(-search_deg, search_deg + step_deg / 2, step_deg)):
        turned = o - phi * sc
        h = np.bincount(((turned - turned.min()) / bin_m).astype(np.int64))
        score = float(h @ h)
        if score > best:
            best, best_phi = score, phi
    oc = o - best_phi * sc
    lo, hi = float(oc.min()) - 2 * bin_m, float(oc.max()) + 2 * bin_m
    nb = int(np.ceil((hi - lo) / bin_m)) + 1
    h = np.bincount(((oc - lo) / bin_m).astype(np.int64).clip(0, nb - 1), minlength=nb).astype(float)
    hs = np.convolve(h, [1.0, 2.0, 1.0], mode="same")
    peaks = [i for i in range(1, nb - 1) if hs[i] > 0 and hs[i] >= hs[i - 1] and hs[i] > hs[i + 1]]
    wires = []  # (centre, points) of the peaks holding a wire
    for i in peaks:
        c = lo + (i + 0.5) * bin_m
        near = np.abs(oc - c) <= peak_m
        if near.sum() < min_points:
            continue
        c = float(np.median(oc[near]))
        near = np.abs(oc - c) <= peak_m
        runs = _runs(s[near], max_gap_m, min_length_m)
        # a wire of the ribbon runs along most of it (not a stub of an arm or a jumper)
        if sum(r[1] - r[0] for r in runs) < 0.5 * longest:
            continue
        wires.append((c, int(near.sum())))
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
    on_wires = np.abs(oc[:, None] - np.array([c for g in merged for c, _ in g])[None, :]).min(axis=1) <= peak_m
    if on_wires.mean() < min_share:
        return None
    # each wire's own line: its points (within peak_m, or within half the gap to its neighbours
    # for a merged bundle) refitted along the turned frame
    redrawn = []
    for g, c in zip(merged, centres):
        half = max(peak_m, 0.5 * (g[-1][0] - g[0][0]) + peak_m)
        mine = np.abs(oc - c) <= half
        runs = _runs(s[mine], max_gap_m, min_length_m)
        if not runs:
            continue
        t0, t1 = min(r[0] for r in runs), max(r[1] for r in runs)
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
        hit = [w for w, (_, (sl, ic, _, _), _) in enumerate(redrawn) if np.all(np.abs(oo - (sl * ss + ic)) <= match_m)]
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
               across_m: float = 0.5 * SIDE_BY_SIDE_MIN_GAP_M, max_angle_deg: float = 0.5) -> list[tuple[int, int]]:
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
    return bool((across <= across_m).all() and (height <= max(3 * max(p.rms, q.rms), 0.15)).all())


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


def _span(line: int, wire: int, number: int, s, off, fit, z=None) -> Span:
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
        on = np.abs(dz) <= max(3 * rms, 0.15)
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


def peel_catenaries(s, z, off, min_points: int, min_span: float, max_rms: float, gap_m: float, tol_m: float = 0.1,
                    lateral_tol_m: float = WIRE_LATERAL_RMS_M, max_slope: float = 0.5, n_samples: int = 2000, max_tries: int = 32,
                    seed: int = 0):
    """Catenaries in a piece of (along-line, height) points that no single one fits, strongest
    first: a parabola through three points (a catenary's first-order form) with the most points
    within ``tol_m``, its points' longest run without a gap over ``gap_m``, a catenary refitted
    to them; kept when its points are thin across the line (``off``: lateral rms within
    ``lateral_tol_m`` about a straight trend, a crown's points lined up in (s, z) are not), it
    fits within ``max_rms``, spans ``min_span`` and hangs gently (slope at most ``max_slope``);
    its points are removed and the rest searched again. The ``max_tries`` best-supported
    parabolas are tried before giving up (RANSAC, seeded: reproducible).
    Returns [(indices into s, (z0, s0, c, rms))]."""
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
                thin = np.abs(r - np.median(r[thin])) <= max(3 * 1.4826 * np.median(np.abs(r[thin] - np.median(r[thin]))), 0.05)
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
        on = (r <= max(3 * rms, 0.15)) & (ls >= ls[run].min()) & (ls <= ls[run].max()) & \
            (np.abs(lo_ - o1 * ls - o0) <= max(3 * o_rms, 0.15))
        found.append((left[on], hit[1]))
        left = left[~on]
    return found


def _longest_run(s, idx, gap_m: float) -> np.ndarray:
    """The longest run of the points ``idx`` along ``s`` without a gap over ``gap_m``."""
    order = idx[np.argsort(s[idx])]
    return max(np.split(order, np.flatnonzero(np.diff(s[order]) > gap_m) + 1), key=len)


def _local_triples(s, z, n: int, min_span: float, max_slope: float, rng, draws: int = 8, chord_tol_m: float = 0.3):
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


def _pick_up(li, line_spans, cand, s, z, off, line_of, wire_of_point, lateral_m: float = 0.5):
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


def straight_wires(xyz: np.ndarray, min_length_m: float, max_gap_m: float, tol_m: float = 0.08, min_points: int = 12,
                   max_slope: float = 0.5, link_m: float = 1.0, n_samples: int = 300, seed: int = 0) -> list[np.ndarray]:
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
        near = _SetNeighbours(tree, min_length_m / 2) if (tree.count_neighbors(tree, min_length_m / 2) - len(left)) \
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



def short_wires(xyz: np.ndarray, off_ground: np.ndarray, steep: np.ndarray, wired: np.ndarray, min_length_m: float,
                max_gap_m: float, max_around: float = 0.5, reach_m: float = 5.0,
                structure_m: float = 1.5, stack_m: float = 1.5, max_stack_deg: float = 10.0, tol_m: float = 0.08,
                n_searched: int | None = None, wire_like: np.ndarray | None = None) -> list[np.ndarray]:
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
        for sub in straight_wires(xyz[beside], length / 2, max_gap_m, tol_m=tol_m, min_points=8):
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
                     max_gap_m: float, wire_like: np.ndarray | None = None, reach_m: float = 5.0,
                     head_m: float = 1.8, max_around: float = 0.5, tol_m: float = 0.08) -> list[np.ndarray]:
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
    if not len(poles) or len(xyz) < 12:
        return []
    axes = cKDTree(poles[:, :2])
    # only points a run reaching a pole may hold
    near = np.flatnonzero(axes.query(xyz[:, :2], distance_upper_bound=reach_m + 2 * min_length_m)[0] < np.inf)
    if len(near) < 12:
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

    def __init__(self, xyz, wire_like=None, plane_m: float = 0.16):
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
    near = np.unique(np.concatenate(around.tree.query_ball_point(q, 0.5))).astype(np.int64)
    rel = around.tree.data[near] - q[0]
    t = rel @ u
    r = np.linalg.norm(rel - t[:, None] * u, axis=1)
    across = np.array([-u[1], u[0], 0.0]) / max(float(np.hypot(u[0], u[1])), 1e-9)
    # (the vertical plane's distance along ``across``; the horizontal plane's in height, as the
    # run is near level)
    up = rel[:, 2] - t * u[2]
    stacked = around.wire_like[near] & ((np.abs(rel @ across) <= around.plane_m) | (np.abs(up) <= around.plane_m))
    return int(((r > 0.2) & (r <= 0.5) & (t >= 0) & (t <= length) & ~stacked).sum()) < max_around * len(q)


def sibling_wires(spans, lines, px, py, pz, max_rms: float, min_sep_m: float, min_span_m: float, owner=None,
                  owner_length=None, max_sep_m: float = 4.0, max_dz_m: float = 3.0, bin_m: float = 0.1, tol_m: float = 0.15,
                  min_points: int = 12, min_cover: float = 0.5, cover_bin_m: float = 2.0,
                  max_rounds: int = 6, stacked: bool = False, max_around: float = 0.5,
                  plane_m: float = 0.16) -> list:
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
                zone = (np.abs(across) < min_sep_m) & (np.abs(dz) > max(3 * sp.rms, tol_m)) & (np.abs(dz) <= max_dz_m)
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
                    pick = np.flatnonzero((r_z <= max(3 * fit[3], tol_m)) & (r_o <= tol_m))
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
    return int(((r > 0.2) & (r <= 0.5) & (np.abs(across) > plane_m)).sum()) < max_around * len(k)


def _best_straight_run(p, min_length_m, max_gap_m, tol_m, n_samples, rng, neighbours=None):
    """The most populous straight run in ``p`` (see straight_wires), its indices sorted along it,
    or None when none reaches ``min_length_m``. ``neighbours(i)``: the points of ``p`` within
    min_length / 2 of its points ``i`` as ``_ball_pairs`` gives them (default: searched here)."""
    n = len(p)
    # pairs drawn locally (the second point within min_length / 2 of the first): a wire of 20
    # points in a set of thousands (linked to a crown) is then drawn as often as the crown
    i = rng.integers(0, n, min(max(n_samples, n), 4 * n_samples))
    # (sample, neighbour) pairs, grouped by sample, each sample's neighbours in index order
    sid, flat = neighbours(i) if neighbours is not None else _ball_pairs(cKDTree(p), p[i], min_length_m / 2)
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


def _ball_pairs(tree, q, radius):
    """(k, index) of each point of ``tree`` within ``radius`` of the point ``q[k]``, grouped by
    k, indices ascending."""
    near = tree.query_ball_point(q, radius)  # (several points: each list sorted)
    sid = np.repeat(np.arange(len(q)), [len(x) for x in near])
    return sid, (np.concatenate(near).astype(np.int64) if len(sid) else np.zeros(0, np.int64))


class _SetNeighbours:
    """The neighbours within ``radius`` of each point of a set (``tree``), searched once
    (``straight_wires`` draws from the set a run at a time, and the neighbourhoods barely
    change): ``of(i)`` gives them among the points still alive (renumbered in order) as
    ``_ball_pairs`` does."""

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

def span_on_surface(s, off, dz, s_from: float, s_to: float, reach_m: float = 2.0, bin_m: float = 0.25,
                    min_run_m: float = 1.5, line_m: float = 0.1, max_tilt_deg: float = 70.0,
                    min_cover: float = 0.3, min_tilt_deg: float = 0.0) -> bool:
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


def _pieces_on_surfaces(s, off, dz, sp, gap_m: float = 2.0, lateral_m: float = 0.15) -> float:
    """The share of the span ``sp``'s own points (``s`` along its line, ``off`` across and ``dz``
    over its curve, as for span_on_surface) that lie in pieces, cut where its points leave gaps
    over ``gap_m``, each in a surface of its own: a short wire found along the top edges of two
    roofs a street apart lies in neither surface over its whole length, nor at one tilt."""
    own = (s >= sp.s_from) & (s <= sp.s_to) & (np.abs(off) <= lateral_m) & (np.abs(dz) <= max(3 * sp.rms, 0.15))
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


def points_on_spans(spans, lines, px, py, pz, max_rms: float, lateral_m: float = 0.25):
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


def grow_span_ends(spans, lines, px, py, pz, free, max_rms: float, max_gap_m: float, reach_m: float,
                   lateral_m: float = 0.25, column_m: float = 0.3, column_dz_m: float = 1.0, own_m: float = 4.0,
                   supports=None, support_m: float = 2.0, margin_m: float = 0.5, stack_m: float = 1.5):
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
            tol = max(3 * sp.rms, 0.15)
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


def _stacked_at(sp, end, sign, line_spans, own_m: float, stack_m: float, across_m: float = 0.5) -> bool:
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


def next_spans(spans, lines, px, py, pz, free, max_rms: float, max_gap_m: float, reach_m: float, min_span_m: float,
               min_points: int = 12, lateral_m: float = 0.3, max_step_m: float = 0.5, max_rise_m: float = 3.0,
               min_contrast: float = 4.0, max_rounds: int = 4, line_of=None, wire_of=None) -> list:
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
                        (np.abs(pz - catenary(s, sp.z0, sp.s0, sp.c)) <= max(3 * sp.rms, 0.15))
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
                    k, fit, _ = hit
                    for _refit in range(3):
                        # the span's points along its own trend and catenary (past a support a wire
                        # turns a little, and the end's trend continued loses it across a long span)
                        o1, o0 = line_fit(s[k], off[k])
                        more = np.flatnonzero((sign * (s - end) > 0) & (sign * (stop - s) > 0) & ~taken &
                                              (np.abs(off - o0 - o1 * s) <= lateral_m) &
                                              (np.abs(pz - catenary(s, *fit[:3])) <= max(3 * fit[3], 0.15)))
                        run = _longest_run(s, more, max_gap_m)
                        if len(run) <= len(k) or not np.isin(k, run).all():
                            break
                        refit = fit_catenary(s[run], pz[run])
                        if refit[3] > thin_m:
                            break
                        k, fit = run, refit
                    o1, o0 = line_fit(s[k], off[k])  # the next search follows this span's own trend
                    found.append((li, wire, k, s[k], off[k], fit))
                    taken[k] = True
                    end = float(s[k].max() if sign > 0 else s[k].min())
                    z_end = float(catenary(end, *fit[:3]))
    return found


def _clumped(s, window_m: float, share: float = 0.5) -> bool:
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
        (np.abs(z - catenary(s, sp.z0, sp.s0, sp.c)) <= max(3 * sp.rms, 0.15))
    if on.sum() < 3:
        return (sp.offset_slope, sp.offset), sp.lateral_tol
    o1, o0, tol = _refined_trend(s[on], off[on], *median_line_fit(s[on], off[on]))
    return (o1, o0), tol


def bridge_gaps(spans, lines, px, py, pz, free, max_rms: float, max_gap_m: float, min_gap_m: float = 1.0,
                sample_m: float = 0.5, line_of=None, wire_of=None) -> list:
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
    return r <= 0.1, (r > 0.2) & (r <= 0.5)


def core_and_ring(r) -> tuple[int, int]:
    """How many of the points at distances ``r`` lie in the core and in the ring
    (``core_and_ring_masks``)."""
    core, ring = core_and_ring_masks(r)
    return int(core.sum()), int(ring.sum())


def core_ring_contrast(core, ring):
    """The core's density over the ring's, per unit of cross-section area (both x pi); counts or
    arrays of counts."""
    return (core / 0.01) / np.maximum(ring / (0.25 - 0.04), 1e-9)


def off_their_spans(spans, lines, px, py, pz, line_of, wire_of, max_rms: float, clutter_xyz=None,
                    clutter_m: float = 0.3, margin_m: float = 0.5) -> np.ndarray:
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


def in_foliage(spans, lines, px, py, pz, line_of, wire_of, max_rms: float, around_xyz, window_m: float = 1.0,
               min_contrast: float = 4.0, min_sides: int = 5, margin_m: float = 0.5, around_tree=None) -> np.ndarray:
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


def in_a_surface(spans, lines, px, py, pz, line_of, wire_of, max_rms: float, around_xyz, around_wire,
                 min_contrast: float = SURFACE_CONTRAST, reach_m: float = 1.5, margin_m: float = 0.5,
                 around_tree=None) -> set:
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


def along_a_surface(spans, lines, px, py, pz, line_of, wire_of, max_rms: float, around_xyz, around_wire,
                    reach_m: float = 3.0, inner_m: float = 0.5, tol_m: float = 0.1, slab_m: float = 0.5,
                    max_slope_deg: float = 60.0, min_share: float = 0.7, bin_m: float = 0.25, min_fill: float = 0.7,
                    min_cover: float = 0.5, min_points: int = 10, margin_m: float = 0.5, around_tree=None) -> set:
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
        ok = (r <= max(3 * sp.rms, 0.15)) & (r < best_r[near])
        best_r[near[ok]], best_k[near[ok]] = r[ok], k
    return best_r, best_k


def _split_bundles(s, off, lab, min_points: int, z=None, min_gap: float = SIDE_BY_SIDE_MIN_GAP_M, depth: int = 3,
                   window_m: float = 5.0, max_sd: float = WIRE_LATERAL_RMS_M) -> np.ndarray:
    """Sub-conductors of a bundle hang side by side (2), in a triangle (3) or a square (4),
    closer than their scatter can keep apart in a neighbour graph: split a piece in two where
    its residual across the line (after a straight trend along it) or, given ``z``, in height
    (after a running mean over ``window_m`` along it: a span's sag is smooth at that scale) is
    clearly bimodal (two-means, centres >= ``min_gap`` apart and >= 4 pooled standard
    deviations, the pooled spread no wider than a wire's, ``max_sd``: layers of a crown are
    wider); of the two directions the clearer split, repeated ``depth`` times (a square bundle
    needs two). Where no such cut exists, the residual across the line about the wires' own
    trend (``_across_wires``), then a cut into one group per wire (a ribbon of 3-4 wires), about
    the straight trend and then about the wires' own."""
    def halves(r):
        split = _two_means_1d(r, min_points)
        return None if split is None else split[0].astype(np.int64)

    def clean_halves(r, split=None):
        return _clean_cut(_two_means_1d(r, min_points) if split is None else split, min_gap, max_sd)

    def per_wire(r):
        found = _clean_groups(r, min_points, min_gap, max_sd)
        return None if found is None else found[1]

    lab = lab.copy()
    for _ in range(depth):
        nxt = lab.max() + 1
        # only pieces big enough to split (a graph of scattered points has hundreds of tiny ones)
        for k in np.flatnonzero(np.bincount(lab) >= 2 * min_points):
            m = np.flatnonzero(lab == k)
            slope, icpt = line_fit(s[m], off[m])
            straight = off[m] - slope * s[m] - icpt
            across = _two_means_1d(straight, min_points)
            found = [clean_halves(straight, across)]
            if z is not None:
                found.append(clean_halves(_height_residual(s[m], z[m], window_m)))
            found = [f for f in found if f is not None]
            best = max(found, key=lambda f: f[0]) if found else None  # (clarity, group of each point)
            # a straight trend fitted to a mixture leans towards whichever wire has more points at
            # each end; a wire's own trend does not (tried only where the straight one finds no
            # clean cut but two groups min_gap apart: a lone wire's halves lie closer)
            apart = across is not None and across[2] - across[1] >= 0.5 * min_gap
            own = straight
            if best is None and apart:
                own = _across_wires(s[m], off[m], halves, 0.5 * min_gap, start=straight)
                best = clean_halves(own)
            if best is None:
                # a ribbon of 3-4 wires side by side: no cut in two is clean (one side holds two
                # wires), a cut into one group per wire is
                best = _clean_groups(straight, min_points, min_gap, max_sd)
            if best is None and own is not straight and _clean_groups(own, min_points, min_gap, max_sd) is not None:
                best = _clean_groups(_across_wires(s[m], off[m], per_wire, 0.5 * min_gap, start=own),
                                     min_points, min_gap, max_sd)
            if best is None and apart and np.ptp(s[m]) >= 2 * WINDOWED_SPLIT_M:
                # the phases' offsets about any straight trend move together along a long piece
                # (0.2-0.3 m over 373 m on ribbon04_d5 seed 8): grouped window by window, linked
                groups = _windowed_groups(s[m], off[m], min_points, min_gap, max_sd, WINDOWED_SPLIT_M)
                best = None if groups is None else (0.0, groups)
            if best is not None:
                groups = best[1]
                for g in range(1, groups.max() + 1):
                    lab[m[groups == g]] = nxt
                    nxt += 1
    return lab


def _clean_cut(split, min_gap: float, max_sd: float):
    """A two-means ``split`` (side, centres, pooled sd) as a clean cut: centres ``min_gap`` and 4
    pooled standard deviations apart, that spread no wider than ``max_sd``: (clarity, group of
    each value), or None."""
    if split is None:
        return None
    side, c0, c1, sd = split
    if c1 - c0 >= max(min_gap, 4 * sd) and sd <= max_sd:
        return (c1 - c0) / max(sd, 1e-9), side.astype(np.int64)
    return None


WINDOWED_SPLIT_M = 50.0


def _windowed_groups(s, off, min_points: int, min_gap: float, max_sd: float, window_m: float):
    """One group per wire of a long piece whose wires move together across its line: in each
    window of about ``window_m`` along it, the offsets about the window's own straight trend cut
    cleanly (in two, or one group per wire, or one wire alone); a window's groups are linked to
    the next window's where their own trends meet at the window border within half of
    ``min_gap``. The groups (0..) of the points, or None where a window has no clean cut or the
    links are not one to one."""
    lo, hi = float(s.min()), float(s.max())
    n_win = int(np.ceil((hi - lo) / window_m))
    if n_win < 2:
        return None
    edges = lo + (hi - lo) * np.arange(n_win + 1) / n_win
    win = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, n_win - 1)
    trends, members = [], []
    for w in range(n_win):
        i = np.flatnonzero(win == w)
        if len(i) < min_points:
            return None
        slope, icpt = line_fit(s[i], off[i])
        r = off[i] - slope * s[i] - icpt
        split = _two_means_1d(r, min_points)
        if split is not None and split[2] - split[1] < 0.5 * min_gap:
            g = np.zeros(len(i), np.int64)  # one wire
        else:
            found = _clean_cut(split, min_gap, max_sd) or _clean_groups(r, min_points, min_gap, max_sd)
            if found is None:
                return None
            g = found[1]
        trends.append([line_fit(s[i[g == k]], off[i[g == k]]) for k in range(g.max() + 1)])
        members.append([i[g == k] for k in range(g.max() + 1)])
    label = [list(range(len(members[0])))]
    nxt = len(members[0])
    for w in range(1, n_win):
        b = edges[w]
        prev = np.array([t[0] * b + t[1] for t in trends[w - 1]])
        mine = []
        for t in trends[w]:
            d = np.abs(prev - (t[0] * b + t[1]))
            k = int(np.argmin(d))
            mine.append(label[w - 1][k] if d[k] <= 0.5 * min_gap else -1)
        linked = [x for x in mine if x >= 0]
        if len(linked) != len(set(linked)):
            return None
        for j, x in enumerate(mine):
            if x < 0:
                mine[j] = nxt
                nxt += 1
        label.append(mine)
    if nxt < 2:
        return None
    out = np.zeros(len(s), np.int64)
    for w in range(n_win):
        for k, idx in enumerate(members[w]):
            out[idx] = label[w][k]
    return out


def _across_wires(s, off, grouping, max_drift_m: float, start=None, rounds: int = 4) -> np.ndarray:
    """Offsets across a line less the trend of the wires in them: the wires of a piece run
    parallel, and a trend fitted to all its points together tilts towards whichever wire has more
    points at each end (a Hough line drawn across two phases holds a third one's points past the
    end of that phase's own line). Starting from one straight trend (or the residuals ``start``),
    ``grouping`` (residuals -> group of each point, or None) groups the points, the common
    slope within the groups is fitted, and so on for ``rounds`` or until the groups hold. Wires
    that are not parallel (converging at a tower: a group's own trend drifts more than
    ``max_drift_m`` from the common one over its extent) keep the starting residuals."""
    if start is None:
        slope, icpt = line_fit(s, off)
        start = off - slope * s - icpt
    r, g, last = start, None, None
    for _ in range(rounds):
        found = grouping(r)
        if found is None:
            break
        g = np.asarray(found, np.int64)
        if last is not None and np.array_equal(g, last):
            break
        last = g
        n = np.bincount(g).astype(float)
        ds = s - (np.bincount(g, s) / np.maximum(n, 1))[g]
        do = off - (np.bincount(g, off) / np.maximum(n, 1))[g]
        slope = float((ds * do).sum() / max(float((ds * ds).sum()), 1e-12))
        r = off - slope * s
        r = r - r.mean()
    if g is None or r is start:
        return start
    for k in range(g.max() + 1):
        m = g == k
        if m.sum() >= 2 and np.ptp(s[m]) > 0:
            own = line_fit(s[m], off[m])[0]
            if abs(own - slope) * np.ptp(s[m]) > max_drift_m:
                return start
    return r


def _clean_groups(r: np.ndarray, min_size: int, min_gap: float, max_sd: float, max_groups: int = 4):
    """The fewest groups (3 to ``max_groups``) of values ``r`` (1D k-means from evenly spread
    quantiles) that are each ``min_size`` or more, neighbouring centres ``min_gap`` and 4 standard
    deviations of the widest group apart, that group no wider than ``max_sd``: (clarity, group of
    each value, numbered from the lowest), or None."""
    for k in range(3, max_groups + 1):
        # (k centres min_gap apart lie within the values' range: too narrow, none of k or more)
        if len(r) < k * min_size or np.ptp(r) < (k - 1) * min_gap:
            return None
        centres = np.quantile(r, (np.arange(k) + 0.5) / k)
        for _ in range(50):
            cuts = 0.5 * (centres[1:] + centres[:-1])
            group = np.searchsorted(cuts, r)
            sizes = np.bincount(group, minlength=k)
            if (sizes == 0).any():
                break
            new = np.bincount(group, weights=r, minlength=k) / sizes
            if np.allclose(new, centres):
                break
            centres = new
        sizes = np.bincount(group, minlength=k)
        if (sizes < min_size).any():
            continue
        # each group as thin as a wire (a crown's layer cut in three is not)
        sd = float(np.sqrt(np.max(np.bincount(group, weights=(r - centres[group]) ** 2, minlength=k) / sizes)))
        gap = float(np.min(np.diff(centres)))
        if gap >= max(min_gap, 4 * sd) and sd <= max_sd:
            return gap / max(sd, 1e-9), group
    return None


def _height_residual(s, z, window_m: float) -> np.ndarray:
    """Heights less their running mean over ``window_m`` along the line; once more with the
    two groups of a first two-means brought together, so that a stretch where one
    sub-conductor has more points does not pull the mean towards it."""
    order = np.argsort(s, kind="stable")
    ss = s[order]
    lo = np.searchsorted(ss, ss - window_m / 2)
    hi = np.searchsorted(ss, ss + window_m / 2, side="right")

    def running_mean(v):
        c = np.r_[0.0, np.cumsum(v[order])]
        out = np.empty(len(v))
        out[order] = (c[hi] - c[lo]) / (hi - lo)
        return out

    r = z - running_mean(z)
    split = _two_means_1d(r, max(3, len(r) // 10))
    if split is not None:
        side, c0, c1, _ = split
        level = np.where(side, c1, c0)  # each point's group centre
        r = z - running_mean(z - level)
    return r


def _two_means_1d(r: np.ndarray, min_size: int):
    """The best split of values ``r`` into a lower and an upper group (least within-group sum of
    squares: exact 2-means in one dimension, every cut of the sorted values tried through prefix
    sums), each of at least ``min_size`` values. Returns (upper-group mask, lower mean, upper
    mean, pooled standard deviation) or None when no such split exists."""
    n = len(r)
    if n < 2 * min_size:
        return None
    order = np.argsort(r, kind="stable")
    v = r[order]
    cs, cs2 = np.cumsum(v), np.cumsum(v * v)
    k = np.arange(min_size, n - min_size + 1)  # size of the lower group
    lo_s, lo_s2 = cs[k - 1], cs2[k - 1]
    hi_s, hi_s2 = cs[-1] - lo_s, cs2[-1] - lo_s2
    sse = (lo_s2 - lo_s * lo_s / k) + (hi_s2 - hi_s * hi_s / (n - k))
    best = int(np.argmin(sse))
    kb = int(k[best])
    upper = np.zeros(n, bool)
    upper[order[kb:]] = True
    sd = float(np.sqrt(max(sse[best], 0.0) / n))
    return upper, float(lo_s[best] / kb), float(hi_s[best] / (n - kb)), sd


def _chain_pieces(s, z, lab, min_points: int, gap_max: float, z_tol: float, slope_window: float = 10.0) -> np.ndarray:
    """Wire number of each connected piece (-1: too small). Pieces follow each other along the
    line across gaps (pylons, occlusions) when one ends where the next begins, at about the same
    height; wires are numbered from the highest down.

    Heights are compared where the two pieces' end slopes (lines over ``slope_window`` at each
    end) meet in the middle of the gap: a wire rises to a pole and falls after it, so across a
    20 m gap at a pole its ends differ by metres while their extrapolations agree."""
    n = lab.max() + 1
    counts = np.bincount(lab, minlength=n)

    def end_line(sk, zk, at, side):
        w = sk >= at - slope_window if side > 0 else sk <= at + slope_window
        if w.sum() >= 5 and np.ptp(sk[w]) > 1.0:
            slope, icpt = line_fit(sk[w], zk[w])
            return float(slope * at + icpt), float(slope)
        near = sk >= at - 2.0 if side > 0 else sk <= at + 2.0
        return float(np.median(zk[near])), 0.0

    info = []
    for k in range(n):
        if counts[k] < min_points:
            continue
        m = lab == k
        sk, zk = s[m], z[m]
        lo, hi = float(sk.min()), float(sk.max())
        z_lo, slope_lo = end_line(sk, zk, lo, -1)
        z_hi, slope_hi = end_line(sk, zk, hi, +1)
        info.append((lo, hi, z_lo, z_hi, k, float(np.median(zk)), slope_lo, slope_hi))
    info.sort()
    parent = {i[4]: i[4] for i in info}

    def root(a):
        while parent[a] != a:
            a = parent[a]
        return a

    # every admissible link costed by its height mismatch and its gap (a metre of gap weighs as
    # 2 cm of height), the cheapest taken first, each piece followed and preceded at most once:
    # of wires stacked 0.3 m apart, the next piece at the same height wins over a nearer one
    # a layer away
    links = []
    for i, (lo_i, hi_i, _, zhi_i, ki, _, _, shi_i) in enumerate(info):
        for lo_j, hi_j, zlo_j, _, kj, _, slo_j, _ in info[i + 1:]:
            gap = lo_j - hi_i
            if gap < -1.0 or gap > gap_max:
                continue
            half = max(gap, 0.0) / 2
            dz = abs((zhi_i + shi_i * half) - (zlo_j - slo_j * half))
            if dz <= z_tol + 0.02 * max(gap, 0.0):
                links.append((dz + 0.02 * max(gap, 0.0), ki, kj))
    has_next, has_prev = set(), set()
    for _, ki, kj in sorted(links):
        if ki in has_next or kj in has_prev:
            continue
        has_next.add(ki)
        has_prev.add(kj)
        parent[root(kj)] = root(ki)
    wire_of = np.full(n, -1)
    roots = sorted({root(i[4]) for i in info},
                   key=lambda r: -np.median([i[5] for i in info if root(i[4]) == r]))
    for w, r in enumerate(roots):
        for i in info:
            if root(i[4]) == r:
                wire_of[i[4]] = w
    return wire_of


@dataclass
class Pylon:
    x: float
    y: float
    height_m: float
    n_spans: int
    heading_deg: float
    cells: np.ndarray  # flat indices (on the search grid) of the tower's footprint
    grid: tuple  # the search grid: (x0, y0, cell_m, rows, cols)
    kind: str = "tower"  # "tower" (the column-and-span-ends rule) or "pole" (a thin vertical column)
    head_m: float = 0.0  # a pole's head: its points within this of the axis, in its top metre (cross arms)

    def extent_m(self) -> float:
        """How far its footprint reaches from its base: its farthest cell's centre and a cell."""
        x0, y0, cell_m, _, cols = self.grid
        r, c = np.divmod(np.asarray(self.cells), cols)
        return float(np.hypot(x0 + (c + 0.5) * cell_m - self.x, y0 + (r + 0.5) * cell_m - self.y).max()) + cell_m


def find_pylons(x, y, hag, span_ends, span_end_hag, line_headings, lines_xy, cell_m: float = 1.0,
                reach_m: float = 12.0, top_share: float = 0.8, column_share: float = 0.5,
                end_radius_m: float = 10.0, max_side_m: float = 40.0, min_ends: int = 2, span_lines=None,
                max_rugged: float = 0.7, min_slenderness: float = 2.0, passed_by: list | None = None,
                under_line_m: float = 2.0, max_side_ratio: float = 2.0, along_deg: float = 10.0,
                wire_xyh=None, max_height_share: float = 1.5, arm_m: float = 6.0,
                reach_down_share: float = 0.35, pole_area_m2: float = 4.0, over_wires_share: float = 1.2,
                over_wires_reach_down_share: float = 0.15, min_axis_share: float = 0.25,
                axis_area_m2: float = 12.0, pair_apart_m: float = 1.5, one_tower_m2: float = 100.0,
                peak_reach_m: float = 5.0):
    """Towers that carry the conductors: tall structures under the lines where spans end.

    x, y, hag: the off-ground, off-wire points (metres; hag = height above ground);
    span_ends: (n, 2) plan positions where 3D spans end, span_end_hag their heights above
    ground; lines_xy: [(a, b)] the 2D conductor segments and line_headings their headings
    (degrees, counter-clockwise from east, 0-180).

    On a ``cell_m`` grid of the points within ``reach_m`` of a conductor line, a cell is *tall*
    when its highest point reaches ``top_share`` of the lowest span end's height within
    ``end_radius_m`` (a tower stands as high as the lowest attachment it holds there, and its
    peak, over the middle of its body, holds the earth wire; a tree with no span ending at it is
    never tall), and a *column* when
    its points fill at least ``column_share`` of the 1 m layers from its top down to 3 m above
    ground (a lattice or a pole, not an arm or a crown). Tall cells join into candidates (8-
    connected); a candidate with a column, at most ``max_side_m`` across, where at least
    ``min_ends`` and more spans end (within ``end_radius_m`` of its body, or its arms' reach; a
    span end counts for the nearest candidate only) than run past it (``span_lines``: each span's
    plan segment, span i's ends being ``span_ends[2i]`` and ``[2i + 1]``) is a tower: wires end at
    towers and pass trees. Only the spans along those that end there (within ``along_deg``) count
    as running past: a pole that ends one line may stand under another line crossing it. Tiles cut spans at their edges,
    where no tower stands: that is what the column is for. A tower is neither vegetation (at most ``max_rugged`` of its points rugged, as
    ``shape_classes`` tells crowns) nor a building (at least ``min_slenderness`` times as tall as
    the square root of its footprint, arms included), and, given the wire points found
    (``wire_xyh``: x, y, hag), it stands at most ``max_height_share`` times as high as the
    highest of them within ``arm_m`` (a tree reaching over a low line, where the wire's pieces
    lost in its crown end, stands twice as high or more; a tower holds the earth wire at its
    peak, a pole its top wire). A candidate wider than a pole (its body over ``pole_area_m2``)
    reaches down to ``reach_down_share`` of its height: a lattice's legs stand on the ground, a
    crown where wire pieces end hangs over a gap (its trunk hidden); a pole's few points may
    leave its foot bare; one that stands over ``over_wires_share`` times as high as the wires
    beside it (a tower holding an earth wire not found) reaches down to
    ``over_wires_reach_down_share`` of its height (a lattice's legs; a crown over the wires hangs
    off the ground). A candidate up to ``axis_area_m2`` (a pole with its arms) has at least
    ``min_axis_share`` of its points under its head on one thin vertical (``_axis_share``: a
    pole's column; a crown spreads over metres). The base is the median of its points (the
    middle of its column cells leans to the side a street scan sees). ``passed_by``, a list, gets the
    candidates that more spans run past than end at (a tree, or a suspension tower the wires run
    through: its arms, if found as lines, tell). A candidate up to twice ``axis_area_m2`` standing
    on two thin verticals at least ``pair_apart_m`` apart, each holding span ends of its own, is
    two poles (``_pole_pair``: a line ending at its pole beside another line's pole). A body over
    ``one_tower_m2`` (the family's largest true tower 73 m2 of cells, AHN4's 76) is a lattice
    with crowns touching it: its base comes from its cells within ``peak_reach_m`` of its
    highest column cell, and its body keeps the cells within the half-diagonal of a square of
    ``one_tower_m2`` of that base.

    A tower stands under the lines it carries: its base within ``under_line_m`` of a conductor in
    plan (an earth wire over its body, a pole's top insulator), or between conductors, the farther
    side's nearest at most ``max_side_ratio`` times as far as the nearer side's, or its footprint
    (the arms) reaching within a cell of one. A tree beside the line, where wires lost in its crown
    end, has them all on one side, clear of it.
    """
    from scipy import ndimage

    if len(x) == 0 or len(span_ends) == 0:
        return []
    g = _tower_grid(x, y, hag, lines_xy, reach_m, cell_m)
    if g is None:
        return []
    x, y, hag, flat, top, n_layers, centres, (x0, y0, _, rows, cols), top_held = g
    has = np.isfinite(top)
    wire_near = None if wire_xyh is None or not len(wire_xyh[0]) else \
        _wires_over_cells((x0, y0, cell_m, rows, cols), *wire_xyh, arm_m)[1]
    wire_top = np.zeros(rows * cols)
    span_end_hag = np.asarray(span_end_hag, float)
    ends = cKDTree(np.asarray(span_ends, float))
    idx = np.flatnonzero(has)
    # the lowest span end around: the earth wire's end over a lattice tower's peak is nearer its
    # middle cells than the phases' ends at its arms, and only the peak reaches that high
    pairs = cKDTree(centres[idx]).sparse_distance_matrix(ends, end_radius_m, output_type="ndarray")
    lowest = np.full(len(idx), np.inf)
    np.minimum.at(lowest, pairs["i"], span_end_hag[pairs["j"]])
    hit = np.isfinite(lowest)
    wire_top[idx[hit]] = lowest[hit]
    tall = has & (wire_top > 0) & (top >= top_share * wire_top)
    column = tall & (n_layers >= np.maximum(3, column_share * (top - 3.0)))  # 3 m of it at least
    structure = has & (n_layers >= 3)  # something standing at least 3 m above 3 m: legs, body, arms
    lab, n = ndimage.label(tall.reshape(rows, cols), structure=np.ones((3, 3), bool))
    lab = lab.ravel()
    shaped = []  # (cells, centre, arm reach, height) of the candidates shaped like a tower
    for k in range(1, n + 1):
        cells = _shaped_bodies(np.flatnonzero(lab == k), column, (rows, cols), centres,
                               lambda c: _tower_shaped(c, x, y, hag, flat, top, top_held, column, centres, cell_m,
                                                       max_side_m, min_slenderness, max_rugged) is not None)
        got = _tower_shaped(cells, x, y, hag, flat, top, top_held, column, centres, cell_m, max_side_m,
                            min_slenderness, max_rugged)
        if got is not None:  # (centre, how far out the wires may hang, height)
            shaped.append((cells, *got))
    if not shaped:
        return []
    # each span end belongs to the nearest candidate that reaches it (a tree beside a pole does
    # not count the pole's span ends)
    cxy = np.array([c for _, c, _, _ in shaped])
    reach = np.array([max(end_radius_m, a) for _, _, a, _ in shaped])
    d_end = np.hypot(*(np.asarray(span_ends, float)[:, None, :] - cxy[None, :, :]).transpose(2, 0, 1))
    # nor the ends of wires held far over its top (another line's, lost in the view beside it)
    can_hold = span_end_hag[:, None] * top_share <= np.array([h for _, _, _, h in shaped])[None, :]
    d_end = np.where((d_end <= reach[None, :]) & can_hold, d_end, np.inf)
    owner = np.where(np.isfinite(d_end.min(axis=1)), d_end.argmin(axis=1), -1)
    found = []
    for k, (cells, (cx, cy), arm, height) in enumerate(shaped):
        n_ends = int(np.sum(owner == k))
        if n_ends < min_ends:
            continue
        # a support stands about as high as the wires beside it; a crown reaching over a low
        # line, where the wire's pieces lost in it end, stands far higher
        if wire_near is not None and np.isfinite(wire_near[cells].max()) and \
                height > max_height_share * float(wire_near[cells].max()):
            continue
        passed = False
        if span_lines is not None:
            running = [(a, b) for a, b in span_lines if _passes(cx, cy, a, b, arm, end_radius_m)]
            if len(span_lines) * 2 == len(span_ends):
                ending = [span_lines[i // 2] for i in np.flatnonzero(owner == k)]
                running = [r for r in running if any(_parallel(r, e, along_deg) for e in ending)]
            passed = len(running) >= n_ends
        if passed and passed_by is None:
            continue
        dist = [_point_segment_distance(cx, cy, a, b) for a, b in lines_xy]
        # a tower reaches the wires it carries (where they sit on its top, its top points are wire points)
        height = max(height, float(np.max(span_end_hag[owner == k])))
        standing = structure & (top >= 0.5 * height)  # legs and body reach up to the head; bushes do not
        body = _grow_body(cells, standing.reshape(rows, cols), centres, np.array([cx, cy]), arm)
        if not passed and not _under_its_lines(cx, cy, centres[body], lines_xy, end_radius_m, under_line_m,
                                               max_side_ratio, cell_m):
            continue
        area = len(body) * cell_m ** 2
        wide = area > pole_area_m2
        down = float(hag[np.isin(flat, body)].min()) / height if wide else 0.0  # (only wide ones are asked)
        if wide and down > reach_down_share:
            continue
        # a tower standing well over the wires found beside it holds an earth wire not found, on
        # legs that reach the ground; a crown over the wires, off the ground, is trees
        if wide and down > over_wires_reach_down_share and wire_near is not None and \
                np.isfinite(wire_near[cells].max()) and height > over_wires_share * float(wire_near[cells].max()):
            continue
        # its base where its points are: the middle of its column cells leans to the side a street
        # scan sees, and to an arm's cells on an angle tower; not where a stack of wires, unfound,
        # runs off its top along the line
        heading = float(line_headings[int(np.argmin(dist))])
        base_cells = _base_cells(cells, column, n_layers, centres, np.radians(heading))
        if area > one_tower_m2:
            # wider than any one tower: a lattice with the crowns touching it; its base under its
            # peak (the earth wire's), not amid the crowns' many points
            col = cells[column[cells]]
            peak = centres[col[np.argmax(top[col])]]
            base_cells = base_cells[np.hypot(*(centres[base_cells] - peak).T) <= peak_reach_m]
        mine = np.flatnonzero(np.isin(flat, base_cells))
        bx, by = (float(np.median(x[mine])), float(np.median(y[mine]))) if len(mine) else (cx, cy)
        if area > one_tower_m2:
            # its points (class 15): the cells one tower's body could cover about that base (the
            # half-diagonal of a square of one_tower_m2), not the crowns'
            body = body[np.hypot(centres[body][:, 0] - bx, centres[body][:, 1] - by) <= np.sqrt(one_tower_m2 / 2)]
        if area <= axis_area_m2:
            # a pole (with its arms) stands on one thin column; a crown where wire pieces end
            # spreads its points over metres
            share, _ = _axis_share(x, y, hag, bx, by, height)
            if share is not None and share < min_axis_share:
                continue
        pair = None if passed or area > 2 * axis_area_m2 else \
            _pole_pair(x, y, hag, flat, body, height, np.asarray(span_ends, float)[owner == k],
                       span_end_hag[owner == k], centres, min_ends, min_axis_share, pair_apart_m)
        if pair is not None:
            # two poles side by side (a line ending at its own pole beside another line's): their
            # arms join their cells into one candidate, whose middle is neither pole
            for (ax, ay), ax_height, ax_ends, ax_body in pair:
                dist = [_point_segment_distance(ax, ay, a, b) for a, b in lines_xy]
                found.append(Pylon(ax, ay, ax_height, ax_ends, float(line_headings[int(np.argmin(dist))]), ax_body,
                                   (x0, y0, cell_m, rows, cols)))
            continue
        (passed_by if passed else found).append(
            Pylon(bx, by, height, n_ends, heading, body,
                  (x0, y0, cell_m, rows, cols)))
    return found


def _pole_pair(x, y, hag, flat, body, height: float, ends_xy, ends_hag, centres, min_ends: int,
               min_share: float, apart_m: float, axis_m: float = 0.5, low_m: float = 3.0, head_m: float = 1.5,
               second_share: float = 0.5, min_points: int = 5, min_rise_share: float = 0.5):
    """Two poles in one candidate, or None: the body's points from ``low_m`` above ground to
    ``head_m`` under its top gathered on thin verticals (the most within ``axis_m``), the densest
    holding ``min_share`` of them (a pole's column, not a lattice's legs) and another at least
    ``apart_m`` from it ``second_share`` as many, rising over ``min_rise_share`` of that height
    (a column, not a crown's piece); each holds at least ``min_ends`` of the candidate's span ends
    (``ends_xy``, their heights ``ends_hag``), the nearer axis's. Returns per pole ((x, y),
    height, its span ends, its body cells: the nearer pole's)."""
    inside = np.flatnonzero(np.isin(flat, body))
    mine = inside[(hag[inside] >= low_m) & (hag[inside] <= height - head_m)]
    if len(mine) < 2 * min_points or len(ends_xy) < 2 * min_ends:
        return None
    pts = np.column_stack([x[mine], y[mine]])
    tree = cKDTree(pts)
    count = tree.query_ball_point(pts, axis_m, return_length=True)
    first = int(np.argmax(count))
    if count[first] < min_share * len(mine):
        return None
    far = np.flatnonzero(np.hypot(*(pts - pts[first]).T) >= apart_m)
    if not len(far):
        return None
    second = int(far[np.argmax(count[far])])
    if count[second] < max(min_points, second_share * count[first]):
        return None
    axes, rise = [], (height - head_m - low_m) * min_rise_share
    for i in (first, second):
        on = tree.query_ball_point(pts[i], axis_m)
        if np.ptp(hag[mine[on]]) < rise:
            return None
        axes.append(pts[on].mean(axis=0))
    axes = np.array(axes)
    which = np.argmin(np.hypot(*(ends_xy[:, None, :] - axes[None, :, :]).transpose(2, 0, 1)), axis=1)
    if min(np.bincount(which, minlength=2)) < min_ends:
        return None
    cell_of = np.argmin(np.hypot(*(centres[body][:, None, :] - axes[None, :, :]).transpose(2, 0, 1)), axis=1)
    out = []
    for j in (0, 1):
        # as high as its own top (its arms) or the wires ending on it
        top = hag[inside[np.hypot(x[inside] - axes[j][0], y[inside] - axes[j][1]) <= 2 * axis_m]].max()
        out.append(((float(axes[j][0]), float(axes[j][1])), max(float(top), float(ends_hag[which == j].max())),
                    int(np.sum(which == j)), np.asarray(body)[cell_of == j]))
    return out


def _axis_share(x, y, hag, cx, cy, height: float, radius_m: float = 2.0, axis_m: float = 0.5, low_m: float = 3.0,
                head_m: float = 1.5):
    """The share of the points within ``radius_m`` of (``cx``, ``cy``) in plan, from ``low_m``
    above ground to ``head_m`` under ``height`` (under a pole's arms), that lie within ``axis_m``
    of the vertical through the densest of them (the most such points within ``axis_m``), and
    how many there are; None for the share under 3 points. A pole's body is one thin column, a
    crown spreads over metres."""
    near = np.flatnonzero((np.abs(x - cx) <= radius_m) & (np.abs(y - cy) <= radius_m))
    near = near[(np.hypot(x[near] - cx, y[near] - cy) <= radius_m) & (hag[near] >= low_m) &
                (hag[near] <= height - head_m)]
    if len(near) < 3:
        return None, len(near)
    pts = np.column_stack([x[near], y[near]])
    within = cKDTree(pts).query_ball_point(pts, axis_m, return_length=True)
    return float(within.max()) / len(near), len(near)


def _base_cells(cells, column, n_layers, centres, heading_rad: float, reach_m: float = 2.5,
                along_deg: float = 30.0) -> np.ndarray:
    """The cells of a tower's candidate its base is taken from: all but those with no structure
    (under 3 layers, see ``_tower_grid``) more than ``reach_m`` from its column cells along the
    line it carries (within ``along_deg`` of ``heading_rad``): a stack of wires the line search
    missed, running off a pole's top, is tall there and pulls the median metres along the line
    (a lattice's arms reach across it)."""
    col = centres[cells[column[cells]]]
    if not len(col):
        return cells
    d, j = cKDTree(col).query(centres[cells])
    v = centres[cells] - col[j]
    u = np.array([np.cos(heading_rad), np.sin(heading_rad)])
    along = np.abs(v @ u) >= np.cos(np.radians(along_deg)) * np.maximum(d, 1e-9)
    return cells[~((d > reach_m) & along & (n_layers[cells] < 3))]


def _tower_grid(x, y, hag, lines_xy, reach_m: float, cell_m: float):
    """The points (x, y, hag) within ``reach_m`` of a conductor segment of ``lines_xy`` on a grid
    of ``cell_m`` cells (on multiples of it: the same cells whatever the extent of the input):
    (x, y, hag, cell of each, highest hag per cell, number of 1 m layers from 3 m up that hold a
    point, cell centres, (x0, y0, cell_m, rows, cols), highest hag per cell of a point with
    another within 5 m under it); None where no point is that near."""
    near = np.zeros(len(x), bool)
    for (a, b) in lines_xy:
        a, b = np.asarray(a, float), np.asarray(b, float)
        d = b - a
        L2 = float(d @ d) or 1.0
        t = np.clip(((x - a[0]) * d[0] + (y - a[1]) * d[1]) / L2, 0.0, 1.0)
        near |= np.hypot(x - a[0] - t * d[0], y - a[1] - t * d[1]) <= reach_m
    if not near.any():
        return None
    x, y, hag = x[near], y[near], hag[near]
    x0, y0 = np.floor(x.min() / cell_m) * cell_m, np.floor(y.min() / cell_m) * cell_m
    c = np.floor((x - x0) / cell_m).astype(np.int64)
    r = np.floor((y - y0) / cell_m).astype(np.int64)
    rows, cols = int(r.max()) + 1, int(c.max()) + 1
    flat = r * cols + c
    top = np.full(rows * cols, -np.inf)
    np.maximum.at(top, flat, hag)
    layer = np.floor(hag).astype(np.int64)
    occupied = np.unique(flat * 4096 + np.clip(layer, 0, 4095))  # distinct (cell, 1 m layer)
    low = (occupied % 4096) >= 3
    n_layers = np.bincount(occupied[low] // 4096, minlength=rows * cols)
    centres = np.column_stack([x0 + (np.arange(rows * cols) % cols + 0.5) * cell_m,
                               y0 + (np.arange(rows * cols) // cols + 0.5) * cell_m])
    # the highest point of each cell with another within 5 m under it: a structure's top (a far
    # pole's few points lie 2-3 m apart), not a stray point over it (a bird, noise the ground
    # filter left)
    order = np.lexsort((hag, flat))
    f, h = flat[order], hag[order]
    held = np.r_[False, (f[1:] == f[:-1]) & (np.diff(h) <= 5.0)]
    top_held = np.full(rows * cols, -np.inf)
    np.maximum.at(top_held, f[held], h[held])
    return x, y, hag, flat, top, n_layers, centres, (x0, y0, cell_m, rows, cols), top_held


def _wires_over_cells(grid, wire_x, wire_y, wire_hag, arm_m: float):
    """Per cell of ``grid`` (``_tower_grid``'s): the lowest height of the wire points in it (inf
    where none) and the highest within ``arm_m`` of it (-inf where none)."""
    from scipy import ndimage

    x0, y0, cell_m, rows, cols = grid
    wc = np.floor((np.asarray(wire_x) - x0) / cell_m).astype(np.int64)
    wr = np.floor((np.asarray(wire_y) - y0) / cell_m).astype(np.int64)
    inside = (wc >= 0) & (wc < cols) & (wr >= 0) & (wr < rows)
    wflat, wh = wr[inside] * cols + wc[inside], np.asarray(wire_hag, float)[inside]
    wire_low, wire_top = np.full(rows * cols, np.inf), np.full(rows * cols, -np.inf)
    np.minimum.at(wire_low, wflat, wh)
    np.maximum.at(wire_top, wflat, wh)
    k = int(np.ceil(arm_m / cell_m))
    dy, dx = np.mgrid[-k:k + 1, -k:k + 1]
    wire_near = ndimage.maximum_filter(wire_top.reshape(rows, cols), footprint=np.hypot(dy, dx) <= k,
                                       mode="constant", cval=-np.inf).ravel()
    return wire_low, wire_near


def _shaped_bodies(cells, column, shape, centres, shaped) -> np.ndarray:
    """The cells of a candidate (tall cells, 8-connected) less its bodies that are not shaped like
    a tower: its column cells grouped into bodies (closer than 5 cells: a lattice's legs are one
    body, and so are the column cells scattered through one crown), every other cell given to the
    nearest body. A crown beside a tower joins it through the tower's arm cells and the wires'
    unlabelled points by the insulators; left in, it moves the base into the crown. Where no body
    or every body is shaped (an H-frame's two poles), the candidate stays whole. ``shaped(cells)``:
    whether those cells pass as a tower."""
    from scipy import ndimage

    mine = cells[column[cells]]
    if len(mine) < 2:
        return cells
    rows, cols = shape
    mask = np.zeros(rows * cols, bool)
    mask[mine] = True
    grown = ndimage.binary_dilation(mask.reshape(rows, cols), structure=np.ones((3, 3), bool), iterations=2)
    lab, n = ndimage.label(grown, structure=np.ones((3, 3), bool))
    if n < 2:
        return cells
    body_of = lab.ravel()[mine]
    nearest = cKDTree(centres[mine]).query(centres[cells])[1]
    parts = [cells[body_of[nearest] == b] for b in np.unique(body_of)]
    ok = [p for p in parts if shaped(p)]
    return np.sort(np.concatenate(ok)) if ok and len(ok) < len(parts) else cells


def _tower_shaped(cells, x, y, hag, flat, top, top_held, column, centres, cell_m, max_side_m, min_slenderness,
                  max_rugged):
    """(centre of the body, arm reach, height: ``top_held``'s highest) of the tall cells
    ``cells`` where they are shaped like a tower (see find_pylons: a column, at most
    ``max_side_m`` across, slender, not a crown's rugged points), else None."""
    if not column[cells].any():
        return None
    pc = centres[cells]
    if np.ptp(pc[:, 0]) + cell_m > max_side_m or np.ptp(pc[:, 1]) + cell_m > max_side_m:
        return None
    held = top_held[cells]
    height = float(held.max()) if np.isfinite(held).any() else float(top[cells].max())
    if height < min_slenderness * np.sqrt(len(cells) * cell_m * cell_m):
        return None
    mine = np.flatnonzero(np.isin(flat, cells))
    if len(mine) >= 4:
        xyz = np.column_stack([x[mine], y[mine], hag[mine]])
        _, _, rugged, _ = shape_classes(xyz - xyz.min(axis=0))
        if rugged.mean() > max_rugged:
            return None
    body = centres[cells[column[cells]]]
    centre = np.array([0.5 * (body[:, 0].min() + body[:, 0].max()), 0.5 * (body[:, 1].min() + body[:, 1].max())])
    return centre, 0.5 * float(np.ptp(pc, axis=0).max()) + cell_m, height


def find_towers_passed_through(x, y, hag, wire_x, wire_y, wire_hag, line_headings, lines_xy, known=(),
                               cell_m: float = 1.0, reach_m: float = 12.0, top_share: float = 0.8,
                               column_share: float = 0.5, arm_m: float = 6.0, max_above_m: float = 2.0,
                               max_side_m: float = 40.0, max_rugged: float = 0.7, min_slenderness: float = 2.0,
                               known_m: float = 10.0, under_line_m: float = 2.0, margin_m: float = 10.0,
                               max_side_ratio: float = 2.0, insulator_m: float = 1.0,
                               reach_down_share: float = 0.5, pole_area_m2: float = 4.0,
                               max_gap_m: float = 2.0, wide_reach_down_share: float = 0.35) -> list:
    """Towers the wires run through without a span ending there, from the towers' own points: a
    suspension tower where one catenary fits the wire across it (short spans on a slope: the
    kink at its insulators is within the noise), which ``find_pylons`` cannot see.

    x, y, hag: the off-ground, off-wire points; wire_*: the wire points found (metres, hag =
    height above ground); line_headings, lines_xy as ``find_pylons``; ``known``: the towers and
    poles found already (a candidate within ``known_m`` of one is it).

    On ``find_pylons``' grid, a cell is *tall* when its top reaches ``top_share`` of the highest
    wire within ``arm_m`` of it; the tall cells join into candidates that stand at most
    ``max_above_m`` over the highest wire near them (a tower's peak holds the earth wire, a pole's
    top its top wire; the crown of a tall tree beside a low line stands far over it), shaped like
    a tower (``_tower_shaped``: a column, slender, not rugged). A candidate is a tower when a wire runs
    through it, not over it: in one of its cells the wire's lowest point is under the cell's top,
    or at most ``insulator_m`` over it (a tower's arms hold the wires; a pole's top wire sits on
    an insulator over its top, whose last few points a sparse scan may miss; trees under a line
    are trimmed 2-3 m below the wires), its points reach down to ``reach_down_share`` of its
    height (no span ends there to vouch for it, so its own body must: a support stands on the
    ground and is seen under its head, from the air as from the street, where a crown's cap
    that a low line runs through hides its trunk), hanging together that far (no gap over
    ``max_gap_m``, as ``pylon_points`` takes a tower's points) unless what stands under the gap
    is no wider than a pole (``pole_area_m2``: a sparse pole's points leave gaps; a bush under a
    line with wire points left over it is wide); one wider than a pole reaches down to
    ``wide_reach_down_share`` (as ``find_pylons`` asks: a lattice's legs stand on the ground, a
    conifer the wires run through stands off it), and it stands
    under its lines (``_under_its_lines``: the lines reaching within ``margin_m`` of it along
    their length). n_spans counts two spans per conductor line passing within ``arm_m`` of its
    base."""
    from scipy import ndimage

    if len(x) == 0 or len(wire_x) == 0:
        return []
    g = _tower_grid(x, y, hag, lines_xy, reach_m, cell_m)
    if g is None:
        return []
    x, y, hag, flat, top, n_layers, centres, grid, top_held = g
    x0, y0, _, rows, cols = grid
    has = np.isfinite(top)
    wire_low, wire_near = _wires_over_cells(grid, wire_x, wire_y, wire_hag, arm_m)
    tall = has & np.isfinite(wire_near) & (top >= top_share * wire_near)
    through = tall & (wire_low <= top + insulator_m)
    column = tall & (n_layers >= np.maximum(3, column_share * (top - 3.0)))
    structure = has & (n_layers >= 3)
    lab, n = ndimage.label(tall.reshape(rows, cols), structure=np.ones((3, 3), bool))
    lab = lab.ravel()
    known_xy = np.array([[p.x, p.y] for p in known], float).reshape(-1, 2)
    found = []
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(1, n + 2))
    for i in range(n):
        cells = order[bounds[i]:bounds[i + 1]]
        if not through[cells].any():
            continue
        shaped = _tower_shaped(cells, x, y, hag, flat, top, top_held, column, centres, cell_m, max_side_m,
                               min_slenderness, max_rugged)
        if shaped is None:
            continue
        centre, arm, height = shaped
        if height > wire_near[cells].max() + max_above_m:
            continue
        if len(known_xy) and np.hypot(*(known_xy - centre).T).min() <= known_m:
            continue
        # a support stands on the ground, its body in view under its head; a crown's cap hides its trunk
        if float(hag[np.isin(flat, cells)].min()) > reach_down_share * height:
            continue
        # its arms reach out under the wires below its head (shorter than the tall cells' top)
        standing = structure & (top >= 0.5 * height)
        body = _grow_body(cells, standing.reshape(rows, cols), centres, centre, max(arm, arm_m))
        mine = np.isin(flat, body) & (hag <= height + max_gap_m)  # not a stray point over its top
        # wider than a pole, as find_pylons asks at span ends: a lattice's legs stand on the ground
        if len(body) * cell_m ** 2 > pole_area_m2 and float(hag[mine].min()) > wide_reach_down_share * height:
            continue
        own = np.sort(hag[mine])[::-1]
        gaps = np.flatnonzero(own[:-1] - own[1:] > max_gap_m)
        if len(gaps) and float(own[gaps[0]]) > reach_down_share * height and \
                len(np.unique(flat[mine & (hag < own[gaps[0]])])) * cell_m ** 2 > pole_area_m2:
            continue
        if not _under_its_lines(centre[0], centre[1], centres[body], lines_xy, margin_m, under_line_m,
                                max_side_ratio, cell_m):
            continue
        dist = np.array([_point_segment_distance(centre[0], centre[1], a, b) for a, b in lines_xy])
        found.append(Pylon(float(centre[0]), float(centre[1]), height, 2 * int(np.sum(dist <= arm_m)),
                           float(line_headings[int(np.argmin(dist))]), body, grid))
    return found


def find_poles(x, y, hag, wire_x, wire_y, wire_hag, line_headings, lines_xy, span_ends=None, span_end_hag=None,
               top_share: float = 0.8, radius_m: float = 0.25, ring_m: float = 0.75, window_m: float = 2.0,
               min_thin_m: float = 2.5, min_fill: float = 0.6, wire_reach_m: float = 2.0, end_radius_m: float = 10.0,
               column_m: float = 0.45, voxel_m: float = 0.05, head_m: float = 1.8,
               max_ring_share: float = 0.6) -> list[Pylon]:
    """Poles that carry the wires: thin vertical columns, as a street scanner sees wooden and
    steel poles (a crown beside the pole is no part of it, a tree trunk ends in its crown).

    x, y, hag: the off-ground, off-wire points (metres; hag = height above ground); wire_x,
    wire_y, wire_hag: the points of the wires found; line_headings, lines_xy as ``find_pylons``.

    On the points thinned to ``voxel_m`` voxels, a point is *thin* where its cylinder of
    ``radius_m`` and ``window_m`` height holds points and the ring out to ``ring_m`` few (under
    ``max_ring_share`` times as many, where points spread evenly, as over a crown, a wall or a
    roof edge, give it 8 times as many; a pole's hardware and the wires leaving it give some). Thin points
    linked in plan (0.3 m) are a pole when they rise over ``min_thin_m``, its column (points
    within ``column_m`` of the axis) fills ``min_fill`` of the 0.5 m layers from 1 m above the
    ground up to its thin part's top, a wire passes within ``wire_reach_m`` of its axis, and it
    stands at least ``top_share`` as high as those wires (a street light under them does not). Where
    spans end within that reach (``span_ends``, ``span_end_hag``: plan positions and heights above
    ground) it is measured against them alone: the pole that ends a line may stand under another
    line's wires.
    Its top is where the column above the thin part first breaks by 1.5 m; its points are its
    column and its head (within ``head_m`` of the axis in its top metre: cross arms, insulators)."""
    from scipy import ndimage

    if len(x) < 5 or len(wire_x) == 0:
        return []
    # only the points within reach of a wire (the axis within wire_reach_m, its ring beyond): on
    # 1 m cells, those of the wires grown by that distance
    x_min, y_min = min(x.min(), wire_x.min()), min(y.min(), wire_y.min())
    grow = int(np.ceil(wire_reach_m + ring_m))
    wc, wr = np.floor(wire_x - x_min).astype(np.int64), np.floor(wire_y - y_min).astype(np.int64)
    pc, pr = np.floor(x - x_min).astype(np.int64), np.floor(y - y_min).astype(np.int64)
    shape = (int(max(pr.max(), wr.max())) + 1, int(max(pc.max(), wc.max())) + 1)
    reach = np.zeros(shape, bool)
    reach[wr, wc] = True
    reach = ndimage.binary_dilation(reach, np.ones((3, 3), bool), iterations=grow)
    near = reach[pr, pc]
    x, y, hag = x[near], y[near], hag[near]
    if len(x) < 5:
        return []
    v = np.unique(np.floor(np.column_stack([x, y, hag]) / voxel_m).astype(np.int64), axis=0)
    p = (v + 0.5) * voxel_m
    half = window_m / 2
    # cylinders as ellipsoids: heights scaled so that one ball is radius_m across and window_m high
    inner = cKDTree(np.column_stack([p[:, :2], p[:, 2] * radius_m / half]))
    outer = cKDTree(np.column_stack([p[:, :2], p[:, 2] * ring_m / half]))
    n_in = inner.query_ball_point(inner.data, radius_m, return_length=True)
    n_out = outer.query_ball_point(outer.data, ring_m, return_length=True)
    thin = (n_in >= 6) & (n_out - n_in <= max_ring_share * n_in) & (p[:, 2] >= 1.0)
    t = p[thin]
    if len(t) < 5:
        return []
    pairs = cKDTree(t[:, :2]).query_pairs(0.3, output_type="ndarray")
    _, lab = connected_components(sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                                    shape=(len(t), len(t))), directed=False)
    plan, wires = cKDTree(p[:, :2]), cKDTree(np.column_stack([wire_x, wire_y]))
    wire_hag = np.asarray(wire_hag, float)
    ends = cKDTree(np.asarray(span_ends, float)) if span_ends is not None and len(span_ends) else None
    end_hag = None if span_end_hag is None else np.asarray(span_end_hag, float)
    cell = 0.1
    k_cells = int(np.ceil(column_m / cell)) + 1
    found = []
    for k in np.unique(lab):
        g = t[lab == k]
        if np.ptp(g[:, 2]) < min_thin_m:
            continue
        axis = np.median(g[:, :2], axis=0)
        h = np.sort(p[plan.query_ball_point(axis, column_m), 2])
        thin_top = float(g[:, 2].max())
        layers = np.unique(np.floor(h[(h >= 1.0) & (h <= thin_top)] / 0.5))
        if len(layers) < min_fill * max(np.ceil((thin_top - 1.0) / 0.5), 1):
            continue
        above = h[h >= thin_top]  # (none where the thin points spread wider than the column)
        breaks = np.flatnonzero(np.diff(above) > 1.5)
        top = float(above[breaks[0]] if len(breaks) else above[-1]) if len(above) else thin_top
        nb = wires.query_ball_point(axis, wire_reach_m)
        mine = ends.query_ball_point(axis, wire_reach_m) if ends is not None and end_hag is not None else []
        carried = float(np.max(end_hag[mine])) if mine else \
            float(wire_hag[nb].max()) if nb else np.inf
        if not nb or top < top_share * carried:
            continue
        dist = [_point_segment_distance(axis[0], axis[1], a, b) for a, b in lines_xy]
        n_ends = len(ends.query_ball_point(axis, end_radius_m)) if ends is not None else 0
        # its footprint: the cells of a fine grid around the axis within column_m of it
        x0, y0 = axis - k_cells * cell
        side = 2 * k_cells
        cc, rr = np.meshgrid(np.arange(side), np.arange(side))
        centre_d = np.hypot(x0 + (cc + 0.5) * cell - axis[0], y0 + (rr + 0.5) * cell - axis[1])
        cells = (rr * side + cc)[centre_d <= column_m].ravel()
        found.append(Pylon(float(axis[0]), float(axis[1]), max(top, carried), n_ends,
                           float(line_headings[int(np.argmin(dist))]) if dist else 0.0, cells,
                           (float(x0), float(y0), cell, side, side), kind="pole", head_m=head_m))
    return found


def _grow_body(cells, structure, centres, centre, reach_m):
    """The tower's footprint: its tall cells (head and arms) and the ``structure`` cells connected
    to them within ``reach_m`` of its centre (the body widening to its legs below the head)."""
    from scipy import ndimage

    rows, cols = structure.shape
    seed = np.zeros(rows * cols, bool)
    seed[cells] = True
    allowed = structure.ravel() & (np.hypot(*(centres - centre).T) <= reach_m)
    grown = ndimage.binary_propagation(seed.reshape(rows, cols), structure=np.ones((3, 3), bool),
                                       mask=(allowed | seed).reshape(rows, cols))
    return np.flatnonzero(grown.ravel())


def pylon_points(p: Pylon, x, y, hag=None, max_gap_m: float = 2.0):
    """Points inside the tower's footprint cells (on the grid it was found on); with ``hag``
    (heights above ground) only those of the structure hanging together from its top down: below
    the first gap of more than ``max_gap_m`` stand fences, bushes and cabinets at its foot."""
    x0, y0, cell_m, rows, cols = p.grid
    c = np.floor((x - x0) / cell_m).astype(np.int64)
    r = np.floor((y - y0) / cell_m).astype(np.int64)
    ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
    inside = np.zeros(len(x), bool)
    inside[ok] = np.isin(r[ok] * cols + c[ok], p.cells)
    if hag is not None and inside.any():
        h = np.sort(hag[inside])[::-1]
        gaps = np.flatnonzero(h[:-1] - h[1:] > max_gap_m)
        if len(gaps):
            inside &= hag >= h[gaps[0]]
    if hag is not None and p.head_m > 0:
        inside |= (np.hypot(x - p.x, y - p.y) <= p.head_m) & (hag >= p.height_m - 1.0) & (hag <= p.height_m + 0.3)
    return inside


def in_pole_columns(poles_xyh, x, y, hag, core_m: float = 0.3, head_m: float = 1.0) -> np.ndarray:
    """Which points (x, y: plan metres, hag: height above ground) lie in a pole's column: within
    ``core_m`` in plan of its base (``poles_xyh``: (n, 3) base x, y and height above ground) and
    more than ``head_m`` under its top. Nothing hangs there but what is fixed to the pole: a
    cable's end clamped to its side is the pole's (as CMU's Oakland labels mark it); the wires
    on its head (cross arms, top insulator) stay wires. ``core_m`` holds the pole's radius and a
    street scan's lean of its base towards the scanner."""
    x, y, hag = (np.asarray(v, float) for v in (x, y, hag))
    out = np.zeros(len(x), bool)
    for px, py, height in np.asarray(poles_xyh, float).reshape(-1, 3):
        out |= (np.hypot(x - px, y - py) <= core_m) & (hag < height - head_m)
    return out


def _parallel(s1, s2, max_deg: float) -> bool:
    """Whether plan segments s1 and s2 ((a, b) each) run within ``max_deg`` of one direction."""
    d1, d2 = np.subtract(s1[1], s1[0]), np.subtract(s2[1], s2[0])
    n = float(np.hypot(*d1) * np.hypot(*d2))
    return n > 0 and abs(float(d1 @ d2)) / n >= np.cos(np.radians(max_deg))


def _passes(px, py, a, b, reach, margin):
    """Whether the segment a-b runs past (px, py) within ``reach`` with both its ends more than
    ``margin`` away along it."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    L = float(np.hypot(*d))
    if L <= 2 * margin:
        return False
    t = ((px - a[0]) * d[0] + (py - a[1]) * d[1]) / L
    return margin < t < L - margin and abs((px - a[0]) * d[1] - (py - a[1]) * d[0]) / L <= reach


def _under_its_lines(cx, cy, footprint, lines_xy, margin_m, under_line_m, max_side_ratio, cell_m) -> bool:
    """Whether a tower candidate at (cx, cy), footprint cell centres ``footprint``, stands under
    the conductors ``lines_xy`` that reach within ``margin_m`` of it along their length (see
    find_pylons)."""
    left, right, reach = np.inf, np.inf, np.inf
    for a, b in lines_xy:
        a, b = np.asarray(a, float), np.asarray(b, float)
        L = float(np.hypot(*(b - a)))
        if L == 0:
            continue
        u = (b - a) / L
        n = np.array([-u[1], u[0]])
        t = (cx - a[0]) * u[0] + (cy - a[1]) * u[1]
        if not -margin_m <= t <= L + margin_m:
            continue
        off = (cx - a[0]) * n[0] + (cy - a[1]) * n[1]
        if off >= 0:
            left = min(left, off)
        else:
            right = min(right, -off)
        reach = min(reach, float(np.abs((footprint - a) @ n).min()))
    near, far = min(left, right), max(left, right)
    if not np.isfinite(near):  # no conductor along it to tell
        return True
    return near <= under_line_m or far <= max_side_ratio * near or reach <= cell_m


def _point_segment_distance(px, py, a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    t = float(np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / max(float(d @ d), 1e-12), 0.0, 1.0))
    return float(np.hypot(px - a[0] - t * d[0], py - a[1] - t * d[1]))

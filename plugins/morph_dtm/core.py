"""Morphological DTM (gLiDAR method): multi-scale opening with a size-dependent height threshold,
DTM interpolation with sound hole filling, and gdaldem-compatible hillshade.

Pure functions on numpy arrays. Grids are north-up: row 0 is the northern edge, ``west`` and
``north`` give the outer corner, ``cell`` the cell size (same units as x, y).

References: D. Mongus, B. Žalik (2014), "Computationally efficient method for the generation of
a digital terrain model from airborne LiDAR data using connected operators", IEEE JSTARS 7(1);
D. Mongus, N. Lukač, B. Žalik (2014), "Ground and building extraction from LiDAR data based on
differential morphological profiles and locally fitted surfaces", ISPRS J. 93; the gLiDAR digest
in METHODS.md §2. The progressive opening follows the same scheme as SMRF (Pingel et al. 2013).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.linalg import spsolve


@dataclass
class Grid:
    west: float
    north: float
    cell: float
    rows: int
    cols: int

    @classmethod
    def around(cls, x, y, cell, pad_cells: int = 1) -> "Grid":
        west = np.floor(x.min() / cell) * cell - pad_cells * cell
        north = np.ceil(y.max() / cell) * cell + pad_cells * cell
        cols = int(np.ceil((x.max() - west) / cell)) + pad_cells
        rows = int(np.ceil((north - y.min()) / cell)) + pad_cells
        return cls(float(west), float(north), float(cell), max(rows, 1), max(cols, 1))

    def index(self, x, y):
        """(row, col) of the cell holding each point; points outside take the nearest edge cell.
        (One scratch array, clipped in place: half the memory traffic of the plain expression,
        which mattered at 10 M points.)"""
        t = np.subtract(x, self.west)
        t /= self.cell
        c = t.astype(np.int64)
        np.clip(c, 0, self.cols - 1, out=c)
        np.subtract(self.north, y, out=t)
        t /= self.cell
        r = t.astype(np.int64)
        np.clip(r, 0, self.rows - 1, out=r)
        return r, c

    def flat_index(self, x, y):
        """Row-major cell number of each point (``row * cols + col``)."""
        r, c = self.index(x, y)
        r *= self.cols
        r += c
        return r

    def fractional(self, x, y):
        """Continuous (row, col) of points with cell centres at integers (for interpolation)."""
        return (self.north - y) / self.cell - 0.5, (x - self.west) / self.cell - 0.5

    def centres(self):
        xs = self.west + (np.arange(self.cols) + 0.5) * self.cell
        ys = self.north - (np.arange(self.rows) + 0.5) * self.cell
        return xs, ys


def minimum_surface(grid: Grid, x, y, z, flat_index=None):
    """Lowest z per cell (NaN where empty), and the flat cell index of each point."""
    if flat_index is None:
        flat_index = grid.flat_index(x, y)
    zmin = np.full(grid.rows * grid.cols, np.inf)
    np.minimum.at(zmin, flat_index, z)
    zmin[np.isinf(zmin)] = np.nan
    return zmin.reshape(grid.rows, grid.cols), flat_index


def minimum_surface_without(grid: Grid, zmin, flat_index, z, removed):
    """``minimum_surface`` of the points not ``removed`` (a mask), from that of all points: only
    the cells that held a removed point are computed again (a few hundred cells, not a pass of
    ``np.minimum.at`` over ten million points)."""
    cells = np.unique(flat_index[removed])
    hit = np.zeros(grid.rows * grid.cols, bool)
    hit[cells] = True
    again = np.flatnonzero(hit[flat_index] & ~removed)
    zf = zmin.ravel().copy()
    zf[cells] = np.inf
    np.minimum.at(zf, flat_index[again], z[again])
    zf[np.isinf(zf)] = np.nan
    return zf.reshape(grid.rows, grid.cols)


def low_outliers(grid: Grid, z, flat_index, zmin, threshold: float):
    """Points far below their neighbourhood: a cell's lowest point is an outlier when it lies more
    than ``threshold`` below the second-lowest of the 3x3 cell minima around it (isolated pits;
    ditches and other real depressions span several cells and are kept)."""
    filled = np.where(np.isnan(zmin), np.inf, zmin)
    # second-lowest of the 3x3 neighbourhood (rank 1 of 9)
    second = ndimage.rank_filter(filled, 1, size=3, mode="nearest")
    bad_cell = np.isfinite(second) & (filled < second - threshold)
    # only points in the few bad cells can be outliers: compare those alone
    out = np.zeros(len(z), bool)
    cand = np.flatnonzero(bad_cell.ravel()[flat_index])
    out[cand] = z[cand] < second.ravel()[flat_index[cand]] - threshold
    return out


def footprint(occupied: np.ndarray, radius_cells: int, max_hole_cells: int | None = None) -> np.ndarray:
    """Cells inside the data's footprint: the occupied cells closed over gaps of up to about
    2·``radius_cells`` and with enclosed holes (water, shadows: no return) filled, those of at most
    ``max_hole_cells`` across in rows and columns when given. A bounded hole is decided from the
    cells around it alone, so a tile whose buffer is wider than the hole decides it as the whole
    survey does; an unbounded one (a lake) is decided by data anywhere."""
    pad = max(int(radius_cells), 1)
    closed = ndimage.binary_closing(np.pad(occupied, pad), iterations=pad)[pad:-pad, pad:-pad] | occupied
    if max_hole_cells is None:
        return ndimage.binary_fill_holes(closed)
    lab, n = ndimage.label(~closed)
    keep = np.zeros(n + 1, bool)
    rows, cols = closed.shape
    for i, sl in enumerate(ndimage.find_objects(lab), start=1):
        r, c = sl
        inner = r.start > 0 and c.start > 0 and r.stop < rows and c.stop < cols  # touching the edge: outside
        keep[i] = inner and r.stop - r.start <= max_hole_cells and c.stop - c.start <= max_hole_cells
    return closed | keep[lab]


def fill_holes(surface: np.ndarray, known: np.ndarray | None = None, domain: np.ndarray | None = None,
               fill_outside: bool = True) -> np.ndarray:
    """Fill unknown cells with the harmonic (Laplace) interpolation of the known cells around them.

    One sparse system over all unknown cells (4-neighbour Laplacian, known cells as Dirichlet
    values): smooth, no nearest-neighbour blocks, exact on planes. Holes touching the grid edge
    get a natural (zero-slope) boundary there. Returns a new array.

    ``domain`` (optional) limits the system to unknown cells inside it (the data's footprint):
    the rest of the grid, outside the survey, takes the value of the nearest filled cell. A
    corridor strip crossing its bounding box diagonally leaves most of the box outside, and
    solving the Laplace system there cost more than the whole ground filter. With
    ``fill_outside=False`` the cells outside ``domain`` stay as they are (a caller that blanks
    them anyway saves the distance transform: 60-70 ms on a 10 M-point tile's 1 m grid).
    """
    out = np.array(surface, dtype=np.float64, copy=True)
    if known is None:
        known = np.isfinite(out)
    if not known.any():
        raise ValueError("no known cell to interpolate from")
    unknown = ~known if domain is None else (~known & domain)
    if domain is not None and unknown.any():
        # only holes that reach a known cell can be solved (a region of the footprint whose
        # cells were all removed as objects has none): the others take nearest values below
        lab, n_lab = ndimage.label(unknown)
        touching = np.unique(lab[ndimage.binary_dilation(known) & unknown])
        unknown = np.isin(lab, touching[touching > 0]) if n_lab else unknown
    m = int(unknown.sum())
    if m:
        rows, cols = out.shape
        ids = np.full(out.shape, -1, np.int64)
        ids[unknown] = np.arange(m)
        rr, cc = np.nonzero(unknown)
        diag = np.zeros(m)
        rhs = np.zeros(m)
        ri, ci = [], []
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            nr, nc = rr + dr, cc + dc
            inside = (nr >= 0) & (nr < rows) & (nc >= 0) & (nc < cols)
            src = np.flatnonzero(inside)
            nr, nc = nr[inside], nc[inside]
            nid = ids[nr, nc]
            unk = nid >= 0
            kn = known[nr, nc]
            # neighbours outside the domain are like the grid edge: no coupling
            diag += np.bincount(src[unk | kn], minlength=m)
            ri.append(src[unk])
            ci.append(nid[unk])
            rhs += np.bincount(src[kn], weights=out[nr[kn], nc[kn]], minlength=m)
        ri = np.concatenate(ri)
        ci = np.concatenate(ci)
        A = sparse.csc_matrix((np.r_[diag, -np.ones(len(ri))], (np.r_[np.arange(m), ri], np.r_[np.arange(m), ci])),
                              shape=(m, m))
        out[rr, cc] = spsolve(A, rhs)
    rest = ~known & ~unknown
    if not fill_outside and domain is not None:
        rest &= domain
    if rest.any():
        filled = known | unknown
        idx = ndimage.distance_transform_edt(~filled, return_distances=False, return_indices=True)
        out[rest] = out[idx[0][rest], idx[1][rest]]
    return out


def scale_sizes(cell: float, max_size: float, growth: float = 1.3) -> list[int]:
    """Odd window widths (cells) from 3 up to ``max_size`` (units), growing geometrically:
    fine steps where objects are small, coarse where a size class is wide."""
    sizes, w = [], 3
    limit = max(3, int(np.ceil(max_size / cell)) | 1)
    while w < limit:
        sizes.append(w)
        w = max(w + 2, int(np.ceil(w * growth)) | 1)
    sizes.append(limit)
    return sorted(set(sizes))


def multiscale_opening(surface: np.ndarray, cell: float, max_size: float, k: float, n: float,
                       growth: float = 1.3):
    """The method's differential morphological profile on a grid.

    Openings of growing square windows (separable running min/max: O(cells) per scale whatever
    the window) are applied progressively; at each scale Δh_i = S_{i-1} - S_i. The scale with the
    largest Δh is the object's size s (its width, units) and that Δh how far it is raised above its
    surroundings; the cell is an object when Δh ≥ n + k · s.

    Returns (object mask, Δh at the characteristic scale, characteristic size in units).
    """
    prev = surface
    best_dh = np.zeros_like(surface)
    best_size = np.zeros_like(surface)
    for w in scale_sizes(cell, max_size, growth):
        opened = ndimage.grey_opening(prev, size=(w, w), mode="nearest")
        dh = prev - opened
        better = dh > best_dh
        best_dh = np.where(better, dh, best_dh)
        best_size = np.where(better, w * cell, best_size)
        prev = opened
    is_object = best_dh >= n + k * best_size
    return is_object & (best_dh > 0), best_dh, best_size


class Sampler:
    """Bilinear sampling of grids at fixed points (weights computed once, reused per surface)."""

    def __init__(self, grid: Grid, x, y):
        r, c = grid.fractional(x, y)
        r = np.clip(r, 0, grid.rows - 1)
        c = np.clip(c, 0, grid.cols - 1)
        r0 = np.minimum(r.astype(np.int64), max(grid.rows - 2, 0))
        c0 = np.minimum(c.astype(np.int64), max(grid.cols - 2, 0))
        self.fr = (r - r0)
        self.fc = (c - c0)
        self.i00 = r0 * grid.cols + c0
        self.dr = grid.cols if grid.rows > 1 else 0
        self.dc = 1 if grid.cols > 1 else 0

    def __call__(self, surface: np.ndarray) -> np.ndarray:
        f = surface.ravel()
        top = f[self.i00] * (1 - self.fc) + f[self.i00 + self.dc] * self.fc
        bot = f[self.i00 + self.dr] * (1 - self.fc) + f[self.i00 + self.dr + self.dc] * self.fc
        return top * (1 - self.fr) + bot * self.fr


def bilinear(grid: Grid, surface: np.ndarray, x, y):
    return Sampler(grid, x, y)(surface)


def surface_slope(surface: np.ndarray, cell: float) -> np.ndarray:
    """Gradient magnitude (rise over run) by Horn's 3x3 differences."""
    p = np.pad(surface, 1, mode="edge")
    a, b, c = p[:-2, :-2], p[:-2, 1:-1], p[:-2, 2:]
    d, f = p[1:-1, :-2], p[1:-1, 2:]
    g, h, i = p[2:, :-2], p[2:, 1:-1], p[2:, 2:]
    dx = ((c + 2 * f + i) - (a + 2 * d + g)) / (8 * cell)
    dy = ((g + 2 * h + i) - (a + 2 * b + c)) / (8 * cell)
    return np.hypot(dx, dy)


@dataclass
class GroundResult:
    ground: np.ndarray  # bool per point
    noise: np.ndarray  # bool per point (low outliers)
    grid: Grid  # the filter grid
    provisional: np.ndarray  # provisional bare-earth surface on the filter grid (after the opening)
    object_cells: np.ndarray  # cells removed by the multi-scale filter
    surface: np.ndarray | None = None  # the surface the final ground test used, on ``surface_grid``
    surface_grid: Grid | None = None
    point_spacing: float = float("nan")  # mean point spacing over the footprint (cloud's units)


def mean_spacing(n_points: int, n_footprint_cells: int, cell: float) -> float:
    """Mean distance between points: sqrt(footprint area / points)."""
    return float(np.sqrt(max(int(n_footprint_cells), 1) * cell * cell / max(int(n_points), 1)))


def lowest_points(x, y, z, s: "GroundSettings", accel=None):
    """Step 1 of ``ground_filter``: the filter grid, the lowest point per cell once the low
    outliers are set aside, each point's cell, and the outliers."""
    grid = Grid.around(x, y, s.cell)
    zmin, flat = accel.minimum_surface(grid, x, y, z) if accel is not None else minimum_surface(grid, x, y, z)
    noise = low_outliers(grid, z, flat, zmin, s.low_outlier)
    if noise.any():
        zmin = minimum_surface_without(grid, zmin, flat, z, noise)
    return grid, zmin, flat, noise


def data_footprint(occupied: np.ndarray, s: "GroundSettings") -> np.ndarray:
    """The filter grid's cells inside the data (closed over 3 cells, holes up to ``s.max_gap``)."""
    return footprint(occupied, 3, None if s.max_gap is None else int(np.floor(s.max_gap / s.cell)))


def spacing_counts(x, y, z, s: "GroundSettings", core_box) -> tuple[int, int]:
    """The points and the footprint cells (by their centres) inside ``core_box`` (x0, y0, x1, y1,
    half-open), from points that reach beyond it by the footprint's reach: summed over the tiles
    of a survey they are the counts ``ground_filter`` takes the point spacing from over the whole."""
    x0, y0, x1, y1 = core_box
    grid, zmin, _, _ = lowest_points(x, y, z, s)
    domain = data_footprint(np.isfinite(zmin), s)
    cx, cy = grid.centres()
    in_x = (cx >= x0) & (cx < x1)
    in_y = (cy >= y0) & (cy < y1)
    n_cells = int(domain[np.ix_(in_y, in_x)].sum())
    n_points = int(((x >= x0) & (x < x1) & (y >= y0) & (y < y1)).sum())
    return n_points, n_cells


def spacing_counts_from_cells(count, zmin, zmax, s: "GroundSettings") -> tuple[int, int]:
    """``spacing_counts`` over a whole survey from its per-cell point count and lowest and highest z
    on the filter grid (north-up, borders on multiples of the cell, as ``Grid`` places points):
    a cell whose points are all low outliers holds no point for the footprint, as in
    ``lowest_points``."""
    count, zmin, zmax = (np.pad(a, 1, constant_values=v) for a, v in ((count, 0), (zmin, np.nan), (zmax, np.nan)))
    filled = np.where(count > 0, zmin, np.inf)
    second = ndimage.rank_filter(filled, 1, size=3, mode="nearest")  # as low_outliers
    bad_cell = np.isfinite(second) & (filled < second - s.low_outlier)
    all_out = bad_cell & (zmax < second - s.low_outlier)
    domain = data_footprint((count > 0) & ~all_out, s)
    return int(count.sum()), int(domain.sum())


REFINE_PER_SPACING = 1.25  # the last refinement's cell over the point spacing (a 3x3 block: ~14 points)


def refine_cell_size(spacing: float, filter_cell: float, smallest: float,
                     per_spacing: float = REFINE_PER_SPACING) -> float:
    """Cell of the last refinement: ``per_spacing`` x the point spacing (a 3x3 block then holds about
    14 points, enough for a robust plane), between ``smallest`` and the filter cell."""
    return float(np.clip(per_spacing * spacing, min(smallest, filter_cell), filter_cell))


def _finer_domain(grid: Grid, domain: np.ndarray, fine: Grid) -> np.ndarray:
    """``domain`` (on ``grid``) sampled at the cell centres of ``fine``."""
    xs, ys = fine.centres()
    r, c = grid.index(np.broadcast_to(xs[None, :], (fine.rows, fine.cols)),
                      np.broadcast_to(ys[:, None], (fine.rows, fine.cols)))
    return domain[r, c]


@dataclass(frozen=True)
class GroundSettings:
    """Every value the ground filter takes, in the cloud's units (see ``ground_filter``)."""

    cell: float  # the filter grid
    max_size: float  # the largest object the opening removes (its width)
    k: float  # Δh ≥ n + k · size
    n: float
    ground_threshold: float  # height of a ground point over the surface on flat ground
    slope_factor: float  # extra tolerance per unit of slope, x the cell
    low_outlier: float  # this far under its neighbourhood a point is noise
    growth: float = 1.3  # the windows' geometric growth
    refine: bool = True
    refill_gaps: bool = True
    refine_cell: float | None = None  # the last refinement's cell (None: from the point spacing)
    min_refine_cell: float = 0.0
    refine_per_spacing: float = REFINE_PER_SPACING
    max_gap: float | None = None  # widest hole without returns inside the footprint (None: any enclosed one)


def ground_filter(x, y, z, settings: GroundSettings, accel=None) -> GroundResult:
    """Label ground points with ``settings`` (all lengths in the cloud's units).

    1. Lowest point per cell; isolated low outliers removed (``low_outlier`` below their
       neighbourhood).
    2. Empty cells filled (harmonic), then the multi-scale opening marks object cells
       (Δh ≥ n + k·size up to ``max_size``). With ``refill_gaps``, the
       empty cells are filled again from the cells kept as ground and the opening repeated.
    3. The remaining cells' minima, holes filled, give a provisional bare earth; a point is
       ground when it lies within ``ground_threshold + slope_factor · slope · cell`` of it
       (steep cells tolerate more, as a cell's points spread over its height range).
    4. With ``refine``: a surface fitted to those ground points (a plane per 3x3 cells) replaces
       it and the test is repeated, first on the filter grid, then on a grid of ``refine_cell``
       (None: ``refine_per_spacing`` x the measured point spacing, at least ``min_refine_cell``);
       where that grid is at most half the filter cell, on it alone.

    ``accel`` (optional) provides ``minimum_surface``, ``moments`` and ``near_surface`` doing the
    per-point passes in parallel kernels; the numpy versions here are their references.
    """
    s = settings
    cell = s.cell
    grid, zmin, flat, noise = lowest_points(x, y, z, s, accel)
    occupied = np.isfinite(zmin)
    domain = data_footprint(occupied, s)  # interpolate inside the survey only (see fill_holes)
    filled = fill_holes(zmin, occupied, domain)
    gaps = domain & ~occupied
    for again in range(2 if s.refill_gaps and gaps.any() else 1):
        if again:
            # a gap (water, a shadow) was filled from the cells around it, trees on its rim
            # included, so the rim's objects were not raised above it: fill it from the ground
            filled = np.where(occupied, zmin, provisional)
        is_object, _, _ = multiscale_opening(filled, cell, s.max_size, s.k, s.n, s.growth)
        keep = occupied & ~is_object
        if not keep.any():
            keep = occupied
        provisional = fill_holes(np.where(keep, zmin, np.nan), keep, domain)
    spacing = mean_spacing(len(x), int(domain.sum()), cell)

    samplers = {}  # numpy: bilinear weights once per grid

    def near(g, surface):
        if accel is not None:
            return accel.near_surface(g, x, y, z, surface, surface_slope(surface, g.cell), s.ground_threshold,
                                      s.slope_factor, s.low_outlier)
        if id(g) not in samplers:
            samplers[id(g)] = Sampler(g, x, y)
        sample = samplers[id(g)]
        return _near_surface(sample, g.cell, surface, z, s.ground_threshold, s.slope_factor, s.low_outlier)

    ground, dz = near(grid, provisional)
    ground &= ~noise
    surface, surface_grid = provisional, grid
    if s.refine:
        fine_cell = s.refine_cell if s.refine_cell is not None else \
            refine_cell_size(spacing, cell, s.min_refine_cell, s.refine_per_spacing)
        fine = grid if fine_cell == cell else Grid.around(x, y, fine_cell)
        # the surface fitted to the ground points (a plane per cell) follows the terrain between
        # cell minima; once more on a grid matched to the point spacing, which follows breaklines
        passes = ((grid, domain), (fine, domain if fine is grid else None))
        if fine.cell <= 0.5 * cell:
            # dense points: the fine grid's blocks hold plenty to start from the provisional surface,
            # and the pass on the filter grid changed nothing measurable but cost a pass over them
            passes = ((fine, None),)
        for g, dom in passes:
            if ground.sum() < 3:
                break
            if dom is None:
                dom = _finer_domain(grid, domain, g)
            surface, _ = dtm_from_ground(g, x, y, z, where=ground,
                                         moments=accel.moments if accel is not None else None, domain=dom)
            surface_grid = g
            ground, dz = near(g, surface)
            ground &= ~noise
    noise |= dz < -2 * s.low_outlier
    return GroundResult(ground, noise, grid, provisional, is_object, surface, surface_grid, spacing)


def _near_surface(sample, cell, surface, z, threshold, slope_factor, below):
    """Points from ``below`` under to ``threshold + slope_factor * slope * cell`` over the surface:
    (mask, height over the surface). The reference of ``kernels.TaichiAccel.near_surface``."""
    tol = threshold + slope_factor * sample(surface_slope(surface, cell)) * cell
    dz = z - sample(surface)
    return (dz <= tol) & (dz >= -below), dz


MOMENTS = ("n", "x", "y", "z", "xx", "yy", "xy", "xz", "yz", "zz")


def cell_moments(grid: Grid, x, y, z, where=None) -> dict:
    """Per-cell sums of 1, dx, dy, z, dx², dy², dx·dy, dx·z, dy·z, z² with dx, dy the offsets of
    each point from its cell's centre, over the points ``where`` (a bool mask) is true, or all
    (numpy; the reference of the taichi kernel)."""
    if where is not None:
        x, y, z = x[where], y[where], z[where]
    r, c = grid.index(x, y)
    xs, ys = grid.centres()
    dx = x - xs[c]
    dy = y - ys[r]
    flat = r * grid.cols + c
    N = grid.rows * grid.cols
    weights = (None, dx, dy, z, dx * dx, dy * dy, dx * dy, dx * z, dy * z, z * z)
    return {name: np.bincount(flat, weights=w, minlength=N).astype(np.float64).reshape(grid.rows, grid.cols)
            for name, w in zip(MOMENTS, weights)}


def dtm_from_ground(grid: Grid, x, y, z, min_points: int = 3, moments=None, domain=None, where=None,
                    fill_outside: bool = True):
    """Bare-earth height at every cell centre from ground points (those ``where`` is true, when
    given: a mask spares copying 10 million ground points out of the cloud).

    Each cell gets the least-squares plane through the ground points of its 3x3 neighbourhood,
    evaluated at the cell centre (unbiased on slopes, unlike a cell mean). Cells with too few
    points or a degenerate fit are holes, filled harmonically. Returns (dtm, support) where
    support marks cells computed from points (not interpolated).
    """
    S = (moments or cell_moments)(grid, x, y, z, where)
    cell = grid.cell
    # the per-cell sums are about each cell's own centre; moved to one frame (origin at the grid's
    # middle cell: small numbers) they add up over each 3x3 block as plain box sums, and are then
    # moved back to the block's centre cell (exact algebra: sums of (u + o)^k expanded)
    cu = ((np.arange(grid.cols) - grid.cols // 2) * cell)[None, :]
    cv = (-(np.arange(grid.rows) - grid.rows // 2) * cell)[:, None]
    n0, sx, sy, sz = S["n"], S["x"], S["y"], S["z"]
    B = {k: _box3_sum(v) for k, v in (
        ("n", n0), ("z", sz), ("zz", S["zz"]), ("x", sx + cu * n0), ("y", sy + cv * n0),
        ("xx", S["xx"] + (2 * sx + cu * n0) * cu), ("yy", S["yy"] + (2 * sy + cv * n0) * cv),
        ("xy", S["xy"] + cu * sy + cv * sx + cu * cv * n0), ("xz", S["xz"] + cu * sz), ("yz", S["yz"] + cv * sz))}
    nb, bx, by, bz = B["n"], B["x"], B["y"], B["z"]
    tot = {"n": nb, "z": bz, "x": bx - cu * nb, "y": by - cv * nb,
           "xx": B["xx"] - (2 * bx - cu * nb) * cu, "yy": B["yy"] - (2 * by - cv * nb) * cv,
           "xy": B["xy"] - cu * by - cv * bx + cu * cv * nb, "xz": B["xz"] - cu * bz, "yz": B["yz"] - cv * bz}
    n_ = tot["n"]
    a, det = _plane_value_at_centre(tot)
    # the same fit on the cell's own points: sharper in ditches and at breaklines, used where the
    # cell holds enough well-spread points
    n0 = S["n"]
    a0, det0 = _plane_value_at_centre(S)
    own = S["n"] > 0
    good = (n_ >= max(min_points, 3)) & (det > (0.05 * cell * cell) ** 2) & np.isfinite(a)
    own_good = (n0 >= 6) & (det0 > (0.15 * cell * cell) ** 2) & np.isfinite(a0)
    # a cell whose own points are few but whose neighbourhood fits is still supported by data
    support = (good & (own | (n_ >= 6))) | own_good
    mean_own = np.where(own, S["z"] / np.maximum(S["n"], 1), np.nan)
    value = np.where(own_good, a0, np.where(support, a, np.where(own, mean_own, np.nan)))
    # a fit evaluated at the centre of a cell whose points sit to one side may extrapolate: keep
    # it within the heights of the points around the cell
    # (bounds from the neighbourhood's mean and spread: cheaper than per-cell min/max scatters)
    with np.errstate(invalid="ignore", divide="ignore"):
        zz = B["zz"]
        mean3 = tot["z"] / n_
        sd3 = np.sqrt(np.maximum(zz / n_ - mean3 * mean3, 0.0))
    zlo = mean3 - 2.5 * sd3 - 0.5 * cell
    zhi = mean3 + 2.5 * sd3 + 0.5 * cell
    value = np.where(np.isfinite(value) & np.isfinite(mean3), np.clip(value, zlo, zhi), value)
    known = np.isfinite(value)
    return fill_holes(value, known, domain, fill_outside), known


def _box3_sum(a: np.ndarray) -> np.ndarray:
    """Sum over each cell's 3x3 neighbourhood (zero outside the grid), separably."""
    s = a.copy()
    s[1:] += a[:-1]
    s[:-1] += a[1:]
    t = s.copy()
    t[:, 1:] += s[:, :-1]
    t[:, :-1] += s[:, 1:]
    return t


def _plane_value_at_centre(m: dict):
    """Least-squares plane z = a + b·dx + c·dy from moment grids (sums of 1, x, y, z, xx, yy, xy,
    xz, yz about the cell centre): returns (a, the determinant of the centred xy covariance)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        n = m["n"]
        mx, my, mz = m["x"] / n, m["y"] / n, m["z"] / n
        cxx = m["xx"] / n - mx * mx
        cyy = m["yy"] / n - my * my
        cxy = m["xy"] / n - mx * my
        cxz = m["xz"] / n - mx * mz
        cyz = m["yz"] / n - my * mz
        det = cxx * cyy - cxy * cxy
        b = (cxz * cyy - cyz * cxy) / det
        c = (cyz * cxx - cxz * cxy) / det
        return mz - b * mx - c * my, det


def hillshade(dem: np.ndarray, ewres: float, nsres: float, azimuth_deg: float = 315.0, altitude_deg: float = 45.0,
              z_factor: float = 1.0, scale: float = 1.0, multidirectional: bool = False, nodata_mask=None,
              compute_edges: bool = True, block_rows: int = 256) -> np.ndarray:
    """Hillshade with gdaldem's formulas (Horn gradient), as uint8 1..255 with 0 = nodata.

    ``ewres`` is the positive cell width and ``nsres`` the (negative, north-up) cell height, as in
    a GDAL geotransform. Neighbours outside the raster or on nodata take the centre cell's value
    (gdaldem -compute_edges); without ``compute_edges`` the border is nodata, as gdaldem by default.
    """
    z = np.asarray(dem, dtype=np.float64)
    valid = np.isfinite(z) if nodata_mask is None else (~nodata_mask & np.isfinite(z))
    rows = z.shape[0]
    if rows > block_rows:
        # row blocks with a one-row halo: bounded temporaries, the same result
        out = np.empty(z.shape, np.uint8)
        for r0 in range(0, rows, block_rows):
            a, b = max(r0 - 1, 0), min(r0 + block_rows + 1, rows)
            part = hillshade(np.where(valid[a:b], z[a:b], np.nan), ewres, nsres, azimuth_deg, altitude_deg,
                             z_factor, scale, multidirectional, None, True, block_rows=b - a)
            out[r0:min(r0 + block_rows, rows)] = part[r0 - a:r0 - a + min(block_rows, rows - r0)]
        if not compute_edges:
            out[0, :] = out[-1, :] = 0
            out[:, 0] = out[:, -1] = 0
        return out
    centre = np.where(valid, z, 0.0)
    p = np.pad(np.where(valid, z, np.nan), 1, constant_values=np.nan)
    rows, cols = z.shape
    win = []
    for dr in range(3):
        for dc in range(3):
            w = p[dr:dr + rows, dc:dc + cols]
            win.append(np.where(np.isnan(w), centre, w))
    inv_ew = 1.0 / ewres
    inv_ns = 1.0 / nsres
    x = ((win[0] + win[3] + win[3] + win[6]) - (win[2] + win[5] + win[5] + win[8])) * inv_ew
    y = ((win[6] + win[7] + win[7] + win[8]) - (win[0] + win[1] + win[1] + win[2])) * inv_ns
    zs = z_factor / (8.0 * scale)
    alt = np.radians(altitude_deg)
    xx_plus_yy = x * x + y * y
    cos_alt_z = np.cos(alt) * zs
    if not multidirectional:
        az = np.radians(azimuth_deg)
        num = 254.0 * np.sin(alt) - (y * 254.0 * np.cos(az) * cos_alt_z - x * 254.0 * np.sin(az) * cos_alt_z)
        c = num / np.sqrt(1.0 + zs * zs * xx_plus_yy)
        out = np.where(c <= 0.0, 1.0, 1.0 + c)
    else:
        s127 = 127.0 * np.sin(alt)
        c225 = 127.0 * np.cos(np.radians(225.0)) * cos_alt_z
        c127 = 127.0 * cos_alt_z
        v225 = np.maximum(s127 + (x - y) * c225, 0)
        v270 = np.maximum(s127 - x * c127, 0)
        v315 = np.maximum(s127 + (x + y) * c225, 0)
        v360 = np.maximum(s127 - y * c127, 0)
        w225 = 0.5 * xx_plus_yy - x * y
        w270 = x * x
        w315 = xx_plus_yy - w225
        w360 = y * y
        with np.errstate(invalid="ignore", divide="ignore"):
            c = (w225 * v225 + w270 * v270 + w315 * v315 + w360 * v360) / xx_plus_yy / np.sqrt(1 + zs * zs * xx_plus_yy)
        out = np.where(xx_plus_yy == 0.0, 1.0 + 254.0 * np.sin(alt), 1.0 + c)
    res = np.clip(np.floor(out + 0.5), 0, 255).astype(np.uint8)
    res[~valid] = 0
    if not compute_edges:
        res[0, :] = res[-1, :] = 0
        res[:, 0] = res[:, -1] = 0
    return res

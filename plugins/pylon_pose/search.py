"""Detection and pose search of pylons in aligned photos (Serebro 2017, METHODS.md §4): pure
functions on arrays and small records; no file access. Coordinates are world coordinates minus a
local origin (keeps float64 projections exact to well under a millimetre)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import core, reference


@dataclass
class View:
    """One aligned photo: ideal pinhole K, pose (X_cam = R·X + t in the local frame), its size and
    its line segments in undistorted pixels (x0, y0, x1, y1; pixel centres at integer + 0.5)."""

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    segments: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        return -self.R.T @ self.t

    def project(self, X: np.ndarray):
        cam = np.atleast_2d(X) @ self.R.T + self.t
        uv = cam[:, :2] / cam[:, 2:3] * [self.K[0, 0], self.K[1, 1]] + self.K[:2, 2]
        return uv, cam[:, 2]

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """Unit world directions through pixels."""
        d = np.column_stack([uv, np.ones(len(uv))]) @ np.linalg.inv(self.K).T @ self.R
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def ray_terrain(C: np.ndarray, d: np.ndarray, ground, above_m: float = 0.0, t_max: float = 2000.0, iters: int = 40):
    """Distance α along rays C + α·d (d: (N, 3) unit) where the ray is ``above_m`` over the
    terrain (``ground(x, y)``), by bisection (the method's: unique where the terrain is never
    steeper along the ray than the ray itself); NaN where the ray never gets there."""
    d = np.atleast_2d(d)
    lo = np.zeros(len(d))
    hi = np.full(len(d), t_max)

    def f(t):
        P = C + t[:, None] * d
        return P[:, 2] - ground(P[:, 0], P[:, 1]) - above_m

    ok = (f(lo) > 0) & (f(hi) < 0)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        above = f(mid) > 0
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return np.where(ok, 0.5 * (lo + hi), np.nan)


# ----------------------------------------------------------------------------------------------
# Detection: triangles of line segments, clustered in each photo and across photos
# ----------------------------------------------------------------------------------------------

def model_triangles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The model's triangles (T, 3, 3): three beams meeting pairwise (at a shared end or a
    crossing), vertices at their meeting points."""
    n = len(a)
    P = np.full((n, n, 3), np.nan)
    d1 = d2 = b - a
    for i in range(n):
        r = a[i] - a
        aa = d1[i] @ d1[i]
        ee = np.einsum("ij,ij->i", d2, d2)
        bb = d2 @ d1[i]
        cc = r @ d1[i]
        ff = np.einsum("ij,ij->i", d2, r)
        den = aa * ee - bb * bb
        par = den < 1e-12 * aa * ee
        s = np.clip(np.where(par, 0, (bb * ff - cc * ee) / np.where(par, 1, den)), 0, 1)
        u = np.clip((bb * s + ff) / ee, 0, 1)
        s = np.clip((bb * u - cc) / aa, 0, 1)
        p = a[i] + s[:, None] * d1[i]
        q = a + u[:, None] * d2
        hit = (np.linalg.norm(p - q, axis=1) < 1e-6) & ~par
        hit[i] = False
        P[i, hit] = p[hit]
    adj = ~np.isnan(P[..., 0])
    tris = []
    for i in range(n):
        for j in np.nonzero(adj[i])[0]:
            if j <= i:
                continue
            for k in np.nonzero(adj[i] & adj[j])[0]:
                if k <= j:
                    continue
                v = np.array([P[i, j], P[j, k], P[i, k]])
                if np.linalg.norm(v - np.roll(v, 1, axis=0), axis=1).min() > 1e-3:
                    tris.append(v)
    return np.array(tris).reshape(-1, 3, 3)


def model_triangle_sides(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Shortest and longest side of the model's triangles."""
    t = model_triangles(a, b)
    sides = np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2)
    return float(sides.min()), float(sides.max())


def _crossings(seg: np.ndarray, extend: float, min_angle_deg: float, rows=slice(None)):
    """Pairwise crossings of the segments extended ``extend`` times about their middle, at ≥
    ``min_angle_deg``: (adjacency (rows x n), crossing points (rows x n x 2))."""
    m = 0.5 * (seg[:, :2] + seg[:, 2:])
    h = 0.5 * extend * (seg[:, 2:] - seg[:, :2])
    p0, d = m - h, 2 * h
    cross = d[rows, None, 0] * d[None, :, 1] - d[rows, None, 1] * d[None, :, 0]
    w = p0[None, :, :] - p0[rows, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (w[..., 0] * d[None, :, 1] - w[..., 1] * d[None, :, 0]) / cross
        u = (w[..., 0] * d[rows, None, 1] - w[..., 1] * d[rows, None, 0]) / cross
    L = np.linalg.norm(d, axis=1)
    sin = np.abs(cross) / (L[rows, None] * L[None, :])
    adj = (s >= 0) & (s <= 1) & (u >= 0) & (u <= 1) & (sin >= np.sin(np.radians(min_angle_deg)))
    X = p0[rows, None, :] + np.where(adj, s, 0)[..., None] * d[rows, None, :]
    return adj, X


def photo_triangles(seg: np.ndarray, min_side_px: np.ndarray, max_side_px: np.ndarray, extend: float = 1.5,
                    min_angle_deg: float = 15.0, max_triangles: int = 200_000) -> np.ndarray:
    """Centres (T, 2) of the photo's triangles (``photo_triangle_vertices``)."""
    return photo_triangle_vertices(seg, min_side_px, max_side_px, extend, min_angle_deg, max_triangles).mean(axis=1)


def photo_triangle_vertices(seg: np.ndarray, min_side_px: np.ndarray, max_side_px: np.ndarray, extend: float = 1.5,
                            min_angle_deg: float = 15.0, max_triangles: int = 200_000) -> np.ndarray:
    """Vertices (T, 3, 2) of the photo's triangles: segments extended ``extend`` times about their
    middle, pairwise intersections at ≥ ``min_angle_deg``, three segments meeting pairwise; each
    triangle's sides within [min_side_px, max_side_px] of its first segment (the metric limits
    turned into pixels at the segment's depth) and no angle under ``min_angle_deg``."""
    if len(seg) < 3:
        return np.empty((0, 3, 2))
    n = len(seg)
    adj, X = _crossings(seg, extend, min_angle_deg)
    np.fill_diagonal(adj, False)
    tris = []
    count = 0
    for i in range(n):
        nj = np.nonzero(adj[i, i + 1:])[0] + i + 1
        for j in nj:
            ks = np.nonzero(adj[i, j + 1:] & adj[j, j + 1:])[0] + j + 1
            if not len(ks):
                continue
            A, B, Cs = X[i, j], X[i, ks], X[j, ks]
            ab = np.linalg.norm(B - A, axis=1)
            bc = np.linalg.norm(Cs - B, axis=1)
            ca = np.linalg.norm(A - Cs, axis=1)
            lo, hi = min_side_px[i], max_side_px[i]
            ok = (np.minimum(np.minimum(ab, bc), ca) >= lo) & (np.maximum(np.maximum(ab, bc), ca) <= hi)
            if not ok.any():
                continue
            tris.append(np.stack([np.broadcast_to(A, B[ok].shape), B[ok], Cs[ok]], axis=1))
            count += int(ok.sum())
            if count > max_triangles:
                break
        if count > max_triangles:
            break
    return np.vstack(tris) if tris else np.empty((0, 3, 2))


def cluster_points(xy: np.ndarray, radius_m: float, weights=None):
    """Connected components of points closer than ``radius_m``: (labels, list of member index
    arrays, largest first)."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    if not len(xy):
        return np.empty(0, int), []
    pairs = cKDTree(xy).query_pairs(radius_m, output_type="ndarray")
    from scipy.sparse import coo_matrix

    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(xy), len(xy)))
    _, lab = connected_components(g, directed=False)
    w = np.ones(len(xy)) if weights is None else weights
    groups = [np.nonzero(lab == k)[0] for k in np.unique(lab)]
    groups.sort(key=lambda g_: -w[g_].sum())
    return lab, groups


# ----------------------------------------------------------------------------------------------
# Scoring poses over several photos
# ----------------------------------------------------------------------------------------------

@dataclass
class RoiDescriptor:
    b: np.ndarray
    table: np.ndarray
    K: np.ndarray
    cell_px: int
    perfect: int  # b's value for a cell whose direction matches exactly


def column_corners(centre: np.ndarray, half_m: float, height_m: float) -> np.ndarray:
    """The 8 corners of the box ``centre`` ± ``half_m`` across, from its base up ``height_m``."""
    unit = np.array([[dx, dy, dz] for dx in (-1, 1) for dy in (-1, 1) for dz in (0, 1)], float)
    return np.asarray(centre, float) + unit * [half_m, half_m, height_m]


def roi_descriptor(view: View, centre: np.ndarray, radius_m: float, height_m: float, cell_px: int,
                   mode: str = "max") -> RoiDescriptor | None:
    """The photo's descriptor b on a region of interest around a pylon standing at ``centre``
    (local frame) ± ``radius_m``: the box of the projections of that volume, K shifted to it (the
    method's ROI: cx, cy move). None when the volume is not in front of the camera or not in view."""
    uv, depth = view.project(column_corners(centre, radius_m, height_m))
    if np.any(depth <= 1.0):
        return None
    x0, y0 = np.floor(np.maximum(uv.min(axis=0), 0) / cell_px).astype(int) * cell_px
    x1, y1 = np.minimum(uv.max(axis=0), [view.width, view.height])
    if x1 <= x0 + cell_px or y1 <= y0 + cell_px:
        return None
    seg = view.segments
    inside = ((np.maximum(seg[:, 0], seg[:, 2]) >= x0) & (np.minimum(seg[:, 0], seg[:, 2]) <= x1)
              & (np.maximum(seg[:, 1], seg[:, 3]) >= y0) & (np.minimum(seg[:, 1], seg[:, 3]) <= y1))
    seg = seg[inside] - [x0, y0, x0, y0]
    b, table = core.photo_descriptor(seg, (int(np.ceil(x1 - x0)), int(np.ceil(y1 - y0))), cell_px=cell_px, mode=mode)
    K = view.K.copy()
    K[0, 2] -= x0
    K[1, 2] -= y0
    w = core.direction_weights()
    return RoiDescriptor(b, table, K, cell_px, int(w.max()))


def score_poses(views, rois, poses: np.ndarray, a: np.ndarray, b: np.ndarray, kernel=None) -> np.ndarray:
    """A_s of each pose (N, 6: x, y, z, heading, pitch, roll in the local frame, degrees) in each
    photo, normalised by the score of a perfect match of the same pose (its beams' cells all on
    photo segments of their direction): (n_views, N) in [0, 1]."""
    out = np.zeros((len(views), len(poses)))
    for k, (v, r) in enumerate(zip(views, rois)):
        if r is None:
            continue
        P = core.pose_matrices(r.K, v.R, v.t, poses[:, 0], poses[:, 1], poses[:, 2], poses[:, 3], poses[:, 4], poses[:, 5])
        s = core.similarity(r.b, r.table, P, a, b, r.cell_px, kernel)
        out[k] = s / r.perfect
    return out


def visible_cells(roi: RoiDescriptor, view: View, pose: np.ndarray, a: np.ndarray, b: np.ndarray) -> int:
    """Cells the model's beams cross inside the ROI at ``pose`` (the normaliser of a score)."""
    full = np.full_like(roi.b[..., :1], 1)
    ones = np.broadcast_to(full, roi.b.shape)
    P = core.pose_matrices(roi.K, view.R, view.t, *pose[:4], pose[4], pose[5])
    return int(reference.similarity(np.ascontiguousarray(ones), P, a, b, roi.cell_px, roi.table)[0])


def grid(centre, half, step):
    """Offsets centre ± half in steps (each parameter its own), as an (N, 6) array of poses."""
    axes = [np.arange(-h, h + 1e-9, s) + c if h > 0 else np.array([c]) for c, h, s in zip(centre, half, step)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([m.ravel() for m in mesh])


def weighted_median(values, weights):
    o = np.argsort(values)
    v, w = np.asarray(values)[o], np.asarray(weights)[o]
    c = np.cumsum(w)
    return float(v[np.searchsorted(c, 0.5 * c[-1])])


def mad_merge(values, weights):
    """The method's merge: weighted median, drop values whose absolute deviation exceeds the
    median absolute deviation, weighted mean of the rest; (value, MAD)."""
    values, weights = np.asarray(values, float), np.asarray(weights, float)
    if not len(values) or weights.sum() <= 0:
        return float("nan"), float("nan")
    med = weighted_median(values, weights)
    dev = np.abs(values - med)
    mad = float(np.median(dev))
    keep = dev <= mad + 1e-12
    return float(np.average(values[keep], weights=weights[keep] + 1e-12)), mad


def wrap_deg(a, period=360.0):
    return (np.asarray(a) + period / 2) % period - period / 2


def vote_columns(views, triangles, ground, height_m: float, cell_m: float = 2.0, min_per_photo: int = 2,
                 samples: int = 16):
    """Where the photos' triangle rays meet: each triangle's ray, between 15 % and 85 % of the
    pylon's height over the terrain, marks the grid cells it crosses (once per photo per cell);
    a cell that at least ``min_per_photo`` triangles of one photo cross is that photo's vote.
    Returns (votes per cell, x0, y0 of the grid, cell_m): votes count photos."""
    segs = []
    for v, tc in zip(views, triangles):
        if not len(tc):
            segs.append(np.empty((0, 2, 2)))
            continue
        d = v.rays(tc)
        lo = ray_terrain(v.centre, d, ground, above_m=0.85 * height_m)
        hi = ray_terrain(v.centre, d, ground, above_m=0.15 * height_m)
        ok = np.isfinite(lo) & np.isfinite(hi)
        A = v.centre + lo[ok, None] * d[ok]
        B = v.centre + hi[ok, None] * d[ok]
        segs.append(np.stack([A[:, :2], B[:, :2]], 1))
    allpts = np.concatenate([s.reshape(-1, 2) for s in segs]) if segs else np.empty((0, 2))
    if not len(allpts):
        return np.zeros((0, 0), int), 0.0, 0.0, cell_m
    x0, y0 = allpts.min(axis=0) - cell_m
    nx, ny = (np.ceil((allpts.max(axis=0) - [x0, y0]) / cell_m) + 2).astype(int)
    votes = np.zeros((ny, nx), np.int32)
    t = np.linspace(0, 1, samples)
    for s in segs:
        if not len(s):
            continue
        P = s[:, None, 0, :] + t[None, :, None] * (s[:, None, 1, :] - s[:, None, 0, :])  # (T, samples, 2)
        ix = ((P[..., 0] - x0) / cell_m).astype(int)
        iy = ((P[..., 1] - y0) / cell_m).astype(int)
        cell = iy * nx + ix
        per = np.zeros(nx * ny, np.int32)
        for row in cell:  # each triangle once per cell
            per[np.unique(row)] += 1
        votes += (per.reshape(ny, nx) >= min_per_photo)
    return votes, float(x0), float(y0), cell_m


def column_peaks(votes, x0, y0, cell_m, min_photos: int = 3, separation_m: float = 15.0):
    """Cells with votes ≥ ``min_photos`` that are the maximum within ``separation_m``: (K, 3) x,
    y (cell centres) and votes, strongest first."""
    from scipy import ndimage

    if not votes.size:
        return np.empty((0, 3))
    sm = ndimage.uniform_filter(votes.astype(float), 3)
    r = max(int(round(separation_m / cell_m)), 1)
    mx = ndimage.maximum_filter(sm, size=2 * r + 1)
    iy, ix = np.nonzero((sm == mx) & (votes >= min_photos) & (sm > 0))
    out = np.column_stack([x0 + (ix + 0.5) * cell_m, y0 + (iy + 0.5) * cell_m, votes[iy, ix]])
    return out[np.argsort(-out[:, 2], kind="stable")]


@dataclass
class PoseResult:
    pose: np.ndarray  # x, y, z (local frame), heading, pitch, roll (degrees)
    score: float  # mean normalised A_s over the photos
    mad: np.ndarray  # MADs of x, y, z (m) and heading (deg) from the per-photo merge
    n_photos: int
    per_photo: np.ndarray  # normalised score in each photo used
    n_edge_points: int = 0  # beam points matched to segment edge pairs in the last refinement
    rms_px: float = float("nan")  # their RMS distance to the edge pairs' midlines
    edge_share: float = 0.0  # their share of the model's beam points in view
    start: str = "grid"  # where the first pose came from: grid or triangles

    def photo_share(self, min_share: float) -> float:
        """Share of the photos in which the pose matches at least ``min_share`` of its cells."""
        return float(np.mean(self.per_photo >= min_share)) if len(self.per_photo) else 0.0


def _rois(views, centre, radius_m, height_m, cell_px, mode):
    rois = [roi_descriptor(v, centre, radius_m, height_m, cell_px, mode) for v in views]
    keep = [k for k, r in enumerate(rois) if r is not None]
    return [views[k] for k in keep], [rois[k] for k in keep]


def _shares(views, rois, pose, a, b, kernel=None) -> np.ndarray:
    """Per photo, the share of the pose's beam cells that match photo segments of their direction."""
    per = score_poses(views, rois, pose[None], a, b, kernel)[:, 0]
    return per / np.array([max(visible_cells(r, v, pose, a, b), 1) for v, r in zip(views, rois)])


def _best_distinct(poses, scores, n, min_dist_m=2.0, min_heading_deg=20.0, period=360.0):
    order = np.argsort(-scores)
    out = []
    for i in order:
        p = poses[i]
        if all(np.hypot(*(p[:2] - q[:2])) > min_dist_m or abs(wrap_deg(p[3] - q[3], period)) > min_heading_deg
               for q in out):
            out.append(p)
        if len(out) == n:
            break
    return out


def tilt_of(pose: np.ndarray) -> tuple[float, float]:
    """(tilt, azimuth) of a pose's vertical axis: its angle from the plumb line and the compass
    direction (degrees clockwise from grid north) its top leans toward."""
    up = core.rotation(pose[3], pose[4], pose[5])[:, 2]
    return (float(np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0)))),
            float(np.degrees(np.arctan2(up[0], up[1])) % 360.0))


def tilted_poses(pose: np.ndarray, tilts: np.ndarray, pivot_m: float) -> np.ndarray:
    """``pose`` with each (pitch, roll) of ``tilts`` (N, 2), the base moved so that the model's
    axis still passes the same point ``pivot_m`` up it: an upright fit of a leaning tower holds its
    body, not its base, so the base is where a tilt must move."""
    up = core.rotation(pose[3], pose[4], pose[5])[:, 2]
    out = np.repeat(np.asarray(pose, float)[None], len(tilts), axis=0)
    out[:, 4:6] = tilts
    for k, (p, r) in enumerate(tilts):
        out[k, :3] = pose[:3] + pivot_m * (up - core.rotation(pose[3], p, r)[:, 2])
    return out


@dataclass(frozen=True)
class TiltGrid:
    """The tilt search's grids: tilt step, shift and turn reach, seeds kept, pivot up the axis."""

    step_deg: float = 1.0
    shift_m: float = 1.0
    turn_deg: float = 3.0
    keep: int = 3
    pivot_share: float = 0.4


def search_tilt(views, rois, pose: np.ndarray, a, b, height_m: float, max_tilt_deg: float, kernel=None,
                tg: TiltGrid = TiltGrid()) -> np.ndarray:
    """A leaning pylon's tilt by A_s (the method searches an upright tower; its future work is
    this). Pitch and roll on a grid of ``step_deg`` over the disc of ``max_tilt_deg``, the base
    moved to keep the axis through ``pivot_share`` of the height, each shifted ± ``shift_m`` and
    turned ± ``turn_deg`` (an upright fit of a leaning tower compromises its position and heading
    too); the ``keep`` best on finer shifts and turns; then, where the best is not upright, a
    quarter of the tilt step about it (where it is, the tilts finer than a step are left to
    MatchSeparate, as for the method's upright search). Each pose scored summed over the photos.
    The upright pose is one of the candidates, so an upright tower keeps it unless a tilt matches
    better. The grids' sizes are ``tg``'s (``TiltGrid``)."""
    def best_of(cand, n=1):
        sc = score_poses(views, rois, cand, a, b, kernel).sum(axis=0)
        return cand[np.argsort(-sc, kind="stable")[:n]]

    def around(poses, half_m, step_m, turn, step_turn):
        offs = grid(np.zeros(6), [half_m, half_m, 0, turn, 0, 0], [step_m, step_m, 1, step_turn, 1, 1])
        return (np.asarray(poses)[:, None, :] + offs[None]).reshape(-1, 6)

    def disc(centre, reach, step):
        g = np.arange(-reach, reach + 1e-9, step)
        t = np.array([(p, r) for p in g for r in g if np.hypot(p, r) <= reach + 1e-9]) + centre
        return t[np.hypot(t[:, 0], t[:, 1]) <= max_tilt_deg + 1e-9]

    pivot = tg.pivot_share * height_m
    coarse = tilted_poses(pose, disc(0.0, max_tilt_deg, tg.step_deg), pivot)
    seeds = best_of(around(coarse, tg.shift_m, tg.shift_m, tg.turn_deg, tg.turn_deg / 2), tg.keep)
    best = best_of(around(seeds, tg.shift_m / 2, tg.shift_m / 4, tg.turn_deg / 2, tg.turn_deg / 2))[0]
    if not np.any(best[4:6]):  # upright on the grid that resolves a tilt: finer tilts are MatchSeparate's
        return best.copy()
    fine = tilted_poses(best, disc(best[4:6], tg.step_deg / 2, tg.step_deg / 4), pivot)
    return best_of(around(fine, tg.shift_m / 4, tg.shift_m / 4, tg.turn_deg / 6, tg.turn_deg / 6))[0].copy()


@dataclass(frozen=True)
class SearchSettings:
    """The pose search's options (the plugin's parameters of the same names)."""

    radius_m: float = 8.0
    mode: str = "max"
    iterations: int = 2
    min_score: float = 0.0
    hypotheses: str = "grid"
    max_tilt_deg: float = 5.0
    min_photo_share: float = 0.0


def _match_separate_and_joint(vC, rC, pose, a, b, height_m: float, period: float, iterations: int, kernel=None):
    """The method's MatchSeparate on 4 px cells (per photo the best rotation, then translation,
    on grids within the current MADs, merged across photos by MAD-weighted medians), then a joint
    search summed over the photos within them: (pose, MADs of x, y, z, heading, pitch, roll)."""
    mad = np.array([0.5, 0.5, 0.5, 2.0, 0.3, 0.3])
    pose = np.asarray(pose, float).copy()
    rays = np.array([pose[:3] + [0, 0, height_m / 2] - v.centre for v in vC])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    for _ in range(iterations):
        rot = grid(pose, [0, 0, 0, max(mad[3], 0.5), max(mad[4], 0.1), max(mad[5], 0.1)], [1, 1, 1, 0.25, 0.1, 0.1])
        sc = score_poses(vC, rC, rot, a, b, kernel)
        best_k = rot[np.argmax(sc, axis=1)]
        w = sc.max(axis=1)
        merged = [mad_merge(wrap_deg(best_k[:, 3] - pose[3], period) + pose[3], w)]
        merged += [mad_merge(best_k[:, k], w) for k in (4, 5)]
        pose[3], pose[4], pose[5] = merged[0][0], merged[1][0], merged[2][0]
        mad[3:] = [m[1] for m in merged]
        tr = grid(pose, [max(mad[0], 0.3), max(mad[1], 0.3), max(mad[2], 0.3), 0, 0, 0], [0.1, 0.1, 0.1, 1, 1, 1])
        sc = score_poses(vC, rC, tr, a, b, kernel)
        best_k = tr[np.argmax(sc, axis=1)]
        w = sc.max(axis=1)
        for k in range(3):  # weight: similarity x sin(angle between the ray and the axis)
            wk = w * np.sqrt(np.clip(1 - rays[:, k] ** 2, 0, 1))
            pose[k], mad[k] = mad_merge(best_k[:, k], wk)
        if np.all(mad[:3] <= 0.3) and mad[3] <= 1.0:
            break
    # D: joint refinement within the MADs (translation, then rotation, twice)
    for _ in range(2):
        tr = grid(pose, [min(max(mad[0], 0.1), 0.4), min(max(mad[1], 0.1), 0.4), min(max(mad[2], 0.1), 0.4), 0, 0, 0],
                  [0.05, 0.05, 0.05, 1, 1, 1])
        sc = score_poses(vC, rC, tr, a, b, kernel).sum(axis=0)
        pose = tr[int(np.argmax(sc))].copy()
        rot = grid(pose, [0, 0, 0, min(max(mad[3], 0.25), 1.0), 0.1, 0.1], [1, 1, 1, 0.125, 0.05, 0.05])
        sc = score_poses(vC, rC, rot, a, b, kernel).sum(axis=0)
        pose = rot[int(np.argmax(sc))].copy()
    return pose, mad


def find_pose(views, rough_xy, ground, a, b, height_m: float, symmetry_deg: float = 360.0, kernel=None,
              settings: SearchSettings = SearchSettings(), progress=None) -> PoseResult | None:
    """A pylon's pose from the photos that see it, from a rough position (local frame) ± radius_m.
    First poses: with ``hypotheses="triangles"`` the method's MatchByTriangles (P3P, merged across
    photos, the best of four quarter turns); with ``"grid"``, or where the triangles give no pose
    scoring ``min_score``, a coarse exhaustive search (x, y, heading on the terrain, upright; 32 px
    cells) and a finer one around the best candidates (8 px). Then the method's MatchSeparate on
    4 px cells: in each photo the best rotation, then the best translation, on grids within the
    current MADs, merged across photos by MAD-weighted medians; a joint search (summed over
    photos) within them; last the continuous refinement on the segments (``refine_on_segments``).
    Between the first poses and MatchSeparate, the tilt up to ``max_tilt_deg`` (``search_tilt``):
    the method's search holds a tower upright. A candidate matching at least half of
    ``min_score`` in fewer than ``min_photo_share`` of its photos there goes no further (the
    caller's rule, applied before the fine stages too)."""
    st = settings
    radius_m, mode, min_score, max_tilt_deg = st.radius_m, st.mode, st.min_score, st.max_tilt_deg
    extent = float(max(np.abs(a[:, :2]).max(), np.abs(b[:, :2]).max()))
    period = min(symmetry_deg, 360.0)
    step = (lambda *_: None) if progress is None else progress
    c0 = np.array([rough_xy[0], rough_xy[1], float(ground(np.array([rough_xy[0]]), np.array([rough_xy[1]]))[0])])
    views = [v for v in views if seen_by([v], c0[:2], ground, height_m)]  # the photos it is in
    vB, rB = _rois(views, c0, radius_m + extent + 2.0, height_m, 8, mode)
    if len(vB) < 2:
        return None
    start = None
    if st.hypotheses == "triangles":  # the method's MatchByTriangles; the exhaustive search where it finds nothing
        start = match_by_triangles(vB, rB, c0, ground, a, b, height_m, period, radius_m, kernel, min_score,
                                   max_tilt_deg=max_tilt_deg + 1.0)
        step("triangles")
    if start is not None:
        best = start[0]
        # P3P on a symmetric lattice cannot tell the quarter turns apart: the method's four-fold choice
        turns = np.unique(np.round((best[3] + 90.0 * np.arange(4)) % period, 6))
        cand = np.repeat(best[None], len(turns), axis=0)
        cand[:, 3] = turns
        best = cand[int(np.argmax(score_poses(vB, rB, cand, a, b, kernel).sum(axis=0)))].copy()
        cand = grid(best, [0.5, 0.5, 0.25, 2.0, 0, 0], [0.125, 0.125, 0.25, 0.5, 1, 1])
        best = cand[int(np.argmax(score_poses(vB, rB, cand, a, b, kernel).sum(axis=0)))].copy()
        shares = _shares(vB, rB, best, a, b, kernel)
        if shares.mean() < min_score:
            start = None  # the method: the exhaustive search where the triangles give no pose scoring over tau
    if start is None:
        # A: coarse, everything the rough position allows
        vA, rA = _rois(views, c0, radius_m + extent, height_m, 32, mode)
        poses = grid([c0[0], c0[1], 0.0, period / 2, 0, 0], [radius_m, radius_m, 0, period / 2, 0, 0], [1.5, 1.5, 1, 5.0, 1, 1])
        poses = poses[poses[:, 3] < period - 1e-9]
        poses[:, 2] = ground(poses[:, 0], poses[:, 1])
        sA = score_poses(vA, rA, poses, a, b, kernel).sum(axis=0)
        step("coarse")
        seeds = _best_distinct(poses, sA, 3, period=period)
        # B: 8 px cells around the best few
        best, best_s = None, -1.0
        for s in seeds:
            cand = grid(s, [1.5, 1.5, 0.5, 4.0, 0, 0], [0.5, 0.5, 0.5, 2.0, 1, 1])
            sc = score_poses(vB, rB, cand, a, b, kernel).sum(axis=0)
            i = int(np.argmax(sc))
            if sc[i] > best_s:
                best, best_s = cand[i].copy(), float(sc[i])
        cand = grid(best, [0.25, 0.25, 0.25, 1.0, 0, 0], [0.125, 0.125, 0.25, 0.5, 1, 1])
        best = cand[int(np.argmax(score_poses(vB, rB, cand, a, b, kernel).sum(axis=0)))].copy()
        step("fine")
        shares = _shares(vB, rB, best, a, b, kernel)
    # a lean moves the top; the body below still matches upright, so a candidate under half of min_score is no pylon
    if max_tilt_deg > 0 and float(shares.mean()) >= min_score / 2:
        best = search_tilt(vB, rB, best, a, b, height_m, max_tilt_deg, kernel)
        shares = _shares(vB, rB, best, a, b, kernel)
        step("tilt")
    # no pylon of this type here, or clutter that lines up with it in a few photos: skip the fine stages
    if float(shares.mean()) < min_score or float(np.mean(shares >= min_score / 2)) < st.min_photo_share:
        return PoseResult(best, float(shares.mean()), np.full(4, np.nan), len(vB), shares)
    # C: MatchSeparate on 4 px cells, per photo, merged
    lean_m = height_m * np.sin(np.radians(tilt_of(best)[0] + 0.5))  # the top's offset from over the base
    vC, rC = _rois(views, best[:3], extent + 1.5 + lean_m, height_m, 4, mode)
    pose, mad = _match_separate_and_joint(vC, rC, best, a, b, height_m, period, st.iterations, kernel)
    step("joint")
    # E: A_s stops at its 4 px cells; the segments themselves carry the pose to a fraction of a pixel
    refined, n_edge, rms, share = refine_on_segments(vC, pose, a, b, extent_m=extent + lean_m)
    if np.all(np.abs(refined[:3] - pose[:3]) <= 0.5) and np.all(np.abs(refined[3:] - pose[3:]) <= 1.0):
        pose = refined
    per = _shares(vC, rC, pose, a, b, kernel)
    pose = core.canonical_pose(pose, period)
    step("refine")
    return PoseResult(pose, float(per.mean()), np.array([mad[0], mad[1], mad[2], mad[3]]), len(vC), per, n_edge, rms, share,
                      "grid" if start is None else "triangles")


# ----------------------------------------------------------------------------------------------
# MatchByTriangles: P3P hypotheses from photo triangles matched to the model's
# ----------------------------------------------------------------------------------------------

_ORDERS = np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1], [0, 2, 1], [2, 1, 0], [1, 0, 2]])


def triangle_hypotheses(view: View, photo_tris: np.ndarray, model_tris: np.ndarray, centre: np.ndarray,
                        heading_step_deg: float = 2.5, shape_tol_px: float = 3.0, shape_tol_rel: float = 0.05,
                        min_area_px2: float = 200.0, max_tilt_deg: float = 1.0, max_dist_m: float = 15.0,
                        max_solves: int = 20_000, level: bool = True) -> np.ndarray:
    """The method's MatchByTriangles in one photo: poses (N, 6) from P3P (``cv2.solveP3P``, up to
    4 solutions) on photo triangle x model triangle x vertex order, without the hypotheses tilted
    more than ``max_tilt_deg`` or further than ``max_dist_m`` from ``centre`` (the rough position
    on the terrain). All pairs would be ~10⁵ solves per photo; a pair is solved only when the photo
    triangle's shape (vertices about their centroid) is within ``shape_tol_px`` +
    ``shape_tol_rel`` x its size of the model triangle's upright projection at ``centre`` for some
    heading on a ``heading_step_deg`` grid (the method's size filter, made exact for the view), at
    most ``max_solves`` pairs. With ``level`` each hypothesis is turned upright about its matched
    triangle: P3P on a triangle a hundred pixels across leaves tilts of about a degree."""
    import cv2
    from scipy.spatial import cKDTree

    if not len(photo_tris) or not len(model_tris):
        return np.empty((0, 6))
    headings = np.arange(0.0, 360.0, heading_step_deg)
    pred = []
    for h in headings:
        uv, _ = view.project(model_tris.reshape(-1, 3) @ core.rotation(h, 0.0, 0.0).T + centre)
        pred.append(uv.reshape(-1, 3, 2))
    pred = np.stack(pred)  # (H, T, 3, 2)
    e1, e2 = pred[..., 1, :] - pred[..., 0, :], pred[..., 2, :] - pred[..., 0, :]
    area = 0.5 * np.abs(e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0])
    hi, ti = np.nonzero(area >= min_area_px2)  # edge-on triangles leave P3P ill-conditioned
    if not len(hi):
        return np.empty((0, 6))
    shapes = pred[hi, ti] - pred[hi, ti].mean(axis=1, keepdims=True)
    tree = cKDTree(shapes.reshape(len(hi), 6))
    q = photo_tris[:, _ORDERS].reshape(-1, 3, 2)  # each triangle in its 6 vertex orders
    qc = (q - q.mean(axis=1, keepdims=True)).reshape(-1, 6)
    size = np.abs(qc).max(axis=1)
    hits = tree.query_ball_point(qc, shape_tol_px + shape_tol_rel * size, p=np.inf)
    pairs = {(i, int(ti[j])) for i, js in enumerate(hits) for j in js}
    pairs = sorted(pairs)[:max_solves]
    rv, tv, tri = [], [], []
    for i, t in pairs:
        n, rvecs, tvecs = cv2.solveP3P(np.ascontiguousarray(model_tris[t], dtype=np.float64), np.ascontiguousarray(q[i]),
                                        view.K, None, flags=cv2.SOLVEPNP_P3P)
        rv += [r.ravel() for r in rvecs[:n]]
        tv += [x.ravel() for x in tvecs[:n]]
        tri += [t] * n
    if not rv:
        return np.empty((0, 6))
    rv, tv, tri = np.array(rv), np.array(tv), np.array(tri)
    Rm = view.R.T @ _rodrigues(rv)  # X_cam = Rc·(Rm·X + T) + tc
    T = (tv - view.t) @ view.R
    keep = (np.degrees(np.arccos(np.clip(Rm[:, 2, 2], -1, 1))) <= max_tilt_deg) & (np.linalg.norm(T - centre, axis=1) <= max_dist_m)
    Rm, T, tri = Rm[keep], T[keep], tri[keep]
    heading = np.degrees(np.arctan2(Rm[:, 1, 0], Rm[:, 0, 0])) % 360.0
    if level:  # upright about the matched triangle, which the photo holds in place
        c = model_tris[tri].mean(axis=1)
        ch, sh = np.cos(np.radians(heading)), np.sin(np.radians(heading))
        upright = np.zeros((len(heading), 3, 3))
        upright[:, 0, 0], upright[:, 0, 1], upright[:, 1, 0], upright[:, 1, 1], upright[:, 2, 2] = ch, -sh, sh, ch, 1.0
        T = T + np.einsum("nij,nj->ni", Rm - upright, c)
        return np.column_stack([T, heading, np.zeros(len(T)), np.zeros(len(T))])
    return np.array([[*x, *core.euler_from_rotation(R)] for x, R in zip(T, Rm)]).reshape(-1, 6)


def _rodrigues(rv: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of rotation vectors (N, 3), as cv2.Rodrigues."""
    theta = np.linalg.norm(rv, axis=1)
    k = rv / np.where(theta > 0, theta, 1.0)[:, None]
    Kx = np.zeros((len(rv), 3, 3))
    Kx[:, 0, 1], Kx[:, 0, 2], Kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    Kx -= Kx.transpose(0, 2, 1)
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * Kx + (1 - c) * Kx @ Kx


_MODEL_TRIANGLES: dict = {}


def _model_triangles_cached(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    key = (a.tobytes(), b.tobytes())
    if key not in _MODEL_TRIANGLES:
        _MODEL_TRIANGLES[key] = model_triangles(a, b)
    return _MODEL_TRIANGLES[key]


def match_by_triangles(views, rois, centre: np.ndarray, ground, a: np.ndarray, b: np.ndarray, height_m: float,
                       period_deg: float, radius_m: float, kernel=None, min_score: float = 0.0, extend: float = 4.0,
                       large_share: float = 0.5, max_above_ground_m: float = 1.5, **kw):
    """The method's MatchByTriangles across photos: in each photo the P3P hypotheses of
    ``triangle_hypotheses`` (photo triangles inside the ROI of a pylon at ``centre`` ± ``radius_m``,
    segments extended ``extend`` times; the model's triangles with the longest sides, top
    ``large_share``, which P3P solves most precisely), those with the base more than
    ``max_above_ground_m`` off the terrain (``ground``) left out (a slide along the photo's ray
    keeps a triangle in place), the rest scored by A_s in that photo (``rois``);
    each photo's best, if its share of matched cells reaches ``min_score``, is merged across photos
    (MAD-weighted medians; weight: similarity x sin(angle between the photo's ray and the axis);
    heading modulo ``period_deg``). Returns (pose, MADs of x, y, z, heading, photos that gave
    one) or None when fewer than two photos did."""
    extent = float(max(np.abs(a[:, :2]).max(), np.abs(b[:, :2]).max()))
    mt = _model_triangles_cached(a, b)
    sides = np.linalg.norm(mt - np.roll(mt, 1, axis=1), axis=2)
    longest = sides.max(axis=1)
    smin, smax = float(sides.min()), float(longest.max())
    mt = mt[longest >= np.quantile(longest, 1.0 - large_share)]
    kw.setdefault("max_dist_m", max(radius_m, 15.0))
    best, scores, rays = [], [], []
    for v, r in zip(views, rois):
        uv, depth = v.project(column_corners(centre, radius_m + extent, height_m))
        (x0, y0), (x1, y1) = uv.min(axis=0), uv.max(axis=0)
        seg = v.segments
        mid = 0.5 * (seg[:, :2] + seg[:, 2:])
        seg = seg[(mid[:, 0] >= x0) & (mid[:, 0] <= x1) & (mid[:, 1] >= y0) & (mid[:, 1] <= y1)]
        px_per_m = v.K[0, 0] / float(v.project(centre + [0, 0, height_m / 2])[1][0])
        tris = photo_triangle_vertices(seg, np.full(len(seg), 0.5 * smin * px_per_m), np.full(len(seg), 2 * smax * px_per_m),
                                       extend=extend)
        hyp = triangle_hypotheses(v, tris, mt, centre, **kw)
        hyp = hyp[np.abs(hyp[:, 2] - ground(hyp[:, 0], hyp[:, 1])) <= max_above_ground_m]
        if not len(hyp):
            continue
        s = score_poses([v], [r], hyp, a, b, kernel)[0]
        i = int(np.argmax(s))
        share = s[i] / max(visible_cells(r, v, hyp[i], a, b), 1)
        if share < min_score:
            continue
        best.append(hyp[i])
        scores.append(s[i])
        d = hyp[i, :3] + [0, 0, height_m / 2] - v.centre
        rays.append(d / np.linalg.norm(d))
    if len(best) < 2:
        return None
    best, w, rays = np.array(best), np.array(scores), np.array(rays)
    pose, mad = np.zeros(6), np.zeros(4)
    for k in range(3):
        pose[k], mad[k] = mad_merge(best[:, k], w * np.sqrt(np.clip(1 - rays[:, k] ** 2, 0, 1)))
    h0 = best[int(np.argmax(w)), 3]
    pose[3], mad[3] = mad_merge(wrap_deg(best[:, 3] - h0, period_deg) + h0, w)
    return pose, mad, len(best)


# ----------------------------------------------------------------------------------------------
# Continuous refinement on the photos' segments
# ----------------------------------------------------------------------------------------------

def _beam_samples(view: View, pose: np.ndarray, a: np.ndarray, b: np.ndarray, step_px: float):
    """Points along the model's beams about ``step_px`` apart in this photo at ``pose``: (beam
    index, fraction along it); beams with an end behind the camera are left out."""
    R = core.rotation(pose[3], pose[4], pose[5])
    ua, za = view.project(a @ R.T + pose[:3])
    ub, zb = view.project(b @ R.T + pose[:3])
    n = np.where((za > 1) & (zb > 1), np.maximum((np.linalg.norm(ub - ua, axis=1) / step_px).astype(int), 1), 0)
    beam = np.repeat(np.arange(len(a)), n)
    frac = (np.arange(len(beam)) - np.repeat(np.cumsum(n) - n, n) + 0.5) / np.repeat(n, n)
    return beam, frac


def _project_beam_points(view: View, pose: np.ndarray, a: np.ndarray, b: np.ndarray, beam, frac):
    """Pixels of the beam points at ``pose`` and the beams' unit image directions there."""
    R = core.rotation(pose[3], pose[4], pose[5])
    D = (b[beam] - a[beam]) @ R.T
    X = a[beam] @ R.T + frac[:, None] * D + pose[:3]
    uv, _ = view.project(X)
    uv2, _ = view.project(X + 1e-3 * D / np.linalg.norm(D, axis=1, keepdims=True))
    d = uv2 - uv
    return uv, d / (np.linalg.norm(d, axis=1, keepdims=True) + 1e-12)


class SegmentIndex:
    """A photo's line segments inside a pixel box, sampled every 1.5 px into a k-d tree, to find
    the segments of a given direction near a point."""

    def __init__(self, seg: np.ndarray, box):
        from scipy.spatial import cKDTree

        x0, y0, x1, y1 = box
        seg = seg[(np.maximum(seg[:, 0], seg[:, 2]) >= x0) & (np.minimum(seg[:, 0], seg[:, 2]) <= x1)
                  & (np.maximum(seg[:, 1], seg[:, 3]) >= y0) & (np.minimum(seg[:, 1], seg[:, 3]) <= y1)]
        p, q = seg[:, :2], seg[:, 2:]
        self.length = np.linalg.norm(q - p, axis=1)
        self.p = p
        self.dir = (q - p) / np.maximum(self.length, 1e-9)[:, None]
        self.normal = np.column_stack([-self.dir[:, 1], self.dir[:, 0]])
        m = np.ceil(self.length / 1.5).astype(int) + 1  # tree points 1.5 px apart
        self.sid = np.repeat(np.arange(len(seg)), m)
        t = np.concatenate([np.linspace(0.0, 1.0, k) for k in m]) if len(m) else np.empty(0)
        self.tree = cKDTree(p[self.sid] + t[:, None] * (q - p)[self.sid]) if len(self.sid) else None

    def edges(self, uv: np.ndarray, d: np.ndarray, radius_px: float, angle_deg: float, k: int = 16):
        """For each point (with the beam's image direction d): the nearest segment within
        ``radius_px`` on each side of it whose direction is within ``angle_deg`` and which spans
        the point; (left, right) segment indices, -1 where there is none."""
        n = len(uv)
        none = np.full(n, -1)
        if self.tree is None or not n:
            return none, none.copy()
        dist, j = self.tree.query(uv, k=k, distance_upper_bound=radius_px, workers=-1)  # every core: same answer
        # only the neighbours found (most of the k slots are empty): per pair, its segment's
        # direction, reach along it and side
        row, slot = np.nonzero(np.isfinite(dist))
        s = self.sid[j[row, slot]]
        dirs, dr = self.dir[s], d[row]
        ok = np.abs(dirs[:, 0] * dr[:, 0] + dirs[:, 1] * dr[:, 1]) >= np.cos(np.radians(angle_deg))
        rel = self.p[s] - uv[row]
        along = -(rel[:, 0] * dirs[:, 0] + rel[:, 1] * dirs[:, 1])
        ok &= (along >= -1.0) & (along <= self.length[s] + 1.0)
        off = rel[:, 0] * -dr[:, 1] + rel[:, 1] * dr[:, 0]
        return self._nearest(n, row, slot, s, ok & (off < 0), -off), self._nearest(n, row, slot, s, ok & (off >= 0), off)

    @staticmethod
    def _nearest(n, row, slot, s, mask, dist):
        """Per point, the segment of the closest pair in ``mask`` (ties: the nearer neighbour
        slot, as an argmin over the slots), -1 where none."""
        out = np.full(n, -1)
        row, slot, s, dist = row[mask], slot[mask], s[mask], dist[mask]
        order = np.lexsort((slot, dist, row))
        first = order[np.unique(row[order], return_index=True)[1]]  # each point's first, in that order
        out[row[first]] = s[first]
        return out


def refine_on_segments(views, pose: np.ndarray, a: np.ndarray, b: np.ndarray, radii_px=(6.0, 4.0, 3.0),
                       step_px: float = 4.0, angle_deg: float = 5.0, f_scale_px: float = 1.0,
                       tilt_grid_deg=(0.6, 0.2), count_radius_px: float = 2.0,
                       max_rematch: int = 4, extent_m: float | None = None):
    """Continuous refinement of a pose (x, y, z, heading, pitch, roll) against the photos' segments,
    past the resolution of the A_s cells: points every ``step_px`` along each projected beam are
    matched to the nearest segment of the beam's direction on either side (a beam wider than a
    pixel gives LSD its two edges), and the 6 pose parameters minimise the distances of the points
    to the midlines of their edge pairs over all photos (robust Huber loss, ``f_scale_px``).
    Matching and solving alternate (up to ``max_rematch`` times per radius, until the pairs hold
    still) with the search radius shrinking through ``radii_px``. Then the tilts of
    ``tilt_grid_deg`` (± half, step) about the solved tilt are tried at the solved position and
    heading, and the one holding the most edge pairs is solved again. The
    solution with the most edge pairs within ``count_radius_px`` wins (the start if none beats it).
    Returns (pose, beam points matched to edge pairs at the last radius, their RMS distance in
    pixels, their share of the beam points in view)."""
    from scipy.optimize import least_squares

    pose = np.asarray(pose, float).copy()
    height = float(max(a[:, 2].max(), b[:, 2].max()))
    extent = float(max(np.abs(a[:, :2]).max(), np.abs(b[:, :2]).max())) if extent_m is None else extent_m
    box = column_corners(pose[:3], extent + 1, height + 1)
    data = []
    for v in views:
        uv, z = v.project(box)
        if np.all(z > 1):
            data.append((v, SegmentIndex(v.segments, (*uv.min(axis=0) - 10, *uv.max(axis=0) + 10))))

    seen = [0]  # beam points in view at the last match

    def match(x, radius, step=step_px):
        rows = []
        seen[0] = 0
        for v, idx in data:
            beam, frac = _beam_samples(v, x, a, b, step)
            if not len(beam):
                continue
            uv, d = _project_beam_points(v, x, a, b, beam, frac)
            left, right = idx.edges(uv, d, radius, angle_deg)
            inside = (uv[:, 0] >= 0) & (uv[:, 0] < v.width) & (uv[:, 1] >= 0) & (uv[:, 1] < v.height)
            seen[0] += int(inside.sum())
            keep = (left >= 0) & (right >= 0) & inside
            if keep.any():
                sign = np.sign(np.einsum("ij,ij->i", idx.normal[left[keep]], idx.normal[right[keep]]))
                rows.append((v, idx, beam[keep], frac[keep], left[keep], right[keep], sign))
        return rows

    def residuals(x, rows):
        out = [np.zeros(0)]
        for v, idx, beam, frac, left, right, sign in rows:
            uv, _ = _project_beam_points(v, x, a, b, beam, frac)
            r1 = np.einsum("ij,ij->i", uv - idx.p[left], idx.normal[left])
            r2 = np.einsum("ij,ij->i", uv - idx.p[right], idx.normal[right])
            out.append(0.5 * (r1 + sign * r2))  # offset from the midline of the two edges
        return np.concatenate(out)

    def count(x, step=step_px):
        return sum(len(r[2]) for r in match(x, count_radius_px, step))

    def solve(x, radii):
        for radius in radii:
            for _ in range(max_rematch):  # match, solve, match again until the pairs hold still
                rows = match(x, radius)
                if sum(len(r[2]) for r in rows) < 12:
                    return x, count(x)
                x_new = least_squares(residuals, x, args=(rows,), loss="huber", f_scale=f_scale_px, x_scale=0.05,
                                      diff_step=1e-6).x
                moved = np.abs(x_new - x)
                x = x_new
                if moved[:3].max() < 1e-3 and moved[3:].max() < 2e-3:
                    break
        return x, count(x)

    best, n_best = pose.copy(), count(pose)
    x, n = solve(pose, radii_px)
    if n >= n_best:
        best, n_best = x, n
    if tilt_grid_deg is not None:
        # a tilt a few tenths of a degree off can hold as many beams as the right one at the wide radii
        # (the top's beams caught by their neighbours); edge pairs within count_radius_px over a grid of
        # tilts tell them apart
        tilts = np.arange(-tilt_grid_deg[0], tilt_grid_deg[0] + 1e-9, tilt_grid_deg[1])
        cands = [np.r_[best[:4], best[4] + tp, best[5] + tr] for tp in tilts for tr in tilts]
        counts = [count(g, 2 * step_px) for g in cands]
        x, n = solve(cands[int(np.argmax(counts))], radii_px[1:])
        if n > n_best:
            best, n_best = x, n
    rows = match(best, radii_px[-1])
    res = residuals(best, rows)
    return best, len(res), float(np.sqrt(np.mean(res ** 2))) if len(res) else float("nan"), len(res) / max(seen[0], 1)


def photo_corners(seg: np.ndarray, max_length_px: np.ndarray, extend: float = 1.5, min_angle_deg: float = 15.0) -> np.ndarray:
    """Meeting points (C, 2) of the photo's segments no longer than ``max_length_px`` (each its
    own limit: the model's longest triangle side x 2 at its depth), extended ``extend`` times about
    their middle, at ≥ ``min_angle_deg``: the lattice's joints. Many more per pylon than the
    method's triangles (which need three segments meeting pairwise)."""
    L = np.hypot(*(seg[:, 2:] - seg[:, :2]).T)
    seg = seg[L <= max_length_px]
    if len(seg) < 2:
        return np.empty((0, 2))
    out = []
    for s0 in range(0, len(seg), 1024):  # blocks of rows keep the pair arrays small
        adj, X = _crossings(seg, extend, min_angle_deg, slice(s0, s0 + 1024))
        adj &= np.arange(len(seg))[None, :] > np.arange(s0, s0 + adj.shape[0])[:, None]
        out.append(X[adj])
    return np.vstack(out)


def seen_by(views, xy, ground, height_m: float) -> int:
    """Photos in whose frame a pylon standing at ``xy`` (its middle) appears."""
    X = np.array([xy[0], xy[1], float(ground(np.array([xy[0]]), np.array([xy[1]]))[0]) + height_m / 2])
    n = 0
    for v in views:
        uv, z = v.project(X)
        n += bool(z[0] > 0 and 0 <= uv[0, 0] < v.width and 0 <= uv[0, 1] < v.height)
    return n

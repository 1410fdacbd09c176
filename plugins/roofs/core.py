"""Roof planes by a 3D Hough transform voting into a ball accumulator.

Pure functions on arrays (lengths in the cloud's units). The method (Borowiec, METHODS.md §3)
votes every point into a (θ, φ, ρ) accumulator and takes the fullest cell as a plane; here the
(θ, φ) part is the ball accumulator of Borrmann et al. (2011, 3D Research 2(2)), whose cells have
nearly equal area on the sphere, and each peak is only a hypothesis: its points are refitted by
least squares and grown to all points within ``max_distance`` of the fitted plane, split into
connected patches, and the patches of at least ``min_points`` become planes whose votes are taken
back from the accumulator before the next peak. At the end every point goes to the nearest plane
whose patch it touches (points along a ridge are near both faces) and near-duplicate planes merge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from . import reference

ACC_BYTES_PER_CELL = 4  # int32 counts


@dataclass
class Plane:
    normal: np.ndarray  # unit normal, z >= 0
    d: float  # normal · p = d, in the coordinates of the points given
    indices: np.ndarray  # the points on the plane
    rms: float


def fit_plane(xyz: np.ndarray):
    """Least-squares plane through points: (unit normal with z >= 0, d, rms of the distances)."""
    c = xyz.mean(axis=0)
    _, s, vt = np.linalg.svd(xyz - c, full_matrices=False)
    n = vt[-1]
    if n[2] < 0:
        n = -n
    rms = float(s[-1] / np.sqrt(max(len(xyz), 1)))
    return n, float(n @ c), rms


def accumulator_shape(n_cells: int, radius: float, rho_step: float):
    """(cells, ρ bins, k_min) of an accumulator for points within ``radius`` of the origin."""
    half = int(np.ceil(radius / rho_step)) + 1
    return n_cells, 2 * half + 1, -half


def accumulator_bytes(angle_step_deg: float, radius: float, rho_step: float) -> int:
    """Memory of the ball accumulator for points within ``radius`` of their centroid (computed
    before anything is allocated)."""
    cells, n_rho, _ = accumulator_shape(len(reference.ball_cells(angle_step_deg)), radius, rho_step)
    return cells * n_rho * ACC_BYTES_PER_CELL


def patches(xy: np.ndarray, link: float) -> tuple[np.ndarray, int]:
    """Connected sets of points in plan, neighbours closer than ``link``: (label per point, count)."""
    if len(xy) == 0:
        return np.zeros(0, np.int64), 0
    pairs = cKDTree(xy).query_pairs(link, output_type="ndarray")
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(xy), len(xy)))
    n, lab = connected_components(g, directed=False)
    return lab, n


def local_normals(xyz: np.ndarray, k: int = 10, return_neighbours: bool = False):
    """Unit normal (z >= 0) of the least-squares plane through each point's ``k`` nearest
    neighbours (itself included); with ``return_neighbours``, also those neighbours' indices
    (nearest first, the point itself in column 0)."""
    k = int(min(k, len(xyz)))
    _, nb = cKDTree(xyz).query(xyz, k=k)
    nb = nb.reshape(len(xyz), k)
    q = xyz[nb] - xyz[nb].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", q, q)
    _, vec = np.linalg.eigh(cov)
    n = vec[:, :, 0]
    n = n * np.where(n[:, 2:3] < 0, -1.0, 1.0)
    return (n, nb) if return_neighbours else n


def _grow(p: np.ndarray, free: np.ndarray, seed: np.ndarray, max_distance: float, normals=None,
          cos_tol: float = -1.0, rounds: int = 4, near_of=None):
    """Refit a plane from ``seed`` points and grow it to the free points within ``max_distance``
    whose own (local) normal is within the tolerance of the plane's; returns (normal, d, inliers
    as indices into p) or None. The normal test is what tells a face from a slice across several
    faces (a horizontal band round a pyramid roof holds as many points as a face)."""
    idx = seed
    n = d = None
    for _ in range(rounds):
        if len(idx) < 3:
            return None
        n, d, _ = fit_plane(p[idx])
        near = np.abs(p[free] @ n - d) <= max_distance
        if normals is not None:
            if near_of is None:
                near &= np.abs(normals[free] @ n) >= cos_tol
            else:  # or a nearest neighbour's does
                agree = np.abs(normals @ n) >= cos_tol
                near &= agree[free] | agree[near_of[free]].any(axis=1)
        new = free[near]
        if len(new) == len(idx) and np.array_equal(new, idx):
            break
        idx = new
    return n, d, idx


def detect_planes(xyz: np.ndarray, angle_step_deg: float, rho_step: float, max_distance: float,
                  min_points: int, link: float, voter=reference.vote, max_failures: int = 200,
                  normal_tol_deg: float | None = 10.0, neighbours: int = 10, min_width: float = 0.0) -> list[Plane]:
    """Planes in one building's points (lengths in the points' units). ``normal_tol_deg``: a point
    joins a plane only when the plane of its ``neighbours`` nearest points is this close to it
    (None: distance alone, as the method). ``min_width``: narrowest face (its points' spread across
    their longest direction, as the width of a uniform strip). ``max_failures``: peaks in a row
    that explain no patch before the search ends (noisy points that fail the normal test keep
    voting; 30 ended the search before a small dormer's peak on 5 cm noise)."""
    xyz = np.asarray(xyz, np.float64)
    if len(xyz) < min_points:
        return []
    centre = xyz.mean(axis=0)
    p = xyz - centre
    normals = reference.ball_cells(angle_step_deg)
    radius = float(np.sqrt((p * p).sum(axis=1).max()))
    cells, n_rho, k_min = accumulator_shape(len(normals), radius, rho_step)
    scaled, off = reference.bin_scales(normals, rho_step, k_min)
    acc = np.zeros((cells, n_rho), np.int32)
    voter(acc, p, scaled, off, 1)
    normals_pt, nb = local_normals(p, neighbours, True) if normal_tol_deg is not None else (None, None)
    near_of = nb[:, 1:5] if nb is not None and nb.shape[1] > 1 else None
    cos_tol = np.cos(np.radians(normal_tol_deg)) if normal_tol_deg is not None else -1.0
    active = np.ones(len(p), bool)
    found: list[tuple[np.ndarray, float, np.ndarray]] = []
    # a second pass over what is left, where a point also passes the normal test when one of its
    # nearest neighbours does: on a face about as narrow as a neighbourhood (a dormer's) most
    # local planes straddle an edge and only a few agree (in the first pass this let slices of
    # neighbouring faces through on real roofs)
    for dilate in ((False, True) if near_of is not None else (False,)):
        if dilate:
            acc[:] = 0
            voter(acc, p[active], scaled, off, 1)
        failures = 0
        while active.sum() >= min_points and failures < max_failures:
            flat = int(np.argmax(acc))
            cell, k = divmod(flat, n_rho)
            if acc[cell, k] < min_points:
                break
            free = np.flatnonzero(active)
            bins = reference.bin_index(p[free], scaled[cell:cell + 1], off)[:, 0]
            grown = _grow(p, free, free[bins == k], max_distance, normals_pt, cos_tol,
                          near_of=near_of if dilate else None)
            accepted = []
            if grown is not None and len(grown[2]) >= min_points:
                n, d, idx = grown
                lab, n_lab = patches(p[idx, :2], link)
                sizes = np.bincount(lab, minlength=n_lab)
                for j in np.flatnonzero(sizes >= min_points):
                    accepted.append(idx[lab == j])
            if not accepted:
                acc[cell, k] = 0  # this hypothesis explains no patch: never try it again
                if dilate and grown is not None:
                    # nor its points (among leftovers, the neighbouring cells hold the same set)
                    voter(acc, p[grown[2]], scaled, off, -1)
                    acc[acc < 0] = 0
                    active[grown[2]] = False
                failures += 1
                continue
            failures = 0
            for part in accepted:
                n, d, _ = fit_plane(p[part])
                found.append((n, d, part))
                active[part] = False
                voter(acc, p[part], scaled, off, -1)
    planes = _assign(p, found, max_distance, link)
    # a plane left small by the nearest-plane rule, or a strip along a ridge (points of two faces
    # whose local planes lean halfway), is no face: its points go to the others
    # (a strip that bends round, a parapet's top round a flat roof, is wide overall; within
    # min_width of each point it is as narrow as it is, where a face, even a dormer's, fills
    # most of the window: 0.3-0.45 m against 1.0-1.6 m on the synthetic family)
    def is_face(idx):
        return len(idx) >= min_points and _width(p[idx]) >= min_width and _width(p[idx], min_width) >= min_width / 2

    kept = _without_strips(p, [t for t in planes if is_face(t[2])], max_distance, link)
    if len(kept) < len(planes):
        planes = _assign(p, kept, max_distance, link)
    planes = _merge(p, planes, max_distance, link)
    kept = [t for t in planes if is_face(t[2])]  # the reassignment may have given a strip more points
    if len(kept) < len(planes):
        planes = _assign(p, kept, max_distance, link)
    ambiguous = _ambiguous(p, planes, max_distance, link)
    out = []
    for (n, d, idx), amb in zip(planes, ambiguous):
        n, d, rms = fit_plane(p[idx])
        # the normal from the points within 2.5 rms that are not as near a neighbouring face (a
        # few points across the intersection tilt a small face's fit; a selection by local
        # normals instead kept a dormer face's middle strip and tilted it as much)
        keep = (np.abs(p[idx] @ n - d) <= 2.5 * rms) & ~amb
        core_pts = idx[keep]
        if len(core_pts) >= max(3, 0.6 * len(idx)):
            n, d, _ = fit_plane(p[core_pts])
            rms = float(np.sqrt(np.mean((p[idx] @ n - d) ** 2)))
        out.append(Plane(n, d + float(n @ centre), idx, rms))
    return out


def _without_strips(p, kept, max_distance, link):
    """The planes (n, d, indices) less those most of whose points lie as near another plane,
    beside that plane's points: a strip across their intersection (beside: a coplanar face
    elsewhere on the roof, cut off by another wing, is no reason). Smallest first."""
    kept = sorted(kept, key=lambda t: len(t[2]))
    plan = {}  # one k-d tree per plane's points in plan, built when first needed
    j = 0
    while j < len(kept):
        n, d, idx = kept[j]
        others = [o for i, o in enumerate(kept) if i != j]
        near = np.zeros(len(idx), bool)
        for n2, d2, idx2 in others:
            close = np.abs(p[idx] @ n2 - d2) <= max_distance
            if close.any():
                if id(idx2) not in plan:
                    plan[id(idx2)] = cKDTree(p[idx2, :2])
                close[close] = plan[id(idx2)].query(p[idx[close], :2], distance_upper_bound=link)[0] <= link
            near |= close
        if others and near.mean() > 0.5:
            del kept[j]
        else:
            j += 1
    return kept


def _assign(p, found, max_distance, link):
    """Every point to the nearest plane (within ``max_distance``) whose patch it touches in plan;
    planes left with fewer than 3 points are dropped."""
    if not found:
        return []
    best = np.full(len(p), -1)
    best_d = np.full(len(p), np.inf)
    for j, (n, d, idx) in enumerate(found):
        near = cKDTree(p[idx, :2]).query(p[:, :2], distance_upper_bound=link)[0] <= link
        dist = np.abs(p @ n - d)
        better = near & (dist <= max_distance) & (dist < best_d)
        best[better] = j
        best_d[better] = dist[better]
    out = []
    for j, (n, d, _) in enumerate(found):
        idx = np.flatnonzero(best == j)
        if len(idx) >= 3:
            out.append((n, d, idx))
    return out


def _ambiguous(p, planes, max_distance, link) -> list[np.ndarray]:
    """Per plane, which of its points lie (their foot on the plane) within ``max_distance`` of
    another plane whose points they touch in plan (within ``link``): the strip along an
    intersection that either face could hold."""
    lo = [p[idx, :2].min(axis=0) - link for _, _, idx in planes]
    hi = [p[idx, :2].max(axis=0) + link for _, _, idx in planes]
    trees: dict[int, cKDTree] = {}
    out = []
    for a, (n, d, idx) in enumerate(planes):
        amb = np.zeros(len(idx), bool)
        # measured from each point's foot on its own plane: by its own noise, a point near an
        # edge would be ambiguous when it strays towards the other face only, and dropping those
        # tilts a small face
        foot = p[idx] - (p[idx] @ n - d)[:, None] * n
        for b, (n2, d2, idx2) in enumerate(planes):
            if b == a or np.any(lo[b] > hi[a]) or np.any(lo[a] > hi[b]):
                continue
            close = np.abs(foot @ n2 - d2) <= max_distance
            if close.any():
                if b not in trees:
                    trees[b] = cKDTree(p[idx2, :2])
                close[close] = trees[b].query(p[idx[close], :2], distance_upper_bound=link)[0] <= link
                amb |= close
        out.append(amb)
    return out


def _width(xyz: np.ndarray, radius: float | None = None, samples: int = 200) -> float:
    """Width of a set of points spread over a strip: sqrt(12 x the middle principal variance);
    with ``radius``, the median of that over the points within ``radius`` (in plan) of up to
    ``samples`` of them: a local width, which a strip keeps where it bends round."""
    if len(xyz) < 3:
        return 0.0
    if radius is None:
        ev = np.linalg.eigvalsh(np.cov((xyz - xyz.mean(axis=0)).T))
        return float(np.sqrt(12.0 * max(ev[1], 0.0)))
    picks = np.unique(np.linspace(0, len(xyz) - 1, min(samples, len(xyz))).astype(np.int64))
    nbs = cKDTree(xyz[:, :2]).query_ball_point(xyz[picks, :2], radius)
    cnt = np.array([len(nb) for nb in nbs])
    flat = np.concatenate(nbs).astype(np.int64)
    starts = np.r_[0, np.cumsum(cnt)[:-1]]
    q = xyz[flat] - xyz[picks].repeat(cnt, axis=0)  # about each window's own point: no cancellation
    mean = np.add.reduceat(q, starts, axis=0) / cnt[:, None]
    second = np.add.reduceat(np.einsum("ni,nj->nij", q, q), starts, axis=0) / cnt[:, None, None]
    cov = (second - np.einsum("gi,gj->gij", mean, mean)) * (cnt / np.maximum(cnt - 1, 1))[:, None, None]
    widths = np.sqrt(12.0 * np.maximum(np.linalg.eigvalsh(cov)[:, 1], 0.0))
    widths[cnt < 3] = 0.0
    return float(np.median(widths))


def _merge(p, planes, max_distance, link, max_angle_deg: float = 3.0):
    """Merge planes of nearly the same orientation and offset whose points touch, while the
    merged set still fits one plane within ``max_distance`` (rms under half of it)."""
    cos_max = np.cos(np.radians(max_angle_deg))
    planes = list(planes)
    merged = True
    while merged:
        merged = False
        for a in range(len(planes)):
            for b in range(a + 1, len(planes)):
                na, da, ia = planes[a]
                nb, db, ib = planes[b]
                if na @ nb < cos_max:
                    continue
                if cKDTree(p[ia, :2]).query(p[ib, :2], distance_upper_bound=link)[0].min() > link:
                    continue
                both = np.r_[ia, ib]
                n, d, rms = fit_plane(p[both])
                if rms > 0.5 * max_distance or np.abs(p[both] @ n - d).max() > 2 * max_distance:
                    continue
                planes[a] = (n, d, both)
                del planes[b]
                merged = True
                break
            if merged:
                break
    return planes


def _slope_aspect_sigma(xyz: np.ndarray, normal: np.ndarray, groups: int = 20):
    """(slope, aspect, σ slope, σ aspect), radians, of a plane with ``normal`` through ``xyz``; the
    σ by a delete-a-group jackknife of the least-squares fit (points i, i + groups, ... left out in
    turn), which also counts what a textbook σ misses on a small face: a few points at its edge
    that lever it."""
    n = len(xyz)
    slope = float(np.arccos(np.clip(normal[2], -1.0, 1.0)))
    # aspect as plane_attributes: clockwise from north, the way the face looks down
    aspect = float(np.arctan2(normal[0], normal[1]))
    g = int(min(groups, n))
    q = xyz - xyz.mean(axis=0)
    lab = np.arange(n) % g
    cnt = np.bincount(lab, minlength=g).astype(float)
    sums = np.zeros((g, 3))
    np.add.at(sums, lab, q)
    raw = np.zeros((g, 3, 3))
    np.add.at(raw, lab, np.einsum("ni,nj->nij", q, q))
    keep_n = n - cnt
    keep_sum = sums.sum(axis=0) - sums
    mean = keep_sum / keep_n[:, None]
    scatter = (raw.sum(axis=0) - raw) - keep_n[:, None, None] * np.einsum("gi,gj->gij", mean, mean)
    reps = np.linalg.eigh(scatter)[1][:, :, 0]
    reps *= np.where(reps @ normal < 0, -1.0, 1.0)[:, None]
    u = np.array([np.sin(aspect), np.cos(aspect)])
    along = reps[:, :2] @ u / max(np.cos(slope), 0.05)
    across = (reps[:, :2] @ np.array([u[1], -u[0]])) / max(np.sin(slope), 1e-9)
    f = (g - 1) / g
    # a floor: points exactly on a plane (no noise) have no scatter, and weights of 1/σ² need one
    sig_s = max(float(np.sqrt(f * np.sum((along - along.mean()) ** 2))), 1e-9)
    sig_a = max(float(np.sqrt(f * np.sum((across - across.mean()) ** 2))), 1e-9)
    return slope, aspect, sig_s, sig_a


def _normal_from(slope: float, aspect: float) -> np.ndarray:
    return np.array([np.sin(slope) * np.sin(aspect), np.sin(slope) * np.cos(aspect), np.cos(slope)])


def regularise_planes(xyz: np.ndarray, planes: list[Plane], k_sigma: float = 3.0) -> tuple[list[Plane], dict]:
    """One building's faces made regular where their own points cannot tell otherwise (as CGAL's
    ``regularize_planes`` and Verdie et al. 2015 do with a fixed angle; here the tolerance is each
    face's own uncertainty, ``k_sigma`` standard errors, so a big face only moves by what its
    points allow and a small one, a dormer's, borrows the precision of the rest):

    - a face whose slope is within the tolerance of 0 is levelled;
    - aspects that agree modulo 90° with the building's best-known face's become exactly one of
      the building's four axis directions (their weighted mean);
    - slopes that agree within their joint tolerance share their weighted mean (a gable's two
      faces, a hip's four, a dormer's pair), groups merged the most alike first.

    Each changed face keeps its points; its offset and rms are refitted with the new normal.
    Returns (planes, counts of levelled faces, snapped aspects, faces in shared-slope groups)."""
    counts = {"levelled": 0, "aspects_snapped": 0, "slopes_shared": 0}
    if not planes or k_sigma <= 0:
        return planes, counts
    est = [_slope_aspect_sigma(xyz[pl.indices], pl.normal) for pl in planes]
    slope = np.array([e[0] for e in est])
    aspect = np.array([e[1] for e in est])
    sig_s = np.array([e[2] for e in est])
    sig_a = np.array([e[3] for e in est])
    flat = slope <= k_sigma * sig_s
    counts["levelled"] = int(flat.sum())
    new_slope = np.where(flat, 0.0, slope)
    new_aspect = aspect.copy()
    tilted = np.flatnonzero(~flat)
    if len(tilted):
        # the building's axes: around the face whose aspect is best known, every face that agrees
        # with it modulo 90°, weighted by its precision
        ref = tilted[np.argmin(sig_a[tilted])]

        def off90(a, b):
            return (a - b + np.pi / 4) % (np.pi / 2) - np.pi / 4

        agree = tilted[np.abs(off90(aspect[tilted], aspect[ref])) <= k_sigma * np.hypot(sig_a[tilted], sig_a[ref])]
        w = 1.0 / sig_a[agree] ** 2
        axis = aspect[ref] + float(np.sum(w * off90(aspect[agree], aspect[ref])) / w.sum())
        sig_axis = float(1.0 / np.sqrt(w.sum()))
        snap = tilted[np.abs(off90(aspect[tilted], axis)) <= k_sigma * np.hypot(sig_a[tilted], sig_axis)]
        new_aspect[snap] = aspect[snap] - off90(aspect[snap], axis)
        counts["aspects_snapped"] = int(len(snap))
        # slopes: groups merged pairwise, the most alike first, while their weighted means agree
        # (a dormer's two faces pool before either is compared with the main roof)
        groups = [[int(i)] for i in tilted]
        wsum = [1.0 / sig_s[i] ** 2 for i in tilted]
        mean = [float(slope[i]) for i in tilted]
        while len(groups) > 1:
            m, w = np.array(mean), np.array(wsum)
            z = np.abs(m[:, None] - m[None, :]) / np.sqrt(1.0 / w[:, None] + 1.0 / w[None, :])
            np.fill_diagonal(z, np.inf)
            a, b = np.unravel_index(np.argmin(z), z.shape)
            if z[a, b] > k_sigma:
                break
            mean[a] = (mean[a] * w[a] + mean[b] * w[b]) / (w[a] + w[b])
            wsum[a] = w[a] + w[b]
            groups[a] += groups[b]
            del groups[b], mean[b], wsum[b]
        for grp, m in zip(groups, mean):
            if len(grp) > 1:
                new_slope[grp] = m
                counts["slopes_shared"] += len(grp)
    out = []
    for i, pl in enumerate(planes):
        if new_slope[i] == slope[i] and new_aspect[i] == aspect[i]:
            out.append(pl)
            continue
        n = _normal_from(new_slope[i], new_aspect[i])
        dist = xyz[pl.indices] @ n
        d = float(np.mean(dist))
        out.append(Plane(n, d, pl.indices, float(np.sqrt(np.mean((dist - d) ** 2)))))
    return out, counts


def plane_attributes(normal: np.ndarray) -> tuple[float, float]:
    """(slope in degrees from horizontal, aspect in degrees clockwise from north: the direction
    the face looks down to)."""
    slope = float(np.degrees(np.arccos(np.clip(normal[2], -1.0, 1.0))))
    aspect = float(np.degrees(np.arctan2(normal[0], normal[1])) % 360.0)
    return slope, aspect


def mean_spacing_xy(xy: np.ndarray) -> float:
    """Median distance in plan from a point to its nearest neighbour."""
    if len(xy) < 2:
        return float("nan")
    d = cKDTree(xy).query(xy, k=2)[0][:, 1]
    return float(np.median(d))


@dataclass
class RoofLine:
    start: np.ndarray  # 3D end points, in the coordinates of the points given
    end: np.ndarray
    kind: str  # ridge (horizontal, convex), hip (sloped, convex), valley (concave), break (one face up, one
    # down: a mansard's or gambrel's knee), step (a height jump: a wall between a face and a lower one)
    plane_a: int  # indices into the planes given
    plane_b: int


def adjacent_pairs(xyz: np.ndarray, planes: list[Plane], link: float) -> list[tuple[int, int]]:
    """Pairs (a, b), a < b, of faces with points within ``link`` of each other in plan, in order;
    boxes that are farther apart than ``link`` are skipped before any tree is asked."""
    if len(planes) < 2:
        return []
    lo = np.array([xyz[pl.indices, :2].min(axis=0) for pl in planes])
    hi = np.array([xyz[pl.indices, :2].max(axis=0) for pl in planes])
    trees: dict[int, cKDTree] = {}
    out = []
    for a in range(len(planes)):
        for b in range(a + 1, len(planes)):
            if np.any(lo[b] > hi[a] + link) or np.any(lo[a] > hi[b] + link):
                continue
            if a not in trees:
                trees[a] = cKDTree(xyz[planes[a].indices, :2])
            if trees[a].query(xyz[planes[b].indices, :2], distance_upper_bound=link)[0].min() <= link:
                out.append((a, b))
    return out


def roof_lines(xyz: np.ndarray, planes: list[Plane], link: float, min_angle_deg: float = 5.0,
               horizontal_deg: float = 5.0, pairs=None) -> list[RoofLine]:
    """Intersections of adjacent faces (``pairs`` from ``adjacent_pairs``, computed when not
    given), clipped to where both faces have points within ``link`` of the line. Kinds: a
    horizontal convex line is a ridge, a sloped one a hip, a concave one a valley, one face up and
    one down a break."""
    if len(planes) < 2:
        return []
    if pairs is None:
        pairs = adjacent_pairs(xyz, planes, link)
    centre = xyz.mean(axis=0)
    p = xyz - centre
    out = []
    for a, b in pairs:
        na, nb = planes[a].normal, planes[b].normal
        u = np.cross(na, nb)
        if np.linalg.norm(u) < np.sin(np.radians(min_angle_deg)):
            continue  # nearly parallel: a step between them, not an intersection
        u /= np.linalg.norm(u)
        if u[0] < 0 or (u[0] == 0 and u[1] < 0):
            u = -u
        da = planes[a].d - na @ centre
        db = planes[b].d - nb @ centre
        x0 = np.linalg.lstsq(np.vstack([na, nb, u]), np.array([da, db, 0.0]), rcond=None)[0]
        spans = []
        sides = []
        for pl in (planes[a], planes[b]):
            q = p[pl.indices] - x0
            t = q @ u
            off = q - t[:, None] * u
            near = np.linalg.norm(off, axis=1) <= link
            if near.sum() < 2:
                break
            spans.append((t[near].min(), t[near].max()))
            sides.append(off[near].mean(axis=0))
        if len(spans) < 2:
            continue
        lo, hi = max(spans[0][0], spans[1][0]), min(spans[0][1], spans[1][1])
        if hi - lo < link:
            continue  # the faces meet at a corner only
        down = [s[2] < 0 for s in sides]
        if all(down):
            kind = "ridge" if abs(u[2]) < np.sin(np.radians(horizontal_deg)) else "hip"
        elif not any(down):
            kind = "valley"
        else:
            kind = "break"
        out.append(RoofLine(x0 + lo * u + centre, x0 + hi * u + centre, kind, a, b))
    return out


def step_edges(xyz: np.ndarray, planes: list[Plane], outlines: list, link: float, min_step: float,
               pairs=None, skip_pairs=frozenset()) -> list[RoofLine]:
    """Height jumps between adjacent faces that do not meet in a line (a flat roof beside a lower
    one, the terraces of a stepped roof, a sawtooth's risers): the parts of the upper face's
    outline (``outlines[i]``, a shapely polygon in plan) within ``link`` of the lower face's
    points, where the upper face's border points stand at least ``min_step`` (median) over their
    nearest neighbours on the lower one.
    Only adjacent ``pairs`` (from ``adjacent_pairs``, computed when not given) are looked at, and
    those in ``skip_pairs`` (with an intersection line) are left out. One RoofLine per straight run
    of outline (the outline's vertices keep their z on the upper plane)."""
    import shapely
    from shapely.geometry import LineString, MultiPoint

    if len(planes) < 2:
        return []
    if pairs is None:
        pairs = adjacent_pairs(xyz, planes, link)
    trees = {}
    out = []
    for a, b in pairs:
        if (a, b) in skip_pairs:
            continue
        for k in (a, b):
            if k not in trees:
                trees[k] = cKDTree(xyz[planes[k].indices, :2])
        pa, pb = xyz[planes[a].indices], xyz[planes[b].indices]
        dist_a, nn_a = trees[b].query(pa[:, :2], distance_upper_bound=link)
        near_a = dist_a <= link
        if near_a.sum() < 2:
            continue
        dist_b, nn_b = trees[a].query(pb[:, :2], distance_upper_bound=link)
        near_b = dist_b <= link
        # which face is up: each border point against its nearest neighbour on the other face
        # (faces that meet at a corner or a hip have neighbours at their own height)
        jump = np.median(np.r_[pa[near_a, 2] - pb[nn_a[near_a], 2], pa[nn_b[near_b], 2] - pb[near_b, 2]])
        if abs(jump) < min_step:
            continue
        up, low_pts = (a, pb[near_b]) if jump > 0 else (b, pa[near_a])
        if planes[up].normal[2] < 0.05:
            continue  # a wall-like face: no outline in plan to speak of
        border = outlines[up].exterior.intersection(MultiPoint(low_pts[:, :2]).buffer(link))
        pieces = [g for g in getattr(border, "geoms", [border]) if isinstance(g, LineString) and not g.is_empty]
        if not pieces:
            continue
        merged = shapely.line_merge(shapely.union_all(pieces))  # the ring's start may split a run in two
        pieces = [shapely.simplify(g, 0.5 * link) for g in getattr(merged, "geoms", [merged])]
        n, d = planes[up].normal, planes[up].d
        for g in pieces:
            if g.length < 2 * link:
                continue  # faces that touch at a corner only
            c = np.asarray(g.coords)
            for i in range(len(c) - 1):
                if np.hypot(*(c[i + 1] - c[i])) < link:
                    continue
                ends = [np.r_[q, (d - q @ n[:2]) / n[2]] for q in (c[i], c[i + 1])]
                out.append(RoofLine(ends[0], ends[1], "step", up, b if up == a else a))
    return out

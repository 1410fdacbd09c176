"""Buildings against vegetation among the non-ground points, and vegetation by height class
(the gLiDAR method's object classification, METHODS.md §2). Pure numpy/scipy.

* Local least-squares plane per point over its ``neighbours`` nearest non-ground points; the
  plane error is the RMS distance to it. Linear sets (wires, edges seen end-on) fit a plane
  trivially, so planarity also asks for a two-dimensional spread.
* Planar points grouped by proximity; groups of at least ``min_building_points`` points standing
  at least ``min_building_height`` above the terrain, holding most (``min_planar_share``) of the
  raised points in the cells they cover, are buildings; a planar set under ``max_bundle_width``
  (1.5 m) wide and over ten times as long is a bundle of conductors (two or three wires side by
  side fit planes too: 990 of real AHN4's class-14 wire points were called building) and stays
  unclassified.
  Non-planar points between them (ridges, eaves, chimneys) join a building when most of their
  neighbours are building.
* Beyond the method: points under a building's roof edge (within ``wall_reach`` in plan of a
  roof point, and not more than ``wall_above`` over it) are its facade, balconies and eaves.
  Real surveys catch walls, and data producers class them with the roof; their plane fits are
  rough (windows, ornament, the corner with the roof), so the plane rule alone left them to
  vegetation: on AHN3 Amsterdam building recall went from 0.68 to 0.92, precision 1.00 to 0.997.
* The rest is vegetation (plane error ≥ ``min_plane_error``) clustered by proximity; each cluster
  gets one class by its height above the terrain: 3 low (< 2 m), 4 medium (< 5 m), 5 high.
  Points that fit neither rule stay 1 (unclassified), as the method's "unknown".
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from toolbox.neighbourhoods import neighbourhood_covariances, symmetric3_eigenvalues

GROUND, UNCLASSIFIED, LOW, MEDIUM, HIGH, BUILDING, NOISE = 2, 1, 3, 4, 5, 6, 7


def local_planes(xyz: np.ndarray, neighbours: int):
    """Per point: RMS plane error of its neighbourhood, 2D spread (second eigenvalue share),
    and the neighbour indices. Eigen-decomposition of each neighbourhood's covariance."""
    tree = cKDTree(xyz)
    k = int(min(neighbours, len(xyz)))
    _, idx = tree.query(xyz, k=k, workers=-1)
    idx = idx.reshape(len(xyz), k)
    # closed-form eigenvalues of chunked covariances: a third of the time of eigvalsh on a
    # gathered (n, k, 3) array (198 k object points of the corridor: 1.15-1.36 -> 0.43-0.51 s)
    ev = symmetric3_eigenvalues(neighbourhood_covariances(xyz, idx))  # ascending
    plane_error = np.sqrt(np.maximum(ev[:, 0], 0))
    total = ev.sum(axis=1) + 1e-12
    spread2d = ev[:, 1] / total  # ~0 for a line, up to 0.5 for a flat patch
    return plane_error, spread2d, idx, tree


def _cell_keys(xyz: np.ndarray, cell: float) -> np.ndarray:
    ij = np.floor(xyz[:, :2] / cell).astype(np.int64)
    ij -= ij.min(axis=0)
    return ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]


def _components(xyz: np.ndarray, radius: float):
    tree = cKDTree(xyz)
    pairs = tree.query_pairs(radius, output_type="ndarray")
    n = len(xyz)
    g = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) else \
        sparse.coo_matrix((n, n))
    return connected_components(g, directed=False)[1]


def _narrow_long_sets(xyz: np.ndarray, lab: np.ndarray, counts: np.ndarray, candidate: np.ndarray,
                      max_width: float = 1.5, max_width_to_length: float = 0.1) -> np.ndarray:
    """Per component: its plan extent (the sides of the uniform rectangle with the same second
    moments) is under ``max_width`` wide and ``max_width_to_length`` of its length. Only the
    components flagged in ``candidate`` (per point) are measured."""
    n_comp = len(counts)
    out = np.zeros(n_comp, bool)
    which = np.unique(lab[candidate])
    if not len(which):
        return out
    xy = xyz[:, :2] - xyz[:, :2].mean(axis=0)
    w = np.maximum(counts, 1)
    mx, my = (np.bincount(lab, weights=xy[:, i], minlength=n_comp) / w for i in (0, 1))
    sxx = np.bincount(lab, weights=xy[:, 0] ** 2, minlength=n_comp) / w - mx * mx
    syy = np.bincount(lab, weights=xy[:, 1] ** 2, minlength=n_comp) / w - my * my
    sxy = np.bincount(lab, weights=xy[:, 0] * xy[:, 1], minlength=n_comp) / w - mx * my
    half_tr, det = 0.5 * (sxx + syy), sxx * syy - sxy * sxy
    root = np.sqrt(np.maximum(half_tr * half_tr - det, 0.0))
    width = np.sqrt(12.0 * np.maximum(half_tr - root, 0.0))
    length = np.sqrt(12.0 * np.maximum(half_tr + root, 0.0))
    out[which] = (width[which] < max_width) & (width[which] < max_width_to_length * length[which])
    return out


def classify_objects(xyz: np.ndarray, height: np.ndarray, *, neighbours: int = 12, max_plane_error: float = 0.08,
                     min_plane_error: float = 0.12, min_building_points: int = 60, min_building_height: float = 2.0,
                     link_distance: float = 1.5, vegetation_link: float = 1.5, low_max: float = 2.0,
                     medium_max: float = 5.0, min_object_height: float = 0.25,
                     min_planar_share: float = 0.6, grow_steps: int = 8, wall_reach: float = 1.0,
                     wall_above: float = 0.5, max_bundle_width: float = 1.5) -> np.ndarray:
    """ASPRS classes (1, 3, 4, 5, 6) for non-ground points ``xyz`` with heights above the terrain
    ``height`` (same units). Lengths are in the cloud's units."""
    n = len(xyz)
    out = np.full(n, UNCLASSIFIED, np.uint8)
    if n == 0:
        return out
    above = height >= min_object_height
    cls_above = np.full(int(above.sum()), UNCLASSIFIED, np.uint8)
    pts = xyz[above]
    h = height[above]
    if len(pts) >= 4:
        err, spread, idx, _ = local_planes(pts, neighbours)
        planar = (err <= max_plane_error) & (spread >= 0.05)
        building = np.zeros(len(pts), bool)
        line_set = np.zeros(len(pts), bool)
        if planar.any():
            p_idx = np.flatnonzero(planar)
            lab = _components(pts[p_idx], link_distance)
            counts = np.bincount(lab)
            hmax = np.zeros(len(counts))
            np.maximum.at(hmax, lab, h[p_idx])
            # a roof is a planar set that dominates the cells it covers; chance-planar patches on
            # crown tops share their cells with the crown's many other returns
            cell = link_distance
            key_all = _cell_keys(pts, cell)
            uniq, inv_all = np.unique(key_all, return_inverse=True)
            all_count = np.bincount(inv_all)
            comp_cell = lab.astype(np.int64) * len(uniq) + inv_all[p_idx]
            cu, cinv, ccount = np.unique(comp_cell, return_inverse=True, return_counts=True)
            cell_of = cu % len(uniq)
            share_cells = ccount / all_count[cell_of]
            comp_of = cu // len(uniq)
            share = np.bincount(comp_of, weights=share_cells * ccount, minlength=len(counts)) / np.maximum(counts, 1)
            ok = (counts[lab] >= min_building_points) & (hmax[lab] >= min_building_height) & \
                (share[lab] >= min_planar_share)
            # two or three wires side by side fit planes too: a planar set under 1.5 m wide and
            # over ten times as long is a bundle of conductors, not a roof (left unclassified)
            wires = _narrow_long_sets(pts[p_idx], lab, counts, ok, max_width=max_bundle_width)
            ok &= ~wires[lab]
            line_set[p_idx[wires[lab]]] = True
            building[p_idx[ok]] = True
            # ridges, eaves, small roof structures: most neighbours are building
            for _ in range(grow_steps):
                share = building[idx].mean(axis=1)
                grow = ~building & (share >= 0.5)
                if not grow.any():
                    break
                building |= grow
            if wall_reach > 0 and building.any() and not building.all():
                # facades: under a roof edge in plan (eaves overhang walls by up to about a
                # metre) and not above it (a crown over the roof is vegetation)
                b_i, r_i = np.flatnonzero(building), np.flatnonzero(~building)
                d, j = cKDTree(pts[b_i, :2]).query(pts[r_i, :2], k=1, distance_upper_bound=wall_reach, workers=-1)
                near = np.isfinite(d)
                near[near] = pts[r_i[near], 2] <= pts[b_i[j[near]], 2] + wall_above
                building[r_i[near]] = True
        cls_above[building] = BUILDING
        rough = (err >= min_plane_error) | ~planar
        rest = ~building & ~line_set
        if rest.any():
            # clusters of the remaining points; a cluster with a fair share of rough (non-planar)
            # points is a plant, all of it, classed by its top; others stay unknown (1)
            v_idx = np.flatnonzero(rest)
            lab = _components(pts[v_idx], vegetation_link)
            top = np.zeros(lab.max() + 1)
            np.maximum.at(top, lab, h[v_idx])
            rough_share = np.bincount(lab, weights=rough[v_idx]) / np.bincount(lab)
            is_veg = rough_share[lab] >= 0.3
            ch = top[lab]
            cls_v = np.where(ch < low_max, LOW, np.where(ch < medium_max, MEDIUM, HIGH))
            cls_above[v_idx[is_veg]] = cls_v[is_veg]
    out[above] = cls_above
    # barely raised points (grass, kerbs) that are not ground: low vegetation by the height rule
    out[~above & (height > 0)] = LOW
    return out

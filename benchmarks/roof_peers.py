"""Plane-detection peers for the roofs bench (bench extras, never runtime dependencies): open3d's
iterative RANSAC (`segment_plane`) and `detect_planar_patches`, CGAL's efficient RANSAC and region
growing. Each takes one building's points and returns a plane number per point (0: none). They
get the settings ours runs with where they have one (distance to the plane, smallest plane,
cluster distance, normal tolerance), so the comparison is of methods, not of settings."""

from __future__ import annotations

import numpy as np


def available() -> dict[str, str]:
    """Peer name -> why it cannot run ('' when it can)."""
    out = {}
    try:
        import open3d  # noqa: F401

        out["open3d"] = ""
    except Exception as exc:  # ImportError, or a missing system library (libusb)
        out["open3d"] = f"open3d not importable ({exc.__class__.__name__}: {exc}); pip install open3d"
    try:
        from CGAL import CGAL_Shape_detection  # noqa: F401

        out["cgal"] = ""
    except Exception as exc:
        out["cgal"] = f"CGAL not importable ({exc.__class__.__name__}); pip install cgal"
    try:
        import whitebox_workflows  # noqa: F401

        out["whitebox"] = ""
    except Exception as exc:
        out["whitebox"] = f"whitebox-workflows not importable ({exc.__class__.__name__}); pip install whitebox-workflows"
    return out


def _pcd(xyz):
    import open3d as o3d

    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(xyz, np.float64))
    return pcd


def open3d_ransac(xyz, distance_m, min_points, iterations=1000, seed=0):
    """Iterative `segment_plane`: the best plane's inliers out, again, until fewer than
    ``min_points`` remain on the best plane (its documented use for several planes)."""
    import open3d as o3d

    o3d.utility.random.seed(seed)
    lab = np.zeros(len(xyz), np.int32)
    left = np.arange(len(xyz))
    k = 0
    while len(left) >= max(min_points, 3):
        _, inl = _pcd(xyz[left]).segment_plane(distance_threshold=distance_m, ransac_n=3, num_iterations=iterations)
        if len(inl) < min_points:
            break
        k += 1
        lab[left[inl]] = k
        left = np.delete(left, inl)
    return lab


def open3d_patches(xyz, min_points, neighbours=10):
    """`detect_planar_patches` (Araujo & Oliveira 2020) at its defaults, on k-NN normals; a point
    goes to the first patch whose oriented box holds it."""
    import open3d as o3d

    pcd = _pcd(xyz)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(neighbours))
    boxes = pcd.detect_planar_patches(min_num_points=min_points)
    lab = np.zeros(len(xyz), np.int32)
    for k, box in enumerate(boxes, 1):
        idx = np.asarray(box.get_point_indices_within_bounding_box(pcd.points), int)
        idx = idx[lab[idx] == 0]
        lab[idx] = k
    return lab


def _point_set(xyz, neighbours):
    from CGAL import CGAL_Point_set_processing_3 as psp
    from CGAL.CGAL_Point_set_3 import Point_set_3

    ps = Point_set_3()
    ps.insert_range(np.ascontiguousarray(xyz, np.float64).ravel().tolist())
    ps.add_normal_map()
    psp.jet_estimate_normals(ps, neighbours)
    return ps


def _labels(ps, pm, n):
    return np.array([pm.get(i) for i in range(n)], np.int32) + 1  # CGAL: -1 for none


def cgal_ransac(xyz, distance_m, cluster_m, min_points, normal_tol_deg, neighbours=10):
    """CGAL's efficient RANSAC (Schnabel et al. 2007), planes only, normals by jet fitting."""
    from CGAL.CGAL_Shape_detection import efficient_RANSAC

    ps = _point_set(xyz, neighbours)
    pm = ps.add_int_map("plane_index")
    efficient_RANSAC(ps, pm, min_points=min_points, epsilon=distance_m, cluster_epsilon=cluster_m,
                     normal_threshold=float(np.cos(np.radians(normal_tol_deg))))
    return _labels(ps, pm, len(xyz))


def cgal_region_growing(xyz, distance_m, min_points, normal_tol_deg, neighbours=10):
    """CGAL's region growing on k nearest neighbours, normals by jet fitting."""
    from CGAL.CGAL_Shape_detection import region_growing

    ps = _point_set(xyz, neighbours)
    pm = ps.add_int_map("plane_index")
    region_growing(ps, pm, min_points=min_points, epsilon=distance_m,
                   normal_treshold=float(np.cos(np.radians(normal_tol_deg))), k=neighbours)
    return _labels(ps, pm, len(xyz))


_WBE = None


def whitebox_segmentation(xyz, distance_m, min_points, normal_tol_deg, radius_m=2.0):
    """whitebox-workflows' `lidar_segmentation` (local RANSAC planes grown into segments whose
    normals differ by at most ``normal_tol_deg``; segment ids come back as RGB). Its sibling
    `lidar_ransac_planes` only tells planar from non-planar points, so it cannot be scored per
    plane. Whitebox reads and writes files: the timing includes a small LAS round trip."""
    import tempfile
    from pathlib import Path

    import laspy
    import whitebox_workflows as wbw

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.las", Path(tmp) / "out.las"
        header = laspy.LasHeader(point_format=2, version="1.2")
        header.scales = [0.001] * 3
        header.offsets = xyz.min(axis=0)
        las = laspy.LasData(header)
        las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        las.write(src)
        global _WBE
        if _WBE is None:  # one environment for all calls, as a user's script would keep
            _WBE = wbw.WbEnvironment()
            _WBE.verbose = False
        _WBE.lidar.lidar_segmentation(input=str(src), output=str(dst), search_radius=radius_m,
                                     inlier_threshold=distance_m, acceptable_model_size=min_points,
                                     norm_diff_threshold=normal_tol_deg, max_planar_slope=80.0)
        out = laspy.read(dst)
        # whitebox may reorder points: match them back by their coordinates
        key_in = np.round((xyz - header.offsets) / 0.001).astype(np.int64)
        key_out = np.column_stack([out.X, out.Y, out.Z]).astype(np.int64)
        rgb = np.column_stack([out.red, out.green, out.blue]).astype(np.int64)
    colour = (rgb[:, 0] << 32) | (rgb[:, 1] << 16) | rgb[:, 2]
    _, seg = np.unique(colour, return_inverse=True)
    seg = seg.astype(np.int32) + 1
    counts = np.bincount(seg)
    seg[counts[seg] < min_points] = 0  # segments smaller than the smallest plane are no plane
    order_out = np.lexsort(key_out.T[::-1])
    order_in = np.lexsort(key_in.T[::-1])
    lab = np.zeros(len(xyz), np.int32)
    lab[order_in] = seg[order_out]
    return lab

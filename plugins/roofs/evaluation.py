"""Plane detection scores against per-point face labels (for tests and the bench)."""

from __future__ import annotations

import numpy as np


def plane_scores(truth: np.ndarray, pred: np.ndarray, min_points: int = 30, min_share: float = 0.5) -> dict:
    """A labelled face and a found plane match when they share at least ``min_share`` of the
    points of each (Awrangjeb & Fraser 2014 count planes this way). ``truth``/``pred``: a face or
    plane number per point, 0 or less for none. Faces with fewer than ``min_points`` points are
    not counted against completeness (a found plane matching one still counts as correct).
    Returns completeness, correctness, the share of the faces' points on their matched plane,
    and the counts (right_planes: planes matched to a face)."""
    truth = np.asarray(truth)
    pred = np.asarray(pred)
    faces, n_face = np.unique(truth[truth > 0], return_counts=True)
    planes, n_plane = np.unique(pred[pred > 0], return_counts=True)
    size_f = dict(zip(faces.tolist(), n_face.tolist()))
    size_p = dict(zip(planes.tolist(), n_plane.tolist()))
    both = (truth > 0) & (pred > 0)
    pairs, shared = np.unique(np.column_stack([truth[both], pred[both]]), axis=0, return_counts=True)
    matched_f, matched_p, on_right = set(), set(), 0
    for (f, p), s in zip(pairs.tolist(), shared.tolist()):
        if s >= min_share * size_f[f] and s >= min_share * size_p[p]:
            matched_f.add(f)
            matched_p.add(p)
            on_right += s
    counted = [f for f in faces.tolist() if size_f[f] >= min_points]
    found = sum(f in matched_f for f in counted)
    return {"faces": len(counted), "planes": len(planes), "right_planes": len(matched_p),
            "completeness": found / max(len(counted), 1),
            "correctness": len(matched_p) / max(len(planes), 1) if len(planes) else float(len(counted) == 0),
            "right_face_share": on_right / max(int((truth > 0).sum()), 1)}

"""Conductor scores against a synthetic corridor's truth (for tests and the bench)."""

from __future__ import annotations

import numpy as np


def conductor_hits(cond, truth: dict, max_angle_deg: float = 0.5, max_offset_m: float = 0.1) -> list[tuple[int, int]]:
    """(truth line, found line) pairs: a found conductor (``cond``: the ``conductors`` layer)
    matches a true 2D line of ``truth["conductor_lines_2d"]`` when parallel within
    ``max_angle_deg`` and within ``max_offset_m`` across it."""
    hits = []
    for k, t in enumerate(truth["conductor_lines_2d"]):
        a, b = np.array(t["a"]), np.array(t["b"])
        td = (b - a) / np.linalg.norm(b - a)
        for i, g in enumerate(cond.geometry):
            (ax, ay), (bx, by) = g.coords[0], g.coords[-1]
            d = np.array([bx - ax, by - ay]) / g.length
            if abs(d @ td) > np.cos(np.radians(max_angle_deg)) and \
                    abs((ax - a[0]) * -td[1] + (ay - a[1]) * td[0]) < max_offset_m:
                hits.append((k, i))
    return hits

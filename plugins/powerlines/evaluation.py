"""Conductor scores against a synthetic corridor's truth (for tests and the bench)."""

from __future__ import annotations

import numpy as np


def conductor_hits(cond, truth: dict, max_angle_deg: float = 0.5, max_offset_m: float = 0.1) -> list[tuple[int, int]]:
    """(truth line, found line) pairs: a found conductor (``cond``: the ``conductors`` layer)
    matches a true 2D line of ``truth["conductor_lines_2d"]`` when parallel within
    ``max_angle_deg`` and within ``max_offset_m`` across it or across its bundle's centre line
    (sub-conductors closer in plan than the Hough's band come out as one conductor per phase)."""
    hits = []
    for k, t in enumerate(truth["conductor_lines_2d"]):
        a, b = np.array(t["a"]), np.array(t["b"])
        td = (b - a) / np.linalg.norm(b - a)
        to_centre = t.get("bundle_offset_m", t["offset_m"]) - t["offset_m"]
        for i, g in enumerate(cond.geometry):
            (ax, ay), (bx, by) = g.coords[0], g.coords[-1]
            d = np.array([bx - ax, by - ay]) / g.length
            off = (ax - a[0]) * -td[1] + (ay - a[1]) * td[0]
            if abs(d @ td) > np.cos(np.radians(max_angle_deg)) and \
                    min(abs(off), abs(off - to_centre)) < max_offset_m:
                hits.append((k, i))
    return hits


def crossing_errors(found_xy: np.ndarray, truth: dict) -> list[float]:
    """Per true crossing, the distance to the nearest found crossing (``found_xy``: (n, 2)),
    measured to the crossing of the two lines or of their bundles' centre lines, whichever is
    nearer."""
    from shapely.geometry import LineString

    found_xy = np.asarray(found_xy, float).reshape(-1, 2)
    lines = truth["conductor_lines_2d"]

    def centre(t):
        a, b = np.array(t["a"]), np.array(t["b"])
        td = (b - a) / np.linalg.norm(b - a)
        shift = (t.get("bundle_offset_m", t["offset_m"]) - t["offset_m"]) * np.array([-td[1], td[0]])
        return LineString([a + shift, b + shift])

    out = []
    for c in truth["crossings"]:
        places = [(c["x"], c["y"])]
        p = centre(lines[c["lines"][0]]).intersection(centre(lines[c["lines"][1]]))
        if not p.is_empty and p.geom_type == "Point":
            places.append((p.x, p.y))
        out.append(min((float(np.min(np.hypot(found_xy[:, 0] - x, found_xy[:, 1] - y))) for x, y in places),
                       default=np.inf) if len(found_xy) else np.inf)
    return out


def false_crossings(found_xy: np.ndarray, truth: dict, max_m: float = 1.0) -> int:
    """How many found crossings (``found_xy``: (n, 2)) lie farther than ``max_m`` from every true
    crossing (at either of the places ``crossing_errors`` measures to): crossings of a false
    line, or plan junctions of lines that do not cross."""
    found_xy = np.asarray(found_xy, float).reshape(-1, 2)
    if not len(found_xy):
        return 0
    near = np.zeros(len(found_xy), bool)
    for k in range(len(truth["crossings"])):
        one = dict(truth, crossings=[truth["crossings"][k]])
        near |= np.array([crossing_errors(f[None, :], one)[0] <= max_m for f in found_xy])
    return int((~near).sum())

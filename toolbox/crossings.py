"""Crossings of conductor lines in plan (Grigillo et al. 2015, §5; METHODS.md §1): pairwise
intersections of fitted lines confirmed by their validated segments or extents. Plan geometry
that algorithm plugins share (the Hough's lines, the power lines' final conductors); it knows no
algorithm."""

from __future__ import annotations

import numpy as np

def intersect(p1, d1, p2, d2):
    """Intersection of two infinite lines (point, direction); None when (nearly) parallel."""
    cross = d1[0] * d2[1] - d1[1] * d2[0]
    if abs(cross) < np.sin(np.radians(2.0)):
        return None
    diff = np.asarray(p2) - np.asarray(p1)
    s = (diff[0] * d2[1] - diff[1] * d2[0]) / cross
    return np.asarray(p1) + s * np.asarray(d1)


def crossings(lines, segments, extend_m: float = 5.0, tolerance_m: float = 1.0, merge_m: float = 1.0,
              excluded=None):
    """Crossings of conductor lines (the method's §5): pairwise intersections of the fitted lines,
    kept where some pair of validated segments (each extended by ``extend_m``) also intersects
    within ``tolerance_m``; where several lines meet (every pair of them crossing within ``merge_m``)
    their crossings are averaged.

    ``lines``: [(anchor, direction)], ``segments``: per line a list of (a, b). ``excluded``
    (optional), ``excluded(i, j, point) -> bool``: an intersection of lines i and j the caller's
    domain rules out (the power lines': past a line's end at a support).
    Returns a list of dicts (x, y, n_lines, angle_deg, lines).
    """
    found = []
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            p = intersect(lines[i][0], lines[i][1], lines[j][0], lines[j][1])
            if p is None:
                continue
            if excluded is not None and excluded(i, j, p):
                continue
            ok = False
            for a1, b1 in segments[i]:
                d1 = (b1 - a1) / max(np.linalg.norm(b1 - a1), 1e-9)
                a1e, b1e = a1 - extend_m * d1, b1 + extend_m * d1
                for a2, b2 in segments[j]:
                    d2 = (b2 - a2) / max(np.linalg.norm(b2 - a2), 1e-9)
                    a2e, b2e = a2 - extend_m * d2, b2 + extend_m * d2
                    q = _segment_intersection(a1e, b1e, a2e, b2e)
                    if q is not None and np.linalg.norm(q - p) <= tolerance_m:
                        ok = True
                        break
                if ok:
                    break
            if ok:
                cosang = abs(float(np.dot(lines[i][1], lines[j][1])))
                found.append((p, {i, j}, float(np.degrees(np.arccos(min(cosang, 1.0))))))
    # where several lines meet: the mean. Lines meet at one point when each pair of them crosses
    # there; crossings of one line with parallel lines side by side (a ribbon of phases) stay apart
    at = {frozenset(f[1]): f[0] for f in found}

    def meet(lines_, point):
        ids = sorted(lines_)
        return all(frozenset((u, v)) in at and np.linalg.norm(at[frozenset((u, v))] - point) <= merge_m
                   for k, u in enumerate(ids) for v in ids[k + 1:])

    merged = []
    used = [False] * len(found)
    for a in range(len(found)):
        if used[a]:
            continue
        group = [a]
        used[a] = True
        members = set(found[a][1])
        for b in range(a + 1, len(found)):
            if not used[b] and np.linalg.norm(found[b][0] - found[a][0]) <= merge_m and \
                    meet(members | found[b][1], found[a][0]):
                group.append(b)
                members |= found[b][1]
                used[b] = True
        pts = np.array([found[g][0] for g in group])
        ids = set().union(*[found[g][1] for g in group])
        merged.append({"x": float(pts[:, 0].mean()), "y": float(pts[:, 1].mean()), "n_lines": len(ids),
                       "angle_deg": float(min(found[g][2] for g in group)), "lines": sorted(ids)})
    return merged


def _segment_intersection(a1, b1, a2, b2):
    d1, d2 = b1 - a1, b2 - a2
    cross = d1[0] * d2[1] - d1[1] * d2[0]
    if abs(cross) < 1e-12:
        return None
    diff = a2 - a1
    s = (diff[0] * d2[1] - diff[1] * d2[0]) / cross
    u = (diff[0] * d1[1] - diff[1] * d1[0]) / cross
    if 0 <= s <= 1 and 0 <= u <= 1:
        return a1 + s * d1
    return None

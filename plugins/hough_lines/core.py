"""2D Hough line detection for power-line conductors (Grigillo, Ozvaldič, Vrečko, Kosmatin Fras
2015, Geodetski vestnik 59(2) 246-261; METHODS.md §1). Pure functions on numpy arrays; the
accumulator is pluggable: ``kernels.TaichiAccumulator`` or its numpy twin ``reference.NumpyAccumulator``.

Normal form x·cosθ + y·sinθ = ρ, θ ∈ [-90°, 90°) in ``theta_step_deg`` steps, ρ rounded to
``rho_step_m``. Peaks are taken one at a time (no local-maximum search): the largest cell, its
inverse-Hough points validated by a run of consecutive points with every gap < V_max spanning at
least S_min, then the votes of every point within ±``band_m`` of the line subtracted, until the
largest cell has fewer than ``min_votes`` votes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .reference import bin_index, bin_scales


@dataclass
class HoughLine:
    rho: float  # of the peak, in the tile's local frame
    theta_deg: float
    votes: int
    members: np.ndarray  # indices (into the input points) of the band used for the fit
    runs: list = field(default_factory=list)  # validated runs: (t_start, t_end) along the line
    anchor: np.ndarray | None = None  # SVD fit: a point on the line (local frame)
    direction: np.ndarray | None = None  # unit vector
    rms: float = 0.0
    t_range: tuple = (0.0, 0.0)  # extent of the fitted points along the line
    v_max: float = 0.0  # the V_max its runs were validated with


class AccumulatorTooLarge(ValueError):
    pass


def accumulator_shape(x, y, rho_step: float, theta_step_deg: float):
    """(θ values, first ρ bin, number of ρ bins). The ρ range is the method's: from the smallest
    to the largest ρ any point takes at any θ in [-90°, 90°] (a point right of the origin spans
    [-|y|, r], one left of it [-r, |y|]); for a tile shifted to its minimum x, y that is
    [-max y, max r], about 15 % narrower than ±max r."""
    thetas = np.deg2rad(np.arange(-90.0, 90.0 - 1e-9, theta_step_deg))
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    r = np.hypot(x, y)
    right = x >= 0
    rho_lo = float(np.min(np.where(right, -np.abs(y), -r))) if len(r) else 0.0
    rho_hi = float(np.max(np.where(right, r, np.abs(y)))) if len(r) else 0.0
    k_min = int(np.floor(rho_lo / rho_step + 0.5)) - 1
    k_max = int(np.floor(rho_hi / rho_step + 0.5)) + 1
    return thetas, k_min, k_max - k_min + 1


def runs_along(t: np.ndarray, max_gap: float, min_length: float):
    """Runs of sorted positions with every gap < ``max_gap`` spanning ≥ ``min_length``."""
    if len(t) < 2:
        return []
    t = np.sort(t)
    breaks = np.flatnonzero(np.diff(t) >= max_gap)
    # (plain lists: this runs for every peak and line, on a few hundred points)
    firsts = [float(t[0])] + t[breaks + 1].tolist()
    lasts = t[breaks].tolist() + [float(t[-1])]
    return [(a, b) for a, b in zip(firsts, lasts) if b - a >= min_length]


def principal_axis(centred: np.ndarray) -> np.ndarray:
    """Unit vector of the largest variance of centred 2D points: the first right singular vector
    of the SVD line fit, from the 2x2 scatter matrix in closed form."""
    sxx, syy = float(centred[:, 0] @ centred[:, 0]), float(centred[:, 1] @ centred[:, 1])
    sxy = float(centred[:, 0] @ centred[:, 1])
    a = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    return np.array([np.cos(a), np.sin(a)])


def line_v_max(t: np.ndarray, v_max_m: float, s_min_m: float, spacings: float) -> float:
    """V_max for the points at positions ``t`` along one line: the method's ``v_max_m``, or with
    ``spacings`` > 0 that many median gaps between them where larger, up to ``s_min_m`` / 2 (so that
    a run of S_min holds three points at least)."""
    if spacings <= 0 or len(t) < 3:
        return v_max_m
    gap = float(np.median(np.diff(np.sort(t))))
    return float(min(max(v_max_m, spacings * gap), max(v_max_m, s_min_m / 2)))


def isolated_points(pts: np.ndarray, max_gap: float) -> np.ndarray:
    """Points with no other point closer than ``max_gap`` (bool per point). Along a line most
    points have a neighbour next to them in the order along the principal axis, which settles
    them without a spatial index; the rest are checked against a k-d tree."""
    n = len(pts)
    if n < 2:
        return np.ones(n, bool)
    order = np.argsort(pts @ principal_axis(pts - pts.mean(axis=0)))
    near = np.hypot(*np.diff(pts[order], axis=0).T) < max_gap  # consecutive along the axis
    settled = np.zeros(n, bool)
    settled[order[1:][near]] = True
    settled[order[:-1][near]] = True
    rest = np.flatnonzero(~settled)
    if len(rest):
        from scipy.spatial import cKDTree

        d, _ = cKDTree(pts).query(pts[rest], k=2)
        settled[rest] = d[:, 1] < max_gap
    return ~settled


def fit_line(px, py, max_gap: float):
    """The method's SVD line fit (its first singular vector, in closed form) on centred points,
    leaving out isolated ones (no neighbour within max_gap). Returns (centre, direction, rms)."""
    pts = np.column_stack([px, py])
    if len(pts) >= 3:
        keep = ~isolated_points(pts, max_gap)
        if keep.sum() >= 2:
            pts = pts[keep]
    c = pts.mean(axis=0)
    direction = principal_axis(pts - c)
    if direction[0] > 0 or (direction[0] == 0 and direction[1] > 0):
        direction = -direction  # one orientation per line (westward), whatever the solver's sign
    normal = np.array([-direction[1], direction[0]])
    resid = (pts - c) @ normal
    return c, direction, float(np.sqrt(np.mean(resid ** 2))) if len(resid) else 0.0


def detect_lines(x, y, new_accumulator, *, theta_step_deg: float = 0.1, rho_step_m: float = 0.1, band_m: float = 0.4,
                 min_votes: int = 15, s_min_m: float = 8.0, v_max_m: float = 2.5, max_lines: int = 500,
                 max_accumulator_bytes: int = 2 << 30, fit_points: str = "band",
                 v_max_spacings: float = 0.0) -> list[HoughLine]:
    """Lines in points (x, y) of one tile, already shifted to a local origin (numerical range).

    ``new_accumulator(cos_t, sin_t, k_min, inv_drho, n_rho, extent=(x_lo, x_hi, y_lo, y_hi))``
    makes the accumulator (see ``reference.NumpyAccumulator`` for its methods); ``extent`` is
    the box of the points, the only ones voted.
    ``fit_points``: "inverse" refits each line on its inverse-Hough points (the paper's choice,
    quantised to the ρ bin), "band" on the points within ±band_m (sharper).
    ``v_max_spacings`` > 0: a peak validated by the method has its runs taken with a V_max of at
    least that many times the median gap between its inverse-Hough points, up to S_min / 2 (a
    sparse wire among dense ones: an earth wire over a stack seen from the street, validated in
    stretches); 0: the method's fixed V_max.
    """
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    if len(x) < 2:
        return []
    thetas, k_min, rows = accumulator_shape(x, y, rho_step_m, theta_step_deg)
    nbytes = rows * len(thetas) * 4
    if nbytes > max_accumulator_bytes:
        raise AccumulatorTooLarge(
            f"a {rows} x {len(thetas)} accumulator needs {nbytes / 2**30:.1f} GiB "
            f"(limit {max_accumulator_bytes / 2**30:.1f} GiB)")
    cos_t, sin_t = np.cos(thetas), np.sin(thetas)
    inv = 1.0 / rho_step_m
    with new_accumulator(cos_t, sin_t, k_min, inv, rows,
                         extent=(float(x.min()), float(x.max()), float(y.min()), float(y.max()))) as acc:
        acc.vote(x, y, 1)
        return _extract_peaks(x, y, acc, thetas, cos_t, sin_t, k_min, rho_step_m, band_m=band_m, min_votes=min_votes, s_min_m=s_min_m, v_max_m=v_max_m,
                              max_lines=max_lines, fit_points=fit_points, v_max_spacings=v_max_spacings)


def _extract_peaks(x, y, acc, thetas, cos_t, sin_t, k_min, rho_step_m, *, band_m, min_votes, s_min_m,
                   v_max_m, max_lines, fit_points, v_max_spacings: float = 0.0) -> list[HoughLine]:
    """The method's iterative peak extraction: take the largest cell, validate its inverse-Hough
    points, subtract the band's votes, until the largest cell is below ``min_votes``."""
    bin_cs, bin_ss, bin_off = bin_scales(cos_t, sin_t, k_min, 1.0 / rho_step_m)
    x32, y32 = x.astype(np.float32), y.astype(np.float32)  # the accumulator's precision, once per tile
    active = np.ones(len(x), bool)
    lines: list[HoughLine] = []
    for _ in range(max_lines * 4):
        c, r, votes = acc.peak()  # c: θ index, r: ρ bin
        if votes < min_votes:
            break
        rho_p = (r + k_min) * rho_step_m
        rho_pts = x * cos_t[c] + y * sin_t[c]
        k_pts = bin_index(x32, y32, bin_cs[c], bin_ss[c], bin_off)  # as the accumulator bins them
        inverse = np.flatnonzero(active & (k_pts == r))
        band = np.flatnonzero(active & (np.abs(rho_pts - rho_p) <= band_m))
        # along-line positions: t = -x sinθ + y cosθ
        t_inv = -x[inverse] * sin_t[c] + y[inverse] * cos_t[c]
        runs = runs_along(t_inv, v_max_m, s_min_m)
        v_line = v_max_m
        if runs and v_max_spacings:
            # a line the method validates runs on at its own points' spacing: a sparse wire's
            # stretches join across its longer gaps
            v_line = line_v_max(t_inv, v_max_m, s_min_m, v_max_spacings)
            runs = runs_along(t_inv, v_line, s_min_m)
        if runs:
            members = band if fit_points == "band" else inverse
            # only the points of the validated runs are the conductor
            t_mem = -x[members] * sin_t[c] + y[members] * cos_t[c]
            on_run = np.zeros(len(members), bool)
            for a, b in runs:
                on_run |= (t_mem >= a - v_line) & (t_mem <= b + v_line)
            members = members[on_run]
            anchor, direction, rms = fit_line(x[members], y[members], v_line)
            tt = (np.column_stack([x[members], y[members]]) - anchor) @ direction
            lines.append(HoughLine(rho_p, float(np.degrees(thetas[c])), votes, members, runs, anchor, direction, rms,
                                   (float(tt.min()), float(tt.max())), v_line))
        # subtract the band's votes (also for a rejected peak, so that the next one comes up)
        if len(band) == 0:
            acc.clear_cell(c, r)  # numerically isolated cell: clear it
            continue
        acc.vote(x[band], y[band], -1, floor=min_votes)  # rows below min_votes are done with
        active[band] = False
        if len(lines) >= max_lines:
            break
    return lines


def segments_of(line: HoughLine, x, y, v_max_m: float, s_min_m: float):
    """Validated runs of a fitted line: (start xy, end xy) pairs along its fitted direction."""
    pts = np.column_stack([x[line.members], y[line.members]])
    t = (pts - line.anchor) @ line.direction
    return [(line.anchor + a * line.direction, line.anchor + b * line.direction)
            for a, b in runs_along(t, v_max_m, s_min_m)]


# ------------------------------------------------------------------------------------------
# tiles (the method's §4) and merging across them
# ------------------------------------------------------------------------------------------

@dataclass
class Conductor:
    anchor: np.ndarray  # world coordinates
    direction: np.ndarray
    members: np.ndarray  # indices into the input points
    votes: int
    rms: float
    t_range: tuple
    segments: list  # [(a, b)] world coordinates
    v_max: float = 0.0  # the V_max its runs were validated with


def tiles(x, y, size: float, overlap: float):
    """(x0, y0, mask) of square tiles of ``size`` overlapping by ``overlap``, starting at multiples
    of ``size - overlap``: a tile holds the same points whatever the extent of the input, so a
    survey cut into pieces finds what the whole finds."""
    step = size - overlap
    x_start, y_start = np.floor(x.min() / step) * step, np.floor(y.min() / step) * step
    xs = np.arange(x_start, max(x.max() - overlap, x_start) + 1e-9, step)
    ys = np.arange(y_start, max(y.max() - overlap, y_start) + 1e-9, step)
    for x0 in xs:
        mx = (x >= x0) & (x < x0 + size)
        if not mx.any():
            continue
        for y0 in ys:
            m = mx & (y >= y0) & (y < y0 + size)
            if m.sum() >= 2:
                yield float(x0), float(y0), m


def detect_tiled(x, y, new_accumulator, *, tile_size_m: float = 100.0, overlap_m: float = 10.0,
                 merge_angle_deg: float = 1.0, merge_offset_m: float = 0.25, merge_gap_m: float = 25.0, progress=None,
                 **kw) -> list[Conductor]:
    """Hough lines per tile (each shifted to its minimum x, y), shifted back and merged: lines that
    are collinear (angle < merge_angle_deg, offset < merge_offset_m) and overlap or come within
    merge_gap_m of each other along their direction (tile overlaps, the gap at a pylon) become one
    conductor, refitted on all its points; a merged group whose points spread across its refit by
    more than merge_offset_m is split where its pieces' offsets part."""
    found = []
    tile_list = list(tiles(x, y, tile_size_m, overlap_m)) if tile_size_m > 0 else [(float(x.min()), float(y.min()), np.ones(len(x), bool))]
    it = progress(tile_list) if progress else tile_list
    v_max = kw.get("v_max_m", 2.5)
    s_min = kw.get("s_min_m", 8.0)
    for x0, y0, m in it:
        idx = np.flatnonzero(m)
        for L in detect_lines(x[idx] - x0, y[idx] - y0, new_accumulator, **kw):
            found.append(Conductor(L.anchor + (x0, y0), L.direction, idx[L.members], L.votes, L.rms,
                                   L.t_range, [], L.v_max))
    # merge collinear pieces (union-find over pairs)
    parent = list(range(len(found)))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    cos_lim = np.cos(np.radians(merge_angle_deg))
    # the angle and offset tests for all pairs at once (a few thousand pairs per km of corridor)
    d = np.array([f.direction for f in found]).reshape(-1, 2)
    p = np.array([f.anchor for f in found]).reshape(-1, 2)
    normal = np.column_stack([-d[:, 1], d[:, 0]])
    offset = np.abs(np.einsum("ik,ijk->ij", normal, p[None, :, :] - p[:, None, :]))  # of j from line i
    close = (np.abs(d @ d.T) >= cos_lim) & (offset <= merge_offset_m)
    for i, j in zip(*np.nonzero(np.triu(close, k=1))):
        # they must overlap or nearly touch along the line (tile overlap, a pylon's gap)
        if _apart_along(found[i], found[j], merge_gap_m):
            continue
        parent[root(j)] = root(i)
    groups: dict[int, list[int]] = {}
    for i in range(len(found)):
        groups.setdefault(root(i), []).append(i)
    # pairwise merging chains: a slightly slanted piece can join two wires side by side into one
    # group, whose refit then lies between them. A group whose points spread across its refit
    # line by more than merge_offset_m is split where its pieces' offsets part (two-means)
    todo, final = list(groups.values()), []
    while todo:
        g = todo.pop()
        if len(g) < 2:
            final.append(g)
            continue
        members = np.unique(np.concatenate([found[i].members for i in g]))
        anchor, direction, rms = fit_line(x[members], y[members], _group_v_max(found, g, v_max))
        if rms <= merge_offset_m:
            final.append(g)
            continue
        nrm = np.array([-direction[1], direction[0]])
        offs = np.array([float(np.median((np.column_stack([x[found[i].members], y[found[i].members]]) - anchor) @ nrm))
                         for i in g])
        order = np.argsort(offs)
        gaps = np.diff(offs[order])
        cut = int(np.argmax(gaps))
        if gaps[cut] <= merge_offset_m:
            final.append(g)
            continue
        todo += [[g[k] for k in order[:cut + 1]], [g[k] for k in order[cut + 1:]]]
    out = [c for c in (_refit(x, y, np.unique(np.concatenate([found[i].members for i in g])),
                              int(sum(found[i].votes for i in g)), _group_v_max(found, g, v_max), s_min)
                       for g in final) if c is not None]
    return merge_pieces_on_lines(out, x, y, v_max, s_min, merge_angle_deg, merge_offset_m, merge_gap_m)


def _group_v_max(found, group, v_max: float) -> float:
    """The V_max of merged pieces: the widest any of them was validated with."""
    return max([v_max] + [found[i].v_max for i in group])


def _apart_along(a, b, gap_m: float) -> bool:
    """Whether conductor ``b``'s extent, projected on ``a``'s line, stays more than ``gap_m``
    from ``a``'s extent."""
    ends = sorted(float(np.dot(b.anchor + t * b.direction - a.anchor, a.direction)) for t in b.t_range)
    return ends[0] > a.t_range[1] + gap_m or ends[1] < a.t_range[0] - gap_m


def _refit(x, y, members, votes: int, v_max: float, s_min: float):
    """A Conductor refitted on the points ``members`` (None: no validated run)."""
    anchor, direction, rms = fit_line(x[members], y[members], v_max)
    t = (np.column_stack([x[members], y[members]]) - anchor) @ direction
    runs = runs_along(t, v_max, s_min)
    segs = [(anchor + a * direction, anchor + b * direction) for a, b in runs]
    return Conductor(anchor, direction, members, votes, rms, (float(t.min()), float(t.max())), segs,
                     v_max) if runs else None


def merge_pieces_on_lines(lines, x, y, v_max: float, s_min: float, merge_angle_deg: float = 1.0,
                          merge_offset_m: float = 0.25, merge_gap_m: float = 25.0) -> list:
    """Conductors with a shorter one merged into a longer one when within ``merge_angle_deg``
    of it, both its ends within ``merge_offset_m`` of the longer line and within ``merge_gap_m``
    of its extent along it, and the two refitted together stay within ``merge_offset_m`` rms: a
    short piece fitted a few tenths of a degree off (a sparse stretch of a mobile scan) whose
    anchor sits too far along for the pairwise test of detect_tiled."""
    out = list(lines)
    cos_lim = np.cos(np.radians(merge_angle_deg))
    merged = True
    while merged:
        merged = False
        for i, j in ((i, j) for i in range(len(out)) for j in range(len(out)) if i != j):
            a, b = out[i], out[j]  # b: the shorter
            if np.ptp(b.t_range) > np.ptp(a.t_range) or abs(float(a.direction @ b.direction)) < cos_lim:
                continue
            nrm = np.array([-a.direction[1], a.direction[0]])
            if any(abs(float((b.anchor + t * b.direction - a.anchor) @ nrm)) > merge_offset_m for t in b.t_range) or \
                    _apart_along(a, b, merge_gap_m):
                continue
            both = _refit(x, y, np.unique(np.r_[a.members, b.members]), a.votes + b.votes,
                          max(v_max, a.v_max, b.v_max), s_min)
            if both is not None and both.rms <= merge_offset_m:
                out = [c for k, c in enumerate(out) if k not in (i, j)] + [both]
                merged = True
                break
    return out

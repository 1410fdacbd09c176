"""Bundles and stacks: a piece of several wires split by height across the line, pieces chained
into wires."""

from __future__ import annotations

import numpy as np

from ..rules import FIT_SEARCH
from .catenaries import SIDE_BY_SIDE_MIN_GAP_M, WIRE_LATERAL_RMS_M, line_fit


def split_bundles(s, off, lab, min_points: int, z=None, min_gap: float = SIDE_BY_SIDE_MIN_GAP_M,
                  depth: int = FIT_SEARCH.bundle_depth, window_m: float = FIT_SEARCH.bundle_window_m,
                  max_sd: float = WIRE_LATERAL_RMS_M) -> np.ndarray:
    """Sub-conductors of a bundle hang side by side (2), in a triangle (3) or a square (4),
    closer than their scatter can keep apart in a neighbour graph: split a piece in two where
    its residual across the line (after a straight trend along it) or, given ``z``, in height
    (after a running mean over ``window_m`` along it: a span's sag is smooth at that scale) is
    clearly bimodal (two-means, centres >= ``min_gap`` apart and >= 4 pooled standard
    deviations, the pooled spread no wider than a wire's, ``max_sd``: layers of a crown are
    wider); of the two directions the clearer split, repeated ``depth`` times (a square bundle
    needs two). Where no such cut exists, the residual across the line about the wires' own
    trend (``_across_wires``), then a cut into one group per wire (a ribbon of 3-4 wires), about
    the straight trend and then about the wires' own."""
    def halves(r):
        split = two_means_1d(r, min_points)
        return None if split is None else split[0].astype(np.int64)

    def clean_halves(r, split=None):
        return _clean_cut(two_means_1d(r, min_points) if split is None else split, min_gap, max_sd)

    def per_wire(r):
        found = _clean_groups(r, min_points, min_gap, max_sd)
        return None if found is None else found[1]

    lab = lab.copy()
    for _ in range(depth):
        nxt = lab.max() + 1
        # only pieces big enough to split (a graph of scattered points has hundreds of tiny ones)
        for k in np.flatnonzero(np.bincount(lab) >= 2 * min_points):
            m = np.flatnonzero(lab == k)
            slope, icpt = line_fit(s[m], off[m])
            straight = off[m] - slope * s[m] - icpt
            across = two_means_1d(straight, min_points)
            found = [clean_halves(straight, across)]
            if z is not None:
                found.append(clean_halves(_height_residual(s[m], z[m], window_m)))
            found = [f for f in found if f is not None]
            best = max(found, key=lambda f: f[0]) if found else None  # (clarity, group of each point)
            # a straight trend fitted to a mixture leans towards whichever wire has more points at
            # each end; a wire's own trend does not (tried only where the straight one finds no
            # clean cut but two groups min_gap apart: a lone wire's halves lie closer)
            apart = across is not None and across[2] - across[1] >= 0.5 * min_gap
            own = straight
            if best is None and apart:
                own = _across_wires(s[m], off[m], halves, 0.5 * min_gap, start=straight)
                best = clean_halves(own)
            if best is None:
                # a ribbon of 3-4 wires side by side: no cut in two is clean (one side holds two
                # wires), a cut into one group per wire is
                best = _clean_groups(straight, min_points, min_gap, max_sd)
            if best is None and own is not straight and _clean_groups(own, min_points, min_gap, max_sd) is not None:
                best = _clean_groups(_across_wires(s[m], off[m], per_wire, 0.5 * min_gap, start=own),
                                     min_points, min_gap, max_sd)
            if best is None and apart and np.ptp(s[m]) >= 2 * WINDOWED_SPLIT_M:
                # the phases' offsets about any straight trend move together along a long piece
                # (0.2-0.3 m over 373 m on ribbon04_d5 seed 8): grouped window by window, linked
                groups = windowed_groups(s[m], off[m], min_points, min_gap, max_sd, WINDOWED_SPLIT_M)
                best = None if groups is None else (0.0, groups)
            if best is not None:
                groups = best[1]
                for g in range(1, groups.max() + 1):
                    lab[m[groups == g]] = nxt
                    nxt += 1
    return lab


def _clean_cut(split, min_gap: float, max_sd: float):
    """A two-means ``split`` (side, centres, pooled sd) as a clean cut: centres ``min_gap`` and 4
    pooled standard deviations apart, that spread no wider than ``max_sd``: (clarity, group of
    each value), or None."""
    if split is None:
        return None
    side, c0, c1, sd = split
    if c1 - c0 >= max(min_gap, 4 * sd) and sd <= max_sd:
        return (c1 - c0) / max(sd, 1e-9), side.astype(np.int64)
    return None


WINDOWED_SPLIT_M = 50.0


def windowed_groups(s, off, min_points: int, min_gap: float, max_sd: float, window_m: float):
    """One group per wire of a long piece whose wires move together across its line: in each
    window of about ``window_m`` along it, the offsets about the window's own straight trend cut
    cleanly (in two, or one group per wire, or one wire alone); a window's groups are linked to
    the next window's where their own trends meet at the window border within half of
    ``min_gap``. The groups (0..) of the points, or None where a window has no clean cut or the
    links are not one to one."""
    lo, hi = float(s.min()), float(s.max())
    n_win = int(np.ceil((hi - lo) / window_m))
    if n_win < 2:
        return None
    edges = lo + (hi - lo) * np.arange(n_win + 1) / n_win
    win = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, n_win - 1)
    trends, members = [], []
    for w in range(n_win):
        i = np.flatnonzero(win == w)
        if len(i) < min_points:
            return None
        slope, icpt = line_fit(s[i], off[i])
        r = off[i] - slope * s[i] - icpt
        split = two_means_1d(r, min_points)
        if split is not None and split[2] - split[1] < 0.5 * min_gap:
            g = np.zeros(len(i), np.int64)  # one wire
        else:
            found = _clean_cut(split, min_gap, max_sd) or _clean_groups(r, min_points, min_gap, max_sd)
            if found is None:
                return None
            g = found[1]
        trends.append([line_fit(s[i[g == k]], off[i[g == k]]) for k in range(g.max() + 1)])
        members.append([i[g == k] for k in range(g.max() + 1)])
    label = [list(range(len(members[0])))]
    nxt = len(members[0])
    for w in range(1, n_win):
        b = edges[w]
        prev = np.array([t[0] * b + t[1] for t in trends[w - 1]])
        mine = []
        for t in trends[w]:
            d = np.abs(prev - (t[0] * b + t[1]))
            k = int(np.argmin(d))
            mine.append(label[w - 1][k] if d[k] <= 0.5 * min_gap else -1)
        linked = [x for x in mine if x >= 0]
        if len(linked) != len(set(linked)):
            return None
        for j, x in enumerate(mine):
            if x < 0:
                mine[j] = nxt
                nxt += 1
        label.append(mine)
    if nxt < 2:
        return None
    out = np.zeros(len(s), np.int64)
    for w in range(n_win):
        for k, idx in enumerate(members[w]):
            out[idx] = label[w][k]
    return out


def _across_wires(s, off, grouping, max_drift_m: float, start=None, rounds: int = FIT_SEARCH.bundle_rounds) -> np.ndarray:
    """Offsets across a line less the trend of the wires in them: the wires of a piece run
    parallel, and a trend fitted to all its points together tilts towards whichever wire has more
    points at each end (a Hough line drawn across two phases holds a third one's points past the
    end of that phase's own line). Starting from one straight trend (or the residuals ``start``),
    ``grouping`` (residuals -> group of each point, or None) groups the points, the common
    slope within the groups is fitted, and so on for ``rounds`` or until the groups hold. Wires
    that are not parallel (converging at a tower: a group's own trend drifts more than
    ``max_drift_m`` from the common one over its extent) keep the starting residuals."""
    if start is None:
        slope, icpt = line_fit(s, off)
        start = off - slope * s - icpt
    r, g, last = start, None, None
    for _ in range(rounds):
        found = grouping(r)
        if found is None:
            break
        g = np.asarray(found, np.int64)
        if last is not None and np.array_equal(g, last):
            break
        last = g
        n = np.bincount(g).astype(float)
        ds = s - (np.bincount(g, s) / np.maximum(n, 1))[g]
        do = off - (np.bincount(g, off) / np.maximum(n, 1))[g]
        slope = float((ds * do).sum() / max(float((ds * ds).sum()), 1e-12))
        r = off - slope * s
        r = r - r.mean()
    if g is None or r is start:
        return start
    for k in range(g.max() + 1):
        m = g == k
        if m.sum() >= 2 and np.ptp(s[m]) > 0:
            own = line_fit(s[m], off[m])[0]
            if abs(own - slope) * np.ptp(s[m]) > max_drift_m:
                return start
    return r


def _clean_groups(r: np.ndarray, min_size: int, min_gap: float, max_sd: float,
                  max_groups: int = FIT_SEARCH.bundle_max_groups):
    """The fewest groups (3 to ``max_groups``) of values ``r`` (1D k-means from evenly spread
    quantiles) that are each ``min_size`` or more, neighbouring centres ``min_gap`` and 4 standard
    deviations of the widest group apart, that group no wider than ``max_sd``: (clarity, group of
    each value, numbered from the lowest), or None."""
    for k in range(3, max_groups + 1):
        # (k centres min_gap apart lie within the values' range: too narrow, none of k or more)
        if len(r) < k * min_size or np.ptp(r) < (k - 1) * min_gap:
            return None
        centres = np.quantile(r, (np.arange(k) + 0.5) / k)
        for _ in range(50):
            cuts = 0.5 * (centres[1:] + centres[:-1])
            group = np.searchsorted(cuts, r)
            sizes = np.bincount(group, minlength=k)
            if (sizes == 0).any():
                break
            new = np.bincount(group, weights=r, minlength=k) / sizes
            if np.allclose(new, centres):
                break
            centres = new
        sizes = np.bincount(group, minlength=k)
        if (sizes < min_size).any():
            continue
        # each group as thin as a wire (a crown's layer cut in three is not)
        sd = float(np.sqrt(np.max(np.bincount(group, weights=(r - centres[group]) ** 2, minlength=k) / sizes)))
        gap = float(np.min(np.diff(centres)))
        if gap >= max(min_gap, 4 * sd) and sd <= max_sd:
            return gap / max(sd, 1e-9), group
    return None


def _height_residual(s, z, window_m: float) -> np.ndarray:
    """Heights less their running mean over ``window_m`` along the line; once more with the
    two groups of a first two-means brought together, so that a stretch where one
    sub-conductor has more points does not pull the mean towards it."""
    order = np.argsort(s, kind="stable")
    ss = s[order]
    lo = np.searchsorted(ss, ss - window_m / 2)
    hi = np.searchsorted(ss, ss + window_m / 2, side="right")

    def running_mean(v):
        c = np.r_[0.0, np.cumsum(v[order])]
        out = np.empty(len(v))
        out[order] = (c[hi] - c[lo]) / (hi - lo)
        return out

    r = z - running_mean(z)
    split = two_means_1d(r, max(3, len(r) // 10))
    if split is not None:
        side, c0, c1, _ = split
        level = np.where(side, c1, c0)  # each point's group centre
        r = z - running_mean(z - level)
    return r


def two_means_1d(r: np.ndarray, min_size: int):
    """The best split of values ``r`` into a lower and an upper group (least within-group sum of
    squares: exact 2-means in one dimension, every cut of the sorted values tried through prefix
    sums), each of at least ``min_size`` values. Returns (upper-group mask, lower mean, upper
    mean, pooled standard deviation) or None when no such split exists."""
    n = len(r)
    if n < 2 * min_size:
        return None
    order = np.argsort(r, kind="stable")
    v = r[order]
    cs, cs2 = np.cumsum(v), np.cumsum(v * v)
    k = np.arange(min_size, n - min_size + 1)  # size of the lower group
    lo_s, lo_s2 = cs[k - 1], cs2[k - 1]
    hi_s, hi_s2 = cs[-1] - lo_s, cs2[-1] - lo_s2
    sse = (lo_s2 - lo_s * lo_s / k) + (hi_s2 - hi_s * hi_s / (n - k))
    best = int(np.argmin(sse))
    kb = int(k[best])
    upper = np.zeros(n, bool)
    upper[order[kb:]] = True
    sd = float(np.sqrt(max(sse[best], 0.0) / n))
    return upper, float(lo_s[best] / kb), float(hi_s[best] / (n - kb)), sd


def _chain_pieces(s, z, lab, min_points: int, gap_max: float, z_tol: float,
                  slope_window: float = FIT_SEARCH.chain_slope_window_m) -> np.ndarray:
    """Wire number of each connected piece (-1: too small). Pieces follow each other along the
    line across gaps (pylons, occlusions) when one ends where the next begins, at about the same
    height; wires are numbered from the highest down.

    Heights are compared where the two pieces' end slopes (lines over ``slope_window`` at each
    end) meet in the middle of the gap: a wire rises to a pole and falls after it, so across a
    20 m gap at a pole its ends differ by metres while their extrapolations agree."""
    n = lab.max() + 1
    counts = np.bincount(lab, minlength=n)

    def end_line(sk, zk, at, side):
        w = sk >= at - slope_window if side > 0 else sk <= at + slope_window
        if w.sum() >= 5 and np.ptp(sk[w]) > 1.0:
            slope, icpt = line_fit(sk[w], zk[w])
            return float(slope * at + icpt), float(slope)
        near = sk >= at - 2.0 if side > 0 else sk <= at + 2.0
        return float(np.median(zk[near])), 0.0

    info = []
    for k in range(n):
        if counts[k] < min_points:
            continue
        m = lab == k
        sk, zk = s[m], z[m]
        lo, hi = float(sk.min()), float(sk.max())
        z_lo, slope_lo = end_line(sk, zk, lo, -1)
        z_hi, slope_hi = end_line(sk, zk, hi, +1)
        info.append((lo, hi, z_lo, z_hi, k, float(np.median(zk)), slope_lo, slope_hi))
    info.sort()
    parent = {i[4]: i[4] for i in info}

    def root(a):
        while parent[a] != a:
            a = parent[a]
        return a

    # every admissible link costed by its height mismatch and its gap (a metre of gap weighs as
    # 2 cm of height), the cheapest taken first, each piece followed and preceded at most once:
    # of wires stacked 0.3 m apart, the next piece at the same height wins over a nearer one
    # a layer away
    links = []
    for i, (lo_i, hi_i, _, zhi_i, ki, _, _, shi_i) in enumerate(info):
        for lo_j, hi_j, zlo_j, _, kj, _, slo_j, _ in info[i + 1:]:
            gap = lo_j - hi_i
            if gap < -1.0 or gap > gap_max:
                continue
            half = max(gap, 0.0) / 2
            dz = abs((zhi_i + shi_i * half) - (zlo_j - slo_j * half))
            if dz <= z_tol + FIT_SEARCH.chain_rise_per_m * max(gap, 0.0):
                links.append((dz + FIT_SEARCH.chain_rise_per_m * max(gap, 0.0), ki, kj))
    has_next, has_prev = set(), set()
    for _, ki, kj in sorted(links):
        if ki in has_next or kj in has_prev:
            continue
        has_next.add(ki)
        has_prev.add(kj)
        parent[root(kj)] = root(ki)
    wire_of = np.full(n, -1)
    roots = sorted({root(i[4]) for i in info},
                   key=lambda r: -np.median([i[5] for i in info if root(i[4]) == r]))
    for w, r in enumerate(roots):
        for i in info:
            if root(i[4]) == r:
                wire_of[i[4]] = w
    return wire_of

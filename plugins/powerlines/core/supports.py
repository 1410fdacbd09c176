"""Supports: lattice towers and poles under the lines (span ends, columns, towers the wires run
through) and their points."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..rules import (POLE_CORE_M, POLE_HEAD_M, PYLON_TOP_SHARE, TOWER_SHAPE, PairRules, PassedThroughRules, PoleRules,
                     TowerRules)
from .candidates import shape_classes


@dataclass
class Pylon:
    x: float
    y: float
    height_m: float
    n_spans: int
    heading_deg: float
    cells: np.ndarray  # flat indices (on the search grid) of the tower's footprint
    grid: tuple  # the search grid: (x0, y0, cell_m, rows, cols)
    kind: str = "tower"  # "tower" (the column-and-span-ends rule) or "pole" (a thin vertical column)
    head_m: float = 0.0  # a pole's head: its points within this of the axis, in its top metre (cross arms)

    def extent_m(self) -> float:
        """How far its footprint reaches from its base: its farthest cell's centre and a cell."""
        x0, y0, cell_m, _, cols = self.grid
        r, c = np.divmod(np.asarray(self.cells), cols)
        return float(np.hypot(x0 + (c + 0.5) * cell_m - self.x, y0 + (r + 0.5) * cell_m - self.y).max()) + cell_m



def find_pylons(x, y, hag, span_ends, span_end_hag, line_headings, lines_xy, top_share: float = PYLON_TOP_SHARE,
                span_lines=None, passed_by: list | None = None, wire_xyh=None, rules: TowerRules | None = None,
                **overrides):
    """Towers that carry the conductors: tall structures under the lines where spans end.

    x, y, hag: the off-ground, off-wire points (metres; hag = height above ground);
    span_ends: (n, 2) plan positions where 3D spans end, span_end_hag their heights above
    ground; lines_xy: [(a, b)] the 2D conductor segments and line_headings their headings
    (degrees, counter-clockwise from east, 0-180).

    On a ``cell_m`` grid of the points within ``reach_m`` of a conductor line, a cell is *tall*
    when its highest point reaches ``top_share`` of the lowest span end's height within
    ``end_radius_m`` (a tower stands as high as the lowest attachment it holds there, and its
    peak, over the middle of its body, holds the earth wire; a tree with no span ending at it is
    never tall), and a *column* when
    its points fill at least ``column_share`` of the 1 m layers from its top down to 3 m above
    ground (a lattice or a pole, not an arm or a crown). Tall cells join into candidates (8-
    connected); a candidate with a column, at most ``max_side_m`` across, where at least
    ``min_ends`` and more spans end (within ``end_radius_m`` of its body, or its arms' reach; a
    span end counts for the nearest candidate only) than run past it (``span_lines``: each span's
    plan segment, span i's ends being ``span_ends[2i]`` and ``[2i + 1]``) is a tower: wires end at
    towers and pass trees. Only the spans along those that end there (within ``along_deg``) count
    as running past: a pole that ends one line may stand under another line crossing it. Tiles cut spans at their edges,
    where no tower stands: that is what the column is for. A tower is neither vegetation (at most ``max_rugged`` of its points rugged, as
    ``shape_classes`` tells crowns) nor a building (at least ``min_slenderness`` times as tall as
    the square root of its footprint, arms included), and, given the wire points found
    (``wire_xyh``: x, y, hag), it stands at most ``max_height_share`` times as high as the
    highest of them within ``arm_m`` (a tree reaching over a low line, where the wire's pieces
    lost in its crown end, stands twice as high or more; a tower holds the earth wire at its
    peak, a pole its top wire). A candidate wider than a pole (its body over ``pole_area_m2``)
    reaches down to ``reach_down_share`` of its height: a lattice's legs stand on the ground, a
    crown where wire pieces end hangs over a gap (its trunk hidden); a pole's few points may
    leave its foot bare; one that stands over ``over_wires_share`` times as high as the wires
    beside it (a tower holding an earth wire not found) reaches down to
    ``over_wires_reach_down_share`` of its height (a lattice's legs; a crown over the wires hangs
    off the ground). A candidate up to ``axis_area_m2`` (a pole with its arms) has at least
    ``min_axis_share`` of its points under its head on one thin vertical (``axis_share``: a
    pole's column; a crown spreads over metres). The base is the median of its points (the
    middle of its column cells leans to the side a street scan sees). ``passed_by``, a list, gets the
    candidates that more spans run past than end at (a tree, or a suspension tower the wires run
    through: its arms, if found as lines, tell). A candidate up to twice ``axis_area_m2`` standing
    on two thin verticals at least ``pair_apart_m`` apart, each holding span ends of its own, is
    two poles (``pole_pair``: a line ending at its pole beside another line's pole). A body over
    ``one_tower_m2`` (the family's largest true tower 73 m2 of cells, AHN4's 76) is a lattice
    with crowns touching it: its base comes from its cells within ``peak_reach_m`` of its
    highest column cell, and its body keeps the cells within the half-diagonal of a square of
    ``one_tower_m2`` of that base.

    A tower stands under the lines it carries: its base within ``under_line_m`` of a conductor in
    plan (an earth wire over its body, a pole's top insulator), or between conductors, the farther
    side's nearest at most ``max_side_ratio`` times as far as the nearer side's, or its footprint
    (the arms) reaching within a cell of one. A tree beside the line, where wires lost in its crown
    end, has them all on one side, clear of it.
    """
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or TowerRules(), **overrides)
    (cell_m, reach_m, column_share, end_radius_m, max_side_m, min_ends, max_rugged, min_slenderness, under_line_m,
     max_side_ratio, along_deg, max_height_share, arm_m, reach_down_share, pole_area_m2, over_wires_share,
     over_wires_reach_down_share, min_axis_share, axis_area_m2, pair_apart_m, one_tower_m2,
     peak_reach_m) = dataclasses.astuple(r)
    if len(x) == 0 or len(span_ends) == 0:
        return []
    g = _tower_grid(x, y, hag, lines_xy, reach_m, cell_m)
    if g is None:
        return []
    x, y, hag, flat, top, n_layers, centres, (x0, y0, _, rows, cols), top_held = g
    wire_near = None if wire_xyh is None or not len(wire_xyh[0]) else \
        _wires_over_cells((x0, y0, cell_m, rows, cols), *wire_xyh, arm_m)[1]
    span_end_hag = np.asarray(span_end_hag, float)
    got = _shaped_candidates(g, span_ends, span_end_hag, top_share, r)
    if got is None:
        return []
    shaped, owner, column, structure = got
    found = []
    for k, (cells, (cx, cy), arm, height) in enumerate(shaped):
        n_ends = int(np.sum(owner == k))
        if n_ends < min_ends:
            continue
        # a support stands about as high as the wires beside it; a crown reaching over a low
        # line, where the wire's pieces lost in it end, stands far higher
        if wire_near is not None and np.isfinite(wire_near[cells].max()) and \
                height > max_height_share * float(wire_near[cells].max()):
            continue
        passed = span_lines is not None and \
            _spans_run_past(cx, cy, arm, np.flatnonzero(owner == k), span_lines, len(span_ends), r) >= n_ends
        if passed and passed_by is None:
            continue
        dist = [_point_segment_distance(cx, cy, a, b) for a, b in lines_xy]
        # a tower reaches the wires it carries (where they sit on its top, its top points are wire points)
        height = max(height, float(np.max(span_end_hag[owner == k])))
        standing = structure & (top >= 0.5 * height)  # legs and body reach up to the head; bushes do not
        body = _grow_body(cells, standing.reshape(rows, cols), centres, np.array([cx, cy]), arm)
        if not passed and not under_its_lines(cx, cy, centres[body], lines_xy, end_radius_m, under_line_m,
                                               max_side_ratio, cell_m):
            continue
        area = len(body) * cell_m ** 2
        wide = area > pole_area_m2
        down = float(hag[np.isin(flat, body)].min()) / height if wide else 0.0  # (only wide ones are asked)
        if wide and down > reach_down_share:
            continue
        # a tower standing well over the wires found beside it holds an earth wire not found, on
        # legs that reach the ground; a crown over the wires, off the ground, is trees
        if wide and down > over_wires_reach_down_share and wire_near is not None and \
                np.isfinite(wire_near[cells].max()) and height > over_wires_share * float(wire_near[cells].max()):
            continue
        # its base where its points are: the middle of its column cells leans to the side a street
        # scan sees, and to an arm's cells on an angle tower; not where a stack of wires, unfound,
        # runs off its top along the line
        heading = float(line_headings[int(np.argmin(dist))])
        (bx, by), body = _base_and_body(g, cells, body, column, (cx, cy), heading, r)
        if area <= axis_area_m2:
            # a pole (with its arms) stands on one thin column; a crown where wire pieces end
            # spreads its points over metres
            share, _ = axis_share(x, y, hag, bx, by, height)
            if share is not None and share < min_axis_share:
                continue
        pair = None if passed or area > 2 * axis_area_m2 else \
            pole_pair(x, y, hag, flat, body, height, np.asarray(span_ends, float)[owner == k],
                       span_end_hag[owner == k], centres, min_ends, min_share=min_axis_share, apart_m=pair_apart_m)
        if pair is not None:
            # two poles side by side (a line ending at its own pole beside another line's): their
            # arms join their cells into one candidate, whose middle is neither pole
            for (ax, ay), ax_height, ax_ends, ax_body in pair:
                dist = [_point_segment_distance(ax, ay, a, b) for a, b in lines_xy]
                found.append(Pylon(ax, ay, ax_height, ax_ends, float(line_headings[int(np.argmin(dist))]), ax_body,
                                   (x0, y0, cell_m, rows, cols)))
            continue
        (passed_by if passed else found).append(
            Pylon(bx, by, height, n_ends, heading, body,
                  (x0, y0, cell_m, rows, cols)))
    return found


def _spans_run_past(cx, cy, arm: float, ends_here, span_lines, n_span_ends: int, r: TowerRules) -> int:
    """How many spans (``span_lines``: each span's plan segment) run past a candidate at (``cx``,
    ``cy``) reaching ``arm`` out, for ``find_pylons``: where span i's ends are span ends ``2i``
    and ``2i + 1`` (``ends_here``: the candidate's), only those along a span ending there (within
    ``r.along_deg``) count: a pole that ends one line may stand under another crossing it."""
    running = [(a, b) for a, b in span_lines if _passes(cx, cy, a, b, arm, r.end_radius_m)]
    if len(span_lines) * 2 == n_span_ends:
        ending = [span_lines[i // 2] for i in ends_here]
        running = [q for q in running if any(_parallel(q, e, r.along_deg) for e in ending)]
    return len(running)


def _base_and_body(g, cells, body, column, centre, heading: float, r: TowerRules):
    """A tower candidate's base (the median of its base cells' points, else ``centre``) and its
    body's cells, for ``find_pylons``: a body over ``r.one_tower_m2`` is a lattice with crowns
    touching it, its base under its peak (within ``r.peak_reach_m`` of its highest column cell)
    and its body the cells one tower could cover about that base."""
    x, y, _, flat, top, n_layers, centres, _, _ = g
    base_cells = _base_cells(cells, column, n_layers, centres, np.radians(heading))
    wide = len(body) * r.cell_m ** 2 > r.one_tower_m2
    if wide:
        # wider than any one tower: a lattice with the crowns touching it; its base under its
        # peak (the earth wire's), not amid the crowns' many points
        col = cells[column[cells]]
        peak = centres[col[np.argmax(top[col])]]
        base_cells = base_cells[np.hypot(*(centres[base_cells] - peak).T) <= r.peak_reach_m]
    mine = np.flatnonzero(np.isin(flat, base_cells))
    bx, by = (float(np.median(x[mine])), float(np.median(y[mine]))) if len(mine) else centre
    if wide:
        # its points (class 15): the cells one tower's body could cover about that base (the
        # half-diagonal of a square of one_tower_m2), not the crowns'
        body = body[np.hypot(centres[body][:, 0] - bx, centres[body][:, 1] - by) <= np.sqrt(r.one_tower_m2 / 2)]
    return (bx, by), body


def _shaped_candidates(g, span_ends, span_end_hag, top_share: float, r: TowerRules):
    """``find_pylons``'s candidates on its grid ``g`` (``_tower_grid``'s): tall cells joined into
    bodies shaped like a tower, and the span ends each owns. Returns (shaped: [(cells, centre,
    arm reach, height)], owner per span end (-1: none), the column and structure cell masks), or
    None when no body is shaped like a tower."""
    from scipy import ndimage

    x, y, hag, flat, top, n_layers, centres, (x0, y0, _, rows, cols), top_held = g
    end_radius_m, column_share = r.end_radius_m, r.column_share
    has = np.isfinite(top)
    wire_top = np.zeros(rows * cols)
    ends = cKDTree(np.asarray(span_ends, float))
    idx = np.flatnonzero(has)
    # the lowest span end around: the earth wire's end over a lattice tower's peak is nearer its
    # middle cells than the phases' ends at its arms, and only the peak reaches that high
    pairs = cKDTree(centres[idx]).sparse_distance_matrix(ends, end_radius_m, output_type="ndarray")
    lowest = np.full(len(idx), np.inf)
    np.minimum.at(lowest, pairs["i"], span_end_hag[pairs["j"]])
    hit = np.isfinite(lowest)
    wire_top[idx[hit]] = lowest[hit]
    tall = has & (wire_top > 0) & (top >= top_share * wire_top)
    column = tall & (n_layers >= np.maximum(3, column_share * (top - 3.0)))  # 3 m of it at least
    structure = has & (n_layers >= 3)  # something standing at least 3 m above 3 m: legs, body, arms
    lab, n = ndimage.label(tall.reshape(rows, cols), structure=np.ones((3, 3), bool))
    lab = lab.ravel()
    shaped = []  # (cells, centre, arm reach, height) of the candidates shaped like a tower
    for k in range(1, n + 1):
        cells = _shaped_bodies(np.flatnonzero(lab == k), column, (rows, cols), centres,
                               lambda c: _tower_shaped(c, g, column, r) is not None)
        got = _tower_shaped(cells, g, column, r)
        if got is not None:  # (centre, how far out the wires may hang, height)
            shaped.append((cells, *got))
    if not shaped:
        return None
    # each span end belongs to the nearest candidate that reaches it (a tree beside a pole does
    # not count the pole's span ends)
    cxy = np.array([c for _, c, _, _ in shaped])
    reach = np.array([max(end_radius_m, a) for _, _, a, _ in shaped])
    d_end = np.hypot(*(np.asarray(span_ends, float)[:, None, :] - cxy[None, :, :]).transpose(2, 0, 1))
    # nor the ends of wires held far over its top (another line's, lost in the view beside it)
    can_hold = span_end_hag[:, None] * top_share <= np.array([h for _, _, _, h in shaped])[None, :]
    d_end = np.where((d_end <= reach[None, :]) & can_hold, d_end, np.inf)
    owner = np.where(np.isfinite(d_end.min(axis=1)), d_end.argmin(axis=1), -1)
    return shaped, owner, column, structure



def pole_pair(x, y, hag, flat, body, height: float, ends_xy, ends_hag, centres, min_ends: int,
              rules: PairRules | None = None, **overrides):
    """Two poles in one candidate, or None: the body's points from ``low_m`` above ground to
    ``head_m`` under its top gathered on thin verticals (the most within ``axis_m``), the densest
    holding ``min_share`` of them (a pole's column, not a lattice's legs) and another at least
    ``apart_m`` from it ``second_share`` as many, rising over ``min_rise_share`` of that height
    (a column, not a crown's piece); each holds at least ``min_ends`` of the candidate's span ends
    (``ends_xy``, their heights ``ends_hag``), the nearer axis's. Returns per pole ((x, y),
    height, its span ends, its body cells: the nearer pole's)."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or PairRules(), **overrides)
    (min_share, apart_m, axis_m, low_m, head_m, second_share, min_points, min_rise_share) = dataclasses.astuple(r)
    inside = np.flatnonzero(np.isin(flat, body))
    mine = inside[(hag[inside] >= low_m) & (hag[inside] <= height - head_m)]
    if len(mine) < 2 * min_points or len(ends_xy) < 2 * min_ends:
        return None
    pts = np.column_stack([x[mine], y[mine]])
    tree = cKDTree(pts)
    count = tree.query_ball_point(pts, axis_m, return_length=True)
    first = int(np.argmax(count))
    if count[first] < min_share * len(mine):
        return None
    far = np.flatnonzero(np.hypot(*(pts - pts[first]).T) >= apart_m)
    if not len(far):
        return None
    second = int(far[np.argmax(count[far])])
    if count[second] < max(min_points, second_share * count[first]):
        return None
    axes, rise = [], (height - head_m - low_m) * min_rise_share
    for i in (first, second):
        on = tree.query_ball_point(pts[i], axis_m)
        if np.ptp(hag[mine[on]]) < rise:
            return None
        axes.append(pts[on].mean(axis=0))
    axes = np.array(axes)
    which = np.argmin(np.hypot(*(ends_xy[:, None, :] - axes[None, :, :]).transpose(2, 0, 1)), axis=1)
    if min(np.bincount(which, minlength=2)) < min_ends:
        return None
    cell_of = np.argmin(np.hypot(*(centres[body][:, None, :] - axes[None, :, :]).transpose(2, 0, 1)), axis=1)
    out = []
    for j in (0, 1):
        # as high as its own top (its arms) or the wires ending on it
        top = hag[inside[np.hypot(x[inside] - axes[j][0], y[inside] - axes[j][1]) <= 2 * axis_m]].max()
        out.append(((float(axes[j][0]), float(axes[j][1])), max(float(top), float(ends_hag[which == j].max())),
                    int(np.sum(which == j)), np.asarray(body)[cell_of == j]))
    return out


def axis_share(x, y, hag, cx, cy, height: float, radius_m: float = TOWER_SHAPE.axis_radius_m,
               axis_m: float = TOWER_SHAPE.axis_m, low_m: float = TOWER_SHAPE.axis_low_m,
               head_m: float = TOWER_SHAPE.axis_head_m):
    """The share of the points within ``radius_m`` of (``cx``, ``cy``) in plan, from ``low_m``
    above ground to ``head_m`` under ``height`` (under a pole's arms), that lie within ``axis_m``
    of the vertical through the densest of them (the most such points within ``axis_m``), and
    how many there are; None for the share under 3 points. A pole's body is one thin column, a
    crown spreads over metres."""
    near = np.flatnonzero((np.abs(x - cx) <= radius_m) & (np.abs(y - cy) <= radius_m))
    near = near[(np.hypot(x[near] - cx, y[near] - cy) <= radius_m) & (hag[near] >= low_m) &
                (hag[near] <= height - head_m)]
    if len(near) < 3:
        return None, len(near)
    pts = np.column_stack([x[near], y[near]])
    within = cKDTree(pts).query_ball_point(pts, axis_m, return_length=True)
    return float(within.max()) / len(near), len(near)


def _base_cells(cells, column, n_layers, centres, heading_rad: float, reach_m: float = TOWER_SHAPE.base_reach_m,
                along_deg: float = TOWER_SHAPE.base_along_deg) -> np.ndarray:
    """The cells of a tower's candidate its base is taken from: all but those with no structure
    (under 3 layers, see ``_tower_grid``) more than ``reach_m`` from its column cells along the
    line it carries (within ``along_deg`` of ``heading_rad``): a stack of wires the line search
    missed, running off a pole's top, is tall there and pulls the median metres along the line
    (a lattice's arms reach across it)."""
    col = centres[cells[column[cells]]]
    if not len(col):
        return cells
    d, j = cKDTree(col).query(centres[cells])
    v = centres[cells] - col[j]
    u = np.array([np.cos(heading_rad), np.sin(heading_rad)])
    along = np.abs(v @ u) >= np.cos(np.radians(along_deg)) * np.maximum(d, 1e-9)
    return cells[~((d > reach_m) & along & (n_layers[cells] < 3))]


def _tower_grid(x, y, hag, lines_xy, reach_m: float, cell_m: float):
    """The points (x, y, hag) within ``reach_m`` of a conductor segment of ``lines_xy`` on a grid
    of ``cell_m`` cells (on multiples of it: the same cells whatever the extent of the input):
    (x, y, hag, cell of each, highest hag per cell, number of 1 m layers from 3 m up that hold a
    point, cell centres, (x0, y0, cell_m, rows, cols), highest hag per cell of a point with
    another within 5 m under it); None where no point is that near."""
    near = np.zeros(len(x), bool)
    for (a, b) in lines_xy:
        a, b = np.asarray(a, float), np.asarray(b, float)
        d = b - a
        L2 = float(d @ d) or 1.0
        t = np.clip(((x - a[0]) * d[0] + (y - a[1]) * d[1]) / L2, 0.0, 1.0)
        near |= np.hypot(x - a[0] - t * d[0], y - a[1] - t * d[1]) <= reach_m
    if not near.any():
        return None
    x, y, hag = x[near], y[near], hag[near]
    x0, y0 = np.floor(x.min() / cell_m) * cell_m, np.floor(y.min() / cell_m) * cell_m
    c = np.floor((x - x0) / cell_m).astype(np.int64)
    r = np.floor((y - y0) / cell_m).astype(np.int64)
    rows, cols = int(r.max()) + 1, int(c.max()) + 1
    flat = r * cols + c
    top = np.full(rows * cols, -np.inf)
    np.maximum.at(top, flat, hag)
    layer = np.floor(hag).astype(np.int64)
    occupied = np.unique(flat * 4096 + np.clip(layer, 0, 4095))  # distinct (cell, 1 m layer)
    low = (occupied % 4096) >= 3
    n_layers = np.bincount(occupied[low] // 4096, minlength=rows * cols)
    centres = np.column_stack([x0 + (np.arange(rows * cols) % cols + 0.5) * cell_m,
                               y0 + (np.arange(rows * cols) // cols + 0.5) * cell_m])
    # the highest point of each cell with another within 5 m under it: a structure's top (a far
    # pole's few points lie 2-3 m apart), not a stray point over it (a bird, noise the ground
    # filter left)
    order = np.lexsort((hag, flat))
    f, h = flat[order], hag[order]
    held = np.r_[False, (f[1:] == f[:-1]) & (np.diff(h) <= TOWER_SHAPE.top_held_m)]
    top_held = np.full(rows * cols, -np.inf)
    np.maximum.at(top_held, f[held], h[held])
    return x, y, hag, flat, top, n_layers, centres, (x0, y0, cell_m, rows, cols), top_held


def _wires_over_cells(grid, wire_x, wire_y, wire_hag, arm_m: float):
    """Per cell of ``grid`` (``_tower_grid``'s): the lowest height of the wire points in it (inf
    where none) and the highest within ``arm_m`` of it (-inf where none)."""
    from scipy import ndimage

    x0, y0, cell_m, rows, cols = grid
    wc = np.floor((np.asarray(wire_x) - x0) / cell_m).astype(np.int64)
    wr = np.floor((np.asarray(wire_y) - y0) / cell_m).astype(np.int64)
    inside = (wc >= 0) & (wc < cols) & (wr >= 0) & (wr < rows)
    wflat, wh = wr[inside] * cols + wc[inside], np.asarray(wire_hag, float)[inside]
    wire_low, wire_top = np.full(rows * cols, np.inf), np.full(rows * cols, -np.inf)
    np.minimum.at(wire_low, wflat, wh)
    np.maximum.at(wire_top, wflat, wh)
    k = int(np.ceil(arm_m / cell_m))
    dy, dx = np.mgrid[-k:k + 1, -k:k + 1]
    wire_near = ndimage.maximum_filter(wire_top.reshape(rows, cols), footprint=np.hypot(dy, dx) <= k,
                                       mode="constant", cval=-np.inf).ravel()
    return wire_low, wire_near


def _shaped_bodies(cells, column, shape, centres, shaped) -> np.ndarray:
    """The cells of a candidate (tall cells, 8-connected) less its bodies that are not shaped like
    a tower: its column cells grouped into bodies (closer than 5 cells: a lattice's legs are one
    body, and so are the column cells scattered through one crown), every other cell given to the
    nearest body. A crown beside a tower joins it through the tower's arm cells and the wires'
    unlabelled points by the insulators; left in, it moves the base into the crown. Where no body
    or every body is shaped (an H-frame's two poles), the candidate stays whole. ``shaped(cells)``:
    whether those cells pass as a tower."""
    from scipy import ndimage

    mine = cells[column[cells]]
    if len(mine) < 2:
        return cells
    rows, cols = shape
    mask = np.zeros(rows * cols, bool)
    mask[mine] = True
    grown = ndimage.binary_dilation(mask.reshape(rows, cols), structure=np.ones((3, 3), bool), iterations=2)
    lab, n = ndimage.label(grown, structure=np.ones((3, 3), bool))
    if n < 2:
        return cells
    body_of = lab.ravel()[mine]
    nearest = cKDTree(centres[mine]).query(centres[cells])[1]
    parts = [cells[body_of[nearest] == b] for b in np.unique(body_of)]
    ok = [p for p in parts if shaped(p)]
    return np.sort(np.concatenate(ok)) if ok and len(ok) < len(parts) else cells


def _tower_shaped(cells, g, column, r):
    """(centre of the body, arm reach, height: ``top_held``'s highest) of the tall cells
    ``cells`` of the grid ``g`` (``_tower_grid``'s) where they are shaped like a tower (see
    find_pylons: a column, at most ``r.max_side_m`` across, slender, not a crown's rugged points),
    else None. ``r``: the caller's rules (TowerRules or PassedThroughRules)."""
    x, y, hag, flat, top, _, centres, _, top_held = g
    cell_m, max_side_m, min_slenderness, max_rugged = r.cell_m, r.max_side_m, r.min_slenderness, r.max_rugged
    if not column[cells].any():
        return None
    pc = centres[cells]
    if np.ptp(pc[:, 0]) + cell_m > max_side_m or np.ptp(pc[:, 1]) + cell_m > max_side_m:
        return None
    held = top_held[cells]
    height = float(held.max()) if np.isfinite(held).any() else float(top[cells].max())
    if height < min_slenderness * np.sqrt(len(cells) * cell_m * cell_m):
        return None
    mine = np.flatnonzero(np.isin(flat, cells))
    if len(mine) >= 4:
        xyz = np.column_stack([x[mine], y[mine], hag[mine]])
        _, _, rugged, _ = shape_classes(xyz - xyz.min(axis=0))
        if rugged.mean() > max_rugged:
            return None
    body = centres[cells[column[cells]]]
    centre = np.array([0.5 * (body[:, 0].min() + body[:, 0].max()), 0.5 * (body[:, 1].min() + body[:, 1].max())])
    return centre, 0.5 * float(np.ptp(pc, axis=0).max()) + cell_m, height



def find_towers_passed_through(x, y, hag, wire_x, wire_y, wire_hag, line_headings, lines_xy, known=(),
                               top_share: float = PYLON_TOP_SHARE, rules: PassedThroughRules | None = None, **overrides) -> list:
    """Towers the wires run through without a span ending there, from the towers' own points: a
    suspension tower where one catenary fits the wire across it (short spans on a slope: the
    kink at its insulators is within the noise), which ``find_pylons`` cannot see.

    x, y, hag: the off-ground, off-wire points; wire_*: the wire points found (metres, hag =
    height above ground); line_headings, lines_xy as ``find_pylons``; ``known``: the towers and
    poles found already (a candidate within ``known_m`` of one is it).

    On ``find_pylons``' grid, a cell is *tall* when its top reaches ``top_share`` of the highest
    wire within ``arm_m`` of it; the tall cells join into candidates that stand at most
    ``max_above_m`` over the highest wire near them (a tower's peak holds the earth wire, a pole's
    top its top wire; the crown of a tall tree beside a low line stands far over it), shaped like
    a tower (``_tower_shaped``: a column, slender, not rugged). A candidate is a tower when a wire runs
    through it, not over it: in one of its cells the wire's lowest point is under the cell's top,
    or at most ``insulator_m`` over it (a tower's arms hold the wires; a pole's top wire sits on
    an insulator over its top, whose last few points a sparse scan may miss; trees under a line
    are trimmed 2-3 m below the wires), its points reach down to ``reach_down_share`` of its
    height (no span ends there to vouch for it, so its own body must: a support stands on the
    ground and is seen under its head, from the air as from the street, where a crown's cap
    that a low line runs through hides its trunk), hanging together that far (no gap over
    ``max_gap_m``, as ``pylon_points`` takes a tower's points) unless what stands under the gap
    is no wider than a pole (``pole_area_m2``: a sparse pole's points leave gaps; a bush under a
    line with wire points left over it is wide); one wider than a pole reaches down to
    ``wide_reach_down_share`` (as ``find_pylons`` asks: a lattice's legs stand on the ground, a
    conifer the wires run through stands off it), and it stands
    under its lines (``under_its_lines``: the lines reaching within ``margin_m`` of it along
    their length). n_spans counts two spans per conductor line passing within ``arm_m`` of its
    base."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or PassedThroughRules(), **overrides)
    (cell_m, reach_m, column_share, arm_m, max_above_m, max_side_m, max_rugged, min_slenderness, known_m,
     under_line_m, margin_m, max_side_ratio, insulator_m, reach_down_share, pole_area_m2, max_gap_m,
     wide_reach_down_share) = dataclasses.astuple(r)
    from scipy import ndimage

    if len(x) == 0 or len(wire_x) == 0:
        return []
    g = _tower_grid(x, y, hag, lines_xy, reach_m, cell_m)
    if g is None:
        return []
    x, y, hag, flat, top, n_layers, centres, grid, top_held = g
    x0, y0, _, rows, cols = grid
    has = np.isfinite(top)
    wire_low, wire_near = _wires_over_cells(grid, wire_x, wire_y, wire_hag, arm_m)
    tall = has & np.isfinite(wire_near) & (top >= top_share * wire_near)
    through = tall & (wire_low <= top + insulator_m)
    column = tall & (n_layers >= np.maximum(3, column_share * (top - 3.0)))
    structure = has & (n_layers >= 3)
    lab, n = ndimage.label(tall.reshape(rows, cols), structure=np.ones((3, 3), bool))
    lab = lab.ravel()
    known_xy = np.array([[p.x, p.y] for p in known], float).reshape(-1, 2)
    found = []
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(1, n + 2))
    for i in range(n):
        cells = order[bounds[i]:bounds[i + 1]]
        if not through[cells].any():
            continue
        shaped = _tower_shaped(cells, g, column, r)
        if shaped is None:
            continue
        centre, arm, height = shaped
        if height > wire_near[cells].max() + max_above_m:
            continue
        if len(known_xy) and np.hypot(*(known_xy - centre).T).min() <= known_m:
            continue
        # a support stands on the ground, its body in view under its head; a crown's cap hides its trunk
        if float(hag[np.isin(flat, cells)].min()) > reach_down_share * height:
            continue
        # its arms reach out under the wires below its head (shorter than the tall cells' top)
        standing = structure & (top >= 0.5 * height)
        body = _grow_body(cells, standing.reshape(rows, cols), centres, centre, max(arm, arm_m))
        mine = np.isin(flat, body) & (hag <= height + max_gap_m)  # not a stray point over its top
        # wider than a pole, as find_pylons asks at span ends: a lattice's legs stand on the ground
        if len(body) * cell_m ** 2 > pole_area_m2 and float(hag[mine].min()) > wide_reach_down_share * height:
            continue
        own = np.sort(hag[mine])[::-1]
        gaps = np.flatnonzero(own[:-1] - own[1:] > max_gap_m)
        if len(gaps) and float(own[gaps[0]]) > reach_down_share * height and \
                len(np.unique(flat[mine & (hag < own[gaps[0]])])) * cell_m ** 2 > pole_area_m2:
            continue
        if not under_its_lines(centre[0], centre[1], centres[body], lines_xy, margin_m, under_line_m,
                                max_side_ratio, cell_m):
            continue
        dist = np.array([_point_segment_distance(centre[0], centre[1], a, b) for a, b in lines_xy])
        found.append(Pylon(float(centre[0]), float(centre[1]), height, 2 * int(np.sum(dist <= arm_m)),
                           float(line_headings[int(np.argmin(dist))]), body, grid))
    return found



def find_poles(x, y, hag, wire_x, wire_y, wire_hag, line_headings, lines_xy, span_ends=None, span_end_hag=None,
               top_share: float = PYLON_TOP_SHARE, rules: PoleRules | None = None, **overrides) -> list[Pylon]:
    """Poles that carry the wires: thin vertical columns, as a street scanner sees wooden and
    steel poles (a crown beside the pole is no part of it, a tree trunk ends in its crown).

    x, y, hag: the off-ground, off-wire points (metres; hag = height above ground); wire_x,
    wire_y, wire_hag: the points of the wires found; line_headings, lines_xy as ``find_pylons``.

    On the points thinned to ``voxel_m`` voxels, a point is *thin* where its cylinder of
    ``radius_m`` and ``window_m`` height holds points and the ring out to ``ring_m`` few (under
    ``max_ring_share`` times as many, where points spread evenly, as over a crown, a wall or a
    roof edge, give it 8 times as many; a pole's hardware and the wires leaving it give some). Thin points
    linked in plan (0.3 m) are a pole when they rise over ``min_thin_m``, its column (points
    within ``column_m`` of the axis) fills ``min_fill`` of the 0.5 m layers from 1 m above the
    ground up to its thin part's top, a wire passes within ``wire_reach_m`` of its axis, and it
    stands at least ``top_share`` as high as those wires (a street light under them does not). Where
    spans end within that reach (``span_ends``, ``span_end_hag``: plan positions and heights above
    ground) it is measured against them alone: the pole that ends a line may stand under another
    line's wires.
    Its top is where the column above the thin part first breaks by 1.5 m; its points are its
    column and its head (within ``head_m`` of the axis in its top metre: cross arms, insulators)."""
    # a value given by name overrides the rule's
    r = dataclasses.replace(rules or PoleRules(), **overrides)
    (radius_m, ring_m, window_m, min_thin_m, min_fill, wire_reach_m, end_radius_m, column_m, voxel_m, head_m,
     max_ring_share, min_thin_voxels, from_ground_m, link_m, layer_m, top_break_m,
     footprint_cell_m) = dataclasses.astuple(r)
    from scipy import ndimage

    if len(x) < 5 or len(wire_x) == 0:
        return []
    # only the points within reach of a wire (the axis within wire_reach_m, its ring beyond): on
    # 1 m cells, those of the wires grown by that distance
    x_min, y_min = min(x.min(), wire_x.min()), min(y.min(), wire_y.min())
    grow = int(np.ceil(wire_reach_m + ring_m))
    wc, wr = np.floor(wire_x - x_min).astype(np.int64), np.floor(wire_y - y_min).astype(np.int64)
    pc, pr = np.floor(x - x_min).astype(np.int64), np.floor(y - y_min).astype(np.int64)
    shape = (int(max(pr.max(), wr.max())) + 1, int(max(pc.max(), wc.max())) + 1)
    reach = np.zeros(shape, bool)
    reach[wr, wc] = True
    reach = ndimage.binary_dilation(reach, np.ones((3, 3), bool), iterations=grow)
    near = reach[pr, pc]
    x, y, hag = x[near], y[near], hag[near]
    if len(x) < 5:
        return []
    v = np.unique(np.floor(np.column_stack([x, y, hag]) / voxel_m).astype(np.int64), axis=0)
    p = (v + 0.5) * voxel_m
    half = window_m / 2
    # cylinders as ellipsoids: heights scaled so that one ball is radius_m across and window_m high
    inner = cKDTree(np.column_stack([p[:, :2], p[:, 2] * radius_m / half]))
    outer = cKDTree(np.column_stack([p[:, :2], p[:, 2] * ring_m / half]))
    n_in = inner.query_ball_point(inner.data, radius_m, return_length=True)
    n_out = outer.query_ball_point(outer.data, ring_m, return_length=True)
    thin = (n_in >= min_thin_voxels) & (n_out - n_in <= max_ring_share * n_in) & (p[:, 2] >= from_ground_m)
    t = p[thin]
    if len(t) < 5:
        return []
    pairs = cKDTree(t[:, :2]).query_pairs(link_m, output_type="ndarray")
    _, lab = connected_components(sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                                    shape=(len(t), len(t))), directed=False)
    plan, wires = cKDTree(p[:, :2]), cKDTree(np.column_stack([wire_x, wire_y]))
    wire_hag = np.asarray(wire_hag, float)
    ends = cKDTree(np.asarray(span_ends, float)) if span_ends is not None and len(span_ends) else None
    end_hag = None if span_end_hag is None else np.asarray(span_end_hag, float)
    cell = footprint_cell_m
    k_cells = int(np.ceil(column_m / cell)) + 1
    found = []
    for k in np.unique(lab):
        g = t[lab == k]
        if np.ptp(g[:, 2]) < min_thin_m:
            continue
        axis = np.median(g[:, :2], axis=0)
        h = np.sort(p[plan.query_ball_point(axis, column_m), 2])
        thin_top = float(g[:, 2].max())
        layers = np.unique(np.floor(h[(h >= from_ground_m) & (h <= thin_top)] / layer_m))
        if len(layers) < min_fill * max(np.ceil((thin_top - from_ground_m) / layer_m), 1):
            continue
        above = h[h >= thin_top]  # (none where the thin points spread wider than the column)
        breaks = np.flatnonzero(np.diff(above) > top_break_m)
        top = float(above[breaks[0]] if len(breaks) else above[-1]) if len(above) else thin_top
        nb = wires.query_ball_point(axis, wire_reach_m)
        mine = ends.query_ball_point(axis, wire_reach_m) if ends is not None and end_hag is not None else []
        carried = float(np.max(end_hag[mine])) if mine else \
            float(wire_hag[nb].max()) if nb else np.inf
        if not nb or top < top_share * carried:
            continue
        dist = [_point_segment_distance(axis[0], axis[1], a, b) for a, b in lines_xy]
        n_ends = len(ends.query_ball_point(axis, end_radius_m)) if ends is not None else 0
        # its footprint: the cells of a fine grid around the axis within column_m of it
        x0, y0 = axis - k_cells * cell
        side = 2 * k_cells
        cc, rr = np.meshgrid(np.arange(side), np.arange(side))
        centre_d = np.hypot(x0 + (cc + 0.5) * cell - axis[0], y0 + (rr + 0.5) * cell - axis[1])
        cells = (rr * side + cc)[centre_d <= column_m].ravel()
        found.append(Pylon(float(axis[0]), float(axis[1]), max(top, carried), n_ends,
                           float(line_headings[int(np.argmin(dist))]) if dist else 0.0, cells,
                           (float(x0), float(y0), cell, side, side), kind="pole", head_m=head_m))
    return found


def _grow_body(cells, structure, centres, centre, reach_m):
    """The tower's footprint: its tall cells (head and arms) and the ``structure`` cells connected
    to them within ``reach_m`` of its centre (the body widening to its legs below the head)."""
    from scipy import ndimage

    rows, cols = structure.shape
    seed = np.zeros(rows * cols, bool)
    seed[cells] = True
    allowed = structure.ravel() & (np.hypot(*(centres - centre).T) <= reach_m)
    grown = ndimage.binary_propagation(seed.reshape(rows, cols), structure=np.ones((3, 3), bool),
                                       mask=(allowed | seed).reshape(rows, cols))
    return np.flatnonzero(grown.ravel())


def pylon_points(p: Pylon, x, y, hag=None, max_gap_m: float = TOWER_SHAPE.max_gap_m):
    """Points inside the tower's footprint cells (on the grid it was found on); with ``hag``
    (heights above ground) only those of the structure hanging together from its top down: below
    the first gap of more than ``max_gap_m`` stand fences, bushes and cabinets at its foot."""
    x0, y0, cell_m, rows, cols = p.grid
    c = np.floor((x - x0) / cell_m).astype(np.int64)
    r = np.floor((y - y0) / cell_m).astype(np.int64)
    ok = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
    inside = np.zeros(len(x), bool)
    inside[ok] = np.isin(r[ok] * cols + c[ok], p.cells)
    if hag is not None and inside.any():
        h = np.sort(hag[inside])[::-1]
        gaps = np.flatnonzero(h[:-1] - h[1:] > max_gap_m)
        if len(gaps):
            inside &= hag >= h[gaps[0]]
    if hag is not None and p.head_m > 0:
        inside |= (np.hypot(x - p.x, y - p.y) <= p.head_m) & (hag >= p.height_m - TOWER_SHAPE.head_depth_m) & \
            (hag <= p.height_m + TOWER_SHAPE.head_over_m)
    return inside


def in_pole_columns(poles_xyh, x, y, hag, core_m: float = POLE_CORE_M, head_m: float = POLE_HEAD_M) -> np.ndarray:
    """Which points (x, y: plan metres, hag: height above ground) lie in a pole's column: within
    ``core_m`` in plan of its base (``poles_xyh``: (n, 3) base x, y and height above ground) and
    more than ``head_m`` under its top. Nothing hangs there but what is fixed to the pole: a
    cable's end clamped to its side is the pole's (as CMU's Oakland labels mark it); the wires
    on its head (cross arms, top insulator) stay wires. ``core_m`` holds the pole's radius and a
    street scan's lean of its base towards the scanner."""
    x, y, hag = (np.asarray(v, float) for v in (x, y, hag))
    out = np.zeros(len(x), bool)
    for px, py, height in np.asarray(poles_xyh, float).reshape(-1, 3):
        out |= (np.hypot(x - px, y - py) <= core_m) & (hag < height - head_m)
    return out


def _parallel(s1, s2, max_deg: float) -> bool:
    """Whether plan segments s1 and s2 ((a, b) each) run within ``max_deg`` of one direction."""
    d1, d2 = np.subtract(s1[1], s1[0]), np.subtract(s2[1], s2[0])
    n = float(np.hypot(*d1) * np.hypot(*d2))
    return n > 0 and abs(float(d1 @ d2)) / n >= np.cos(np.radians(max_deg))


def _passes(px, py, a, b, reach, margin):
    """Whether the segment a-b runs past (px, py) within ``reach`` with both its ends more than
    ``margin`` away along it."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    L = float(np.hypot(*d))
    if L <= 2 * margin:
        return False
    t = ((px - a[0]) * d[0] + (py - a[1]) * d[1]) / L
    return margin < t < L - margin and abs((px - a[0]) * d[1] - (py - a[1]) * d[0]) / L <= reach


def under_its_lines(cx, cy, footprint, lines_xy, margin_m, under_line_m, max_side_ratio, cell_m) -> bool:
    """Whether a tower candidate at (cx, cy), footprint cell centres ``footprint``, stands under
    the conductors ``lines_xy`` that reach within ``margin_m`` of it along their length (see
    find_pylons)."""
    left, right, reach = np.inf, np.inf, np.inf
    for a, b in lines_xy:
        a, b = np.asarray(a, float), np.asarray(b, float)
        L = float(np.hypot(*(b - a)))
        if L == 0:
            continue
        u = (b - a) / L
        n = np.array([-u[1], u[0]])
        t = (cx - a[0]) * u[0] + (cy - a[1]) * u[1]
        if not -margin_m <= t <= L + margin_m:
            continue
        off = (cx - a[0]) * n[0] + (cy - a[1]) * n[1]
        if off >= 0:
            left = min(left, off)
        else:
            right = min(right, -off)
        reach = min(reach, float(np.abs((footprint - a) @ n).min()))
    near, far = min(left, right), max(left, right)
    if not np.isfinite(near):  # no conductor along it to tell
        return True
    return near <= under_line_m or far <= max_side_ratio * near or reach <= cell_m


def _point_segment_distance(px, py, a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    t = float(np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / max(float(d @ d), 1e-12), 0.0, 1.0))
    return float(np.hypot(px - a[0] - t * d[0], py - a[1] - t * d[1]))

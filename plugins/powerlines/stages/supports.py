"""Stage 6, supports: pylons and poles, tall columns under the lines where spans end or that the
wires run through (``pylons`` layer and tower points); a line that never leaves a tower's
footprint is one of its arms, not a conductor; with the supports known, a stack's wires grow up
to the pole or tower they face, and a wire continued across a tower's footprint is the tower's.

From here the labels are also kept per input point (``State.conductor_of``)."""

from __future__ import annotations

import time

import geopandas as gpd
import numpy as np
from shapely.geometry import LineString, Point

from ..core import catenary, find_poles, find_pylons, find_towers_passed_through, grow_span_ends, pylon_points
from ..rules import POLE_FOOTPRINT_M, POLE_TAKES_M, TOWERS, TOWER_SHAPE, Rules
from ..state import CandidateLabels, State, Supports, Wires
from ..wire_sets import keep_conductors


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, vu, params, low = scene.pc, scene.hu, scene.vu, settings.params, scene.low
    timings, grown = st.timings, st.grown
    lines, geo, spans = st.wires.as_tuple()
    keep, line_of, wire_of_pt = st.labels.as_tuple()
    t = time.perf_counter()
    conductor_of = np.full(len(pc), -1)  # per input point: the conductor it is a wire point of
    conductor_of[keep] = line_of
    passed_by = []
    pylons, tower_pt, found = pylons_layer(scene, conductor_of, Wires(lines, geo, spans), params, passed_by=passed_by,
                                           rules=settings.rules)
    with_arms, own_arms = [], []
    wire_ends = fitted_wire_ends(geo, spans, params["max_rms_3d_m"])
    arms = arm_lines(lines["conductors"], found, hu, settings.rules.towers.end_radius_m, with_arms=with_arms,
                     wire_ends=wire_ends)
    # a tower the wires run through (a suspension tower where the 3D step did not cut them) has
    # more spans past it than ending at it, as a tree has; a line that never leaves it is its arm
    arms |= arm_lines(lines["conductors"], passed_by, hu, settings.rules.towers.end_radius_m, with_arms=own_arms,
                      own_only=True, wire_ends=wire_ends)
    if arms:
        kept = [i for i in range(len(geo)) if i not in arms]
        lines, geo, spans, line_of, wire_of_pt = keep_conductors(kept, lines, geo, spans, line_of, wire_of_pt)
        conductor_of[keep] = line_of
        # a tower whose arms were taken for conductors stays one, though without their span ends
        # too few may end at it (a suspension tower the wires run through)
        also = [found[i] for i in sorted(set(with_arms))] + [passed_by[i] for i in sorted(set(own_arms))]
        pylons, tower_pt, found = pylons_layer(scene, conductor_of, Wires(lines, geo, spans), params, also=also,
                                               rules=settings.rules)
    if params["grow_spans"] and found:
        # with the supports found, a stack's wires grow up to the pole or tower they face: in a
        # sparse stack the other wires' few points made the columns too noisy to tell the support
        t_grow = time.perf_counter()
        g_line, g_wire = grow_span_ends(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu,
                                        conductor_of[low] < 0, params["max_rms_3d_m"],
                                        max_gap_m=2 * params["v_max_m"], reach_m=2 * params["s_min_m"],
                                        supports=np.array([[p.x, p.y] for p in found]), rules=settings.rules.grow)
        on = g_line >= 0
        keep = np.r_[keep, low[on]]
        line_of, wire_of_pt = np.r_[line_of, g_line[on]], np.r_[wire_of_pt, g_wire[on]]
        conductor_of[low[on]] = g_line[on]
        grown = np.r_[grown, low[on]]
        grow_time = time.perf_counter() - t_grow  # counted with the growth, not the pylons
        timings["grow_spans_s"] = timings.get("grow_spans_s", 0.0) + grow_time
        t += grow_time
        if on.any():  # a tower's footprint may have grown along the wires' points now taken
            pylons, tower_pt, found = pylons_layer(scene, conductor_of, Wires(lines, geo, spans), params, also=found,
                                                   rules=settings.rules)
    if len(grown) and found:
        # a wire continued across a tower's footprint is the tower's (the producer's convention
        # on AHN4: the wire between the arms is class 15); one grown up to a pole stays wire
        on_tower = np.zeros(len(grown), bool)
        for p in found:
            if p.extent_m() > POLE_FOOTPRINT_M:
                on_tower |= pylon_points(p, pc.x[grown] * hu, pc.y[grown] * hu)
        gone = grown[on_tower & (conductor_of[grown] >= 0)]
        conductor_of[gone] = -1
        tower_pt[gone] = True
    timings["pylons_s"] = time.perf_counter() - t
    st.grown, st.conductor_of, st.supports = grown, conductor_of, Supports(pylons, tower_pt, found)
    st.wires, st.labels = Wires(lines, geo, spans), CandidateLabels(keep, line_of, wire_of_pt)
    return st


def pylons_layer(scene, conductor_of, wires: Wires, params, also=(), passed_by=None, rules=None):
    """The ``pylons`` layer (PointZ at each tower's base) and the mask of tower points, given each
    point's conductor so far (``conductor_of``, -1: none) and the ``wires`` found; towers of
    ``also`` (found before) are kept where none is found within 2 m of them now. ``rules``: the run's
    ``settings.Rules`` (None: the plugin's)."""
    rules = rules or Rules()
    pc, hag, ground_cls, hu, vu, dtm = scene.pc, scene.hag, scene.ground_cls, scene.hu, scene.vu, scene.dtm
    _, geo, spans = wires.as_tuple()
    cond = wires.lines["conductors"]
    off = np.isfinite(hag) & (hag >= TOWER_SHAPE.from_ground_m) & (conductor_of < 0) & (ground_cls != 2) & \
        (ground_cls != 7)
    ends, end_z, span_lines = [], [], []
    for sp in spans:
        if not sp.rms <= params["max_rms_3d_m"]:  # no catenary fits it: no evidence of a span ending here
            continue
        if sp.chained:  # its near end is its support's, found already; its far end, where the view stopped
            continue
        a, d, _, _ = geo[sp.conductor]
        normal = np.array([-d[1], d[0]])
        e = [a + s_ * d + (sp.offset + sp.offset_slope * s_) * normal for s_ in (sp.s_from, sp.s_to)]
        ends += e
        end_z += [catenary(s_, sp.z0, sp.s0, sp.c) for s_ in (sp.s_from, sp.s_to)]
        span_lines.append(tuple(e))
    ends = np.asarray(ends, float).reshape(-1, 2)
    ground_z = dtm.sample(ends[:, 0] / hu, ends[:, 1] / hu) * vu if len(ends) else np.zeros(0)
    lines_xy = [(np.array(g.coords[0]) * hu, np.array(g.coords[-1]) * hu) for g in cond.geometry]
    headings = [float(np.degrees(np.arctan2(b[1] - a[1], b[0] - a[0])) % 180.0) for a, b in lines_xy]
    wire = conductor_of >= 0
    off_xyh = (pc.x[off] * hu, pc.y[off] * hu, hag[off])
    wire_xyh = (pc.x[wire] * hu, pc.y[wire] * hu, hag[wire])
    found = find_pylons(*off_xyh, ends, np.asarray(end_z) - ground_z, headings, lines_xy,
                        top_share=params["pylon_top_share"], span_lines=span_lines, passed_by=passed_by,
                        wire_xyh=wire_xyh, rules=rules.towers)
    found += [t for t in also if all(np.hypot(t.x - q.x, t.y - q.y) > 2.0 for q in found)]
    poles = find_poles(*off_xyh, *wire_xyh, headings, lines_xy, span_ends=ends,
                       span_end_hag=np.asarray(end_z) - ground_z, top_share=params["pylon_top_share"],
                       rules=rules.poles)
    if poles:
        # where a pole carries the wires, a tower found beside it is the crown next to the pole
        # that took its span ends (a street scan's trees reach the wires' height)
        pxy = np.array([[q.x, q.y] for q in poles])
        found = [t for t in found if np.hypot(*(pxy - [t.x, t.y]).T).min() > POLE_TAKES_M] + poles
    # suspension towers the wires run through with no span ending there
    found += find_towers_passed_through(*off_xyh, *wire_xyh, headings, lines_xy, known=found,
                                        top_share=params["pylon_top_share"], rules=rules.passed_through)
    tower = np.zeros(len(pc), bool)
    # foundations and what the ground filter leaves under a tower (< 1 m) are not the tower
    cand = np.flatnonzero(np.isfinite(hag) & (hag >= TOWER_SHAPE.from_ground_m) & (conductor_of < 0) & (ground_cls != 2))
    rows, geoms = [], []
    for i, p in enumerate(found):
        inside = pylon_points(p, pc.x[cand] * hu, pc.y[cand] * hu, hag[cand])
        tower[cand[inside]] = True
        x, y = p.x / hu, p.y / hu
        z = float(dtm.sample(np.array([x]), np.array([y]))[0])
        geoms.append(Point(x, y, z))
        rows.append({"pylon": i, "kind": p.kind, "height_m": round(p.height_m, 2), "n_spans": p.n_spans,
                     "line_heading_deg": round(p.heading_deg, 2), "n_points": int(inside.sum())})
    gdf = gpd.GeoDataFrame(rows, geometry=geoms, crs=pc.crs) if rows else gpd.GeoDataFrame(
        {"pylon": np.array([], np.int64), "kind": np.array([], str)}, geometry=gpd.GeoSeries([], crs=pc.crs),
        crs=pc.crs)
    gdf.attrs["geometry_type"] = "Point Z"
    return gdf, tower, found


def arm_lines(cond, found, hu, end_radius_m: float = TOWERS.end_radius_m,
              min_angle_deg: float = TOWER_SHAPE.arm_min_angle_deg, with_arms=None,
          own_only: bool = False, wire_ends=None) -> set:
    """Conductors whose both ends lie within a tower's reach (its footprint, and at least the
    ``end_radius_m`` within which find_pylons counts span ends as its) and that cross a longer
    conductor reaching the same tower at ``min_angle_deg`` or more: straight, level lines that
    never leave the tower, across its line, are its arms. (A short wire to a pole with nothing
    across it stays a wire.) A conductor within the tower's own extent (its cells' reach and a
    metre) is part of it whatever crosses it: the arms of a tower whose line is not found there
    (a gap in the data beside it). ``with_arms``, a list, gets the indices of the towers with arms;
    ``own_only``: only the lines within a tower's own extent. ``wire_ends``: per conductor, the
    ends of the stretch its fitting spans cover, where known (a tower's cross-arm drawn by the
    Hough through the wire crossings beside it reaches far past the tower; its only wire is the
    arm)."""
    if not found or not len(cond):
        return set()

    towers = []
    for p in found:
        far = p.extent_m()
        # a pole's arm is a cross arm of a metre or two: the wires leaving it across the street are wires
        margin = TOWER_SHAPE.arm_margin_m
        towers.append((p.x, p.y, far + TOWER_SHAPE.pole_arm_m, far + margin) if p.kind == "pole" else
                      (p.x, p.y, max(end_radius_m, far), far + margin))
    lines = [LineString(np.asarray(g.coords)[:, :2] * hu) for g in cond.geometry]
    ends = [np.asarray(g.coords)[[0, -1]] for g in lines]
    unit = [(e[1] - e[0]) / max(np.hypot(*(e[1] - e[0])), 1e-9) for e in ends]
    if wire_ends is not None:
        ends = [np.asarray(w) if w is not None else e for w, e in zip(wire_ends, ends)]
    arms = set()
    for k, (x, y, reach, own) in enumerate(towers):
        mine = {i for i, e in enumerate(ends) if (np.hypot(e[:, 0] - x, e[:, 1] - y) <= own).all()}
        inside = [] if own_only else \
            [i for i, e in enumerate(ends) if (np.hypot(e[:, 0] - x, e[:, 1] - y) <= reach).all()]
        at = Point(x, y)
        for i in inside:
            across = [j for j, g in enumerate(lines) if j not in inside and g.distance(at) <= reach
                      and abs(float(unit[i] @ unit[j])) <= np.cos(np.radians(min_angle_deg))]
            if across:
                mine.add(i)
        if mine and with_arms is not None:
            with_arms.append(k)
        arms |= mine
    return arms


def fitted_wire_ends(geo, spans, max_rms: float) -> list:
    """Per conductor, the plan ends of the stretch its fitting spans cover along its line (None
    where no span fits)."""
    reach = {}
    for sp in spans:
        if sp.rms <= max_rms:
            lo, hi = reach.get(sp.conductor, (np.inf, -np.inf))
            reach[sp.conductor] = (min(lo, sp.s_from), max(hi, sp.s_to))
    out = []
    for li, (a, d, _, _) in enumerate(geo):
        out.append(np.array([a + reach[li][0] * d, a + reach[li][1] * d]) if li in reach else None)
    return out

"""Stage 2, plan lines: the top-hat (``tophat``), the tiled Hough (``hough-lines``) and the 3D
step (wires along each line split by height and continuity, a catenary per span) on the
wire-like candidates; V_max derived from the wires' point spacing where it is automatic; short
lines along a longer one folded into it."""

from __future__ import annotations

import time

import numpy as np

from ..core import band_owner, conductors_3d, ribbon_lines, stands_clear, thin_across, twin_lines, wire_point_spacing
from ..plan_geometry import merge_twins, realign, redrawn_lines
from ..rules import GAP_SPACINGS, STANDS_CLEAR_MAX, STANDS_CLEAR_RADIUS_M, Rules
from ..state import CandidateLabels, State, Wires
from ..wire_sets import fold_stubs, keep_conductors


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, params, timings = scene.pc, scene.hu, settings.params, st.timings
    keep = scene.candidates[scene.linear]
    found = lines_and_wires(pc, keep, scene.hag, settings.cell_m, params, ctx, timings, rules=settings.rules)
    lines, geo, spans, line_of, wire_of_pt, n_th = found
    spacing = wire_point_spacing(spans, geo, pc.x[keep] * hu, pc.y[keep] * hu, line_of, wire_of_pt,
                                 params["max_rms_3d_m"], 2 * params["v_max_m"])
    if settings.derive_v_max(spacing):
        for k in ("n_lines_realigned", "n_twin_lines_merged"):  # the lines of the run kept are the ones counted
            timings.pop(k, None)
        lines, geo, spans, line_of, wire_of_pt, n_th = lines_and_wires(pc, keep, scene.hag, settings.cell_m, params,
                                                                       ctx, timings, rules=settings.rules)
    lines, geo, spans, line_of, wire_of_pt = fold_stubs(lines, geo, spans, line_of, wire_of_pt, hu, params)
    st.wires, st.labels = Wires(lines, geo, spans), CandidateLabels(keep, line_of, wire_of_pt)
    st.n_tophat, st.wire_spacing_m = n_th, spacing
    return st


def lines_and_wires(pc, keep, hag, cell_used, params, ctx, timings, min_fit_share=0.0, optional=False, rules=None):
    """Top-hat, tiled Hough and the 3D step on the wire-like candidates ``keep`` (indices into
    ``pc``): (Hough layers, line geometry, spans, per-keep conductor and wire, top-hat size);
    None when ``optional`` and the top-hat keeps too few points for a line. ``rules``: the run's
    ``settings.Rules`` (None: the plugin's)."""
    rules = rules or Rules()
    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    t = time.perf_counter()
    sub = pc.subset(keep)
    th = ctx.call("tophat", {"points": sub}, cell_size_m=cell_used,
                  max_points_per_cell=params["max_points_per_cell"]).outputs["points"]
    timings["tophat_s"] = timings.get("tophat_s", 0.0) + time.perf_counter() - t
    if optional and len(th) < params["min_votes"]:  # no line can reach min_votes: nothing to search
        return None
    t = time.perf_counter()
    hp = {k: params[k] for k in ("theta_step_deg", "rho_step_m", "band_m", "min_votes", "s_min_m", "v_max_m",
                                 "tile_size_m", "overlap_m", "merge_gap_m", "fit_points", "crossing_validation")}
    # its crossings are numbered over lines the 3D step may drop: they are computed once at the end
    # with V_max automatic, the second pass (the wire-like points no first-pass wire took) takes a
    # validated line's runs at its own points' spacing: a wire much sparser than the rest (an earth
    # wire high over a stack seen from the street) is seen in stretches too short for the 3D step
    sparse = GAP_SPACINGS if params["v_max_auto"] and min_fit_share else 0.0
    found = ctx.call("hough-lines", {"points": th}, v_max_spacings=sparse, **hp).outputs["lines"]
    lines = {k: found[k] for k in ("conductors", "conductor_segments")}
    timings["hough_s"] = timings.get("hough_s", 0.0) + time.perf_counter() - t
    # wires along each 2D line, split by height and continuity, a catenary per span
    t = time.perf_counter()
    geo = []
    for g in lines["conductors"].geometry:
        (ax, ay), (bx, by) = g.coords[0], g.coords[-1]
        a = np.array([ax, ay]) * hu
        d = np.array([bx - ax, by - ay]) * hu
        L = float(np.hypot(*d))
        geo.append((a, d / L, 0.0, L))
    px, py = pc.x[keep] * hu, pc.y[keep] * hu
    # three or more wires side by side within twice band_m (a horizontal three-phase line): the
    # Hough's lines lie between them, leaning from one to the next; one line per wire instead
    redrawn = ribbon_lines(geo, px, py, params["band_m"] * hu, params["s_min_m"], 2 * params["v_max_m"],
                           rules=rules.ribbons)
    if redrawn is not None:
        geo, source, held = redrawn
        lines = redrawn_lines(lines, geo, source, held, hu)
        timings["n_ribbon_lines_added"] = timings.get("n_ribbon_lines_added", 0) + len(geo) - len(set(source))

    def step_3d(geo, only=None):
        return conductors_3d(
            geo, px, py, pc.z[keep] * vu, params["band_3d_m"], z_link=1.0,
            s_link=2 * params["v_max_m"], min_span=params["s_min_m"], max_rms=params["max_rms_3d_m"],
            ground_z=(pc.z[keep] * vu - hag[keep]), only=only, rules=rules.wires)

    spans, line_of, wire_of_pt = step_3d(geo)
    before = geo
    lines, geo, turned = realign(lines, geo, spans, params, hu)
    if turned:
        # the 3D step again along the lines whose band's points changed: the turned ones and
        # their neighbours (a line's result depends on its band's points alone)
        was = band_owner(before, px, py, params["band_3d_m"], params["band_3d_m"])
        now = band_owner(geo, px, py, params["band_3d_m"], params["band_3d_m"])
        redo = {int(li) for li in np.unique(np.r_[was[was != now], now[was != now]]) if li >= 0}
        redo |= {li for li in range(len(geo)) if geo[li] is not before[li]}
        new_spans, new_line, new_wire = step_3d(geo, only=redo)
        spans = sorted([sp for sp in spans if sp.conductor not in redo] + new_spans, key=lambda sp: sp.conductor)
        mine = np.isin(now, list(redo)) | np.isin(was, list(redo))
        line_of[mine], wire_of_pt[mine] = new_line[mine], new_wire[mine]
        timings["n_lines_realigned"] = timings.get("n_lines_realigned", 0) + turned
    # lines either side of one wire (a ribbon's, drawn between its phases) are one line: the 3D
    # step then tells its phases apart across it, and side_by_side draws each
    twins = twin_lines(spans, geo, params["max_rms_3d_m"], params["s_min_m"], params["band_3d_m"])
    if twins:
        lines, geo, merged = merge_twins(lines, geo, twins, hu)
        spans, line_of, wire_of_pt = step_3d(geo)
        timings["n_twin_lines_merged"] = timings.get("n_twin_lines_merged", 0) + merged
    # a conductor is a wire in 3D too: a catenary span at least S_min long that fits its points,
    # is thin across the line and hangs gently (pylon members, roof edges and a crown's edge are
    # straight in plan but not wires); shorter pieces only add wire points to a conductor that has one
    good = {sp.conductor for sp in spans if sp.rms <= params["max_rms_3d_m"] and sp.s_to - sp.s_from >= params["s_min_m"]
            and thin_across(sp)
            and abs(np.sinh((sp.s_to - sp.s0) / sp.c)) <= 0.5 and abs(np.sinh((sp.s_from - sp.s0) / sp.c)) <= 0.5}
    if sparse and len(lines["conductors"]):  # (an empty layer has no columns)
        # a line validated only at its own spacing is a wire standing clear in the air (an earth
        # wire over its stack), not rows of a sparse roof or crown far from the scanner
        wide = np.flatnonzero(lines["conductors"]["v_max_m"].to_numpy() * hu > params["v_max_m"] + 1e-9)
        good -= {int(li) for li in wide if not stands_clear_of(pc, hag, keep[line_of == li], params["height_min_m"])}
    if min_fit_share:  # and most of what its spans hold fits them
        tot, fit = np.zeros(len(geo)), np.zeros(len(geo))
        for sp in spans:
            tot[sp.conductor] += sp.n_points
            fit[sp.conductor] += sp.n_points if sp.rms <= params["max_rms_3d_m"] else 0
        good = {c for c in good if fit[c] >= min_fit_share * tot[c]}
    if params["validate_3d"]:
        lines, geo, spans, line_of, wire_of_pt = keep_conductors(sorted(good), lines, geo, spans, line_of, wire_of_pt)
    timings["conductors_3d_s"] = timings.get("conductors_3d_s", 0.0) + time.perf_counter() - t
    return lines, geo, spans, line_of, wire_of_pt, len(th)


def stands_clear_of(pc, hag, own, height_min_m: float, radius_m: float = STANDS_CLEAR_RADIUS_M) -> bool:
    """Whether the points ``own`` (indices into ``pc``) have on average at most STANDS_CLEAR_MAX
    other points above ``height_min_m`` within ``radius_m`` (core.stands_clear, on the points
    around them)."""
    if not len(own):
        return True
    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    x, y = pc.x * hu, pc.y * hu
    lo_x, hi_x, lo_y, hi_y = x[own].min() - radius_m, x[own].max() + radius_m, y[own].min() - radius_m, \
        y[own].max() + radius_m
    around = np.flatnonzero((x >= lo_x) & (x <= hi_x) & (y >= lo_y) & (y <= hi_y) & (hag >= height_min_m))
    around = np.union1d(around, own)
    xyz = np.column_stack([x[around], y[around], pc.z[around] * vu])
    return stands_clear(xyz, np.searchsorted(around, own), radius_m, STANDS_CLEAR_MAX)

"""Adapter of the power-line chain ``powerlines``: ground and height above ground (through the
``dtm`` algorithm), candidates, top-hat (``tophat``), tiled 2D Hough with crossings
(``hough-lines``'s core through its algorithm), the 3D conductor step; a GeoPackage."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, Input, LayerMerge, Output, Parameter

# the method's V_max, and how many median point spacings along a wire a gap may span before it
# ends a run: 2.5 m is about 10 spacings on 10 pts/m2 ALS (and 36 on the method's 228 pts/m2), so
# surveys as dense or denser keep the method's value and sparser ones scale it
V_MAX_METHOD_M = 2.5
GAP_SPACINGS = 10.0
STANDS_CLEAR_MAX = 0.5  # other points within 0.5 m of a sparse second-pass wire's points, on average
SETTLE_DRIFT_M = 0.02  # a plan line's drift off its wires' trend that its output is turned for
# a tower found this close to a pole is the pole's (its span ends and a crown beside it)
POLE_TAKES_M = 6.0
# how far a pole's footprint reaches from its base at most (its cross arms, on the 1 m search
# grid); a lattice tower's reaches 4-8 m
POLE_FOOTPRINT_M = 3.0
# a pole's column: within this of its base in plan (its radius and a street scan's lean of the
# base towards the scanner) and more than POLE_HEAD_M under its top (its arms and top insulator)
POLE_CORE_M = 0.3
POLE_HEAD_M = 1.0
# how far from a wire's points a point alone in the air is still taken for its: the closest two
# wires of a line hang on their supports (a ribbon's or a joint-use pole's cables, 0.3-0.5 m)
ALONE_REACH_M = 0.5
# at most this many others within ALONE_AROUND_M of a point alone in the air: a dense scan's
# crown points near a wire hold more (Oakland: most 20 or more)
ALONE_AROUND_M = 1.0
ALONE_MAX_AROUND = 8
# tan 1 deg: a span runs along its line within 1 deg of it (as _along's lines)
ALONG_SLOPE_MAX = 0.01746

REFERENCE = ("Grigillo, Ozvaldič, Vrečko, Kosmatin Fras (2015), Geodetski vestnik 59(2) 246-261 (METHODS.md §1); "
             "3D step: catenary per span (beyond the method's stated 2D limitation)")


def _run(inputs, params, ctx):
    import time

    import numpy as np
    from shapely.geometry import LineString


    from .core import (WIRE_ID_BASE, along_a_surface, grow_span_ends, height_window_top, in_a_surface, in_foliage, local_surface_density, off_their_spans, points_on_spans,
                       shape_classes, wire_point_spacing)

    pc = inputs["points"]
    pc.require_points("powerlines", 100)
    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    timings = {}
    t = time.perf_counter()
    # 1. ground and height above ground, through the DTM algorithm
    # the filter's ground and noise alone (the input's own classes would pass through the DTM's output)
    ground_in = pc if params["ground"] == "file" else pc.with_fields(classification=np.ones(len(pc), np.uint8))
    dres = ctx.call("dtm", {"points": ground_in}, ground=params["ground"], resolution_m=1.0)
    dtm = dres.outputs["dtm"]
    ground_cls = dres.outputs["classified"].classification
    # height above ground (metres) where it is needed: off-ground points (most points are ground)
    off = np.flatnonzero((ground_cls != 2) & (ground_cls != 7))
    hag = np.full(len(pc), -np.inf)
    hag[off] = (pc.z[off] - dtm.sample(pc.x[off], pc.y[off])) * vu
    timings["ground_s"] = time.perf_counter() - t

    # 2. candidates: not ground or noise, height window, first returns where the file has them
    t = time.perf_counter()
    cand = hag >= params["height_min_m"]
    h_max = params["height_max_m"]
    if h_max is None:  # automatic: everything above the window's floor, birds and lone returns left out
        above = np.flatnonzero(cand)
        h_max = height_window_top(hag[above], np.column_stack([pc.x[above] * hu, pc.y[above] * hu,
                                                               pc.z[above] * vu]), link_m=V_MAX_METHOD_M)
    cand &= hag <= h_max
    rn = pc.fields.get("return_number")
    if params["first_returns_only"] and rn is not None and np.any(rn > 0):
        cand &= rn == 1
    idx = np.flatnonzero(cand)
    if len(idx) < 10:  # a field, a road: nothing to find is a result, not an error
        note = (f"only {len(idx)} points stand {params['height_min_m']:g}-{h_max:.1f} m above the ground: no wire "
                "can be there (check height_min_m / height_max_m if there is one)")
        ctx.log.info("powerlines: %s: %s", pc.source, note)
        return _nothing_found(pc, ground_cls, ctx, note, {
            "n_points": len(pc), "n_candidates": int(len(idx)), "height_max_m_used": round(float(h_max), 2),
            "cell_size_m_used": params["cell_size_m"] if params["cell_size_m"] is not None
            else round(params["band_m"] / 3, 3),
            "v_max_m_used": V_MAX_METHOD_M if params["v_max_m"] is None else params["v_max_m"],
            **{k: round(v, 3) for k, v in timings.items()}})
    xyz = np.column_stack([pc.x[idx] * hu, pc.y[idx] * hu, pc.z[idx] * vu])
    # the density of the surfaces around each candidate: first returns per occupied square metre
    # within density_radius_m (roofs and crowns are that dense, wires are not)
    first = (rn == 1) if rn is not None and np.any(rn > 0) and params["first_returns_only"] else None
    density = local_surface_density(pc.x * hu, pc.y * hu, first, radius_m=params["density_radius_m"])
    surface_density = density[idx]
    linear, planar, rugged, steep = shape_classes(xyz - xyz.min(axis=0), params["neighbours"], params["rugged_share"],
                                           params["planar_share"], surface_density)
    keep = idx[linear]
    timings["candidates_s"] = time.perf_counter() - t

    # 3. top-hat filter, 4. tiled Hough (through their algorithms), 5. the 3D step
    # the mask cell must keep conductors band_m apart (the closest the Hough tells apart) in
    # separate cells with an empty one between them, or the opening keeps their band and the
    # top-hat throws the wires away (AHN4's side-by-side conductors at the method's 0.5 m)
    cell_used = params["cell_size_m"] if params["cell_size_m"] is not None else round(params["band_m"] / 3, 3)
    v_max_auto = params["v_max_m"] is None
    params = dict(params, v_max_m=V_MAX_METHOD_M if v_max_auto else params["v_max_m"], v_max_auto=v_max_auto)
    lines, geo, spans, line_of, wire_of_pt, n_th = _lines_and_wires(pc, keep, hag, cell_used, params, ctx, timings)
    spacing = wire_point_spacing(spans, geo, pc.x[keep] * hu, pc.y[keep] * hu, line_of, wire_of_pt,
                                 params["max_rms_3d_m"], 2 * params["v_max_m"])
    if v_max_auto and spacing is not None and GAP_SPACINGS * spacing > params["v_max_m"]:
        # a sparser survey than the method's samples its wires with gaps over V_max every few
        # spans, and each such gap cuts a run: the gap allowed scales with the measured spacing
        params["v_max_m"] = round(GAP_SPACINGS * spacing, 2)
        for k in ("n_lines_realigned", "n_twin_lines_merged"):  # the lines of the run kept are the ones counted
            timings.pop(k, None)
        lines, geo, spans, line_of, wire_of_pt, n_th = _lines_and_wires(pc, keep, hag, cell_used, params, ctx,
                                                                        timings)
    lines, geo, spans, line_of, wire_of_pt = _fold_stubs(lines, geo, spans, line_of, wire_of_pt, hu, params)
    free = keep[line_of < 0]
    if params["second_pass"] and len(free) >= 100:
        # the wire-like points on no wire, searched again: a stretch past a bend in the line whose
        # votes the first line's band took, wires a stronger line outvoted in a tile; what is left
        # is mostly clutter, so a line found there must be mostly wire (half its span points on
        # catenaries that fit)
        t = time.perf_counter()
        counts = {}  # its stage times are second_pass_s; its turned lines count with the first's
        found2 = _lines_and_wires(pc, free, hag, cell_used, params, ctx, counts, min_fit_share=0.5, optional=True)
        if found2 is not None:
            for k in ("n_lines_realigned", "n_twin_lines_merged"):
                timings[k] = timings.get(k, 0) + counts.get(k, 0)
        lines, geo, spans = _add_pass(found2, lines, geo, spans, line_of, wire_of_pt, hu, params)
        timings["second_pass_s"] = time.perf_counter() - t
    n_short = 0
    if params["short_wires"]:
        # what is left may hold wires seen over a few metres only (a mobile scanner's view of a
        # wire across its street): straight 3D runs of S_min / 2, the shortest piece of wire the
        # 3D step fits
        t = time.perf_counter()
        n_free = int((line_of < 0).sum())
        wired = keep[line_of >= 0]
        # the wires of a stack beside a short wire are not clutter around it
        wire_like = np.zeros(len(pc), bool)
        wire_like[idx[linear | steep]] = True
        # a stack's wires one over another make a ribbon on end, whose points the shape test may
        # take for a pole's: they join the search beside a short wire found
        n_keep = len(keep)
        keep = np.r_[keep, idx[steep]]
        line_of, wire_of_pt = np.r_[line_of, np.full(steep.sum(), -1)], np.r_[wire_of_pt, np.full(steep.sum(), -1)]
        found3 = _short_wires(pc, keep[line_of < 0], off, idx[steep], wired, params, hu, vu, n_searched=n_free,
                              wire_like=wire_like[off])
        n_before = len(geo)
        lines, geo, spans = _add_pass(found3, lines, geo, spans, line_of, wire_of_pt, hu, params)
        held = np.r_[np.ones(n_keep, bool), line_of[n_keep:] >= 0]
        keep, line_of, wire_of_pt = keep[held], line_of[held], wire_of_pt[held]
        n_short = len(geo) - n_before
        timings["short_wires_s"] = time.perf_counter() - t
    n_sibling = 0
    if params["sibling_wires"]:
        # a line's phases hang side by side with one sag: beside each span, the points of a phase
        # too sparse to find alone share one offset across it and one height above its catenary
        t = time.perf_counter()
        lines, geo, spans, line_of, wire_of_pt, n_sibling = _sibling_wires(pc, keep, lines, geo, spans, line_of,
                                                                           wire_of_pt, params, hu, vu)
        timings["sibling_wires_s"] = time.perf_counter() - t

    # candidates the shape test left out that lie on a fitted span are its points too: steep ones
    # (next to a pole top a wire point's neighbourhood leans on the pole), and flat or rough ones
    # right on it, within 0.1 m in plan (a ribbon's phases or a crown shared their neighbourhood)
    # (steep points a short wire took are on a wire already)
    for more, lateral_m in ((np.setdiff1d(idx[steep], keep), 0.25), (idx[~linear & ~steep], 0.1)):
        m_line, m_wire = points_on_spans(spans, geo, pc.x[more] * hu, pc.y[more] * hu, pc.z[more] * vu,
                                         params["max_rms_3d_m"], lateral_m=lateral_m)
        on = m_line >= 0
        keep = np.r_[keep, more[on]]
        line_of, wire_of_pt = np.r_[line_of, m_line[on]], np.r_[wire_of_pt, m_wire[on]]

    # a span's catenary continued past its ends picks up its wire where the candidates stopped
    # (under the height window on a slope; next to a tower, where the shape test sees the structure)
    grown = np.zeros(0, np.int64)
    low = off[hag[off] >= 1.0]  # what the growth and the next spans search: off the ground, 1 m up
    if params["grow_spans"]:
        t = time.perf_counter()
        g_line, g_wire = grow_span_ends(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu,
                                        ~np.isin(low, keep[line_of >= 0]), params["max_rms_3d_m"],
                                        max_gap_m=2 * params["v_max_m"], reach_m=2 * params["s_min_m"])
        on = g_line >= 0
        grown = low[on]
        # candidates on no wire yet are relabelled in place, the rest appended
        pos = np.full(len(pc), -1, np.int64)
        pos[keep] = np.arange(len(keep))
        at = pos[grown]
        line_of[at[at >= 0]], wire_of_pt[at[at >= 0]] = g_line[on][at >= 0], g_wire[on][at >= 0]
        keep = np.r_[keep, grown[at < 0]]
        line_of, wire_of_pt = np.r_[line_of, g_line[on][at < 0]], np.r_[wire_of_pt, g_wire[on][at < 0]]
        timings["grow_spans_s"] = time.perf_counter() - t

    # a conductor in a surface is a roof's scan row or an eave seen from the street; one in a
    # volume, points of a crown that line up
    t = time.perf_counter()
    crowded = []
    not_wires = _not_wires(spans, geo, pc.x[idx] * hu, pc.y[idx] * hu, pc.z[idx] * vu, params["max_rms_3d_m"],
                           below=(pc.x[off] * hu, pc.y[off] * hu, pc.z[off] * vu), crowded=crowded)
    fitting = {k for k, sp in enumerate(spans) if sp.rms <= params["max_rms_3d_m"]}
    # a line whose every span is so is none (its spans' pooled contrast may pass on a few dense ones)
    not_wires |= {li for li in {spans[k].conductor for k in crowded}
                  if all(k in crowded for k in fitting if spans[k].conductor == li)}
    crowded = [spans[k] for k in crowded if spans[k].conductor not in not_wires]
    n_crowded = len(crowded)
    timings["not_wires_s"] = time.perf_counter() - t
    if not_wires:
        kept = [i for i in range(len(geo)) if i not in not_wires]
        lines, geo, spans, line_of, wire_of_pt = _keep_conductors(kept, lines, geo, spans, line_of, wire_of_pt)
    if crowded:
        # a span no denser than around it, on a line that holds wires: crown points lined up beside them
        spans, line_of, wire_of_pt = _drop_spans(crowded, spans, geo, pc.x[keep] * hu, pc.y[keep] * hu, line_of,
                                                 wire_of_pt)
    n_next = 0
    if params["next_spans"] and spans:
        # past its last support a wire hangs in a new catenary; seen sparsely among crowns, the
        # shape test and the Hough had too few of its points
        t = time.perf_counter()
        lines, geo, spans, keep, line_of, wire_of_pt, n_next = _next_spans(pc, low, keep, lines, geo, spans, line_of,
                                                                         wire_of_pt, params, hu, vu)
        timings["next_spans_s"] = time.perf_counter() - t
    n_bridges = 0
    if params["bridge_gaps"] and spans:
        # between two pieces of a wire on one catenary (it ran through a crown): the wire
        t = time.perf_counter()
        lines, geo, spans, keep, line_of, wire_of_pt, n_bridges = _bridge_gaps(
            pc, low, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu)
        timings["bridge_gaps_s"] = time.perf_counter() - t

    # 6. pylons: tall columns under the lines where spans end; a line that never leaves a tower's
    # footprint is one of its arms, not a conductor
    t = time.perf_counter()
    conductor_of = np.full(len(pc), -1)  # per input point: the conductor it is a wire point of
    conductor_of[keep] = line_of
    passed_by = []
    pylons, tower_pt, found = _pylons(pc, hag, ground_cls, conductor_of, spans, geo, lines["conductors"], hu, vu, dtm,
                                      params, passed_by=passed_by)
    with_arms, own_arms = [], []
    wire_ends = _wire_ends(geo, spans, params["max_rms_3d_m"])
    arms = _arms(lines["conductors"], found, hu, with_arms=with_arms, wire_ends=wire_ends)
    # a tower the wires run through (a suspension tower where the 3D step did not cut them) has
    # more spans past it than ending at it, as a tree has; a line that never leaves it is its arm
    arms |= _arms(lines["conductors"], passed_by, hu, with_arms=own_arms, own_only=True, wire_ends=wire_ends)
    if arms:
        kept = [i for i in range(len(geo)) if i not in arms]
        lines, geo, spans, line_of, wire_of_pt = _keep_conductors(kept, lines, geo, spans, line_of, wire_of_pt)
        conductor_of[keep] = line_of
        # a tower whose arms were taken for conductors stays one, though without their span ends
        # too few may end at it (a suspension tower the wires run through)
        pylons, tower_pt, found = _pylons(pc, hag, ground_cls, conductor_of, spans, geo, lines["conductors"], hu, vu,
                                          dtm, params, also=[found[i] for i in sorted(set(with_arms))] +
                                          [passed_by[i] for i in sorted(set(own_arms))])
    if params["grow_spans"] and found:
        # with the supports found, a stack's wires grow up to the pole or tower they face: in a
        # sparse stack the other wires' few points made the columns too noisy to tell the support
        t_grow = time.perf_counter()
        g_line, g_wire = grow_span_ends(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu,
                                        conductor_of[low] < 0, params["max_rms_3d_m"],
                                        max_gap_m=2 * params["v_max_m"], reach_m=2 * params["s_min_m"],
                                        supports=np.array([[p.x, p.y] for p in found]))
        on = g_line >= 0
        keep = np.r_[keep, low[on]]
        line_of, wire_of_pt = np.r_[line_of, g_line[on]], np.r_[wire_of_pt, g_wire[on]]
        conductor_of[low[on]] = g_line[on]
        grown = np.r_[grown, low[on]]
        grow_time = time.perf_counter() - t_grow  # counted with the growth, not the pylons
        timings["grow_spans_s"] = timings.get("grow_spans_s", 0.0) + grow_time
        t += grow_time
        if on.any():  # a tower's footprint may have grown along the wires' points now taken
            pylons, tower_pt, found = _pylons(pc, hag, ground_cls, conductor_of, spans, geo, lines["conductors"], hu,
                                              vu, dtm, params, also=found)
    if len(grown) and found:
        # a wire continued across a tower's footprint is the tower's (the producer's convention
        # on AHN4: the wire between the arms is class 15); one grown up to a pole stays wire
        from .core import pylon_points

        on_tower = np.zeros(len(grown), bool)
        for p in found:
            if p.extent_m() > POLE_FOOTPRINT_M:
                on_tower |= pylon_points(p, pc.x[grown] * hu, pc.y[grown] * hu)
        gone = grown[on_tower & (conductor_of[grown] >= 0)]
        conductor_of[gone] = -1
        tower_pt[gone] = True
    timings["pylons_s"] = time.perf_counter() - t
    n_pole_wires = 0
    if params["short_wires"] and any(p.kind == "pole" for p in found):
        # with the poles known, a wire seen over a few metres where it leaves one (too short to
        # join the wires found as short_wires asks)
        t = time.perf_counter()
        more = np.setdiff1d(idx[linear], keep)  # (the growth dropped none; the rest are in keep)
        n_keep = len(keep)
        keep = np.r_[keep, more]
        line_of, wire_of_pt = np.r_[line_of, np.full(len(more), -1)], np.r_[wire_of_pt, np.full(len(more), -1)]
        free = keep[line_of < 0]
        found4 = _wires_from_poles(pc, free, ~tower_pt[free] & np.isin(free, idx[linear]), off, idx[linear | steep],
                                   [p for p in found if p.kind == "pole"], dtm, params, hu, vu)
        if found4 is not None:
            n_before, was, old = len(geo), line_of < 0, {id(sp) for sp in spans}
            lines, geo, spans = _add_pass(found4, lines, geo, spans, line_of, wire_of_pt, hu, params)
            n_pole_wires = len(geo) - n_before
            now = was & (line_of >= 0)
            conductor_of[keep[now]] = line_of[now]
        held = np.r_[np.ones(n_keep, bool), line_of[n_keep:] >= 0]
        keep, line_of, wire_of_pt = keep[held], line_of[held], wire_of_pt[held]
        if found4 is not None:
            # the rest of their points, off the run's tolerance or not wire-like (as for the spans
            # found before: next to a pole top a wire point's neighbourhood leans on the pole)
            more = low[(conductor_of[low] < 0) & ~tower_pt[low]]
            m_line, m_wire = points_on_spans([sp for sp in spans if id(sp) not in old], geo, pc.x[more] * hu,
                                             pc.y[more] * hu, pc.z[more] * vu, params["max_rms_3d_m"],
                                             lateral_m=0.25)
            on = m_line >= 0
            keep = np.r_[keep, more[on]]
            line_of, wire_of_pt = np.r_[line_of, m_line[on]], np.r_[wire_of_pt, m_wire[on]]
            conductor_of[more[on]] = m_line[on]
        timings["pole_wires_s"] = time.perf_counter() - t

    # a wire's points lie on its plan trend; the foliage it runs through, on its catenary in height,
    # scatters across it
    t = time.perf_counter()
    wire_pt = np.flatnonzero(conductor_of >= 0)
    wire_of_input = np.full(len(pc), -1)
    wire_of_input[keep] = wire_of_pt
    clutter = np.flatnonzero(np.isfinite(hag) & (hag >= 1.0) & (conductor_of < 0))
    off_trend = wire_pt[off_their_spans(spans, geo, pc.x[wire_pt] * hu, pc.y[wire_pt] * hu, pc.z[wire_pt] * vu,
                                        conductor_of[wire_pt], wire_of_input[wire_pt], params["max_rms_3d_m"],
                                        clutter_xyz=np.column_stack([pc.x[clutter] * hu, pc.y[clutter] * hu,
                                                                     pc.z[clutter] * vu]))]
    conductor_of[off_trend] = -1
    # where a wire runs through a crown, the crown's points on its curve may be its span's own (and
    # set the span's lateral tolerance): foliage surrounds them, denser than the wire's core
    from scipy.spatial import cKDTree

    wire_pt = np.flatnonzero(conductor_of >= 0)
    around = np.flatnonzero(np.isfinite(hag) & (hag >= 1.0))
    around_xyz = np.column_stack([pc.x[around] * hu, pc.y[around] * hu, pc.z[around] * vu])
    around_tree = cKDTree(around_xyz) if len(around) else None
    wires = (spans, geo, pc.x[wire_pt] * hu, pc.y[wire_pt] * hu, pc.z[wire_pt] * vu, conductor_of[wire_pt],
             wire_of_input[wire_pt], params["max_rms_3d_m"], around_xyz)
    foliage = wire_pt[in_foliage(*wires, around_tree=around_tree)]
    # a line whose points lie in a surface (the tops of crowns, a roof's rows) or along one (a sparse
    # roof's scan row or eave) is none
    around_wire = np.where(conductor_of[around] >= 0, conductor_of[around] * WIRE_ID_BASE + wire_of_input[around], -1)
    surfaces = in_a_surface(*wires, around_wire, around_tree=around_tree) | \
        along_a_surface(*wires, around_wire, around_tree=around_tree)
    conductor_of[foliage] = -1
    if surfaces:
        kept = [i for i in range(len(geo)) if i not in surfaces]
        lines, geo, spans, conductor_of, wire_of_input = _keep_conductors(kept, lines, geo, spans, conductor_of,
                                                                          wire_of_input)
    timings["off_trend_s"] = time.perf_counter() - t
    if params["sibling_wires"] and spans:
        # one over another (a joint-use pole's cables), among every candidate: a stack's wires make
        # a ribbon on end that the shape test takes for a surface (searched once the lines in a
        # surface are gone: a facade's scan rows hang one over another under such a line)
        t = time.perf_counter()
        spans, n_stacked = _stacked_wires(pc, idx[(conductor_of[idx] < 0) & ~tower_pt[idx]], geo, spans,
                                          conductor_of, wire_of_input, params, hu, vu)
        n_sibling += n_stacked
        timings["sibling_wires_s"] = timings.get("sibling_wires_s", 0.0) + time.perf_counter() - t

    # wires the 3D step told apart across one Hough line (a ribbon's phases closer than band_m)
    # are conductors of their own in plan
    lines, geo, spans, conductor_of, wire_of_input, n_side = _side_by_side(lines, geo, spans, conductor_of,
                                                                           wire_of_input, pc.x * hu, pc.y * hu,
                                                                           params, hu)
    n_alone, max_around = 0, None
    fitted_of = conductor_of  # the lone points taken next do not reach a line any further
    if params["alone_beside_wires"] and (conductor_of >= 0).any():
        # points alone in the air right beside a wire are its (or a wire's hanging beside it): the
        # fits' tolerance left them out; not those the foliage and trend tests just took off
        t = time.perf_counter()
        from .core import alone_beside_wires

        free = (conductor_of[around] < 0) & ~tower_pt[around]
        free[np.isin(around, np.r_[foliage, off_trend])] = False
        # alone: fewer others than a quarter of what a surface of the survey's density through
        # the ball holds (a sparse survey's crown edges are as empty as a dense one's wires)
        max_around = min(ALONE_MAX_AROUND, int(np.median(surface_density) * np.pi * ALONE_AROUND_M ** 2 / 4))
        taken, via = alone_beside_wires(around_xyz, conductor_of[around] >= 0, free, reach_m=ALONE_REACH_M,
                                        around_m=ALONE_AROUND_M, max_around=max_around, tree=around_tree)
        conductor_of = conductor_of.copy()
        conductor_of[around[taken]] = conductor_of[around[via]]
        wire_of_input[around[taken]] = wire_of_input[around[via]]
        n_alone = len(taken)
        timings["alone_beside_wires_s"] = time.perf_counter() - t
    n_pole_column = 0
    poles = [p for p in found if p.extent_m() <= POLE_FOOTPRINT_M]
    if poles and (conductor_of >= 0).any():
        # a wire point inside a pole's column under its head is the pole's: a cable's end clamped
        # to its side, which the span's growth or the lone points carried onto the pole
        from .core import in_pole_columns

        wire_pt = np.flatnonzero(conductor_of >= 0)
        inside = wire_pt[in_pole_columns([(p.x, p.y, p.height_m) for p in poles], pc.x[wire_pt] * hu,
                                         pc.y[wire_pt] * hu, hag[wire_pt], core_m=POLE_CORE_M, head_m=POLE_HEAD_M)]
        conductor_of = conductor_of.copy()
        conductor_of[inside] = -1
        tower_pt[inside] = True
        n_pole_column = len(inside)
    # the plan layers (and so the crossings) of a line one span holds settle on that span's trend
    # where it drifts off the line by more than the crossings' tolerance: a wire seen over one
    # stretch from one side, leant by the points of a line crossing it in its band (the 3D step
    # told those apart by height). Over several spans the Hough's fit is as good, and their pooled
    # trends turned ribbons' and bundles' lines the wrong way. The 3D layer keeps its frame
    lines = _realign(lines, geo, spans, params, hu, min_drift_m=SETTLE_DRIFT_M, max_spans=1)[0]
    # over several spans, a drift of a quarter band_m is the Hough's line between a ribbon's
    # phases (their points in its band): the trend of the line's own wire, not the others' pieces
    # it holds, settles it
    lines = _realign(lines, geo, _main_wire_spans(spans, params["max_rms_3d_m"]), params, hu,
                     min_drift_m=params["band_m"] / 4)[0]
    cond = lines["conductors"]
    # attributes of the 2D conductors: heights above ground of their 3D points
    hmin, hmax = [], []
    for li in range(len(cond)):
        h = hag[conductor_of == li]
        hmin.append(float(h.min()) if len(h) else np.nan)
        hmax.append(float(h.max()) if len(h) else np.nan)
    cond = cond.assign(height_min_m=hmin, height_max_m=hmax,
                       n_wires=[len(np.unique(wire_of_input[conductor_of == li])) for li in range(len(cond))])
    import geopandas as gpd

    # a piece no catenary fits (a crown the wire runs through) is no span of a wire: its points are
    # not wire points, and it is not drawn
    spans = [sp for sp in spans if sp.rms <= params["max_rms_3d_m"]]
    rows, geoms = [], []
    for sp in spans:
        a, dvec, _, _ = geo[sp.conductor]
        ss = np.linspace(sp.s_from, sp.s_to, max(int((sp.s_to - sp.s_from) / 2.0), 2) + 1)
        from .core import catenary

        zz = catenary(ss, sp.z0, sp.s0, sp.c)
        normal = np.array([-dvec[1], dvec[0]])
        xy = a[None, :] + ss[:, None] * dvec[None, :] + (sp.offset + sp.offset_slope * ss)[:, None] * normal[None, :]
        geoms.append(LineString(np.column_stack([xy[:, 0] / hu, xy[:, 1] / hu, zz / vu])))
        rows.append({"conductor": sp.conductor, "wire": sp.wire, "span": sp.span, "sag_m": sp.sag,
                     "catenary_c_m": sp.c, "rms_m": sp.rms, "n_points": sp.n_points,
                     "offset_m": sp.offset + sp.offset_slope * (sp.s_from + sp.s_to) / 2,
                     "length_m": sp.s_to - sp.s_from})
    c3d = gpd.GeoDataFrame(rows, geometry=geoms, crs=pc.crs) if rows else gpd.GeoDataFrame(
        {"conductor": np.array([], np.int64)}, geometry=gpd.GeoSeries([], crs=pc.crs), crs=pc.crs)
    c3d.attrs["geometry_type"] = "LineString Z"
    bounds = (float(pc.x.min()) * hu, float(pc.y.min()) * hu, float(pc.x.max()) * hu, float(pc.y.max()) * hu)
    wire_reach = _wire_reach(cond, fitted_of, pc, hu) if params["crossing_validation"] == "extent" else None
    crossings = _crossings_of(cond, lines["conductor_segments"], params["crossing_validation"], hu, found,
                              bounds=bounds, wire_reach=wire_reach)
    layers = {"conductors": cond, "conductor_segments": lines["conductor_segments"],
              "crossings": crossings, "conductors_3d": c3d, "pylons": pylons}
    out = {"lines": layers}
    if ctx.wants("classified"):
        out["classified"] = pc.with_fields(classification=_classes_decided(pc, ground_cls, tower_pt,
                                                                           conductor_of >= 0))
    if (len(cond) == 0 or params["cell_size_m"] is not None) and linear.sum() >= 200 and n_th < 0.15 * linear.sum():
        # the AHN4 case: conductors side by side closer than the mask cell make a strip that the
        # opening keeps, and the top-hat throws the wires away
        ctx.log.warning(
            "powerlines: the top-hat kept %d of %d wire-like points and %d conductors were found; conductors "
            "hanging side by side within 3 x cell_size_m=%g merge into a band the opening removes - "
            "leave cell_size_m automatic or set it to a third of their spacing", n_th, int(linear.sum()), len(cond),
            cell_used)
    stats = {"n_points": len(pc), "n_candidates": int(len(idx)), "n_linear": int(linear.sum()), "n_tophat": n_th,
             "height_max_m_used": round(h_max, 2),
             "surface_density_used": round(float(np.median(surface_density)), 2) if len(surface_density) else None,
             "cell_size_m_used": cell_used, "v_max_m_used": params["v_max_m"], "wire_spacing_m": None if spacing is None else round(spacing, 3), "n_short_wires": n_short, "n_pole_wires": n_pole_wires, "n_sibling_wires": n_sibling, "n_next_spans": n_next, "n_bridged_gaps": n_bridges, "n_side_by_side": n_side, "n_crowded_spans": n_crowded, "n_lines_realigned": timings.pop("n_lines_realigned", 0), "n_twin_lines_merged": timings.pop("n_twin_lines_merged", 0), "n_not_wires": len(not_wires), "n_surface_lines": len(surfaces), "n_conductors": len(cond), "n_wires_3d": len({(s.conductor, s.wire) for s in spans}),
             "n_spans": len(spans), "n_crossings": len(crossings), "n_wire_points": int((conductor_of >= 0).sum()),
             "n_grown_points": int((conductor_of[grown] >= 0).sum()), "n_alone_points": n_alone, "n_pole_column_points": n_pole_column, "alone_max_around_used": max_around, "n_off_trend_points": len(off_trend), "n_foliage_points": len(foliage),
             "n_pylons": len(pylons), "n_poles": sum(p.kind == "pole" for p in found), "n_tower_points": int(tower_pt.sum()),
             **{k: round(v, 3) for k, v in timings.items()}}
    return toolbox.Result(out, stats=stats)


# the layers' fields, for a run that finds nothing (the same layout as when something is found)
EMPTY_LAYERS = {
    "conductors": ("LineString", {"conductor": "int64", "votes": "int64", "n_points": "int64", "length_m": "float64",
                                  "rms_m": "float64", "azimuth_deg": "float64", "v_max_m": "float64",
                                  "height_min_m": "float64", "height_max_m": "float64", "n_wires": "int64"}),
    "conductor_segments": ("LineString", {"conductor": "int64", "segment": "int64", "length_m": "float64"}),
    "crossings": ("Point", {"n_lines": "int64", "angle_deg": "float64", "conductors": "object"}),
    "conductors_3d": ("LineString Z", {"conductor": "int64", "wire": "int64", "span": "int64", "sag_m": "float64",
                                       "catenary_c_m": "float64", "rms_m": "float64", "n_points": "int64",
                                       "offset_m": "float64", "length_m": "float64"}),
    "pylons": ("Point Z", {"pylon": "int64", "kind": "object", "height_m": "float64", "n_spans": "int64",
                           "line_heading_deg": "float64", "n_points": "int64"}),
}


def _classes_decided(pc, ground_cls, tower=None, wire=None):
    """The input's classes with what this run decides: wires 14 and towers 15 (a former 14 or 15
    it does not find becomes 1), and its ground step's ground 2 and noise 7 on the points whose
    input class a ground filter decides (below 8: water, bridge decks, 18 and above stay)."""
    import numpy as np

    given = pc.classification
    filterable = np.ones(len(pc), bool) if given is None else np.asarray(given) < 8
    g = np.asarray(ground_cls)
    decided = [(2, filterable & (g == 2)), (7, filterable & (g == 7))]
    decided += [(15, tower)] if tower is not None else []
    decided += [(14, wire)] if wire is not None else []
    return pc.classes_with(decided, released=(2, 14, 15))


def _nothing_found(pc, ground_cls, ctx, note, stats):
    """Empty layers (and the ground's classes) for an input with nothing to find, and the note why."""
    import geopandas as gpd
    import numpy as np
    import pandas as pd

    layers = {}
    for name, (gtype, fields) in EMPTY_LAYERS.items():
        gdf = gpd.GeoDataFrame({k: pd.Series([], dtype=t) for k, t in fields.items()},
                               geometry=gpd.GeoSeries([], crs=pc.crs), crs=pc.crs)
        gdf.attrs["geometry_type"] = gtype
        layers[name] = gdf
    out = {"lines": layers}
    if ctx.wants("classified"):
        out["classified"] = pc.with_fields(classification=_classes_decided(pc, ground_cls))
    return toolbox.Result(out, stats={**stats, "n_conductors": 0, "n_pylons": 0, "n_wire_points": 0, "note": note})


def _pylons(pc, hag, ground_cls, conductor_of, spans, geo, cond, hu, vu, dtm, params, also=(), passed_by=None):
    """The ``pylons`` layer (PointZ at each tower's base) and the mask of tower points; towers of
    ``also`` (found before) are kept where none is found within 2 m of them now."""
    import geopandas as gpd
    import numpy as np
    from shapely.geometry import Point

    from .core import catenary, find_poles, find_pylons, find_towers_passed_through, pylon_points

    off = np.isfinite(hag) & (hag >= 1.0) & (conductor_of < 0) & (ground_cls != 2) & (ground_cls != 7)
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
                        wire_xyh=wire_xyh)
    found += [t for t in also if all(np.hypot(t.x - q.x, t.y - q.y) > 2.0 for q in found)]
    poles = find_poles(*off_xyh, *wire_xyh, headings, lines_xy, span_ends=ends,
                       span_end_hag=np.asarray(end_z) - ground_z, top_share=params["pylon_top_share"])
    if poles:
        # where a pole carries the wires, a tower found beside it is the crown next to the pole
        # that took its span ends (a street scan's trees reach the wires' height)
        pxy = np.array([[q.x, q.y] for q in poles])
        found = [t for t in found if np.hypot(*(pxy - [t.x, t.y]).T).min() > POLE_TAKES_M] + poles
    # suspension towers the wires run through with no span ending there
    found += find_towers_passed_through(*off_xyh, *wire_xyh, headings, lines_xy, known=found,
                                        top_share=params["pylon_top_share"])
    tower = np.zeros(len(pc), bool)
    # foundations and what the ground filter leaves under a tower (< 1 m) are not the tower
    cand = np.flatnonzero(np.isfinite(hag) & (hag >= 1.0) & (conductor_of < 0) & (ground_cls != 2))
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


def _add_pass(found2, lines, geo, spans, line_of, wire_of_pt, hu, params):
    """A further pass's result (``_lines_and_wires`` on the points on no wire, or None) added to
    the first's: a line along one found already is the rest of its points (near a tower, a
    sparse stretch, past the end of its 2D extent), not another conductor, so its wires are
    folded into that line's; the others are appended as new conductors. ``line_of`` and
    ``wire_of_pt`` are updated in place. Returns (lines, geo, spans)."""
    import numpy as np

    if found2 is None:
        return lines, geo, spans
    lines2, geo2, spans2, line_of2, wire2, _ = found2
    along = {}  # pass-2 line -> the pass-1 line it runs along
    for i, g in enumerate(geo2):
        j = next((j for j, h in enumerate(geo) if _along(g, h, params["band_m"])), None)
        if j is not None:
            along[i] = j
    pos = np.flatnonzero(line_of < 0)  # where pass 2's points sit among pass 1's
    if along:
        spans, geo, lines = _fold_into(along, geo2, spans2, line_of2, wire2, geo, spans, lines, line_of,
                                       wire_of_pt, pos, hu)
    new = [i for i in range(len(geo2)) if i not in along]
    lines2, geo2, spans2, line_of2, wire2 = _keep_conductors(new, lines2, geo2, spans2, line_of2, wire2)
    if len(geo2):
        n0 = len(geo)
        for sp in spans2:
            sp.conductor += n0
        geo, spans = geo + geo2, spans + spans2
        mine = line_of2 >= 0  # the kept lines' points (the folded ones' are given out already)
        line_of[pos[mine]] = line_of2[mine] + n0
        wire_of_pt[pos[mine]] = wire2[mine]
        lines = _append_conductors(lines, lines2, n0)
    return lines, geo, spans


def _fold_stubs(lines, geo, spans, line_of, wire_of_pt, hu, params):
    """A line at most half as long as another that it runs along (``_along``) is a stretch of
    that conductor the Hough fitted on its own (a sub-conductor of a bundle near a tower, a
    stretch past a gap), not another one: folded into it as ``_add_pass`` folds a further pass's
    lines. Returns (lines, geo, spans, line_of, wire_of_pt)."""
    import dataclasses

    import numpy as np

    length = [t1 - t0 for (_, _, t0, t1) in geo]
    stubs = [i for i, g in enumerate(geo)
             if any(j != i and length[j] >= 2 * length[i] and _along(g, h, params["band_m"]) for j, h in enumerate(geo))]
    if not stubs:
        return lines, geo, spans, line_of, wire_of_pt
    # (_keep_conductors renumbers the spans in place: the stubs' selection works on copies)
    sub = _keep_conductors(stubs, lines, geo, [dataclasses.replace(sp) for sp in spans], line_of, wire_of_pt)
    lines, geo, spans, line_of, wire_of_pt = _keep_conductors([i for i in range(len(geo)) if i not in stubs], lines,
                                                              geo, spans, line_of, wire_of_pt)
    pos = np.flatnonzero(line_of < 0)
    lines, geo, spans = _add_pass((*sub[:3], sub[3][pos], sub[4][pos], 0), lines, geo, spans, line_of, wire_of_pt,
                                  hu, params)
    return lines, geo, spans, line_of, wire_of_pt


def _short_wires(pc, free, off_ground, steep, wired, params, hu, vu, n_searched=None, wire_like=None):
    """``short_wires`` among the wire-like points ``free`` (indices into ``pc``; ``off_ground``,
    ``steep``, ``wired``: the points off the ground, of structures and of the wires found;
    ``wire_like``: which of ``off_ground`` are; runs are drawn from the first ``n_searched`` of
    ``free``, the rest only join a stack beside one) as a further pass's result for
    ``_add_pass`` (one conductor and one straight span per run), or None."""
    import numpy as np

    from .core import short_wires

    if (len(free) if n_searched is None else n_searched) < 12 or len(wired) == 0:
        return None
    xyz = np.column_stack([pc.x[free] * hu, pc.y[free] * hu, pc.z[free] * vu])
    origin = xyz.min(axis=0)

    def local(ix):
        return np.column_stack([pc.x[ix] * hu, pc.y[ix] * hu, pc.z[ix] * vu]) - origin

    runs = short_wires(xyz - origin, local(off_ground), local(steep), local(wired), params["s_min_m"] / 2,
                       params["v_max_m"], n_searched=n_searched, wire_like=wire_like)
    if not runs:
        return None
    lines_xy = []
    for run in runs:
        q = xyz[run]
        d = q[-1, :2] - q[0, :2]
        L = float(np.hypot(*d))
        lines_xy.append((q[0, :2], d / max(L, 1e-9), L, [run]))
    return _straight_conductors(pc, xyz, lines_xy, hu)


def _wires_from_poles(pc, free, searched, off_ground, wire_like, poles, dtm, params, hu, vu):
    """``wires_from_poles`` among the points ``free`` (indices into ``pc``; runs drawn from
    those where ``searched``), with ``off_ground`` and the ``wire_like`` points among them for
    the stand-alone test and the ``poles`` found, as a further pass's result for ``_add_pass``
    (one conductor and one straight span per run), or None."""
    import numpy as np

    from .core import wires_from_poles

    sub = np.flatnonzero(searched)
    if len(sub) < 12:
        return None
    xyz = np.column_stack([pc.x[free] * hu, pc.y[free] * hu, pc.z[free] * vu])
    origin = xyz.min(axis=0)
    base = dtm.sample(np.array([p.x / hu for p in poles]), np.array([p.y / hu for p in poles])) * vu
    axes = np.column_stack([[p.x for p in poles], [p.y for p in poles], base, base + [p.height_m for p in poles]])
    ground = np.column_stack([pc.x[off_ground] * hu, pc.y[off_ground] * hu, pc.z[off_ground] * vu])
    runs = wires_from_poles(xyz[sub] - origin, axes - np.r_[origin, origin[2]], ground - origin,
                            params["s_min_m"] / 4, params["v_max_m"], wire_like=np.isin(off_ground, wire_like))
    if not runs:
        return None
    lines_xy = []
    for run in runs:
        q = xyz[sub[run]]
        d = q[-1, :2] - q[0, :2]
        L = float(np.hypot(*d))
        lines_xy.append((q[0, :2], d / max(L, 1e-9), L, [sub[run]]))
    return _straight_conductors(pc, xyz, lines_xy, hu)


def _straight_conductors(pc, xyz, lines_xy, hu):
    """A further pass's result for ``_add_pass`` from conductors drawn as straight 2D lines, each
    (anchor, unit direction, length, [indices into ``xyz`` of each of its spans' points]): one
    catenary per span."""
    import geopandas as gpd
    import numpy as np
    from shapely.geometry import LineString

    from .core import _span, fit_catenary

    geo, spans, rows, segs = [], [], [], []
    line_of = np.full(len(xyz), -1, np.int64)
    for li, (a, d, L, pieces) in enumerate(lines_xy):
        n_points, offs = 0, []
        for number, run in enumerate(pieces):
            q = xyz[run]
            s, off = (q[:, :2] - a) @ d, (q[:, :2] - a) @ np.array([-d[1], d[0]])
            spans.append(_span(li, 0, number, s, off, fit_catenary(s, q[:, 2])))
            line_of[run] = li
            n_points += len(run)
            offs.append(off)
        geo.append((a, d, 0.0, L))
        g = LineString([a / hu, (a + L * d) / hu])
        off = np.concatenate(offs)
        rows.append({"conductor": li, "votes": n_points, "n_points": n_points, "length_m": L,
                     "rms_m": float(np.sqrt(np.mean(off ** 2))),
                     "azimuth_deg": float(np.degrees(np.arctan2(d[0], d[1])) % 180.0), "geometry": g})
        segs.append({"conductor": li, "segment": 0, "length_m": L, "geometry": g})
    lines = {"conductors": gpd.GeoDataFrame(rows, geometry="geometry", crs=pc.crs),
             "conductor_segments": gpd.GeoDataFrame(segs, geometry="geometry", crs=pc.crs)}
    return lines, geo, spans, line_of, np.where(line_of >= 0, 0, -1), 0


def _sibling_wires(pc, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu):
    """``sibling_wires`` beside the fitted spans among the wire-like points ``keep`` (indices
    into ``pc``; ``line_of``, ``wire_of_pt``: their conductor and wire so far), added as new
    conductors (pieces beside the spans of one line at one offset make one, a span each). A line
    whose points a sibling takes for the most part was a stretch of it: it is dropped and the
    sibling holds its points. Returns (lines, geo, spans, line_of, wire_of_pt, number added)."""
    import numpy as np

    from .core import sibling_wires

    min_points = 12  # sibling_wires' default: a piece left with fewer is no wire of its own
    if len(keep) < min_points or not spans:
        return lines, geo, spans, line_of, wire_of_pt, 0
    xyz = np.column_stack([pc.x[keep] * hu, pc.y[keep] * hu, pc.z[keep] * vu])
    length = np.array([t1 - t0 for (_, _, t0, t1) in geo] + [0.0])
    found = sibling_wires(spans, geo, xyz[:, 0], xyz[:, 1], xyz[:, 2], params["max_rms_3d_m"], params["band_m"],
                          params["s_min_m"], owner=line_of, owner_length=length[line_of], min_points=min_points)
    if not found:
        return lines, geo, spans, line_of, wire_of_pt, 0
    taken = np.zeros(len(keep), bool)
    reach = np.zeros(len(geo) + 1)  # per line: the longest piece that took points of it
    for k, _, s, _ in found:
        taken[k] = True
        reach[line_of[k]] = np.maximum(reach[line_of[k]], np.ptp(s))
    owners = line_of[taken & (line_of >= 0)]
    absorbed = {int(li) for li in np.unique(owners)
                if (owners == li).sum() >= 0.5 * (line_of == li).sum() and length[li] <= reach[li]}
    searched = list(geo)
    if absorbed:
        lines, geo, spans, line_of, wire_of_pt = _keep_conductors(
            [i for i in range(len(geo)) if i not in absorbed], lines, geo, spans, line_of, wire_of_pt)
    free = np.flatnonzero(line_of < 0)
    at = np.full(len(keep), -1, np.int64)
    at[free] = np.arange(len(free))
    groups = []  # [parent line, offset at its middle, [pieces], their s and offsets]
    for k, li, s, off in found:
        mine = at[k] >= 0  # (points of a line not absorbed stay with it)
        if mine.sum() < min_points:
            continue
        k, s, off = at[k[mine]], s[mine], off[mine]
        o1, o0 = np.polyfit(s, off, 1)
        mid = float(np.mean(s))
        g = next((g for g in groups if g[0] == li and abs(g[1] - (o0 + o1 * mid)) <= params["band_m"]), None)
        if g is None:
            groups.append([li, o0 + o1 * mid, [k], [s], [off]])
        else:
            g[2].append(k), g[3].append(s), g[4].append(off)
    lines_xy = []
    for li, _, pieces, ss, offs in groups:
        if np.ptp(np.concatenate(ss)) < params["s_min_m"]:
            continue  # what the lines kept leave of it is shorter than a conductor's run
        a, d, _, _ = searched[li]  # the parent's frame as searched (dropping absorbed lines renumbers)
        n = np.array([-d[1], d[0]])
        s, off = np.concatenate(ss), np.concatenate(offs)
        o1, o0 = np.polyfit(s, off, 1)
        ends = [a + t * d + (o0 + o1 * t) * n for t in (float(s.min()), float(s.max()))]
        L = float(np.hypot(*(ends[1] - ends[0])))
        lines_xy.append((ends[0], (ends[1] - ends[0]) / max(L, 1e-9), L, pieces))
    n_before = len(geo)
    lines, geo, spans = _add_pass(_straight_conductors(pc, xyz[free], lines_xy, hu) if lines_xy else None, lines,
                                  geo, spans, line_of, wire_of_pt, hu, params)
    return lines, geo, spans, line_of, wire_of_pt, len(geo) - n_before


def _stacked_wires(pc, pool, geo, spans, conductor_of, wire_of, params, hu, vu):
    """``sibling_wires`` over and under the fitted spans among the points ``pool`` (indices into
    ``pc``, on no wire), each added as a further wire of the span's conductor (one over another,
    they are one line in plan): ``conductor_of`` and ``wire_of`` (per point of ``pc``) are
    updated in place. Returns (spans, number added)."""
    import numpy as np

    from .core import _span, fit_catenary, sibling_wires

    if len(pool) < 12 or not spans:
        return spans, 0
    xyz = np.column_stack([pc.x[pool] * hu, pc.y[pool] * hu, pc.z[pool] * vu])
    # (S_min long, but covering no share of the span: the cables of a stack hide one another
    # over stretches, and a leftover stub of the span's own wire is inside its fit tolerance)
    found = sibling_wires(spans, geo, xyz[:, 0], xyz[:, 1], xyz[:, 2], params["max_rms_3d_m"], params["band_m"],
                          params["s_min_m"], stacked=True, min_cover=0.0)
    # each conductor's highest wire number so far (its spans' and its points'), found once
    top = np.full(len(geo), -1, np.int64)
    on = conductor_of >= 0
    np.maximum.at(top, conductor_of[on], wire_of[on])
    for sp in spans:
        top[sp.conductor] = max(top[sp.conductor], sp.wire)
    spans = list(spans)
    for k, li, s, off in found:
        top[li] += 1
        spans.append(_span(li, int(top[li]), 0, s, off, fit_catenary(s, xyz[k, 2]), xyz[k, 2]))
        conductor_of[pool[k]], wire_of[pool[k]] = li, int(top[li])
    return spans, len(found)


def _labels_of_low(low, keep, line_of, wire_of_pt, n_points):
    """Each of the points ``low`` (indices into the cloud of ``n_points``): its conductor and wire
    so far (-1: on no wire)."""
    import numpy as np

    at_low = np.full(n_points, -1, np.int64)
    at_low[low] = np.arange(len(low))
    in_low = at_low[keep] >= 0
    low_line, low_wire = np.full(len(low), -1, np.int64), np.full(len(low), -1, np.int64)
    low_line[at_low[keep[in_low]]], low_wire[at_low[keep[in_low]]] = line_of[in_low], wire_of_pt[in_low]
    return low_line, low_wire


def _next_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu):
    """``next_spans`` of the wires found among the points ``low`` (indices into ``pc``: off the
    ground), added by ``_add_found_spans``. Returns what it returns."""
    from .core import next_spans

    low_line, low_wire = _labels_of_low(low, keep, line_of, wire_of_pt, len(pc))
    found = next_spans(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu, low_line < 0,
                       params["max_rms_3d_m"], max_gap_m=2 * params["v_max_m"],
                       reach_m=max(60.0, 8 * params["s_min_m"]), min_span_m=params["s_min_m"], line_of=low_line,
                       wire_of=low_wire)
    return _add_found_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, found, hu, vu)


def _bridge_gaps(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, params, hu, vu):
    """``bridge_gaps`` of the wires found among the points ``low`` (indices into ``pc``: off the
    ground), added by ``_add_found_spans``. Returns what it returns."""
    from .core import bridge_gaps

    low_line, low_wire = _labels_of_low(low, keep, line_of, wire_of_pt, len(pc))
    found = bridge_gaps(spans, geo, pc.x[low] * hu, pc.y[low] * hu, pc.z[low] * vu, low_line < 0,
                        params["max_rms_3d_m"], max_gap_m=2 * params["s_min_m"], line_of=low_line, wire_of=low_wire)
    return _add_found_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, found, hu, vu)


def _add_found_spans(pc, low, keep, lines, geo, spans, line_of, wire_of_pt, found, hu, vu):
    """Spans ``found`` past or between a wire's fitted ones ([(line, wire, indices into ``low``, s,
    offsets, fit)]) added as chained spans of those wires; their points join ``keep`` (relabelled
    where they are candidates on no wire) and each conductor's 2D line is stretched over them.
    Returns (lines, geo, spans, keep, line_of, wire_of_pt, number of spans added)."""
    import dataclasses

    import numpy as np
    from shapely.geometry import LineString

    from .core import _span

    if not found:
        return lines, geo, spans, keep, line_of, wire_of_pt, 0
    spans, geo = list(spans), list(geo)
    number = {}
    for sp in spans:
        number[(sp.conductor, sp.wire)] = max(number.get((sp.conductor, sp.wire), -1), sp.span)
    pos = np.full(len(pc), -1, np.int64)
    pos[keep] = np.arange(len(keep))
    cond = lines["conductors"].copy()
    for li, wire, k, s, off, fit in found:
        number[(li, wire)] += 1
        spans.append(dataclasses.replace(_span(li, wire, number[(li, wire)], s, off, fit, z=pc.z[low[k]] * vu),
                                         chained=True))
        pts = low[k]
        at = pos[pts]
        line_of[at[at >= 0]], wire_of_pt[at[at >= 0]] = li, wire
        new = pts[at < 0]
        pos[new] = len(keep) + np.arange(len(new))
        keep = np.r_[keep, new]
        line_of, wire_of_pt = np.r_[line_of, np.full(len(new), li)], np.r_[wire_of_pt, np.full(len(new), wire)]
        a, d, t0, t1 = geo[li]
        t0, t1 = min(t0, float(s.min())), max(t1, float(s.max()))
        if (t0, t1) != geo[li][2:]:
            geo[li] = (a, d, t0, t1)
            row = cond.index[li]
            cond.loc[row, "geometry"] = LineString([tuple((a + t0 * d) / hu), tuple((a + t1 * d) / hu)])
            if "length_m" in cond.columns:
                cond.loc[row, "length_m"] = t1 - t0
    cond.attrs.update(lines["conductors"].attrs)
    return {**lines, "conductors": cond}, geo, spans, keep, line_of, wire_of_pt, len(found)


def _arms(cond, found, hu, end_radius_m: float = 10.0, min_angle_deg: float = 45.0, with_arms=None,
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
    import numpy as np
    from shapely.geometry import LineString, Point

    towers = []
    for p in found:
        far = p.extent_m()
        # a pole's arm is a cross arm of a metre or two: the wires leaving it across the street are wires
        towers.append((p.x, p.y, far + 1.5, far + 1.0) if p.kind == "pole" else
                      (p.x, p.y, max(end_radius_m, far), far + 1.0))
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


def _wire_ends(geo, spans, max_rms: float) -> list:
    """Per conductor, the plan ends of the stretch its fitting spans cover along its line (None
    where no span fits)."""
    import numpy as np

    reach = {}
    for sp in spans:
        if sp.rms <= max_rms:
            lo, hi = reach.get(sp.conductor, (np.inf, -np.inf))
            reach[sp.conductor] = (min(lo, sp.s_from), max(hi, sp.s_to))
    out = []
    for li, (a, d, _, _) in enumerate(geo):
        out.append(np.array([a + reach[li][0] * d, a + reach[li][1] * d]) if li in reach else None)
    return out


def _lines_and_wires(pc, keep, hag, cell_used, params, ctx, timings, min_fit_share=0.0, optional=False):
    """Top-hat, tiled Hough and the 3D step on the wire-like candidates ``keep`` (indices into
    ``pc``): (Hough layers, line geometry, spans, per-keep conductor and wire, top-hat size);
    None when ``optional`` and the top-hat keeps too few points for a line."""
    import time

    import numpy as np

    from .core import band_owner, conductors_3d, ribbon_lines, thin_across, twin_lines

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
    redrawn = ribbon_lines(geo, px, py, params["band_m"] * hu, params["s_min_m"], 2 * params["v_max_m"])
    if redrawn is not None:
        geo, source, held = redrawn
        lines = _redrawn_lines(lines, geo, source, held, hu)
        timings["n_ribbon_lines_added"] = timings.get("n_ribbon_lines_added", 0) + len(geo) - len(set(source))

    def step_3d(geo, only=None):
        return conductors_3d(
            geo, px, py, pc.z[keep] * vu, params["band_3d_m"], z_link=1.0,
            s_link=2 * params["v_max_m"], min_span=params["s_min_m"], max_rms=params["max_rms_3d_m"],
            ground_z=(pc.z[keep] * vu - hag[keep]), only=only)

    spans, line_of, wire_of_pt = step_3d(geo)
    before = geo
    lines, geo, turned = _realign(lines, geo, spans, params, hu)
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
    # step then tells its phases apart across it, and _side_by_side draws each
    twins = twin_lines(spans, geo, params["max_rms_3d_m"], params["s_min_m"], params["band_3d_m"])
    if twins:
        lines, geo, merged = _merge_twins(lines, geo, twins, hu)
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
        good -= {int(li) for li in wide if not _stands_clear_of(pc, hag, keep[line_of == li], params["height_min_m"])}
    if min_fit_share:  # and most of what its spans hold fits them
        tot, fit = np.zeros(len(geo)), np.zeros(len(geo))
        for sp in spans:
            tot[sp.conductor] += sp.n_points
            fit[sp.conductor] += sp.n_points if sp.rms <= params["max_rms_3d_m"] else 0
        good = {c for c in good if fit[c] >= min_fit_share * tot[c]}
    if params["validate_3d"]:
        lines, geo, spans, line_of, wire_of_pt = _keep_conductors(sorted(good), lines, geo, spans, line_of, wire_of_pt)
    timings["conductors_3d_s"] = timings.get("conductors_3d_s", 0.0) + time.perf_counter() - t
    return lines, geo, spans, line_of, wire_of_pt, len(th)


def _stands_clear_of(pc, hag, own, height_min_m: float, radius_m: float = 0.5) -> bool:
    """Whether the points ``own`` (indices into ``pc``) have on average at most STANDS_CLEAR_MAX
    other points above ``height_min_m`` within ``radius_m`` (core._stands_clear, on the points
    around them)."""
    import numpy as np

    from .core import _stands_clear

    if not len(own):
        return True
    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    x, y = pc.x * hu, pc.y * hu
    lo_x, hi_x, lo_y, hi_y = x[own].min() - radius_m, x[own].max() + radius_m, y[own].min() - radius_m, \
        y[own].max() + radius_m
    around = np.flatnonzero((x >= lo_x) & (x <= hi_x) & (y >= lo_y) & (y <= hi_y) & (hag >= height_min_m))
    around = np.union1d(around, own)
    xyz = np.column_stack([x[around], y[around], pc.z[around] * vu])
    return _stands_clear(xyz, np.searchsorted(around, own), radius_m, STANDS_CLEAR_MAX)


def _redrawn_lines(lines, geo, source, held, hu):
    """The Hough's layers for the lines ``geo`` (anchor, direction, from, to; metres) that
    ``ribbon_lines`` redrew: each takes the attributes of its ``source`` line, the points it
    ``held`` as its votes (where redrawn), its own geometry and one segment over its extent."""
    import geopandas as gpd
    import numpy as np
    import pandas as pd
    from shapely.geometry import LineString

    cond, seg = lines["conductors"], lines["conductor_segments"]
    rows, segs = [], []
    for k, ((a, d, t0, t1), src, n_held) in enumerate(zip(geo, source, held)):
        ends = [tuple((a + t * d) / hu) for t in (t0, t1)]
        row = cond.iloc[src].copy()
        row["conductor"] = k
        if n_held is not None:
            for col in ("votes", "n_points"):
                if col in row.index:
                    row[col] = n_held
        row["geometry"] = LineString(ends)
        if "length_m" in row.index:
            row["length_m"] = float(t1 - t0)
        if "azimuth_deg" in row.index:
            row["azimuth_deg"] = float(np.degrees(np.arctan2(d[0], d[1])) % 180.0)
        rows.append(row)
        segs.append({"conductor": k, "segment": 0, "length_m": float(t1 - t0), "geometry": LineString(ends)})
    out_c = gpd.GeoDataFrame(pd.DataFrame(rows).reset_index(drop=True), geometry="geometry", crs=cond.crs)
    out_s = gpd.GeoDataFrame(pd.DataFrame(segs, columns=["conductor", "segment", "length_m", "geometry"]),
                             geometry="geometry", crs=seg.crs)
    out_c.attrs.update(cond.attrs)
    out_s.attrs.update(seg.attrs)
    return {**lines, "conductors": out_c, "conductor_segments": out_s}


def _merge_twins(lines, geo, pairs, hu):
    """Each group of lines joined by ``pairs`` (twin_lines) as one: the least-squares line through
    their ends in the frame of the longest, each line's ends weighted by its length (a stub at a
    tower does not turn a long line), over all their extents; the longest line's conductor takes
    it and their segments (moved onto it), the others are dropped. Returns (lines, geo, number of
    lines merged away)."""
    import numpy as np
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components
    from shapely.geometry import LineString

    i, j = np.array(pairs, np.int64).reshape(-1, 2).T
    _, group_of = connected_components(sparse.coo_matrix((np.ones(len(i)), (i, j)), shape=(len(geo), len(geo))),
                                       directed=False)
    groups = {}
    for k, g in enumerate(group_of):
        groups.setdefault(int(g), []).append(k)
    geo = list(geo)
    seg = lines["conductor_segments"].copy()
    cond = lines["conductors"].copy()
    keep = []
    for members in groups.values():
        main = max(members, key=lambda k: geo[k][3] - geo[k][2])
        keep.append(main)
        if len(members) < 2:
            continue
        ah, dh, _, _ = geo[main]
        nh = np.array([-dh[1], dh[0]])
        ends = np.array([a + t * d for k in members for a, d, *ts in [geo[k]] for t in ts])
        w = np.repeat([geo[k][3] - geo[k][2] for k in members], 2)
        s, o = (ends - ah) @ dh, (ends - ah) @ nh
        sm, om = (w @ s) / w.sum(), (w @ o) / w.sum()
        slope = float(w @ ((s - sm) * (o - om)) / max(float(w @ (s - sm) ** 2), 1e-12))
        d2 = (dh + slope * nh) / np.hypot(1.0, slope)
        a2 = ah + s.min() * dh + (om + slope * (s.min() - sm)) * nh
        geo[main] = (a2, d2, 0.0, float((s.max() - s.min()) * np.hypot(1.0, slope)))

        def onto(xy, a2=a2, d2=d2):
            p = np.asarray(xy) * hu
            return tuple((a2 + float((p - a2) @ d2) * d2) / hu)
        row = cond.index[main]
        cond.loc[row, "geometry"] = LineString([a2 / hu, (a2 + geo[main][3] * d2) / hu])
        if "azimuth_deg" in cond.columns:
            cond.loc[row, "azimuth_deg"] = float(np.degrees(np.arctan2(d2[0], d2[1])) % 180.0)
        if "length_m" in cond.columns:
            cond.loc[row, "length_m"] = geo[main][3]
        for k in seg.index[seg["conductor"].isin(members)]:
            seg.loc[k, "geometry"] = LineString([onto(c) for c in seg.loc[k, "geometry"].coords])
            seg.loc[k, "conductor"] = main
    keep = sorted(keep)
    out = _select_conductors({"conductors": cond, "conductor_segments": seg}, keep)
    for name in ("conductors", "conductor_segments"):
        out[name].attrs.update(lines[name].attrs)
    return {**lines, **out}, [geo[k] for k in keep], len(geo) - len(keep)


def _plan_trends(spans, params) -> dict:
    """Per line, the plan trend of its wires: their spans' offset slope along it, pooled over the
    spans that fit and are S_min long, each weighted by its precision. line -> (trend, whether the
    spans agree on it (no bend at a support, no fan of wires), and per span: weight, middle along
    the line, offset there, points; then the trend of the spans' offsets from one span to the next
    along each wire (a common slope, each wire its own intercept, weighted by the points over their
    scatter), None where no wire has two such spans)."""
    import numpy as np

    from .core import WIRE_LATERAL_RMS_M

    pooled = {}  # line -> [(weight of its slope, slope, middle, offset there, points)] per span
    for sp in spans:
        length = sp.s_to - sp.s_from
        if sp.rms <= params["max_rms_3d_m"] and length >= params["s_min_m"] and sp.offset_rms <= WIRE_LATERAL_RMS_M:
            # 1 / var(slope) of a least-squares line through n points spread evenly over the span
            w = sp.n_points * length ** 2 / 12.0 / max(sp.offset_rms, 0.01) ** 2
            mid = 0.5 * (sp.s_from + sp.s_to)
            pooled.setdefault(sp.conductor, []).append((w, sp.offset_slope, mid, sp.offset + sp.offset_slope * mid,
                                                        sp.n_points, sp.wire, sp.n_points / max(sp.offset_rms, 0.01) ** 2))
    out = {}
    for li, rows in pooled.items():
        w, slope, mid, off, n, wire, v = map(np.array, zip(*rows))
        trend = float(w @ slope / w.sum())
        agree = bool(w @ (slope - trend) ** 2 <= 9.0 * max(len(w) - 1, 1))
        sxx = sxy = 0.0
        for k in np.unique(wire):
            on = wire == k
            if on.sum() < 2:
                continue
            ds = mid[on] - v[on] @ mid[on] / v[on].sum()
            sxx += float(v[on] @ ds ** 2)
            sxy += float(v[on] @ (ds * (off[on] - v[on] @ off[on] / v[on].sum())))
        out[li] = (trend, agree, w, mid, off, n, sxy / sxx if sxx > 0 else None)
    return out


def _wire_reach(cond, conductor_of, pc, hu: float) -> list:
    """Per conductor of ``cond``, how far its wire points (``conductor_of``) reach along it: the
    two ends of their extent in plan (metres), or None where it holds none. The growth and the
    later passes take points past the Hough line's extent (a wire seen again near its pole)."""
    import numpy as np

    n = len(cond)
    if n == 0:
        return []
    a = np.array([np.asarray(g.coords[0], float)[:2] for g in cond.geometry]) * hu
    d = np.array([np.asarray(g.coords[-1], float)[:2] for g in cond.geometry]) * hu - a
    d /= np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    own = np.flatnonzero((conductor_of >= 0) & (conductor_of < n))
    li = conductor_of[own]
    t = (pc.x[own] * hu - a[li, 0]) * d[li, 0] + (pc.y[own] * hu - a[li, 1]) * d[li, 1]
    t_min, t_max = np.full(n, np.inf), np.full(n, -np.inf)
    np.minimum.at(t_min, li, t)
    np.maximum.at(t_max, li, t)
    return [(a[i] + t_min[i] * d[i], a[i] + t_max[i] * d[i]) if np.isfinite(t_min[i]) else None for i in range(n)]


def _main_wire_spans(spans, max_rms: float) -> list:
    """The spans (those that fit, within ``max_rms``) of each line's main wire: the one whose
    fitting spans hold the most points."""
    held = {}
    for sp in spans:
        if sp.rms <= max_rms:
            held[(sp.conductor, sp.wire)] = held.get((sp.conductor, sp.wire), 0) + sp.n_points
    main = {}
    for (li, w), n in sorted(held.items()):
        if li not in main or n > held[(li, main[li])]:
            main[li] = w
    return [sp for sp in spans if sp.rms <= max_rms and main.get(sp.conductor) == sp.wire]


def _realign(lines, geo, spans, params, hu, min_drift_m: float | None = None, max_spans: int | None = None):
    """Lines turned onto the plan trend of their wires: the Hough's line through a wire seen from
    one side (a mobile scanner's view of a line crossing its street) can lean off it by a few
    tenths of a degree, a drift across its length that its band and its crossings inherit. The
    trend is the spans' own (their offset's slope along the line, pooled over the spans that fit
    and are S_min long, each weighted by its precision); a line turns about the middle of its
    spans where that trend drifts more than band_m over the line's length (its band loses the
    wire at one end), lies more than three standard errors off zero and its spans agree on it
    (a line bending at a support, or wires fanning out from a pole, keep the Hough's compromise).
    ``min_drift_m``: the drift that turns a line (default band_m); ``max_spans``: only lines held
    by at most that many such spans. Returns (lines, geo, number turned)."""
    import numpy as np
    from shapely.geometry import LineString

    turn = {}
    drift = params["band_m"] if min_drift_m is None else min_drift_m
    for li, (trend, agree, w, mid, off, n, between) in _plan_trends(spans, params).items():
        if max_spans is not None and len(w) > max_spans:
            continue
        length = geo[li][3] - geo[li][2]
        # where a wire holds several spans, their offsets from one to the next must drift too: the
        # spans' own slopes, tens of metres each, can share a bias of a few 1e-4 (a sparse scan's
        # pattern along them) that no drift of the wire across the line bears out
        confirmed = between is None or (between * trend > 0 and abs(between) * length > drift)
        if abs(trend) * length > drift and abs(trend) > 3.0 / np.sqrt(w.sum()) and agree and confirmed:
            pivot = float(w @ mid / w.sum())
            # the line moves onto its wire there: the offset most of its points share (another
            # line's wire its lean let into the band is out-numbered)
            at = off + trend * (pivot - mid)
            order = np.argsort(at)
            turn[li] = (trend, pivot, float(at[order][np.searchsorted(np.cumsum(n[order]), 0.5 * n.sum())]))
    if not turn:
        return lines, geo, 0
    geo = list(geo)
    cond, seg = lines["conductors"].copy(), lines["conductor_segments"].copy()
    for li, (slope, mid, off) in turn.items():
        a, d, t0, t1 = geo[li]
        n = np.array([-d[1], d[0]])
        pivot = a + mid * d
        d2 = d + slope * n
        d2 = d2 / np.hypot(*d2)
        centre = pivot + off * n
        geo[li] = (centre - mid * d2, d2, t0, t1)

        def onto(xy):  # the layers follow: each end keeps its place along the line
            s = float((np.asarray(xy) * hu - pivot) @ d)
            return tuple((centre + s * d2) / hu)
        row = cond.index[li]
        cond.loc[row, "geometry"] = LineString([onto(c) for c in cond.loc[row, "geometry"].coords])
        if "azimuth_deg" in cond.columns:
            cond.loc[row, "azimuth_deg"] = float(np.degrees(np.arctan2(d2[0], d2[1])) % 180.0)
        for k in seg.index[seg["conductor"] == li]:
            seg.loc[k, "geometry"] = LineString([onto(c) for c in seg.loc[k, "geometry"].coords])
    for g, src in ((cond, lines["conductors"]), (seg, lines["conductor_segments"])):
        g.attrs.update(src.attrs)
    return {**lines, "conductors": cond, "conductor_segments": seg}, geo, len(turn)


def _side_by_side(lines, geo, spans, conductor_of, wire_of, x, y, params, hu, min_gap_m: float | None = None):
    """Conductors whose fitted spans lie in groups side by side across the line, ``min_gap_m`` or
    more apart (the 3D step's cut across a piece): a ribbon's phases 0.3-0.4 m apart share one
    Hough line (its band is band_m), and so do the sub-conductors of a bundle side by side that
    far apart. Each group becomes a conductor of its own in plan (the original's extent, on the
    group's own trend), with its spans and the points nearest its trend (``conductor_of``,
    ``wire_of``: per input point, ``x``, ``y`` in metres); a group along another conductor (a
    phase that line also holds) joins it, as further wires. Sub-conductors closer than
    ``min_gap_m`` in plan (default: the 3D step's own cut, SIDE_BY_SIDE_MIN_GAP_M; a triangle
    bundle's 0.2 m) stay one conductor per phase. Spans are grouped by their offsets about the
    line's plan trend (``_plan_trends``, where its spans agree on one), spans more than 1 deg off
    the line (jumpers) left out. Returns (lines, geo, spans, conductor_of, wire_of, number of
    conductors added)."""
    import numpy as np
    import pandas as pd
    from shapely.geometry import LineString

    from .core import SIDE_BY_SIDE_MIN_GAP_M, line_fit, span_in_frame

    min_gap_m = SIDE_BY_SIDE_MIN_GAP_M if min_gap_m is None else min_gap_m

    fitting = [sp for sp in spans if sp.rms <= params["max_rms_3d_m"]]
    cond, seg = lines["conductors"], lines["conductor_segments"]
    new_geo, new_rows, new_segs, new_spans = list(geo), [], [], []
    conductor_of, wire_of = conductor_of.copy(), wire_of.copy()
    next_wire = {li: int(max([sp.wire for sp in spans if sp.conductor == li], default=-1)) + 1
                 for li in range(len(geo))}
    moved = {}  # original conductor -> [(new index, offset trend (slope, intercept))]
    plan = _plan_trends(spans, params)
    for li in range(len(geo)):
        # spans along the line (within 1 deg, as _along) that lie at one offset: a jumper at a
        # tower, a piece there drifting half the gap across, or one whose points are two wires'
        # (scattered across as two wires half the gap apart would be, over the line's own wires'
        # scatter) has its middle between their groups and would chain them into one
        trend, agree = plan.get(li, (0.0, False))[:2]
        lean = trend if agree else 0.0
        along = [sp for sp in fitting if sp.conductor == li and abs(sp.offset_slope) <= ALONG_SLOPE_MAX]
        if len(along) < 2:
            continue
        max_scatter = np.hypot(np.median([sp.offset_rms for sp in along]), 0.25 * min_gap_m)
        mine = [sp for sp in along if sp.offset_rms <= max_scatter and
                abs(sp.offset_slope - lean) * (sp.s_to - sp.s_from) <= 0.5 * min_gap_m]
        if len(mine) < 2:
            continue
        # span middles' offsets about the wires' own plan trend: the Hough's line can lie across
        # two phases at a small angle, so that one phase's offset drifts along it by a good part
        # of the gap to the next
        smid = np.array([0.5 * (sp.s_from + sp.s_to) for sp in mine])
        mid = np.array([sp.offset + sp.offset_slope * s for sp, s in zip(mine, smid)]) - lean * smid
        order = np.argsort(mid)
        # runs of span offsets without a gap of half min_gap_m, then neighbouring runs whose
        # middles lie closer than min_gap_m joined
        runs = np.split(order, np.flatnonzero(np.diff(mid[order]) >= 0.5 * min_gap_m) + 1)
        groups = [list(runs[0])]
        for prev, r in zip(runs[:-1], runs[1:]):
            if np.median(mid[r]) - np.median(mid[prev]) < min_gap_m:
                groups[-1] += list(r)
            else:
                groups.append(list(r))
        # a group is a wire along the line: S_min or more, and half the length its spans cover (a piece
        # of a neighbouring wire at the line's end, a tower's arms and jumpers are not)
        cover = sum(sp.s_to - sp.s_from for sp in mine)

        def long_enough(parts):
            return [g for g in parts if sum(mine[k].s_to - mine[k].s_from for k in g) >= max(
                params["s_min_m"], 0.5 * cover / len(parts))]
        groups = long_enough(groups) if len(groups) > 1 else groups
        if not groups:
            continue
        to_centre = np.zeros(len(mine))
        if len(groups) < 2 and np.ptp(mid[groups[0]]) > 0.5 * min_gap_m:
            # one phase whose sub-conductors lie closer than min_gap_m in plan (a triangle
            # bundle): its line runs through the middle of the outermost, not through its points'
            # centroid, which a sub-conductor holding more points pulls off by centimetres (a
            # crossing at 25 deg by 2.4 times as much); each as long as the groups above
            wires = long_enough(runs)
            if len(wires) < 2:
                continue
            centre = 0.5 * (np.median(mid[wires[0]]) + np.median(mid[wires[-1]]))
            for r in runs:
                to_centre[r] = centre - np.median(mid[r])
        a, d, t0, t1 = geo[li]
        n = np.array([-d[1], d[0]])
        trends = []
        for g in groups:  # the group's offset along the line: its spans' trends, sampled at both ends
            ss = np.concatenate([[mine[k].s_from, mine[k].s_to] for k in g])
            oo = np.concatenate([[mine[k].offset + mine[k].offset_slope * mine[k].s_from + to_centre[k],
                                  mine[k].offset + mine[k].offset_slope * mine[k].s_to + to_centre[k]] for k in g])
            trends.append(line_fit(ss, oo) if np.ptp(ss) > 0 else (0.0, float(np.median(oo))))
        moved[li] = []
        for gi, (g, (o1, o0)) in enumerate(zip(groups, trends)):
            d2 = d + o1 * n
            d2 = d2 / np.hypot(*d2)
            a2 = a + o0 * n
            extent = (min(mine[k].s_from for k in g), max(mine[k].s_to for k in g))
            onto_other = [j for j in range(len(geo)) if j != li and
                          _along((a2, d2, *extent), geo[j], 0.5 * min_gap_m)]
            if gi > 0 and onto_other:
                moved[li].append((onto_other[0], o1, o0, [mine[k] for k in g]))
                continue
            if gi == 0:
                k_new = li
            else:
                k_new = len(new_geo)
                row = cond.iloc[li].copy()
                row["conductor"] = k_new
                new_rows.append(row)
                for _, sr in seg[seg["conductor"] == li].iterrows():
                    sr = sr.copy()
                    sr["conductor"] = k_new
                    new_segs.append(sr)
                new_geo.append(None)
            new_geo[k_new] = (a2, d2, t0, t1)
            moved[li].append((k_new, o1, o0, [mine[k] for k in g]))
    if not moved:
        return lines, geo, spans, conductor_of, wire_of, 0
    cond = pd.concat([cond, pd.DataFrame(new_rows)], ignore_index=True) if new_rows else cond.copy()
    seg = pd.concat([seg, pd.DataFrame(new_segs)], ignore_index=True) if new_segs else seg.copy()
    cond = cond.set_geometry("geometry", crs=lines["conductors"].crs)
    seg = seg.set_geometry("geometry", crs=lines["conductor_segments"].crs)
    for li, parts in moved.items():
        a, d, t0, t1 = geo[li]
        n = np.array([-d[1], d[0]])
        pts = np.flatnonzero(conductor_of == li)
        ps = (x[pts] - a[0]) * d[0] + (y[pts] - a[1]) * d[1]
        po = -(x[pts] - a[0]) * d[1] + (y[pts] - a[1]) * d[0]
        # each point to the group whose trend lies nearest across the line
        near = np.argmin(np.abs(np.column_stack([po - (o1 * ps + o0) for _, o1, o0, _ in parts])), axis=1)
        for k, (k_new, o1, o0, group_spans) in enumerate(parts):
            conductor_of[pts[near == k]] = k_new
            if k_new < len(geo) and k_new != li:  # joins another conductor: its wires numbered on after
                renum = {}
                for sp in group_spans:
                    if sp.wire not in renum:
                        renum[sp.wire] = next_wire[k_new]
                        next_wire[k_new] += 1
                mine_pts = pts[near == k]
                wire_of[mine_pts] = [renum.get(w, renum[group_spans[0].wire]) for w in wire_of[mine_pts]]
                for sp in group_spans:
                    new_spans.append(span_in_frame(sp, geo[li], geo[k_new], k_new, renum[sp.wire]))
                continue
            a2, d2, _, _ = new_geo[k_new]

            def onto(xy, o1=o1, o0=o0):  # a point of the original line onto the group's trend
                p = np.asarray(xy) * hu
                t = float((p - a) @ d)
                return tuple((p + (o0 + o1 * t) * n) / hu)
            rows = cond.index[cond["conductor"] == k_new]
            cond.loc[rows[0], "geometry"] = LineString([onto(c) for c in cond.loc[rows[0], "geometry"].coords])
            cond.loc[rows[0], "azimuth_deg"] = float(np.degrees(np.arctan2(d2[0], d2[1])) % 180.0)
            cond.loc[rows[0], "n_points"] = int((near == k).sum())
            for r in seg.index[seg["conductor"] == k_new]:
                seg.loc[r, "geometry"] = LineString([onto(c) for c in seg.loc[r, "geometry"].coords])
            for sp in group_spans:
                new_spans.append(span_in_frame(sp, geo[li], new_geo[k_new], k_new, sp.wire))
    done = {id(sp) for parts in moved.values() for _, _, _, g in parts for sp in g}
    # the rest (spans that do not fit, groups under S_min) stay on the original conductor, in its new frame
    spans = [span_in_frame(sp, geo[sp.conductor], new_geo[sp.conductor], sp.conductor, sp.wire)
             if sp.conductor in moved else sp for sp in spans if id(sp) not in done] + new_spans
    for g, src in ((cond, lines["conductors"]), (seg, lines["conductor_segments"])):
        g.attrs.update(src.attrs)
    return ({**lines, "conductors": cond, "conductor_segments": seg}, new_geo, spans, conductor_of, wire_of,
            len(new_geo) - len(geo))


def _not_wires(spans, geo, px, py, pz, max_rms: float, min_contrast: float = 4.0, below=None, crowded=None) -> set:
    """Conductors that are not wires seen in the cross-section of their fitted spans, over the
    candidates ``p*``: most span points in a surface (``span_on_surface``: a roof's scan row,
    an eave), or no denser within 0.1 m than 0.2-0.5 m around (under ``min_contrast`` times:
    points of a crown that happen to line up; a wire is a concentration of points, its
    sub-conductors and neighbours sit at a few places around it). ``below``: (x, y, z) of every
    point off the ground, whatever its height: a span that is the top edge of a wall (a truck, a
    fence seen from the street) is in a surface that reaches under the height window. ``crowded``,
    a list, gets the indices (into ``spans``) of the spans that fit and are, on their own, under
    ``min_contrast``."""
    import numpy as np

    from .core import _pieces_on_surfaces, catenary, core_and_ring, core_ring_contrast, span_on_surface

    def frame(qx, qy, qz, a, d, lo, hi, reach):
        dx, dy = qx - a[0], qy - a[1]
        s, off = dx * d[0] + dy * d[1], -dx * d[1] + dy * d[0]
        near = np.flatnonzero((s >= lo) & (s <= hi) & (np.abs(off) <= reach))
        return s[near], off[near], qz[near]

    out = set()
    for li, (a, d, _, _) in enumerate(geo):
        numbered = [(k, sp) for k, sp in enumerate(spans) if sp.conductor == li and sp.rms <= max_rms]
        line_spans = [sp for _, sp in numbered]
        if not line_spans:
            continue
        lo, hi = min(sp.s_from for sp in line_spans), max(sp.s_to for sp in line_spans)
        reach = 2.0 + max(abs(sp.offset) + abs(sp.offset_slope) * max(abs(lo), abs(hi)) for sp in line_spans)
        s, off, z = frame(px, py, pz, a, d, lo, hi, reach)
        if below is not None:
            sb, offb, zb = frame(*below, a, d, lo, hi, reach)
        flat = core_n = ring_n = 0
        for k, sp in numbered:
            o, dz = off - sp.offset - sp.offset_slope * s, z - catenary(s, sp.z0, sp.s0, sp.c)
            if span_on_surface(s, o, dz, sp.s_from, sp.s_to) or _pieces_on_surfaces(s, o, dz, sp) > 0.5:
                flat += sp.n_points
            elif below is not None and span_on_surface(
                    sb, offb - sp.offset - sp.offset_slope * sb, zb - catenary(sb, sp.z0, sp.s0, sp.c), sp.s_from,
                    sp.s_to, bin_m=0.1, min_run_m=1.0, min_tilt_deg=70.0, max_tilt_deg=90.0):
                # a wall seen from the side is dense down its scan lines: every 0.1 m filled
                # for a metre (wires stacked 0.3 m apart leave gaps)
                flat += sp.n_points
            inside = (s >= sp.s_from) & (s <= sp.s_to)
            core, ring = core_and_ring(np.hypot(o[inside], dz[inside]))
            core_n, ring_n = core_n + core, ring_n + ring
            if crowded is not None and ring and core_ring_contrast(core, ring) < min_contrast:
                crowded.append(k)
        if flat > 0.5 * sum(sp.n_points for sp in line_spans) or core_ring_contrast(core_n, ring_n) < min_contrast:
            out.add(li)
    return out


def _drop_spans(gone, spans, geo, px, py, line_of, wire_of_pt):
    """The spans ``gone`` taken out, with their points (those of their wire within their extent,
    ``p*`` in metres) on no wire again. Returns (spans, line_of, wire_of_pt)."""
    import numpy as np

    for sp in gone:
        a, d, _, _ = geo[sp.conductor]
        mine = np.flatnonzero((line_of == sp.conductor) & (wire_of_pt == sp.wire))
        s = (px[mine] - a[0]) * d[0] + (py[mine] - a[1]) * d[1]
        out = mine[(s >= sp.s_from) & (s <= sp.s_to)]
        line_of[out], wire_of_pt[out] = -1, -1
    return [sp for sp in spans if not any(sp is q for q in gone)], line_of, wire_of_pt


def _fold_into(along: dict, geo2, spans2, line_of2, wire2, geo, spans, lines, line_of, wire_of_pt, pos, hu):
    """Second-pass lines ``along`` first-pass ones ({pass-2 line: pass-1 line}) folded into them:
    their spans re-expressed in the pass-1 line's frame as new wires of it, their points (``pos``:
    where pass 2's per-point arrays sit in the pass-1 ones) given to it, and its 2D extent and
    plan line stretched over them. Returns (spans, geo, lines)."""
    import numpy as np
    from shapely.geometry import LineString

    from .core import span_in_frame

    next_wire = {j: max([sp.wire for sp in spans if sp.conductor == j], default=-1) + 1 for j in set(along.values())}
    wire_map, spans = {}, list(spans)
    for sp in spans2:
        if sp.conductor not in along:
            continue
        j = along[sp.conductor]
        if (sp.conductor, sp.wire) not in wire_map:
            wire_map[(sp.conductor, sp.wire)] = next_wire[j]
            next_wire[j] += 1
        spans.append(span_in_frame(sp, geo2[sp.conductor], geo[j], j, wire_map[(sp.conductor, sp.wire)]))
    for k in np.flatnonzero(np.isin(line_of2, list(along))):
        key = (int(line_of2[k]), int(wire2[k]))
        if key not in wire_map:
            wire_map[key] = next_wire[along[key[0]]]
            next_wire[along[key[0]]] += 1
        line_of[pos[k]], wire_of_pt[pos[k]] = along[key[0]], wire_map[key]
    geo = list(geo)
    cond = lines["conductors"].copy()
    for j in set(along.values()):
        a, d, t0, t1 = geo[j]
        t0 = min([t0] + [sp.s_from for sp in spans if sp.conductor == j])
        t1 = max([t1] + [sp.s_to for sp in spans if sp.conductor == j])
        geo[j] = (a, d, t0, t1)
        cond.loc[cond.index[j], "geometry"] = LineString([(a + t0 * d) / hu, (a + t1 * d) / hu])
        if "length_m" in cond.columns:
            cond.loc[cond.index[j], "length_m"] = t1 - t0
    return spans, geo, {**lines, "conductors": cond}


def _along(g, h, band_m: float, max_angle_deg: float = 1.0) -> bool:
    """Whether line ``g`` runs along line ``h`` (both (anchor, direction, t0, t1)): within
    ``max_angle_deg`` of it and both its ends within ``band_m`` of it."""
    import numpy as np

    (a, d, t0, t1), (b, e, _, _) = g, h
    # a short line's Hough angle is loose (a 10 m stub leant 1.4 deg off its wire): its ends within
    # band_m of the other line tell, up to the angle that band allows over its length
    max_angle_deg = max(max_angle_deg, float(np.degrees(np.arctan2(band_m, t1 - t0))))
    if abs(float(d @ e)) < np.cos(np.radians(max_angle_deg)):
        return False
    normal = np.array([-e[1], e[0]])
    return all(abs(float((a + t * d - b) @ normal)) <= band_m for t in (t0, t1))


def _append_conductors(lines: dict, more: dict, n0: int) -> dict:
    """The layers of a second Hough pass appended to the first's, its conductors numbered from
    ``n0`` (crossings are computed once, over the final conductors)."""
    import pandas as pd

    out = {}
    for name in ("conductors", "conductor_segments"):
        add = more[name].assign(conductor=more[name]["conductor"] + n0)
        g = pd.concat([lines[name], add], ignore_index=True)
        g.attrs.update(lines[name].attrs)
        out[name] = g
    return out


def _keep_conductors(keep_lines, lines, geo, spans, line_of, wire_of_pt):
    """Only the given conductors (renumbered) in the layers, the geometry, the spans and the
    per-point conductor and wire of the 3D step."""
    import numpy as np

    new_id = np.full(len(geo) + 1, -1, np.int64)  # old conductor -> new (-1: dropped; -1 stays -1)
    new_id[keep_lines] = np.arange(len(keep_lines))
    line_of = new_id[line_of]
    wire_of_pt = np.where(line_of < 0, -1, wire_of_pt)
    spans = [sp for sp in spans if new_id[sp.conductor] >= 0]
    for sp in spans:
        sp.conductor = int(new_id[sp.conductor])
    return _select_conductors(lines, keep_lines), [geo[i] for i in keep_lines], spans, line_of, wire_of_pt


def _select_conductors(lines: dict, keep: list) -> dict:
    """Keep the given conductors (renumbered) with their segments (crossings are computed once,
    over the final conductors)."""
    cond = lines["conductors"]
    remap = {old: new for new, old in enumerate(keep)}
    new_cond = cond.iloc[keep].reset_index(drop=True).assign(conductor=list(range(len(keep))))
    seg = lines["conductor_segments"]
    seg = seg[seg["conductor"].isin(keep)].reset_index(drop=True)
    seg = seg.assign(conductor=[remap[c] for c in seg["conductor"]])
    for g, src in ((new_cond, cond), (seg, lines["conductor_segments"])):
        g.attrs.update(src.attrs)
    return {"conductors": new_cond, "conductor_segments": seg}


def _far_ends(lines, checks) -> list:
    """Per line (anchor, direction), the two far ends of its checked extents (``checks``, a list
    of (a, b)) as (position, outward direction); none for a line without extents."""
    import numpy as np

    out = []
    for (a, d), segs in zip(lines, checks):
        if not len(segs):
            out.append([])
            continue
        pts = np.array([e for seg in segs for e in seg], float)
        t = (pts - a) @ d
        out.append([(pts[int(np.argmin(t))], -d), (pts[int(np.argmax(t))], d)])
    return out


def _circuit_ends(lines, checks, bounds, max_angle_deg: float = 1.0, across_m: float = 5.0, along_m: float = 1.0,
                  edge_m: float = 5.0) -> list:
    """Supports seen or not: where two or more parallel conductors (within ``max_angle_deg``
    and ``across_m`` of one another) have the far ends of their checked extents (``checks``, per
    line a list of (a, b)) within ``along_m`` of one another along them, more than ``edge_m``
    inside the data's ``bounds`` (xmin, ymin, xmax, ymax): the circuit ends there, at a pole
    the scan saw too little of to find (a street scanner's view of a pole across the block).
    Returns [(x, y, reach_m)], each reaching its members' ends and a metre."""
    import numpy as np

    ends = [(i, e, u) for i, line_ends in enumerate(_far_ends(lines, checks)) for e, u in line_ends
            if bounds[0] + edge_m < e[0] < bounds[2] - edge_m and bounds[1] + edge_m < e[1] < bounds[3] - edge_m]
    cos_max = np.cos(np.radians(max_angle_deg))
    out, used = [], set()
    for k, (i, e, u) in enumerate(ends):
        if k in used:
            continue
        group = [k] + [m for m in range(k + 1, len(ends)) if m not in used and ends[m][0] != i
                       and float(ends[m][2] @ u) >= cos_max and abs(float((ends[m][1] - e) @ u)) <= along_m
                       and abs(float(u[0] * (ends[m][1] - e)[1] - u[1] * (ends[m][1] - e)[0])) <= across_m]
        if len({ends[m][0] for m in group}) < 2:
            continue
        used.update(group)
        pts = np.array([ends[m][1] for m in group])
        centre = pts.mean(axis=0)
        out.append((float(centre[0]), float(centre[1]), float(np.hypot(*(pts - centre).T).max()) + 1.0))
    return out


def _circuit_reach(lines, checks, max_angle_deg: float = 1.0, across_m: float = 3.0, min_m: float = 1.0,
                   max_m: float = 5.0) -> list:
    """``checks`` (per line a list of (a, b)) with each line's far ends carried on to where a
    parallel conductor of its circuit (within ``max_angle_deg``, its end within ``across_m``
    across) is seen to end, ``min_m`` to ``max_m`` farther: the phases of a circuit end at one
    support, so a wire seen short of its sibling's end runs on (unseen) at least that far, past
    a support of another line beside it (mobile_dist seed 5: line B's wire seen 2 m short of line
    A's pole, its sibling on to B's own pole 1.9 m past it, which was taken for A's). Ends
    closer than ``min_m`` are where each wire was seen to, at one support (the crossings'
    margin past a line's seen end covers them)."""
    import numpy as np

    cos_max = np.cos(np.radians(max_angle_deg))
    far = _far_ends(lines, checks)
    out = [list(c) for c in checks]
    for i, ends in enumerate(far):
        for e, u in ends:
            ahead = min_m
            for j, other in enumerate(far):
                if j == i:
                    continue
                for f, v in other:
                    w = f - e
                    along, across = float(w @ u), abs(float(u[0] * w[1] - u[1] * w[0]))
                    if float(u @ v) >= cos_max and across <= across_m and ahead < along <= max_m:
                        ahead = along
            if ahead > min_m:
                out[i].append((e, e + ahead * u))
    return out


def _crossings_of(cond, segs, validation: str, hu: float, found=(), bounds=None, wire_reach=None):
    """The ``crossings`` layer of the final conductors, whichever pass found them: pairs of plan
    lines (``cond``) confirmed by their extents or (``segments``, the paper) by their validated
    ``segs``, as the Hough confirms its own. A crossing the Hough merged with a line dropped
    later (a tower member through the same point) is then still a crossing of the lines kept.
    A line that ends at a found tower or pole (``found``; its footprint's reach and 3 m), or
    where its circuit ends (``_circuit_ends`` within the data's ``bounds``), crosses nothing past
    that end; a line reaches at least as far as its circuit's other conductors (``_circuit_reach``)
    and, validated by extent, as its own wire points (``wire_reach``: per line, the ends of their
    extent along it, or None)."""
    import geopandas as gpd
    import numpy as np
    from shapely.geometry import Point

    from toolbox.crossings import crossings

    def ends(g):
        return np.asarray(g.coords[0], float)[:2] * hu, np.asarray(g.coords[-1], float)[:2] * hu

    supports = [(p.x, p.y, max(3.0, p.extent_m() + 1.0)) for p in found]
    beyond_m = 1.0  # how far past its checked extent a line at a support reaches (crossings())

    def short_of_supports(q, a, d, side):
        # a wire seen up to a found support ends at it: its reach is held beyond_m short of the
        # support, which crossings() carries to the support, no farther
        out = side * float((q - a) @ d)
        for x, y, r in supports:
            if np.hypot(q[0] - x, q[1] - y) <= r:
                out = min(out, side * float((np.array([x, y]) - a) @ d) - beyond_m)
        return a + side * out * d

    lines, checks = [], []
    for i, g in enumerate(cond.geometry):
        a, b = ends(g)
        lines.append((a, (b - a) / max(float(np.hypot(*(b - a))), 1e-12)))
        checks.append([(a, b)] if validation == "extent" else
                      [ends(s) for s in segs.geometry[(segs["conductor"] == i).to_numpy()]])
        if validation == "extent" and wire_reach is not None and wire_reach[i] is not None:
            # at a found support the support's rule says where the line ends: wire points on its
            # arm or top would carry it past the support onto the line beside it
            w0, w1 = (np.asarray(w, float) for w in wire_reach[i])
            d = lines[-1][1]
            checks[-1].append((short_of_supports(w0, a, d, -1.0), short_of_supports(w1, a, d, 1.0)))
    checks = _circuit_reach(lines, checks)
    if bounds is not None:
        supports += _circuit_ends(lines, checks, bounds)
    cross = crossings(lines, checks, supports=supports, beyond_m=beyond_m)
    rows = [{"n_lines": k["n_lines"], "angle_deg": k["angle_deg"], "conductors": ",".join(map(str, k["lines"]))}
            for k in cross]
    geoms = gpd.GeoSeries([Point(k["x"] / hu, k["y"] / hu) for k in cross], crs=cond.crs)
    out = gpd.GeoDataFrame(rows if rows else {"n_lines": [], "angle_deg": [], "conductors": []}, geometry=geoms,
                           crs=cond.crs)
    out.attrs["geometry_type"] = "Point"
    return out


def _tile_buffer_m(p) -> float:
    """Survey runs: every Hough tile that reaches a survey tile whole (Hough tiles sit on a fixed
    grid, so it then votes as in the whole survey), and around each of its points what decides
    that point: the density window (density_radius_m and a block) and the ground filter's largest
    window at its defaults (50 m and a few cells)."""
    from .core import DENSITY_BLOCK_M

    hough = p["tile_size_m"] if p["tile_size_m"] > 0 else 200.0
    return hough + max(p["density_radius_m"] + DENSITY_BLOCK_M, 60.0 if p["ground"] == "filter" else 0.0)


# how the layers of the tiles of a survey become one: lines cut at tile borders joined, the
# conductors renumbered and every reference to them following
_REFS = {"conductor": "conductors"}
LAYER_MERGE = {
    "conductors": LayerMerge(id_field="conductor", combine={"length_m": "length", "height_min_m": "min",
                                                            "height_max_m": "max", "n_wires": "max"}),
    "conductor_segments": LayerMerge(refs=_REFS, combine={"length_m": "length"}),
    "crossings": LayerMerge(refs={"conductors": "conductors"}),
    "conductors_3d": LayerMerge(refs=_REFS, combine={"length_m": "length"}),
    "pylons": LayerMerge(id_field="pylon"),
}


@toolbox.hookimpl
def toolbox_algorithms():
    return [Algorithm(
        id="powerlines", title="Power-line conductors from a raw point cloud", run=_run,
        description=(
            "The method's chain: ground and height above ground (dtm), candidates by class, returns and a height "
            "window, an eigenvalue planar/rugged pre-classification (a flat set that falls into narrow bands across it, or within one band in plan into bands in height, is wires side by side or one above another, not a roof), the top-hat point filter, tiled 2D Hough with "
            "validation, SVD refit, merging across tiles; then the 3D step: the points near each 2D "
            "line split by height and continuity into wires (stacked conductors come apart) and a catenary fitted "
            "per span (where one does not fit, catenaries peeled one at a time: wires stacked under 1 m apart; "
            "pieces between cuts or occlusions from S_min / 2; a piece cut where two catenaries meeting with a slope "
            "drop fit it 1.5 times better than one: a tower the wire runs through); V_max is the method's 2.5 m unless a first pass "
            "finds the wires sampled sparser than 10 points per 2.5 m, then 10 x their median point spacing "
            "(v_max_m_used, wire_spacing_m); a 2D line whose spans agree it leans off their wire by more than "
            "band_m over its length is turned onto their trend and searched again (n_lines_realigned); a short "
            "first-pass line along a line twice its length is folded "
            "into it; a conductor holds a span of S_min that fits, hangs "
            "gently and is thin across the line (lateral rms <= 0.15 m); the wire-like points left on no wire are "
            "searched once more (second_pass: a line's stretch past a bend; a line along one found already is folded "
            "into it), and what is still left for "
            "straight 3D runs of S_min / 2 (short_wires: a mobile scan's wires across the street, fanning from "
            "a pole; one must leave the wires found at a support, lead away from them and stand alone in its "
            "cross-section; n_short_wires; after the pylons, a run of S_min / 4 that leads from a found pole, "
            "continued along its axis across gaps under V_max, aimed within 1.8 m of the pole's axis under its top and "
            "reaching S_min / 2 from it: n_pole_wires), and beside each fitted span for a phase too sparse to find alone "
            "(sibling_wires, n_sibling_wires); each span's catenary continued past its ends takes the wire where the "
            "candidates stopped (under the height window, beside a tower; grow_spans, n_grown_points), a stack's "
            "wires (one within 1.5 m over or under another) up to the pole or tower found ahead, and the wire "
            "across a found tower's footprint being the tower's; a wire point farther across its span's plan trend "
            "than 3 robust sigma (at least 0.05 m) with other points off the ground within 0.3 m is foliage the "
            "wire runs through (n_off_trend_points), and so is one where, within 1 m along the wire, the points "
            "0.2-0.5 m round its curve are no sparser than within 0.1 m and surround it on 5 of 8 sides "
            "(n_foliage_points); a conductor must stand out in its cross-section (not a roof's scan row or "
            "an eave in a surface, not the top edge of a wall, not points of a crown lined up; n_not_wires; on a line "
            "that holds wires, a span that on its own does not gives its points back: n_crowded_spans); past each "
            "wire's outermost span, its next span (a catenary of S_min or more meeting it within 0.5 m at the "
            "support, a concentration of points; next_spans, n_next_spans). Bundled sub-conductors: rugged "
            "sets shaped as tubes are wire-like, and the 3D step splits pieces across and in height, so each "
            "sub-conductor is a wire of conductors_3d; in plan one conductor per sub-conductor where they are at "
            "least 0.25 m apart, else one per phase at the bundle's centre (the middle of its outermost "
            "sub-conductors; a ribbon's phases closer than band_m "
            "share a Hough line and are drawn apart from their fitted spans: n_side_by_side); pylons where spans end on a tall column (or "
            "where the wires run through it uncut, when a line never leaves it: its arm) standing under the lines "
            "(its base within 2 m of a conductor in plan, between conductors, or its arms over one: not a tree "
            "beside the line where wires lost in its crown end), and "
            "poles: thin vertical columns (a ring of 0.25-0.75 m around them holding under 0.6 times the points "
            "within 0.25 m over 2 m of height, over 2.5 m of it) with a wire within 2 m and at least pylon_top_share as high as it; a tower found within "
            "6 m of a pole is the crown beside it (layer pylons: kind tower or pole, base point, height, spans, "
            "line heading; class 15 in the classified output: a pole's column within 0.45 m of its axis and its head, within 1.8 m in its top metre); crossings over the final conductors, whichever pass found them "
            "(confirmed by extents or segments as in the Hough), none more than 1 m past the end of a line at a "
            "tower or pole found (the method's crossings are not pylon positions). GeoPackage layers conductors, "
            "conductor_segments, "
            "crossings, conductors_3d, pylons."),
        reference=REFERENCE,
        tile_buffer_m=_tile_buffer_m,
        parameters=[
            Parameter("ground", str, "filter", "ground from the morphological filter or the file's class 2",
                      choices=("filter", "file")),
            Parameter("height_min_m", float, 3.5, "lowest candidate height above ground (the method: 3.5 m)",
                      unit="m", minimum=0.0, maximum=500.0),
            Parameter("height_max_m", float, None, "highest candidate height above ground; the method's 12 m suits "
                      "distribution lines, transmission lines sit at 10-60 m; auto: up to the highest points "
                      "(above the 99.95th percentile, those with two others within 2.5 m)", unit="m", minimum=0.0, maximum=1000.0, allow_auto=True),
            Parameter("first_returns_only", bool, True, "keep first returns only (ignored when the file has no return numbers)"),
            Parameter("density_radius_m", float, 200.0, "surface density (first returns per occupied m²) measured "
                      "around each candidate within this radius: a roof or crown neighbourhood must hold half of it "
                      "within 1 m, sparse wires never do", unit="m", minimum=5.0, maximum=5000.0),
            Parameter("neighbours", int, 12, "points in each shape (eigenvalue) neighbourhood", minimum=4, maximum=100),
            Parameter("rugged_share", float, 0.04, "smallest-eigenvalue share above which a neighbourhood is "
                      "vegetation", minimum=0.0, maximum=0.34),
            Parameter("planar_share", float, 0.2, "middle-eigenvalue share above which a flat neighbourhood is a roof",
                      minimum=0.0, maximum=0.5),
            Parameter("cell_size_m", float, None, "top-hat mask cell; auto: band_m / 3 (0.13 m), so that conductors "
                      "side by side band_m apart (bundles, three-phase ribbons) stay separate lines the top-hat keeps; "
                      "the method's 0.5 m suits single wires 1.5 m apart or more", unit="m", minimum=0.01,
                      maximum=10.0, allow_auto=True),
            Parameter("max_points_per_cell", int, 45, "top-hat: denser cells are dropped", unit="points", minimum=1),
            # the Hough stage's parameters (passed on to the hough-lines algorithm), the method's values
            Parameter("theta_step_deg", float, 0.1, "θ resolution of the accumulator", unit="deg", minimum=0.001,
                      maximum=10.0),
            Parameter("rho_step_m", float, 0.1, "ρ resolution", unit="m", minimum=0.001, maximum=10.0),
            Parameter("band_m", float, 0.4, "half-width of the band subtracted after each peak", unit="m",
                      minimum=0.0, maximum=50.0),
            Parameter("min_votes", int, 15, "stop below this many votes", unit="votes", minimum=2),
            Parameter("s_min_m", float, 8.0, "S_min: shortest run of a conductor", unit="m", minimum=0.0),
            Parameter("v_max_m", float, None, "V_max: largest gap within a run; auto: the method's 2.5 m, or on "
                      "sparser surveys 10 x the median spacing of points along the wires a first pass finds "
                      "(v_max_m_used, wire_spacing_m)", unit="m", minimum=0.01, maximum=1000.0, allow_auto=True),
            Parameter("tile_size_m", float, 100.0, "Hough tile size", unit="m", minimum=0.0, maximum=100000.0),
            Parameter("overlap_m", float, 10.0, "tile overlap", unit="m", minimum=0.0, maximum=1000.0),
            Parameter("merge_gap_m", float, 100.0, "collinear pieces this close are one conductor", unit="m",
                      minimum=0.0),
            Parameter("fit_points", str, "band", "points of the refit: band (±band_m) or inverse (the paper)",
                      choices=("band", "inverse")),
            Parameter("crossing_validation", str, "extent", "crossings confirmed by conductor extents or (the "
                      "paper) by validated segments", choices=("extent", "segments")),
            Parameter("validate_3d", bool, True, "keep only conductors that are wires in 3D (a catenary span of at "
                      "least S_min with a small residual, gentle slope and thin across the line)"),
            Parameter("second_pass", bool, True, "search the wire-like points left on no wire once more (a line's "
                      "stretch past a bend, wires outvoted in a tile); its lines must hold mostly wire"),
            Parameter("short_wires", bool, True, "search what is left for straight 3D runs of wire-like points "
                      "S_min / 2 long: wires seen over a few metres only (a mobile scan's wires across the street) "
                      "that the 2D Hough's S_min misses; and, with the poles found, runs of S_min / 4 leading "
                      "from a pole"),
            Parameter("sibling_wires", bool, True, "search beside each fitted span (band_m to 4 m across, 3 m up "
                      "or down) for a phase too sparse to find alone: points at one offset across it and one height "
                      "above its catenary, a catenary of their own over half the span or more; and over and under "
                      "it (within band_m across) for the cables of a stack, each standing alone but in its plane"),
            Parameter("grow_spans", bool, True, "continue each fitted span's catenary past its ends and take the "
                      "points on it (within 0.25 m in plan and the fit's tolerance, no gap over 2 x v_max_m, up to "
                      "2 x s_min_m): a wire under the height window or next to a tower"),
            Parameter("next_spans", bool, True, "past each wire's outermost span, and into the holes between its "
                      "spans, search its plan trend for the next span (a catenary meeting it at its support, S_min "
                      "long or more, as thin as the span it continues, a concentration of points, not a crown's "
                      "edge or a pole's blob): a wire seen sparsely past the last support the Hough found"),
            Parameter("bridge_gaps", bool, True, "between two pieces of a wire up to 2 x s_min_m apart that one "
                      "catenary fits as closely as their own points, take the points on it: a wire through a crown"),
            Parameter("alone_beside_wires", bool, True, "take the points alone in the air (at most 2 others within "
                      "0.4 m; within 1 m at most 8 and a quarter of what a surface of the survey's density holds) "
                      "up to 0.5 m from a wire's points as wire: the points its fits left out and a wire hanging "
                      "beside it closer than the 2D step tells apart"),
            Parameter("max_rms_3d_m", float, 0.2, "largest RMS residual of a span's catenary", unit="m", minimum=0.0),
            Parameter("pylon_top_share", float, 0.8, "a tower reaches at least this share of the height where the "
                      "spans ending at it are attached", minimum=0.1, maximum=2.0),
            Parameter("band_3d_m", float, 1.0, "half-width of the band around a 2D line whose points the 3D step "
                      "splits into wires by height (conductors side by side at other heights are caught too)",
                      unit="m", minimum=0.05, maximum=10.0),
        ],
        inputs=[Input("points", "points", "raw LAS/LAZ point cloud",
                      dims=("classification", "return_number", "number_of_returns"))],
        outputs=[
            Output("lines", "vector", "layers conductors, conductor_segments, crossings, conductors_3d, pylons",
                   merge=LAYER_MERGE),
            Output("classified", "points", "the input with the detected wire points as class 14, tower points "
                   "as 15, and ground 2 and noise 7 among points of input classes 0-7; a former 2, 14 or 15 not "
                   "found so becomes 1, every other point keeps its class", optional=True,
                   suffix="_wires"),
        ],
    )]

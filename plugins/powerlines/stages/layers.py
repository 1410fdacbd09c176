"""Stage 11, layers: the conductors' attributes (heights above ground, wires), the 3D layer (a
catenary per span that fits), the crossings, the pylons, the classified cloud, and the stats."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
from shapely.geometry import LineString, Point

import toolbox
from toolbox.crossings import crossings

from ..rules import CIRCUITS, TOPHAT_WARN_MIN_LINEAR, TOPHAT_WARN_SHARE
from ..core import catenary, ends_at_supports
from ..plan_geometry import wire_reach_of
from ..state import State

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


def stage(scene, st: State, settings, ctx):
    pc, hu, vu, params, hag = scene.pc, scene.hu, scene.vu, settings.params, scene.hag
    lines, geo, spans = st.wires.as_tuple()
    conductor_of, wire_of_input = st.labels.conductor, st.labels.wire
    supports, timings = st.supports, st.timings
    cond = lines["conductors"]
    # attributes of the 2D conductors: heights above ground of their 3D points
    hmin, hmax = [], []
    for li in range(len(cond)):
        h = hag[conductor_of == li]
        hmin.append(float(h.min()) if len(h) else np.nan)
        hmax.append(float(h.max()) if len(h) else np.nan)
    cond = cond.assign(height_min_m=hmin, height_max_m=hmax,
                       n_wires=[len(np.unique(wire_of_input[conductor_of == li])) for li in range(len(cond))])
    # a piece no catenary fits (a crown the wire runs through) is no span of a wire: its points are
    # not wire points, and it is not drawn
    spans = [sp for sp in spans if sp.rms <= params["max_rms_3d_m"]]
    c3d = conductors_3d_layer(spans, geo, pc.crs, hu, vu)
    bounds = (float(pc.x.min()) * hu, float(pc.y.min()) * hu, float(pc.x.max()) * hu, float(pc.y.max()) * hu)
    wire_reach = wire_reach_of(cond, st.fitted_of, pc, hu) if params["crossing_validation"] == "extent" else None
    crossings = crossings_layer(cond, lines["conductor_segments"], params["crossing_validation"], hu, supports.found,
                                bounds=bounds, wire_reach=wire_reach)
    layers = {"conductors": cond, "conductor_segments": lines["conductor_segments"],
              "crossings": crossings, "conductors_3d": c3d, "pylons": supports.layer}
    out = {"lines": layers}
    if ctx.wants("classified"):
        out["classified"] = pc.with_fields(classification=classes_decided(pc, scene.ground_cls, supports.tower_pt,
                                                                          conductor_of >= 0))
    n_linear = int(scene.linear.sum())
    if (len(cond) == 0 or params["cell_size_m"] is not None) and n_linear >= TOPHAT_WARN_MIN_LINEAR and \
            st.n_tophat < TOPHAT_WARN_SHARE * n_linear:
        # the AHN4 case: conductors side by side closer than the mask cell make a strip that the
        # opening keeps, and the top-hat throws the wires away
        ctx.log.warning(
            "powerlines: the top-hat kept %d of %d wire-like points and %d conductors were found; conductors "
            "hanging side by side within 3 x cell_size_m=%g merge into a band the opening removes - "
            "leave cell_size_m automatic or set it to a third of their spacing", st.n_tophat, n_linear, len(cond),
            settings.cell_m)
    spacing = st.wire_spacing_m
    stats = {**scene_stats(scene, settings), "n_linear": n_linear, "n_tophat": st.n_tophat,
             "surface_density_used": round(float(np.median(scene.surface_density)), 2)
             if len(scene.surface_density) else None,
             "wire_spacing_m": None if spacing is None else round(spacing, 3), **st.counts,
             "n_lines_realigned": timings.pop("n_lines_realigned", 0),
             "n_twin_lines_merged": timings.pop("n_twin_lines_merged", 0),
             "n_conductors": len(cond), "n_wires_3d": len({(s.conductor, s.wire) for s in spans}),
             "n_spans": len(spans), "n_crossings": len(crossings), "n_wire_points": int((conductor_of >= 0).sum()),
             "n_grown_points": int((conductor_of[st.grown] >= 0).sum()),
             "n_pylons": len(supports.layer), "n_poles": sum(p.kind == "pole" for p in supports.found),
             "n_tower_points": int(supports.tower_pt.sum()),
             **{k: round(v, 3) for k, v in timings.items()}}
    return toolbox.Result(out, stats=stats)


def scene_stats(scene, settings) -> dict:
    """The stats every run reports, whatever it found."""
    return {"n_points": len(scene.pc), "n_candidates": int(len(scene.candidates)),
            "height_max_m_used": round(scene.h_max, 2), "cell_size_m_used": settings.cell_m,
            "v_max_m_used": settings.params["v_max_m"]}


def conductors_3d_layer(spans, geo, crs, hu, vu):
    """The ``conductors_3d`` layer: each span's catenary drawn every 2 m or so along its line."""
    rows, geoms = [], []
    for sp in spans:
        a, dvec, _, _ = geo[sp.conductor]
        ss = np.linspace(sp.s_from, sp.s_to, max(int((sp.s_to - sp.s_from) / 2.0), 2) + 1)
        zz = catenary(ss, sp.z0, sp.s0, sp.c)
        normal = np.array([-dvec[1], dvec[0]])
        xy = a[None, :] + ss[:, None] * dvec[None, :] + (sp.offset + sp.offset_slope * ss)[:, None] * normal[None, :]
        geoms.append(LineString(np.column_stack([xy[:, 0] / hu, xy[:, 1] / hu, zz / vu])))
        rows.append({"conductor": sp.conductor, "wire": sp.wire, "span": sp.span, "sag_m": sp.sag,
                     "catenary_c_m": sp.c, "rms_m": sp.rms, "n_points": sp.n_points,
                     "offset_m": sp.offset + sp.offset_slope * (sp.s_from + sp.s_to) / 2,
                     "length_m": sp.s_to - sp.s_from})
    c3d = gpd.GeoDataFrame(rows, geometry=geoms, crs=crs) if rows else gpd.GeoDataFrame(
        {"conductor": np.array([], np.int64)}, geometry=gpd.GeoSeries([], crs=crs), crs=crs)
    c3d.attrs["geometry_type"] = "LineString Z"
    return c3d


def nothing_found_for(scene, settings, ctx, timings: dict):
    """The result of an input where fewer candidates than a wire needs stand in the window."""
    params = settings.params
    note = (f"only {len(scene.candidates)} points stand {params['height_min_m']:g}-{scene.h_max:.1f} m above the "
            "ground: no wire can be there (check height_min_m / height_max_m if there is one)")
    ctx.log.info("powerlines: %s: %s", scene.pc.source, note)
    return nothing_found(scene.pc, scene.ground_cls, ctx, note,
                         {**scene_stats(scene, settings), **{k: round(v, 3) for k, v in timings.items()}})


def classes_decided(pc, ground_cls, tower=None, wire=None):
    """The input's classes with what this run decides: wires 14 and towers 15 (a former 14 or 15
    it does not find becomes 1), and its ground step's ground 2 and noise 7 on the points whose
    input class a ground filter decides (below 8: water, bridge decks, 18 and above stay)."""
    given = pc.classification
    filterable = np.ones(len(pc), bool) if given is None else np.asarray(given) < 8
    g = np.asarray(ground_cls)
    decided = [(2, filterable & (g == 2)), (7, filterable & (g == 7))]
    decided += [(15, tower)] if tower is not None else []
    decided += [(14, wire)] if wire is not None else []
    return pc.classes_with(decided, released=(2, 14, 15))


def nothing_found(pc, ground_cls, ctx, note, stats):
    """Empty layers (and the ground's classes) for an input with nothing to find, and the note why."""
    layers = {}
    for name, (gtype, fields) in EMPTY_LAYERS.items():
        gdf = gpd.GeoDataFrame({k: pd.Series([], dtype=t) for k, t in fields.items()},
                               geometry=gpd.GeoSeries([], crs=pc.crs), crs=pc.crs)
        gdf.attrs["geometry_type"] = gtype
        layers[name] = gdf
    out = {"lines": layers}
    if ctx.wants("classified"):
        out["classified"] = pc.with_fields(classification=classes_decided(pc, ground_cls))
    return toolbox.Result(out, stats={**stats, "n_conductors": 0, "n_pylons": 0, "n_wire_points": 0, "note": note})


def crossings_layer(cond, segs, validation: str, hu: float, found=(), bounds=None, wire_reach=None):
    """The ``crossings`` layer of the final conductors, whichever pass found them: pairs of plan
    lines (``cond``) confirmed by their extents or (``segments``, the paper) by their validated
    ``segs``, as the Hough confirms its own. A crossing the Hough merged with a line dropped
    later (a tower member through the same point) is then still a crossing of the lines kept.
    A line that ends at a found tower or pole (``found``; its footprint's reach and 3 m), or
    where its circuit ends (``circuit_ends`` within the data's ``bounds``), crosses nothing past
    that end; a line reaches at least as far as its circuit's other conductors (``circuit_reach``)
    and, validated by extent, as its own wire points (``wire_reach``: per line, the ends of their
    extent along it, or None)."""
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
    checks = circuit_reach(lines, checks)
    if bounds is not None:
        supports += circuit_ends(lines, checks, bounds)
    cross = crossings(lines, checks, excluded=ends_at_supports(lines, checks, supports, beyond_m=beyond_m))
    rows = [{"n_lines": k["n_lines"], "angle_deg": k["angle_deg"], "conductors": ",".join(map(str, k["lines"]))}
            for k in cross]
    geoms = gpd.GeoSeries([Point(k["x"] / hu, k["y"] / hu) for k in cross], crs=cond.crs)
    out = gpd.GeoDataFrame(rows if rows else {"n_lines": [], "angle_deg": [], "conductors": []}, geometry=geoms,
                           crs=cond.crs)
    out.attrs["geometry_type"] = "Point"
    return out


def far_ends(lines, checks) -> list:
    """Per line (anchor, direction), the two far ends of its checked extents (``checks``, a list
    of (a, b)) as (position, outward direction); none for a line without extents."""
    out = []
    for (a, d), segs in zip(lines, checks):
        if not len(segs):
            out.append([])
            continue
        pts = np.array([e for seg in segs for e in seg], float)
        t = (pts - a) @ d
        out.append([(pts[int(np.argmin(t))], -d), (pts[int(np.argmax(t))], d)])
    return out


def circuit_ends(lines, checks, bounds, max_angle_deg: float = CIRCUITS.max_angle_deg,
                 across_m: float = CIRCUITS.ends_across_m, along_m: float = CIRCUITS.ends_along_m,
                 edge_m: float = CIRCUITS.edge_m) -> list:
    """Supports seen or not: where two or more parallel conductors (within ``max_angle_deg``
    and ``across_m`` of one another) have the far ends of their checked extents (``checks``, per
    line a list of (a, b)) within ``along_m`` of one another along them, more than ``edge_m``
    inside the data's ``bounds`` (xmin, ymin, xmax, ymax): the circuit ends there, at a pole
    the scan saw too little of to find (a street scanner's view of a pole across the block).
    Returns [(x, y, reach_m)], each reaching its members' ends and a metre."""
    ends = [(i, e, u) for i, line_ends in enumerate(far_ends(lines, checks)) for e, u in line_ends
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


def circuit_reach(lines, checks, max_angle_deg: float = CIRCUITS.max_angle_deg,
                  across_m: float = CIRCUITS.reach_across_m, min_m: float = CIRCUITS.reach_min_m,
                  max_m: float = CIRCUITS.reach_max_m) -> list:
    """``checks`` (per line a list of (a, b)) with each line's far ends carried on to where a
    parallel conductor of its circuit (within ``max_angle_deg``, its end within ``across_m``
    across) is seen to end, ``min_m`` to ``max_m`` farther: the phases of a circuit end at one
    support, so a wire seen short of its sibling's end runs on (unseen) at least that far, past
    a support of another line beside it (mobile_dist seed 5: line B's wire seen 2 m short of line
    A's pole, its sibling on to B's own pole 1.9 m past it, which was taken for A's). Ends
    closer than ``min_m`` are where each wire was seen to, at one support (the crossings'
    margin past a line's seen end covers them)."""
    cos_max = np.cos(np.radians(max_angle_deg))
    far = far_ends(lines, checks)
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

"""Scene truth as GeoDataFrames (one layer per object kind) and as a JSON document."""

from __future__ import annotations

import numpy as np


def _gdf(rows, geoms, crs, gtype):
    import geopandas as gpd

    gdf = gpd.GeoDataFrame(rows, geometry=geoms, crs=crs) if rows else gpd.GeoDataFrame(
        {"id": np.array([], dtype=np.int64)}, geometry=gpd.GeoSeries([], crs=crs), crs=crs)
    gdf.attrs["geometry_type"] = gtype
    return gdf


def truth_layers(scene, crs) -> dict:
    from shapely import wkt
    from shapely.geometry import LineString, Point, Polygon

    t = scene.truth
    layers = {}
    rows = [{"line": c["line"], "offset_m": c["offset_m"], "wire_ids": ",".join(map(str, c["wire_ids"])),
             "n_wires": len(c["wire_ids"])} for c in t["conductor_lines_2d"]]
    layers["truth_conductors_2d"] = _gdf(rows, [LineString([c["a"], c["b"]]) for c in t["conductor_lines_2d"]], crs, "LineString")
    rows = [{"wire_id": s["wire_id"], "line": s["line"], "span": s["span"], "length_m": s["length_m"],
             "catenary_c_m": s["catenary_c_m"], "sag_m": s["sag_m"], "n_points": s["n_points"]} for s in t["spans"]]
    layers["truth_catenaries"] = _gdf(rows, [LineString(s["curve"]) for s in t["spans"]], crs, "LineString Z")
    rows = [{"line_a": c["lines"][0], "line_b": c["lines"][1], "angle_deg": c["angle_deg"]} for c in t["crossings"]]
    layers["truth_crossings"] = _gdf(rows, [Point(c["x"], c["y"]) for c in t["crossings"]], crs, "Point")
    rows = [{"plane_id": p["plane_id"], "building_id": p["building_id"], "face": p["face"],
             "nx": p["normal"][0], "ny": p["normal"][1], "nz": p["normal"][2], "offset": p["offset"],
             "slope_deg": p["slope_deg"], "n_points": p["n_points"]} for p in t["roof_planes"]]
    layers["truth_roof_planes"] = _gdf(rows, [wkt.loads(p["polygon_wkt"]) for p in t["roof_planes"]], crs, "Polygon")
    rows = [{"id": b["id"], "roof": b["roof"], "length_m": b["length_m"], "width_m": b["width_m"],
             "heading_deg": b["heading_deg"], "eave_z": b["eave_z"], "top_z": b["top_z"], "pitch_deg": b["pitch_deg"]}
            for b in t["buildings"]]
    layers["truth_buildings"] = _gdf(rows, [Polygon(b["footprint"]) for b in t["buildings"]], crs, "Polygon")
    rows = [{k: p[k] for k in ("id", "line", "model", "z", "heading_deg", "roll_deg", "pitch_deg", "height_m",
                               "in_scene")} for p in t["pylons"]]
    layers["truth_pylons"] = _gdf(rows, [Point(p["x"], p["y"]) for p in t["pylons"]], crs, "Point")
    rows = [{k: tr[k] for k in ("id", "ground_z", "top_z", "radius_m", "conifer", "asprs_class")} for tr in t["trees"]]
    layers["truth_trees"] = _gdf(rows, [Point(tr["x"], tr["y"]) for tr in t["trees"]], crs, "Point")
    w = t.get("water")
    layers["truth_water"] = _gdf([{"level_z": w["level_z"]}] if w else [], [Polygon(w["ring"])] if w else [], crs, "Polygon")
    return layers


def truth_json(scene) -> dict:
    t = dict(scene.truth)
    return {
        "scene": {"kind": scene.kind, "seed": scene.seed, "origin": list(scene.origin), "extent_m": list(scene.extent),
                  "crs": scene.crs, "dtm_resolution_m": scene.dtm_resolution_m},
        "classes": {"2": "ground", "3": "low vegetation (plant < 2 m)", "4": "medium vegetation (2-5 m)",
                    "5": "high vegetation (>= 5 m)", "6": "building", "7": "noise (low outliers, birds)",
                    "9": "water", "14": "wire conductor", "15": "transmission tower", "17": "bridge deck"},
        **t,
    }

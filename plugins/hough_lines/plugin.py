"""Adapter of the 2D Hough line plugin: ``hough-lines`` (points to conductor lines, segments and
crossings in a GeoPackage)."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, Input, Output, Parameter, UsageError

REFERENCE = ("Grigillo, Ozvaldič, Vrečko, Kosmatin Fras (2015), Extraction of power lines from airborne and "
             "terrestrial laser scanning data using the Hough transform, Geodetski vestnik 59(2) 246-261 "
             "(METHODS.md §1, steps 3-5)")

PARAMETERS = [
    Parameter("theta_step_deg", float, 0.1, "θ resolution of the accumulator", unit="deg", minimum=0.001, maximum=10.0),
    Parameter("rho_step_m", float, 0.1, "ρ resolution (ρ rounded to it)", unit="m", minimum=0.001, maximum=10.0),
    Parameter("band_m", float, 0.4, "half-width of the band whose votes are subtracted after each peak",
              unit="m", minimum=0.0, maximum=50.0),
    Parameter("min_votes", int, 15, "stop when the largest accumulator cell has fewer votes", unit="votes", minimum=2),
    Parameter("s_min_m", float, 8.0, "S_min: shortest run of points that makes a conductor", unit="m", minimum=0.0),
    Parameter("v_max_m", float, 2.5, "V_max: largest gap between consecutive points of a run", unit="m",
              minimum=0.01),
    Parameter("v_max_spacings", float, 0.0, "where > 0, a validated peak's runs are taken with a V_max of at least "
              "this many median gaps between its inverse-Hough points, up to S_min / 2 (a sparse wire among dense "
              "ones, validated in stretches); 0: V_max alone (the method)", minimum=0.0, maximum=100.0),
    Parameter("tile_size_m", float, 100.0, "tile size (0: one tile)", unit="m", minimum=0.0, maximum=100000.0),
    Parameter("overlap_m", float, 10.0, "tile overlap", unit="m", minimum=0.0, maximum=1000.0),
    Parameter("merge_gap_m", float, 100.0, "collinear pieces (within 1 degree and 0.25 m) this close along the "
              "line are one conductor (tile overlaps, gaps at pylons and crossings)", unit="m", minimum=0.0),
    Parameter("fit_points", str, "band", "points of the least-squares refit: 'inverse' = the inverse-Hough points "
              "(the paper; quantised to the ρ bin), 'band' = the points within ±band_m (sharper)",
              choices=("band", "inverse")),
    Parameter("crossing_validation", str, "extent", "a line intersection is a crossing when it lies on both "
              "conductors' extents (each extended 5 m), or - the paper - near an intersection of their validated "
              "segments; the top-hat empties the mask where several lines cross, so segments stop short there",
              choices=("extent", "segments")),
    Parameter("max_accumulator_mb", float, 2048.0, "largest accumulator allowed per tile", unit="MB", minimum=1.0),
]


def hough_params(params: dict) -> dict:
    return {k: params[k] for k in ("theta_step_deg", "rho_step_m", "band_m", "min_votes", "s_min_m", "v_max_m",
                                   "fit_points", "v_max_spacings")}


def detect(ctx, x, y, params):
    """Tiled detection with the taichi accumulator; errors as one line."""
    from .core import AccumulatorTooLarge, detect_tiled
    from .kernels import TaichiAccumulator

    if params["overlap_m"] >= params["tile_size_m"] > 0:
        raise UsageError(f"overlap_m ({params['overlap_m']}) must be smaller than tile_size_m ({params['tile_size_m']})")
    ti = ctx.taichi()
    try:
        return detect_tiled(
            x, y, lambda *a, **kw: TaichiAccumulator(ti, *a, **kw), tile_size_m=params["tile_size_m"],
            overlap_m=params["overlap_m"], merge_gap_m=params["merge_gap_m"],
            max_accumulator_bytes=int(params["max_accumulator_mb"] * 2**20),
            progress=lambda it: ctx.progress(it, desc="hough tiles", unit="tile"), **hough_params(params))
    except AccumulatorTooLarge as exc:
        raise UsageError(f"hough-lines: {exc}; use a coarser rho_step_m / theta_step_deg, a smaller tile_size_m "
                         "or raise max_accumulator_mb") from None


def layers(conductors, x, y, crs, extra=None, validation: str = "extent"):
    """GeoDataFrames: conductors (clipped to the extent of their points), segments, crossings."""
    import geopandas as gpd
    import numpy as np
    from shapely.geometry import LineString, Point

    from toolbox.crossings import crossings

    rows, geoms, srows, sgeoms = [], [], [], []
    for i, c in enumerate(conductors):
        a = c.anchor + c.t_range[0] * c.direction
        b = c.anchor + c.t_range[1] * c.direction
        row = {"conductor": i, "votes": c.votes, "n_points": int(len(c.members)), "length_m": float(np.linalg.norm(b - a)),
               "rms_m": c.rms, "azimuth_deg": float(np.degrees(np.arctan2(c.direction[0], c.direction[1])) % 180.0),
               "v_max_m": c.v_max}
        if extra:
            row.update(extra(i, c))
        rows.append(row)
        geoms.append(LineString([a, b]))
        for k, (sa, sb) in enumerate(c.segments):
            srows.append({"conductor": i, "segment": k, "length_m": float(np.linalg.norm(sb - sa))})
            sgeoms.append(LineString([sa, sb]))
    if validation == "extent":  # each conductor's whole extent stands for its segments
        checks = [[(c.anchor + c.t_range[0] * c.direction, c.anchor + c.t_range[1] * c.direction)] for c in conductors]
    else:
        checks = [c.segments for c in conductors]
    cross = crossings([(c.anchor, c.direction) for c in conductors], checks)
    crows = [{"n_lines": k["n_lines"], "angle_deg": k["angle_deg"], "conductors": ",".join(map(str, k["lines"]))}
             for k in cross]
    cgeoms = [Point(k["x"], k["y"]) for k in cross]

    def gdf(r, g, gtype):
        out = gpd.GeoDataFrame(r, geometry=g, crs=crs) if r else gpd.GeoDataFrame(
            {"conductor": np.array([], np.int64)}, geometry=gpd.GeoSeries([], crs=crs), crs=crs)
        out.attrs["geometry_type"] = gtype
        return out

    return {"conductors": gdf(rows, geoms, "LineString"), "conductor_segments": gdf(srows, sgeoms, "LineString"),
            "crossings": gdf(crows, cgeoms, "Point")}, cross


def _run(inputs, params, ctx):
    pc = inputs["points"]
    pc.require_points("hough-lines", 2)
    hu = pc.horizontal_unit_m
    p = dict(params)
    for k in ("rho_step_m", "band_m", "s_min_m", "v_max_m", "tile_size_m", "overlap_m", "merge_gap_m"):
        p[k] = params[k] / hu
    conductors = detect(ctx, pc.x, pc.y, p)
    out, cross = layers(conductors, pc.x, pc.y, pc.crs, validation=params["crossing_validation"])
    return toolbox.Result({"lines": out}, stats={"n_points": len(pc), "n_conductors": len(conductors),
                                                 "n_crossings": len(cross)})


def _run_raster(inputs, params, ctx):
    """Cells above the threshold of a (binary) raster vote as points at their centres."""
    import numpy as np

    from toolbox import DataError

    r = inputs["image"]
    t = r.transform
    if t.b != 0 or t.d != 0:
        raise DataError(f"input {r.source!r} is rotated; warp it to a north-up grid first")
    band = r.bands()[0]
    on = r.valid_mask() & (band > params["threshold"])
    rows, cols = np.nonzero(on)
    if len(rows) < 2:
        raise DataError(f"input {r.source!r} has {len(rows)} cells above {params['threshold']}; nothing to detect")
    x = t.c + (cols + 0.5) * t.a
    y = t.f + (rows + 0.5) * t.e
    p = dict(params)
    conductors = detect(ctx, x, y, p)
    out, cross = layers(conductors, x, y, r.crs, validation=params["crossing_validation"])
    return toolbox.Result({"lines": out}, stats={"n_cells": int(len(x)), "n_lines": len(conductors),
                                                 "n_crossings": len(cross)})


@toolbox.hookimpl
def toolbox_algorithms():
    return [Algorithm(
        id="hough-lines-raster", title="2D Hough lines on a binary raster (e.g. roof edges)", run=_run_raster,
        description=("The same detection on the cells of a raster above a threshold (each votes at its centre), "
                     "e.g. the building-edge image of the roof method (mask minus its erosion). Lengths are in the "
                     "raster's units; give rho_step_m and band_m about one cell."),
        reference=REFERENCE + "; Borowiec, Hough transform as a tool supporting building roof detection (METHODS.md §3)",
        parameters=[Parameter("threshold", float, 0.0, "cells above this value vote"), *PARAMETERS],
        inputs=[Input("image", "raster", "a binary (or thresholded) GeoTIFF")],
        outputs=[Output("lines", "vector", "layers conductors (the lines), conductor_segments, crossings")],
    ), Algorithm(
        id="hough-lines", title="2D Hough lines (conductors) with crossings", run=_run,
        description=("2D Hough transform on the points' x, y (taichi accumulator): peaks taken one at a time, "
                     "validated by a run of points with gaps < V_max spanning ≥ S_min, the band's votes subtracted; "
                     "100 m tiles with 10 m overlap in a local origin, lines merged across tiles, refitted by SVD, "
                     "crossings from line pairs confirmed by their validated segments."),
        reference=REFERENCE,
        parameters=PARAMETERS,
        inputs=[Input("points", "points", "points of thin structures (e.g. the tophat output)", dims=())],
        outputs=[Output("lines", "vector", "layers conductors, conductor_segments, crossings")],
    )]

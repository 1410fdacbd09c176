"""Adapter of the morphological DTM plugin: algorithms ``dtm``, ``hillshade`` and ``classify``
(parameters, inputs, outputs). The computing lives in ``core`` and ``objects``."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, DataError, NothingFound, Input, Output, Parameter, UsageError

REFERENCE = ("Mongus & Žalik (2014) IEEE JSTARS 7(1) 340-351; Mongus, Lukač & Žalik (2014) ISPRS J. 93, 145-156; "
             "Mongus & Horvat, gLiDAR, Geodetski vestnik (METHODS.md §2)")
MAX_CELLS = 400_000_000

GROUND_PARAMETERS = [
    Parameter("filter_cell_m", float, 2.0, "cell of the minimum surface the multi-scale filter works on "
              "(about 2 points per cell or more)", unit="m", minimum=0.1, maximum=50.0),
    Parameter("max_filter_size_m", float, 50.0, "largest object to remove (its width); larger flattens "
              "ridges in steep terrain and costs time", unit="m", minimum=1.0, maximum=1000.0),
    Parameter("slope_k", float, 0.08, "k: growth of the removal threshold with object size (Δh ≥ n + k·size)",
              unit="m/m", minimum=0.0, maximum=5.0),
    Parameter("min_height_n_m", float, 0.45, "n: smallest height difference that removes an object",
              unit="m", minimum=0.0, maximum=50.0),
    Parameter("ground_threshold_m", float, 0.25, "largest height of a ground point over the filtered "
              "surface on flat terrain", unit="m", minimum=0.0, maximum=10.0),
    Parameter("slope_factor", float, 1.0, "extra tolerance per unit of terrain slope (x cell size)",
              minimum=0.0, maximum=10.0),
    Parameter("low_outlier_m", float, 2.0, "points this far below their neighbourhood are noise (class 7)",
              unit="m", minimum=0.1, maximum=100.0),
    Parameter("max_gap_m", float, 50.0, "widest area without returns (water, a shadow) that is interpolated; "
              "a wider one is left without ground (nodata in the DTM), and a tile in a survey needs a buffer this "
              "wide to see it whole", unit="m", minimum=0.0, maximum=1000.0),
    Parameter("refine_cell_m", float, None, "cell of the last refinement surface (a plane per 3x3 cells through "
              "the ground points); auto: 1.25 x the mean point spacing, between 1 m and filter_cell_m "
              "(reported as refine_cell_m_used)", unit="m", minimum=0.1, maximum=50.0, allow_auto=True),
]
MIN_AUTO_REFINE_CELL_M = 1.0  # finer grids cost memory and time on dense tiles for no gain in the ground test


def _ground(pc, p, accel=None):
    """Run the ground filter with the parameters converted to the cloud's units."""
    from .core import Grid, ground_filter

    pc.require_points("the ground filter", 10)
    _check_grid(pc, p["filter_cell_m"] / pc.horizontal_unit_m, "filter_cell_m")
    return ground_filter(pc.x, pc.y, pc.z, _ground_settings(pc, p), accel=accel), Grid


def survey_summary(pc, core_box, p) -> dict:
    """Survey runs: this tile's share of the counts that the auto refine_cell_m comes from (the
    point spacing over the footprint), so that every tile takes the survey's value, not its own."""
    from .core import spacing_counts

    if p["ground"] == "file" or p["refine_cell_m"] is not None or len(pc) == 0:
        return {}
    n_points, n_cells = spacing_counts(pc.x, pc.y, pc.z, _ground_settings(pc, p), core_box)
    return {"n_points": n_points, "n_footprint_cells": n_cells}


def survey_cells(p, horizontal_unit_m: float) -> float | None:
    """Survey runs: the grid whose per-cell statistics give the same counts as ``survey_summary``
    (the filter grid), or None when no value is taken from the whole input."""
    if p["ground"] == "file" or p["refine_cell_m"] is not None:
        return None
    return p["filter_cell_m"] / horizontal_unit_m


def survey_cell_summary(cells, p) -> dict:
    """``survey_summary`` summed over every tile, from the split pass's ``CellStats``."""
    from .core import spacing_counts_from_cells

    settings = _settings_in_units(p, cells.horizontal_unit_m, cells.vertical_unit_m)
    n_points, n_cells = spacing_counts_from_cells(cells.count, cells.zmin, cells.zmax, settings)
    return {"n_points": n_points, "n_footprint_cells": n_cells} if n_points else {}


def survey_values(sums, p, horizontal_unit_m: float) -> dict:
    """The survey's refine_cell_m, from the tiles' ``survey_summary`` summed: what one run over
    the whole survey would choose."""
    from .core import REFINE_PER_SPACING, mean_spacing, refine_cell_size

    if not sums.get("n_points"):
        return {}
    hu = horizontal_unit_m
    cell = p["filter_cell_m"] / hu
    spacing = mean_spacing(sums["n_points"], sums["n_footprint_cells"], cell)
    return {"refine_cell_m": refine_cell_size(spacing, cell, MIN_AUTO_REFINE_CELL_M / hu, REFINE_PER_SPACING) * hu}


def _ground_settings(pc, p):
    return _settings_in_units(p, pc.horizontal_unit_m, pc.vertical_unit_m)


def _settings_in_units(p, hu: float, vu: float):
    from .core import GroundSettings

    cell = p["filter_cell_m"] / hu
    return GroundSettings(
        cell=cell, max_size=p["max_filter_size_m"] / hu,
        k=p["slope_k"] * hu / vu, n=p["min_height_n_m"] / vu, ground_threshold=p["ground_threshold_m"] / vu,
        slope_factor=p["slope_factor"], low_outlier=p["low_outlier_m"] / vu,
        refine_cell=None if p["refine_cell_m"] is None else p["refine_cell_m"] / hu,
        min_refine_cell=MIN_AUTO_REFINE_CELL_M / hu, max_gap=p["max_gap_m"] / hu)


BYTES_PER_CELL = 320  # the DTM fit holds about 40 float64 grids at once


def _max_cells() -> int:
    """Grids may take half of the machine's memory."""
    from toolbox.memory import total_ram_bytes

    return int(min(MAX_CELLS, 0.5 * total_ram_bytes() / BYTES_PER_CELL))


def _ground_and_noise(pc, params, accel=None):
    """Ground and noise masks: from the morphological filter, or the file's classes 2 and 7."""
    import numpy as np

    if params["ground"] == "file":
        cls0 = pc.classification
        if cls0 is None or not np.any(cls0 == 2):
            raise NothingFound(f"input {pc.source!r} has no ground class (2); use ground=filter")
        return cls0 == 2, cls0 == 7, {}
    gr, _ = _ground(pc, params, accel)
    hu = pc.horizontal_unit_m
    return gr.ground, gr.noise, {"point_spacing_m": round(gr.point_spacing * hu, 3),
                                 "refine_cell_m_used": round(gr.surface_grid.cell * hu, 3)}


def _check_grid(pc, cell, name, caller=""):
    w, s, e, n = pc.bounds()
    cells = ((e - w) / cell + 3) * ((n - s) / cell + 3)
    limit = _max_cells()
    if cells > limit:
        size = (f"a {cell * pc.horizontal_unit_m:g} m grid over {pc.source!r} ({(e - w) * pc.horizontal_unit_m:.0f} x "
                f"{(n - s) * pc.horizontal_unit_m:.0f} m) would have {cells / 1e6:.0f} million cells, about "
                f"{cells * BYTES_PER_CELL / 2**30:.0f} GiB (limit here {limit / 1e6:.0f} million)")
        if caller:  # inside another algorithm: this grid is not the user's to set
            raise UsageError(f"{caller}: its ground step's {size}; run it in tiles (--tile-size-m) or remove the "
                             "points far from the rest")
        raise UsageError(f"{name}: {size}; use a larger {name} or run it in tiles (--tile-size-m)")


def _check_grids(pc, params, caller=""):
    """Refuse grids too big for memory before any work starts."""
    pc.require_points("the ground filter", 10)
    _check_grid(pc, params["filter_cell_m"] / pc.horizontal_unit_m, "filter_cell_m", caller)
    _check_grid(pc, params["resolution_m"] / pc.horizontal_unit_m, "resolution_m", caller)
    refine = params["refine_cell_m"]
    if refine is not None or params["filter_cell_m"] > MIN_AUTO_REFINE_CELL_M:
        # (auto: the smallest it may choose)
        _check_grid(pc, min(refine or MIN_AUTO_REFINE_CELL_M, params["filter_cell_m"]) / pc.horizontal_unit_m,
                    "refine_cell_m", caller)


def _footprint(grid, x, y, radius_cells, max_hole_cells=None):
    """Cells inside the data's footprint (holes without returns of at most ``max_hole_cells``
    included)."""
    import numpy as np

    from .core import footprint

    occ = np.zeros(grid.rows * grid.cols, bool)
    occ[grid.flat_index(x, y)] = True
    return footprint(occ.reshape(grid.rows, grid.cols), radius_cells, max_hole_cells)


KERNEL_MIN_POINTS = 300_000  # below this the numpy passes are as fast as the kernels
# The kernels' first use in a process costs start-up: taichi's own start (about 0.5 s, unless
# another algorithm started it) and its Python front end on the three kernels (about 0.35 s,
# paid even when the offline cache holds their machine code). The numpy passes cost more per
# point: 0.17 s per million in a warm process (AHN4's 0.7 M points +0.12 s, the 1.9 M corridor
# +0.28 s, the 10 M tile +2.0 s), about 0.5 s per million in a fresh one (their temporaries are
# paid in page faults as well: a fresh `toolbox run dtm` on the 1.9 M corridor was 0.2 s slower
# with numpy, on AHN4's 0.77 M 0.55 s faster). So a process takes numpy until the time numpy
# has lost would have paid for the start-up (rent or buy), counted at the fresh-process rate:
# a single file under about 1.7 M points never starts taichi for the DTM, a batch worker starts
# it after a few files, a larger tile at once.
NUMPY_EXTRA_S_PER_POINT = 0.5e-6
KERNELS_FIRST_USE_S = 0.35
TAICHI_START_S = 0.5
_numpy_extra_s = [0.0]  # what this process's numpy passes are estimated to have lost so far


def use_kernels(n_points: int, kernels_used: bool, taichi_started: bool, requested: bool) -> bool:
    """The rule above; counts the loss when it answers numpy for a cloud the kernels would take."""
    if n_points < KERNEL_MIN_POINTS:
        return False
    if kernels_used or requested:
        return True
    start_up = KERNELS_FIRST_USE_S + (0.0 if taichi_started else TAICHI_START_S)
    extra = NUMPY_EXTRA_S_PER_POINT * n_points
    if _numpy_extra_s[0] + extra >= start_up:
        return True
    _numpy_extra_s[0] += extra
    return False


def _accel(ctx, n_points: int):
    """Parallel taichi kernels for the per-point passes of large clouds, numpy for small ones
    (and in a fresh process, while the kernels' start-up would cost more than they save)."""
    from . import kernels

    if not use_kernels(n_points, kernels.used(), ctx.taichi_started(), ctx.taichi_requested()):
        return None
    return kernels.TaichiAccel(ctx.taichi())


def _dtm_raster(pc, ground_mask, resolution_m, max_gap_m, accel=None):
    import numpy as np
    from affine import Affine

    from toolbox.io.rasters import Raster

    from .core import Grid, dtm_from_ground

    res = resolution_m / pc.horizontal_unit_m
    _check_grid(pc, res, "resolution_m")
    grid = Grid.around(pc.x, pc.y, res, pad_cells=0)
    g = ground_mask
    if g.sum() < 3:
        raise NothingFound(f"input {pc.source!r}: fewer than 3 ground points were found; check the parameters")
    inside = _footprint(grid, pc.x, pc.y, max(2, int(np.ceil(5.0 / resolution_m))),
                        int(np.floor(max_gap_m / resolution_m)))
    dtm, _ = dtm_from_ground(grid, pc.x, pc.y, pc.z, where=g, moments=accel.moments if accel is not None else None,
                             domain=inside, fill_outside=False)  # outside the footprint is nodata
    dtm = np.where(inside, dtm, np.nan).astype(np.float32)
    return Raster(dtm, Affine(grid.cell, 0, grid.west, 0, -grid.cell, grid.north), crs=pc.crs,
                  nodata=float("nan"), style="dtm", description="bare-earth DTM (morphological filter)"), grid


def _preview(dtm_raster, pc, ground, noise):
    """Hillshade of the DTM with the points to be removed drawn over it (objects red, noise blue),
    on the DTM's grid (the PNG is georeferenced)."""
    import numpy as np

    from toolbox.io.rasters import Raster

    from .core import Grid, hillshade

    t = dtm_raster.transform
    hs = hillshade(dtm_raster.data, t.a, t.e).astype(np.float32)
    rgb = np.repeat(hs[..., None], 3, axis=2)
    grid = Grid(t.c, t.f, t.a, *dtm_raster.data.shape)
    r, c = grid.index(pc.x, pc.y)
    for mask, colour in ((~ground & ~noise, (230, 40, 40)), (noise, (30, 90, 255))):
        cover = np.zeros(hs.shape, bool)
        cover[r[mask], c[mask]] = True
        rgb[cover] = 0.35 * rgb[cover] + 0.65 * np.array(colour, np.float32)
    return Raster(np.moveaxis(np.clip(rgb, 0, 255).astype(np.uint8), -1, 0), t, crs=dtm_raster.crs,
                  description="DTM preview: removed points red, noise blue")


# classify assigns ASPRS classes 1-7; the input's classes from 8 on (water 9, wires 14, towers 15,
# bridge decks 17, 18 and above) are other producers' decisions, which it keeps unless told
CLASSIFY_ASSIGNS_BELOW = 8


def _run_dtm(inputs, params, ctx):
    import time

    import numpy as np

    pc = inputs["points"]
    _check_grids(pc, params, ctx.caller)
    accel = _accel(ctx, len(pc))
    t0 = time.perf_counter()
    ground, noise, filter_stats = _ground_and_noise(pc, params, accel)
    t1 = time.perf_counter()
    # ground 2 and noise 7 where the filter says so; a former 2 it does not keep is 1
    classified = pc.with_fields(classification=pc.classes_with([(2, ground), (7, noise)], released=(2,)))
    dtm, _ = _dtm_raster(pc, ground, params["resolution_m"], params["max_gap_m"], accel)
    t2 = time.perf_counter()
    out = {"dtm": dtm, "classified": classified}
    if ctx.wants("preview"):
        out["preview"] = _preview(dtm, pc, ground, noise)
    stats = {"n_points": len(pc), "n_ground": int(ground.sum()), "n_noise": int(noise.sum()),
             "ground_share": round(float(ground.mean()), 4), **filter_stats,
             "filter_s": round(t1 - t0, 3),
             "dtm_s": round(t2 - t1, 3)}
    if "label" in pc.fields:  # ISPRS filter-test reference labels: 0 bare earth, 1 object
        from .evaluation import ground_errors

        stats.update({f"isprs_{k}": v for k, v in ground_errors(pc.fields["label"] == 0, ground).items()})
    return toolbox.Result(outputs=out, stats=stats)


def _run_hillshade(inputs, params, ctx):
    from toolbox.io.rasters import Raster

    from .core import hillshade

    dem = inputs["dem"]
    t = dem.transform
    if t.b != 0 or t.d != 0:
        raise DataError(f"input {dem.source!r} is rotated; warp it to a north-up grid first (gdalwarp)")
    n_bands = dem.bands().shape[0]
    if n_bands > 1:
        raise DataError(f"input {dem.source!r} has {n_bands} bands (an RGB image?); hillshade needs a single-band "
                        "elevation raster: give the DEM, or take its band with gdal_translate -b 1")
    valid = dem.valid_mask()
    if not valid.any():
        raise DataError(f"input {dem.source!r} holds no elevation: every cell is nodata or NaN; check the DEM")
    ewres, nsres, stats = t.a, t.e, {}
    if dem.crs is not None and dem.crs.is_geographic and params["scale"] == 1.0:
        # cells in degrees, heights in metres: each axis in metres at the DEM's middle latitude
        lat = t.f + t.e * dem.shape[0] / 2
        m_lon, m_lat = metres_per_degree(lat)
        ewres, nsres = t.a * m_lon, t.e * m_lat
        stats = {"metres_per_degree_used": [round(m_lon, 1), round(m_lat, 1)], "latitude_deg": round(lat, 4)}
        ctx.log.info("%s is in degrees: cells taken as %.1f x %.1f m", dem.source, abs(ewres), abs(nsres))
    hs = hillshade(dem.bands()[0], ewres, nsres, params["azimuth_deg"], params["altitude_deg"], params["z_factor"],
                   params["scale"], params["multidirectional"], ~valid, params["compute_edges"])
    return toolbox.Result({"hillshade": Raster(hs, t, crs=dem.crs, nodata=0, style="hillshade",
                                               description="hillshade")}, stats=stats)


def metres_per_degree(lat_deg: float) -> tuple[float, float]:
    """Metres per degree of longitude and of latitude on the WGS84 ellipsoid at ``lat_deg`` (the
    series of the US NGA's geodesy tables, within a millimetre)."""
    import math

    p = math.radians(lat_deg)
    m_lat = 111132.92 - 559.82 * math.cos(2 * p) + 1.175 * math.cos(4 * p) - 0.0023 * math.cos(6 * p)
    m_lon = 111412.84 * math.cos(p) - 93.5 * math.cos(3 * p) + 0.118 * math.cos(5 * p)
    return m_lon, m_lat


def _run_classify(inputs, params, ctx):
    import numpy as np

    from .core import bilinear
    from .objects import classify_objects

    pc = inputs["points"]
    _check_grids(pc, params, ctx.caller)
    accel = _accel(ctx, len(pc))
    ground, noise, filter_stats = _ground_and_noise(pc, params, accel)
    dtm, grid = _dtm_raster(pc, ground, params["resolution_m"], params["max_gap_m"], accel)
    surface = np.nan_to_num(dtm.data.astype(np.float64), nan=float(np.nanmin(dtm.data)))
    h = pc.z - bilinear(grid, surface, pc.x, pc.y)
    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    cls = np.ones(len(pc), np.uint8)
    cls[ground] = 2
    rest = ~ground & ~noise
    xyz = np.column_stack([pc.x[rest], pc.y[rest], pc.z[rest] * vu / hu])  # isotropic units for the fits
    cls[rest] = classify_objects(
        xyz, h[rest] * vu / hu, neighbours=params["neighbours"], max_plane_error=params["max_plane_error_m"] / hu,
        min_plane_error=params["min_plane_error_m"] / hu, min_building_points=params["min_building_points"],
        min_building_height=params["min_building_height_m"] / hu, link_distance=params["link_distance_m"] / hu,
        vegetation_link=params["link_distance_m"] / hu, wall_reach=params["wall_reach_m"] / hu,
        wall_above=0.5 / hu, max_bundle_width=1.5 / hu,
        low_max=2.0 / hu, medium_max=5.0 / hu, min_object_height=0.25 / hu)  # ASPRS height classes in metres
    below = rest & (h < -params["low_outlier_m"] / vu)
    cls[noise | below] = 7
    n_kept = 0
    if params["reclassify"] == "own" and pc.classification is not None:
        given = np.asarray(pc.classification)
        theirs = given >= CLASSIFY_ASSIGNS_BELOW
        cls[theirs] = given[theirs]
        n_kept = int(theirs.sum())
    u, c = np.unique(cls, return_counts=True)
    return toolbox.Result(outputs={"classified": pc.with_fields(classification=cls), "dtm": dtm},
                          stats={"classes": {int(a): int(b) for a, b in zip(u, c)}, "n_kept_input_class": n_kept,
                                 **filter_stats})


def ground_buffer_m(p) -> float:
    """Survey runs: the points around a tile that its ground and DTM need: the largest opening
    window reaches max_filter_size_m (not with the file's own ground), a hole without returns is
    decided from the cells around it (max_gap_m), and the footprint's closing, the harmonic fill's
    rim and the 3x3 refinement planes reach a few filter cells more."""
    widest = max(0.0 if p.get("ground") == "file" else p["max_filter_size_m"], p["max_gap_m"])
    return widest + 5 * p["filter_cell_m"]


@toolbox.hookimpl
def toolbox_algorithms():
    resolution = Parameter("resolution_m", float, 1.0, "DTM cell size (0.5 m and 1 m are standard; bounded by "
                           "point density)", unit="m", minimum=0.05, maximum=1000.0)
    return [
        Algorithm(
            id="dtm", title="Morphological DTM and ground classification", run=_run_dtm,
            description=(
                "Ground filter by multi-scale morphological opening: openings of growing size up to the largest "
                "object; at each cell the scale with the largest height drop is the object's size, and it is "
                "removed when Δh ≥ n + k·size; gaps in the data (water, shadows) are filled from the ground the "
                "first opening kept and the opening repeated, so trees on a gap's rim stand out. "
                "Ground points lie within a slope-aware tolerance of the filtered "
                "surface, refined by planes fitted to the ground points per 3x3 filter cells, then per 3x3 cells of "
                "about the point spacing (refine_cell_m; where that is at most half the filter cell, there "
                "alone). They make the DTM: a plane fitted per cell, holes under buildings and water filled by "
                "harmonic interpolation. Writes the DTM GeoTIFF and the LAZ with ground (2) and noise (7). "
                "Several input files, or a folder, run as a batch in parallel."),
            reference=REFERENCE,
            tile_buffer_m=ground_buffer_m, survey_summary=survey_summary, survey_values=survey_values,
            survey_cells=survey_cells, survey_cell_summary=survey_cell_summary,
            parameters=[resolution,
                        Parameter("ground", str, "filter", "where ground comes from: the morphological filter, or "
                                  "the file's own class 2 (then only the DTM is made)", choices=("filter", "file")),
                        *GROUND_PARAMETERS],
            inputs=[Input("points", "points", "LAS/LAZ or ASCII point cloud")],
            outputs=[
                Output("dtm", "raster", "bare-earth DTM", style="dtm"),
                Output("classified", "points", "the input with ground (2) and noise (7) where the filter says "
                       "so; a former ground point it does not keep becomes 1, every other point keeps its class",
                       suffix="_classified"),
                Output("preview", "image", "hillshade with the removed points in red and noise in blue "
                       "(the view to tune parameters with)", optional=True),
            ],
        ),
        Algorithm(
            id="hillshade", title="Hillshade (gdaldem compatible)", run=_run_hillshade,
            description=("Analytical hillshade of a DEM with gdaldem's Horn-gradient formulas: one light "
                         "(azimuth, altitude) or the multidirectional blend of four. 1..255, 0 = nodata."),
            reference="Horn (1981), Hill shading and the reflectance map, Proc. IEEE 69(1); GDAL gdaldem; "
                      "Mark (1992) USGS OF 92-422 (multidirectional)",
            parameters=[
                Parameter("azimuth_deg", float, 315.0, "direction the light comes from, clockwise from north",
                          unit="deg", minimum=0.0, maximum=360.0),
                Parameter("altitude_deg", float, 45.0, "height of the light above the horizon", unit="deg",
                          minimum=0.0, maximum=90.0),
                Parameter("z_factor", float, 1.0, "vertical exaggeration", minimum=0.0, exclusive_minimum=True,
                          maximum=1000.0),
                Parameter("scale", float, 1.0, "ratio of horizontal to vertical units; a DEM in degrees (geographic "
                          "CRS) with heights in metres is scaled by the metres per degree at its latitude when this "
                          "is left at 1 (reported as metres_per_degree_used)",
                          minimum=0.0, exclusive_minimum=True, maximum=1e7),
                Parameter("multidirectional", bool, False, "blend lights from 225, 270, 315 and 360 degrees"),
                Parameter("compute_edges", bool, True, "shade the border cells too (gdaldem -compute_edges)"),
            ],
            inputs=[Input("dem", "raster", "elevation GeoTIFF")],
            outputs=[Output("hillshade", "raster", "hillshade, uint8", style="hillshade")],
        ),
        Algorithm(
            id="classify", title="Ground, buildings, vegetation (low/medium/high), noise", run=_run_classify,
            description=(
                "Among the non-ground points, local least-squares planes separate buildings (small plane error, "
                "large connected planar sets) from vegetation, and the points under a roof edge (facades, "
                "balconies, eaves) join their building; vegetation clusters are classed low (< 2 m), "
                "medium (< 5 m) or high by their height above the terrain; points below the terrain are noise. "
                "Writes ASPRS classes 1-7 on the points whose input class is 0-7; classes 8 and above (water 9, "
                "wires 14, towers 15, bridge decks 17, 18 and above) are kept unless reclassify=all."),
            reference=REFERENCE,
            # the ground's need, and a building's whole roof (its planar set) seen from either side
            tile_buffer_m=lambda p: max(ground_buffer_m(p), 50.0),
            survey_summary=survey_summary, survey_values=survey_values,
            survey_cells=survey_cells, survey_cell_summary=survey_cell_summary,
            parameters=[
                resolution,
                Parameter("ground", str, "filter", "where ground comes from: the morphological filter, or the "
                          "file's own class 2", choices=("filter", "file")),
                *GROUND_PARAMETERS,
                Parameter("neighbours", int, 12, "points in each local plane fit", minimum=4, maximum=200),
                Parameter("max_plane_error_m", float, 0.08, "largest RMS plane error of a building point",
                          unit="m", minimum=0.0, maximum=5.0),
                Parameter("min_plane_error_m", float, 0.12, "smallest RMS plane error of a vegetation point",
                          unit="m", minimum=0.0, maximum=5.0),
                Parameter("min_building_points", int, 60, "smallest planar set that is a building",
                          unit="points", minimum=3),
                Parameter("min_building_height_m", float, 2.0, "lowest building top above the terrain",
                          unit="m", minimum=0.0, maximum=500.0),
                Parameter("link_distance_m", float, 1.5, "points closer than this belong to one set",
                          unit="m", minimum=0.01, maximum=50.0),
                Parameter("reclassify", str, "own", "own: only points of input classes 0-7 get a new class, "
                          "the producer's others (water, wires, towers, bridge decks, 18 and above) stay; all: "
                          "every point gets one of 1-7", choices=("own", "all")),
                Parameter("wall_reach_m", float, 1.0, "points under a roof edge, within this distance in plan "
                          "of a roof point and at most 0.5 m over it, are its facade (walls, balconies, "
                          "eaves); 0 keeps the method's plane rule alone", unit="m", minimum=0.0, maximum=10.0),
            ],
            inputs=[Input("points", "points", "LAS/LAZ point cloud")],
            outputs=[
                Output("classified", "points", "the input with ASPRS classes 1-7 (classes 8 and above kept, see "
                       "reclassify)"),
                Output("dtm", "raster", "the DTM used for heights above ground", style="dtm"),
            ],
        ),
    ]

"""Adapter of the synthetic scene generator: parameters, outputs (LAZ, truth GeoPackage and JSON,
true DTM). The generator itself is ``generator`` beside it (pure numpy)."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, Output, Parameter, UsageError

MAX_POINTS = 200_000_000
KINDS = ("corridor", "terrain", "roofs", "pylons")


def _run(inputs, params, ctx):
    import datetime

    from toolbox.io.points import PointCloud, parse_crs
    from toolbox.io.rasters import Raster

    from .generator import make_scene
    from .generator.scene import DEFAULT_EXTENT, DEFAULT_SPAN_M
    from .truth import truth_json, truth_layers

    if params["kind"] == "pylons":
        return _pylons(params, ctx)
    W0, H0 = DEFAULT_EXTENT[params["kind"]]
    W = params["width_m"] or W0
    H = params["height_m"] or H0
    expected = params["density_ppm2"] * W * H
    if expected > MAX_POINTS:
        raise UsageError(
            f"synthetic-scene: {W:g} x {H:g} m at {params['density_ppm2']:g} pts/m2 would be about "
            f"{expected / 1e6:.0f} million points (limit {MAX_POINTS / 1e6:.0f} million); lower density_ppm2 or the extent"
        )
    if params["scanner"] == "mobile" and params["kind"] != "corridor":
        raise UsageError(f"synthetic-scene: scanner=mobile needs kind=corridor (got {params['kind']!r})")
    crs = parse_crs(params["crs"])
    if not crs.is_projected:
        raise UsageError(f"synthetic-scene: crs {params['crs']!r} is not a projected CRS in metres; use e.g. EPSG:25832")
    scene = make_scene(params["kind"], params["seed"], params["density_ppm2"], params["noise_m"], W, H,
                       params["dtm_resolution_m"], (params["origin_x"], params["origin_y"]), params["crs"],
                       line_variant=params["line_variant"], phase_spacing_m=params["phase_spacing_m"],
                       bundle=params["bundle"], bundle_spacing_m=params["bundle_spacing_m"],
                       roof_set=params["roof_set"], span_m=params["span_m"], slope_pct=params["slope_pct"],
                       scanner=params["scanner"], track_offset_m=params["track_offset_m"],
                       comm_cables=params["comm_cables"], comm_spacing_m=params["comm_spacing_m"])
    pc = PointCloud(scene.x, scene.y, scene.z, fields=scene.fields, crs=crs, source=f"synthetic-scene:{scene.kind}:{scene.seed}",
                    meta={"creation_date": datetime.date(2026, 1, 1)})
    dtm = Raster(scene.dtm, scene.dtm_transform, crs=crs, nodata=float("nan"), style="dtm",
                 description="true bare-earth DTM of the synthetic scene (cell centres)")
    stats = {"n_points": len(pc), "kind": scene.kind, "seed": scene.seed,
             "density_ppm2_measured": round(len(pc) / (W * H), 3),
             "n_buildings": len(scene.truth["buildings"]), "n_roof_planes": len(scene.truth["roof_planes"]),
             "n_trees": len(scene.truth["trees"]), "n_wires": len(scene.truth["wires"]),
             "n_pylons": len(scene.truth["pylons"]), "n_crossings": len(scene.truth["crossings"]),
             "width_m_used": W, "height_m_used": H, "span_m_used": params["span_m"] or DEFAULT_SPAN_M}
    return toolbox.Result(
        outputs={"points": pc, "truth": truth_layers(scene, crs), "truth_json": truth_json(scene), "dtm": dtm,
                 "dem": None, "survey": None},
        stats=stats,
    )


def _pylons(params, ctx):
    """kind=pylons: a UAV photo survey of lattice pylons (no point cloud)."""
    from toolbox.io.points import parse_crs
    from toolbox.io.rasters import Raster

    from .generator.pylons import leaning_pylons, make_pylon_survey, survey_files

    crs = parse_crs(params["crs"])
    if not crs.is_projected:
        raise UsageError(f"synthetic-scene: crs {params['crs']!r} is not a projected CRS in metres; use e.g. EPSG:25832")
    s = make_pylon_survey(params["seed"], params["n_pylons"], params["photos_per_pylon"], params["span_m"] or 150.0,
                          (params["origin_x"], params["origin_y"]), params["crs"], slope_pct=params["slope_pct"],
                          leans=leaning_pylons(params["n_pylons"], params["lean_deg"], params["lean_share"],
                                               params["lean_direction"], params["seed"]))
    files = survey_files(s, progress=ctx.progress)
    dem = Raster(s.dem, s.dem_transform, crs=crs, nodata=float("nan"), style="dtm",
                 description="terrain heights of the photo survey (cell centres)")
    return toolbox.Result(
        outputs={"points": None, "truth": None, "truth_json": s.truth(), "dtm": None, "dem": dem, "survey": files},
        stats={"kind": "pylons", "seed": s.seed, "n_pylons": len(s.pylons), "n_photos": len(s.shots),
               "span_m_used": params["span_m"] or 150.0, "width_m_used": None, "height_m_used": None,
               "pylon_types": sorted({p.model for p in s.pylons}),
               "n_leaning": sum(s.truth()["pylons"][i]["tilt_deg"] > 0.5 for i in range(len(s.pylons)))})


@toolbox.hookimpl
def toolbox_algorithms():
    return [Algorithm(
        id="synthetic-scene",
        title="Synthetic ALS scene with exact truth",
        run=_run,
        description=(
            "Generates a deterministic airborne laser-scanning scene in a projected CRS: terrain with hills, "
            "a steep slope, a ridge, a ditch, an embankment with a bridge and a pond; buildings from sheds to "
            "60 m halls with flat, gable, hip and hip-with-dormer roofs; trees and bushes with multiple returns; "
            "low outliers; and for kind=corridor a double-circuit transmission line on lattice pylons (bundled "
            "phases, earth wire) crossed at a sharp angle by a lower distribution line. Writes the points (the "
            "classification is the truth), the truth as GeoPackage and JSON, and the true DTM. kind=pylons writes "
            "a UAV photo survey instead: JPEG photos of lattice pylons (two types) in clutter with lens distortion, "
            "their cameras as a COLMAP text model and a Metashape XML, the DEM, the pylon types as OBJ and the true "
            "poses as JSON."
        ),
        reference="Scene truth for the methods of Grigillo et al. 2015 (power lines), Mongus & Žalik 2014 (DTM), "
                  "Borowiec (roof planes, test building with a gable dormer); see METHODS.md.",
        parameters=[
            Parameter("kind", str, "corridor", "scene kind", choices=KINDS),
            Parameter("seed", int, 1, "random seed; the same seed gives the same file", minimum=0, maximum=2**31 - 1),
            Parameter("density_ppm2", float, 12.0, "mean pulse density", unit="pts/m2", minimum=0.0,
                      exclusive_minimum=True, maximum=400.0),
            Parameter("noise_m", float, 0.03, "standard deviation of the range noise", unit="m", minimum=0.0, maximum=1.0),
            Parameter("width_m", float, None, "east-west extent (auto: 600 corridor, 400 terrain, 160 roofs)",
                      unit="m", minimum=50.0, maximum=20000.0, allow_auto=True),
            Parameter("height_m", float, None, "north-south extent (auto: 250 corridor, 300 terrain, 120 roofs)",
                      unit="m", minimum=50.0, maximum=20000.0, allow_auto=True),
            Parameter("dtm_resolution_m", float, 1.0, "cell size of the true DTM raster", unit="m",
                      minimum=0.1, maximum=20.0),
            Parameter("origin_x", float, 512000.0, "easting of the south-west corner", unit="m"),
            Parameter("origin_y", float, 5403000.0, "northing of the south-west corner", unit="m"),
            Parameter("crs", str, "EPSG:25832", "projected CRS (metres) of the coordinates"),
            Parameter("line_variant", str, "double-circuit", "corridor: the power lines (double-circuit: a lattice "
                      "transmission line with bundled phases and an earth wire, crossed by a distribution line on "
                      "poles; ribbon: a compact line, its three phases side by side at one height, crossed above "
                      "by two conductors; distribution: three wires on 9 m poles with trees under and beside "
                      "them, crossed by a two-wire low-voltage line on 7 m poles; stacked: a double circuit whose "
                      "three phases hang one above another, 5 m apart, on each side of taller towers)",
                      choices=("double-circuit", "stacked", "ribbon", "distribution")),
            Parameter("span_m", float, None, "double-circuit and stacked: the distance between towers (auto: 185 m)",
                      unit="m", minimum=30.0, maximum=1000.0, allow_auto=True),
            Parameter("slope_pct", float, 0.0, "the ground rises eastwards (along the lines) by this much "
                      "(a corridor on a hillside)", unit="%", minimum=-60.0, maximum=60.0),
            Parameter("scanner", str, "airborne", "corridor: airborne (uniform density), or mobile: a car-mounted "
                      "scanner 2 m over a road beside line A, every point kept with probability min(1, (10 m / "
                      "range)^2) - wires seen from below, density falling with range; give it a high density_ppm2 "
                      "(the density within 10 m of the scanner)", choices=("airborne", "mobile")),
            Parameter("track_offset_m", float, 6.0, "mobile: the road's distance beside line A", unit="m",
                      minimum=-100.0, maximum=100.0),
            Parameter("phase_spacing_m", float, 0.6, "ribbon: the distance between neighbouring phases", unit="m",
                      minimum=0.2, maximum=3.0),
            Parameter("comm_cables", int, 0, "distribution: communication cables on the low-voltage line's poles, "
                      "one above another under its wires (joint-use poles: a vertical ribbon of wires)",
                      minimum=0, maximum=4),
            Parameter("comm_spacing_m", float, 0.3, "distribution: the height between neighbouring communication "
                      "cables", unit="m", minimum=0.2, maximum=1.5),
            Parameter("bundle", int, 2, "double-circuit: sub-conductors per phase (1; 2 side by side; 3 a "
                      "triangle; 4 a square)", minimum=1, maximum=4),
            Parameter("bundle_spacing_m", float, 0.6, "double-circuit: the distance between sub-conductors",
                      unit="m", minimum=0.2, maximum=2.0),
            Parameter("n_pylons", int, 3, "pylons: lattice pylons along a line, alternating types VL-220 (180° "
                      "symmetric) and U-110 (asymmetric top)", minimum=1, maximum=12),
            Parameter("photos_per_pylon", int, 12, "pylons: photos of each pylon from 100-150 m, a sixth of them "
                      "nadir, the rest oblique (35-70° elevation) all round", minimum=3, maximum=60),
            Parameter("lean_deg", float, 0.0, "pylons: the tilt of the leaning pylons (a foundation failure, a "
                      "storm); the others stand within 0.3° of upright", unit="deg", minimum=0.0, maximum=10.0),
            Parameter("lean_share", float, 0.34, "pylons: the share of the pylons that lean by lean_deg, the middle "
                      "ones first (at least one when above 0)", minimum=0.0, maximum=1.0),
            Parameter("lean_direction", str, "random", "pylons: where the leaning pylons' tops lean: along the "
                      "line, across it, or random", choices=("random", "along", "across")),
            Parameter("roof_set", str, "basic", "roofs: the buildings (basic: gable, hip, hip with a dormer, flat; all: "
                      "also pyramid, shed, mansard, gambrel, L, T, cross and flat roofs with a parapet, crowns over "
                      "some eaves, on a 300 x 220 m scene)", choices=("basic", "all")),
        ],
        inputs=[],
        outputs=[
            Output("points", "points", "the point cloud; classification = ASPRS truth class; extra dimensions "
                   "object_id and plane_id tie points to truth objects and roof planes"),
            Output("truth", "vector", "truth layers: conductors 2D, catenaries, crossings, roof planes, buildings, "
                   "pylons, trees, water", suffix="_truth"),
            Output("truth_json", "json", "the same truth as JSON, with class counts and scene parameters", suffix="_truth"),
            Output("dtm", "raster", "true bare-earth DTM", style="dtm"),
            Output("dem", "raster", "kind=pylons: the terrain heights under the photo survey", style="dtm", suffix="_dem"),
            Output("survey", "folder", "kind=pylons: photos/ (JPEG), colmap/ (COLMAP text model), colmap_bin/ (the "
                   "same, binary), cameras.xml (the same cameras as a Metashape XML), models/*.obj (each pylon type's "
                   "beams), in the output folder"),
        ],
    )]

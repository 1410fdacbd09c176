"""Adapter of the power-line chain ``powerlines``: ground and height above ground (through the
``dtm`` algorithm), candidates, top-hat (``tophat``), tiled 2D Hough with crossings
(``hough-lines``'s core through its algorithm), the 3D conductor step; a GeoPackage."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, Input, LayerMerge, Output, Parameter

from .rules import CANDIDATES, PYLON_TOP_SHARE


def _run(inputs, params, ctx):
    """The chain of ``stages`` (see its docstring), then the layers stage's result."""
    import time

    from .settings import Settings
    from .stages import layers, no_wire_possible, run_chain

    pc = inputs["points"]
    pc.require_points("powerlines", 100)
    settings = Settings.of(params)
    scene, st = run_chain(pc, settings, ctx)
    if no_wire_possible(scene):  # a field, a road: nothing to find is a result, not an error
        return layers.nothing_found_for(scene, settings, ctx, st.timings)
    t = time.perf_counter()
    result = layers.stage(scene, st, settings, ctx)
    result.stats["stage_layers_s"] = round(time.perf_counter() - t, 3)
    return result


REFERENCE = ("Grigillo, Ozvaldič, Vrečko, Kosmatin Fras (2015), Geodetski vestnik 59(2) 246-261 (METHODS.md §1); "
             "3D step: catenary per span (beyond the method's stated 2D limitation)")


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


DESCRIPTION = (
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
    "crossings, conductors_3d, pylons.")

# the parameters users set, declared once (Settings.of derives the rest)
PARAMETERS = [
    Parameter("ground", str, "filter", "ground from the morphological filter or the file's class 2",
              choices=("filter", "file")),
    Parameter("height_min_m", float, 3.5, "lowest candidate height above ground (the method: 3.5 m)",
              unit="m", minimum=0.0, maximum=500.0),
    Parameter("height_max_m", float, None, "highest candidate height above ground; the method's 12 m suits "
              "distribution lines, transmission lines sit at 10-60 m; auto: up to the highest points "
              "(above the 99.95th percentile, those with two others within 2.5 m)", unit="m", minimum=0.0, maximum=1000.0, allow_auto=True),
    Parameter("first_returns_only", bool, True, "keep first returns only (ignored when the file has no return numbers)"),
    Parameter("density_radius_m", float, CANDIDATES.density_radius_m, "surface density (first returns per occupied m²) measured "
              "around each candidate within this radius: a roof or crown neighbourhood must hold half of it "
              "within 1 m, sparse wires never do", unit="m", minimum=5.0, maximum=5000.0),
    Parameter("neighbours", int, CANDIDATES.neighbours, "points in each shape (eigenvalue) neighbourhood", minimum=4, maximum=100),
    Parameter("rugged_share", float, CANDIDATES.rugged_share, "smallest-eigenvalue share above which a neighbourhood is "
              "vegetation", minimum=0.0, maximum=0.34),
    Parameter("planar_share", float, CANDIDATES.planar_share, "middle-eigenvalue share above which a flat neighbourhood is a roof",
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
    Parameter("pylon_top_share", float, PYLON_TOP_SHARE, "a tower reaches at least this share of the height where the "
              "spans ending at it are attached", minimum=0.1, maximum=2.0),
    Parameter("band_3d_m", float, 1.0, "half-width of the band around a 2D line whose points the 3D step "
              "splits into wires by height (conductors side by side at other heights are caught too)",
              unit="m", minimum=0.05, maximum=10.0),
]


@toolbox.hookimpl
def toolbox_algorithms():
    return [Algorithm(
        id="powerlines", title="Power-line conductors from a raw point cloud", run=_run,
        description=DESCRIPTION,
        reference=REFERENCE,
        tile_buffer_m=_tile_buffer_m,
        bytes_per_point=450,  # peak per point measured on AHN4 07CZ2_14 (the process's start taken off)
        parameters=list(PARAMETERS),
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

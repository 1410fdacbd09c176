"""The whole power-line chain (`toolbox run powerlines`): synthetic scenes against their truth, the real AHN4 and Oakland files, the CLI."""


import json

import geopandas as gpd
import laspy
import numpy as np
import pytest
from conftest import shared_file
from pl_helpers import (  # noqa: F401 (fixtures)
    OAKLAND_SCANS,
    _ahn4_real,
    chain_until,
    corridor,
    corridor_result,
    oakland_run,
    wire_points,
)
from toolbox_plugins.powerlines.evaluation import conductor_hits, crossing_errors, false_crossings

import toolbox


@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
def test_every_conductor_found_no_false_one(corridor_result):
    rep, gpkg, _, truth = corridor_result
    cond = gpd.read_file(gpkg, layer="conductors")
    matched = {}
    for i, g in enumerate(cond.geometry):
        (ax, ay), (bx, by) = g.coords[0], g.coords[-1]
        d = np.array([bx - ax, by - ay]) / g.length
        for k, t in enumerate(truth["conductor_lines_2d"]):
            a, b = np.array(t["a"]), np.array(t["b"])
            td = (b - a) / np.linalg.norm(b - a)
            off = abs((ax - a[0]) * -td[1] + (ay - a[1]) * td[0])
            if abs(d @ td) > np.cos(np.radians(0.5)) and off < 0.1:
                matched.setdefault(k, []).append(i)
    # every truth conductor (all longer than S_min) is found once; bundles 0.6 m apart are kept apart
    assert sorted(matched) == list(range(len(truth["conductor_lines_2d"])))
    assert all(len(v) == 1 for v in matched.values())
    assert len(cond) == len(truth["conductor_lines_2d"])  # nothing from trees, roofs or pylons
    assert set(cond.columns) >= {"votes", "n_points", "length_m", "rms_m", "height_min_m", "height_max_m"}



@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
def test_pylons_on_the_synthetic_corridor(corridor, corridor_result):
    """Towers where spans end on a tall column: the lattice towers and the distribution poles of
    the scene's truth, each within 2 m, none false; their points are class 15. (Two poles of
    line B are missed: the 3D step does not split the wire there, so no span ends at them.)"""
    rep, gpkg, wires, truth = corridor_result
    py = gpd.read_file(gpkg, layer="pylons")
    assert set(py.columns) >= {"height_m", "n_spans", "line_heading_deg", "n_points"}
    assert py.geometry.has_z.all()
    found = np.column_stack([py.geometry.x, py.geometry.y])
    true_xy = np.array([[p["x"], p["y"]] for p in truth["pylons"]])
    d_false = np.min(np.hypot(*(found[:, None, :] - true_xy[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert (d_false <= 2.0).all(), d_false  # none false
    d_true = np.min(np.hypot(*(true_xy[:, None, :] - found[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert (d_true <= 2.0).sum() >= 9, d_true
    for p, dd in zip(truth["pylons"], d_true):  # heights and bases where found
        if dd <= 2.0:
            k = int(np.argmin(np.hypot(found[:, 0] - p["x"], found[:, 1] - p["y"])))
            assert abs(py.height_m[k] - p["height_m"]) <= 1.0
            assert abs(py.geometry.z[k] - p["z"]) <= 0.3
    cls = np.asarray(laspy.read(wires).classification)
    assert rep["stats"]["n_tower_points"] == int((cls == 15).sum()) > 0
    true_tower = np.asarray(laspy.read(corridor).classification) == 15
    assert (true_tower & (cls == 15)).sum() / (cls == 15).sum() >= 0.9  # tower points are tower points



def test_ribbon_corridor_at_default_parameters(tmp_path):
    """The compact line (three phases 0.6 m apart at one height, 11 m up) crossed above by two
    conductors: every conductor found once, none false, and its wire points."""
    path = tmp_path / "ribbon.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="ribbon", seed=1)
    truth = json.loads(path.with_name("ribbon_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    found = {k for k, _ in conductor_hits(cond, truth)}
    assert len(found) == len(truth["conductor_lines_2d"]) == len(cond) == 5
    t14 = np.asarray(laspy.read(path).classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    # recall 0.972 measured (0.960 before spans grew past their ends: beside a tower the shape test
    # sees the structure in a wire point's neighbourhood)
    assert (t14 & p14).sum() / p14.sum() >= 0.99 and (t14 & p14).sum() / t14.sum() >= 0.97
    assert rep["stats"]["n_pylons"] >= 10
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 6  # line B over each phase: not averaged into one
    for c in truth["crossings"]:
        assert np.min(np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])) <= 0.05



@pytest.mark.parametrize("stem, seed, variant, n_conductors", [
    ("r03", 4, {"line_variant": "ribbon", "phase_spacing_m": 0.3}, 5),
    ("r04", 4, {"line_variant": "ribbon", "phase_spacing_m": 0.4}, 5),
    ("b3", 4, {"bundle": 3, "bundle_spacing_m": 0.4}, 10),
    ("b3", 2, {"bundle": 3, "bundle_spacing_m": 0.4}, 10),
    ("r04d5", 8, {"line_variant": "ribbon", "phase_spacing_m": 0.4, "density_ppm2": 5.0}, 5),
    ("r03", 17, {"line_variant": "ribbon", "phase_spacing_m": 0.3}, 5),
    ("r04", 16, {"line_variant": "ribbon", "phase_spacing_m": 0.4}, 5)])
def test_ribbons_and_bundles_have_every_phase(tmp_path, stem, seed, variant, n_conductors):
    """Ribbons and triangle bundles on generator seed 4 (which the variant family's seeds 1-3 do
    not cover) and bundles on seed 2: every conductor once, none false, every crossing within
    5 cm. How they failed: the 0.3 m ribbon's Hough line leant 0.02 deg across two phases (a
    trend fitted to the whole piece kept them one wire: 4 of 5, crossings 2 of 6); the 0.4 m
    ribbon's two lines lay either side of the middle phase, each band holding half of it (two
    leaning conductors along it, crossings 0.051 m off); a jumper at a tower, drifting across a
    triangle bundle, joined its sub-conductors' groups into two conductors beside the phase (9 of
    10, crossings 15 of 21); on seed 2 a 10 m stub at a tower merged as the bundle's twin turned
    its line by 0.01 deg while the stub's ends weighed as much as the line's (8 of 10); the
    0.4 m ribbon at 5 points/m² on seed 8: in a 373 m piece the phases' offsets moved together
    0.2-0.3 m along it, which no straight trend removes (4 of 5, R 0.888, crossings 4 of 6).
    Seeds 17 and 16, first run after those fixes (held out: 6 of 20 scenes of the 0.3 and 0.4 m
    ribbons on seeds 15-24 failed so): one Hough line over all three 0.3 m phases (3 of 5,
    crossings 2 of 6), and the 0.4 m ribbon's lines leaning across the phases (4 of 5, R 0.879);
    ``ribbon_lines`` now redraws such lines one per wire."""
    path = tmp_path / f"{stem}.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=seed, **variant)
    truth = json.loads(path.with_name(f"{stem}_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert len({k for k, _ in hits}) == len(truth["conductor_lines_2d"]) == n_conductors
    assert len({i for _, i in hits}) == len(cond)  # none false
    # none along another (two conductors on one phase, each leaning with its band's edge)
    inner = [[g.interpolate(f, normalized=True) for f in (0.25, 0.5, 0.75)] for g in cond.geometry]
    assert not any(i != j and max(h.distance(q) for q in inner[i]) < 0.1
                   for i in range(len(cond)) for j, h in enumerate(cond.geometry))
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert max(crossing_errors(xy, truth)) <= 0.05 and false_crossings(xy, truth) == 0



def test_distribution_corridor_at_default_parameters(tmp_path):
    """Three wires on 9 m poles (1.2 m apart, the middle one 1 m higher) with trees under and
    beside them, crossed by a two-wire line: every conductor once, none false, every crossing
    within 5 cm. (Pairwise merging of tile pieces once chained two of its wires into one line
    between them.)"""
    path = tmp_path / "dist.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", seed=1)
    truth = json.loads(path.with_name("dist_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(5)) and len(cond) == len(hits) == 5
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 6
    for c in truth["crossings"]:
        assert np.min(np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])) <= 0.05
    t14 = np.asarray(laspy.read(path).classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    # 0.995 / 0.979 measured (recall 0.960 before spans grew past their ends: on the hill line B's
    # wires hang under the 3.5 m window)
    assert (t14 & p14).sum() / p14.sum() >= 0.99 and (t14 & p14).sum() / t14.sum() >= 0.97
    # a wire grown up to its pole stays wire there (a lattice tower's arms take the wire across
    # them, the AHN4 producer's convention; a pole's do not): measured 1.00 (0.93 before)
    src = laspy.read(path)
    poles = np.array([(q["x"], q["y"]) for q in truth["pylons"] if q["model"] == "pole"])
    near = np.min(np.hypot(np.asarray(src.x)[:, None] - poles[:, 0], np.asarray(src.y)[:, None] - poles[:, 1]),
                  axis=1) <= 1.5
    assert (t14 & near).sum() >= 50 and (t14 & near & p14).sum() / (t14 & near).sum() >= 0.98



@pytest.mark.parametrize("cables, density", [(3, None), (4, 5.0)])
def test_joint_use_corridor_at_default_parameters(tmp_path, cables, density):
    """The distribution corridor with three communication cables 0.3 m apart one above another on
    line B's poles (a vertical ribbon, as on the Oakland scans' poles), and four at 5 points/m²
    (a few points per metre of each cable): every conductor once, none false, every crossing within
    5 cm, wire-point precision and recall of at least the issue's 0.97, and most of the cables'
    points. Measured on seed 1: recall 0.983 and 0.976 (0.981 and 0.972 while a pole's footprint took
    the wire grown up to it), the cables' own 0.930 and 0.927."""
    path = tmp_path / "comm.laz"
    extra = {} if density is None else {"density_ppm2": density}
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", comm_cables=cables,
                seed=1, **extra)
    truth = json.loads(path.with_name("comm_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    n = len(truth["conductor_lines_2d"])
    assert n == 6 and sorted({k for k, _ in hits}) == list(range(n)) and len(cond) == len(hits) == n
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 9
    for c in truth["crossings"]:
        assert np.min(np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])) <= 0.05
    src = laspy.read(path)
    t14 = np.asarray(src.classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    assert (t14 & p14).sum() / p14.sum() >= 0.97 and (t14 & p14).sum() / t14.sum() >= 0.97
    comm = np.isin(np.asarray(src.object_id), [w["id"] for w in truth["wires"] if w["kind"] == "communication"]) & t14
    assert (comm & p14).sum() / comm.sum() >= 0.90



def test_a_sparse_survey_gets_a_gap_scaled_to_its_wire_spacing(tmp_path):
    """A distribution corridor at 5 pts/m2 (wire points 0.4 m apart along the wire, twice the
    method's data's spacing per its V_max): at the method's V_max = 2.5 m a gap cuts a run every
    few spans (recall 0.942 measured on seed 2 without the searches that recover cut runs); the
    automatic V_max, 10 median spacings (about 4 m), finds every conductor, none false, crossings
    within 5 cm and the wire points (0.994 / 0.998 measured; recall 0.993 at V_max 2.5 m with the
    searches). Seed 1's cut runs were mostly in a span the generator strung a few metres over an
    escarpment's brow, below the height window; a pole stands there now.
    An explicit V_max is used as given."""
    path = tmp_path / "sparse.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", density_ppm2=5.0,
                seed=2)
    truth = json.loads(path.with_name("sparse_truth.json").read_text())
    t14 = np.asarray(laspy.read(path).classification) == 14

    def run(tag, **kw):
        rep = toolbox.run("powerlines", path, tmp_path / f"{tag}.gpkg",
                          outputs={"classified": str(tmp_path / f"{tag}.laz")}, **kw)
        p14 = np.asarray(laspy.read(tmp_path / f"{tag}.laz").classification) == 14
        return rep["stats"], (t14 & p14).sum() / p14.sum(), (t14 & p14).sum() / t14.sum()

    st, precision, recall = run("auto")
    assert 0.35 <= st["wire_spacing_m"] <= 0.45 and st["v_max_m_used"] == pytest.approx(10 * st["wire_spacing_m"],
                                                                                         abs=0.01)
    cond = gpd.read_file(tmp_path / "auto.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"]))) and len(cond) == len(hits)
    cr = gpd.read_file(tmp_path / "auto.gpkg", layer="crossings")
    assert max(crossing_errors(np.column_stack([cr.geometry.x, cr.geometry.y]), truth)) <= 0.05
    assert precision >= 0.99 and recall >= 0.97, (precision, recall)
    st_m, _, recall_m = run("method", v_max_m=2.5, sibling_wires=False, next_spans=False)
    assert st_m["v_max_m_used"] == 2.5 and recall_m < recall - 0.05, (recall_m, recall)
    # the searches beside fitted spans and on from their ends (into the holes the cuts left) find
    # most of the cut runs again, not all
    assert run("method_siblings", v_max_m=2.5)[2] < recall, recall



@pytest.mark.parametrize("variant, extra, min_recall", [
    ("stacked", {}, 0.99),  # three phases 5 m above one another on each side (0.997 measured)
    ("distribution", {"slope_pct": 25.0}, 0.9),  # a 25 % hillside, trees under and beside the wires
    # phases in triangle and square bundles (0.989 and 0.982 measured; 0.43 and 0.29 before the
    # wire-like tubes and the split in height): in plan one conductor per phase where the
    # sub-conductors are closer than the Hough's band (the triangle's 0.2 m), in 3D one wire each
    ("double-circuit", {"bundle": 3, "bundle_spacing_m": 0.4}, 0.97),
    ("double-circuit", {"bundle": 4, "bundle_spacing_m": 0.6}, 0.97),
    # a ribbon's phases 0.3 m apart, closer than the Hough's band: one plan line holds them, each
    # a conductor of its own once the 3D step tells them apart (R 0.953, under the issue's 0.97;
    # 0.275 before, every conductor but one lost). At 0.4 m a 9.5 m stub line is still false.
    ("ribbon", {"phase_spacing_m": 0.3}, 0.95),
])
def test_corridor_variants_at_default_parameters(variant, extra, min_recall, tmp_path):
    path = tmp_path / "v.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant=variant, seed=1, **extra)
    truth = json.loads(path.with_name("v_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len({i for _, i in hits})  # no false conductor
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert max(crossing_errors(cr_xy, truth)) <= 0.05 and false_crossings(cr_xy, truth) == 0
    t14 = np.asarray(laspy.read(path).classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    assert (t14 & p14).sum() / p14.sum() >= 0.99 and (t14 & p14).sum() / t14.sum() >= min_recall



@pytest.mark.parametrize("seed", [1, 2, 3])
def test_crossings_are_computed_over_the_conductors_of_every_pass(seed, tmp_path):
    """A distribution line seen by a mobile scanner 12 m aside: one wire of the line across it is
    found only by a later pass (seed 3: the second pass, 12 m of it in plan; seeds 1 and 2: the
    search beside the other wire's span, 20-40 points over 13-18 m, 4 of 5 conductors without it);
    its crossings with the three phases are crossings too."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", seed=seed,
                scanner="mobile", density_ppm2=100.0, width_m=300.0, height_m=120.0, track_offset_m=12.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len({i for _, i in hits})
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 6 == rep["stats"]["n_crossings"]
    assert max(crossing_errors(np.column_stack([cr.geometry.x, cr.geometry.y]), truth)) <= 0.05



def test_a_short_line_leant_by_the_line_it_crosses_settles_on_its_wires_trend(tmp_path):
    """The same street scan, seed 7: line B's wire is seen over 26 m only, and line A's three
    phases crossing it at 69 degrees put their points in its band near the crossings, leaning
    its plan line 0.13 degrees (7 cm at its end: crossings 3 of 6 within 5 cm, up to 8.7 cm).
    The 3D step told them apart by height; the line's output settles on its spans' own trend.
    (Its false lines on a sparse gable roof at the scene's edge are an open failure.)"""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", seed=7,
                scanner="mobile", density_ppm2=100.0, width_m=300.0, height_m=120.0, track_offset_m=12.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    assert sorted({k for k, _ in conductor_hits(cond, truth)}) == list(range(len(truth["conductor_lines_2d"])))
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 6 and false_crossings(xy, truth) == 0
    assert max(crossing_errors(xy, truth)) <= 0.05



def test_a_lattice_member_is_no_pole_and_no_crash(tmp_path):
    """60 m spans (seed 1): a slanted lattice member seen by ALS has thin points spread wider than
    a pole's column around their middle, which holds none of the highest (the pole search raised
    an IndexError there once). Towers as before, none false; no pole among them."""
    path = tmp_path / "s.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=1, span_m=60.0)
    truth = json.loads(path.with_name("s_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    assert rep["stats"]["n_poles"] == 0
    d = [np.hypot(py.geometry.x - q["x"], py.geometry.y - q["y"]).min() for q in truth["pylons"]]
    assert sum(x <= 2.0 for x in d) >= 12
    assert all(min(np.hypot(x - q["x"], y - q["y"]) for q in truth["pylons"]) <= 2.0
               for x, y in zip(py.geometry.x, py.geometry.y))



def test_towers_the_wires_run_through_keep_their_arms(tmp_path):
    """60 m spans (seed 3): at three towers the 3D step does not cut the wires, so more spans run
    past than end there, as past a tree. Where one of them has a line that never leaves it, that
    line is its arm and it is a tower (the false conductor and its 5 false crossings before); a
    tower whose arms were taken in the first search stays one without their span ends, and one
    with neither is found from its own points (find_towers_passed_through): all 16 towers standing
    in the scene (15 before that search; the 17th stands past its east edge, unsurveyed)."""
    path = tmp_path / "s.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=3, span_m=60.0)
    truth = json.loads(path.with_name("s_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"]))) and len(cond) == len(hits)
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert max(crossing_errors(cr_xy, truth)) <= 0.05 and false_crossings(cr_xy, truth) == 0
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    d = [np.hypot(py.geometry.x - q["x"], py.geometry.y - q["y"]).min() for q in truth["pylons"] if q["in_scene"]]
    assert len(d) == 16 and sum(x <= 2.0 for x in d) == 16
    assert all(min(np.hypot(x - q["x"], y - q["y"]) for q in truth["pylons"]) <= 2.0
               for x, y in zip(py.geometry.x, py.geometry.y))



def test_mobile_double_circuit_crossings_stop_at_the_last_pole(tmp_path):
    """A double circuit seen by a mobile scanner, line B ending at a pole just short of line A's
    far circuit: B crosses the three conductors of the near one only (9 of 9 true; 11 reported
    while the 5 m extension carried B past its last pole). Line A's lattice towers are found:
    with its earth wire (31 m up) in the height window, the earth wire's span ends over their
    peaks set how tall their cells must be (the nearest end), and their hollow bodies held no
    column that high (2 of 5 supports). No line on the sparse hip roof at the scene's far edge:
    the second pass's runs at a line's own spacing reached 8 m in its rows (a line validated so
    must stand clear: no other point within 0.5 m of its points, on average)."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=1, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len(truth["conductor_lines_2d"])  # none false
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 9 and false_crossings(cr_xy, truth) == 0
    assert max(crossing_errors(cr_xy, truth)) <= 0.05
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    lattice = [q for q in truth["pylons"] if q["model"] == "lattice" and q["in_scene"]]
    assert len(lattice) == 2
    for q in lattice:
        assert np.hypot(py.geometry.x - q["x"], py.geometry.y - q["y"]).min() <= 2.0
    for p in py.geometry:  # none false
        assert min(np.hypot(p.x - q["x"], p.y - q["y"]) for q in truth["pylons"]) <= 2.0



def test_a_sparse_earth_wire_over_a_stack_seen_from_the_street_is_found(tmp_path):
    """A stacked double circuit seen by a mobile scanner (seed 8): its earth wire hangs 35-38 m
    up with 185 points over 185 m. The automatic height window (the 99.95th percentile) stopped
    at 34.2 m, and once inside, the method's 2.5 m V_max validated it in 10-11 m stretches, too
    few points for the 3D step: 7 of 8 conductors, 12 of 15 crossings."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=8, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0, line_variant="stacked")
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    assert rep["stats"]["height_max_m_used"] >= 38.0
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert len({k for k, _ in hits}) == len(truth["conductor_lines_2d"]) == 8 and len(cond) == 8
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 15 and false_crossings(xy, truth) == 0
    assert max(crossing_errors(xy, truth)) <= 0.05



def test_two_crowns_tops_lined_up_are_no_conductor(tmp_path):
    """A mobile double circuit (seed 7): the tops of two dome crowns beside the road lie on one
    10 m line that fits a catenary and has nothing above it (one false conductor, P 0.996). Its
    points lie in the crowns' surface: the line is dropped, and the eight conductors stay."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=7, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": tmp_path / "c.laz"})
    assert rep["stats"]["n_surface_lines"] >= 1
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert len({k for k, _ in hits}) == len(truth["conductor_lines_2d"]) == 8 and len(cond) == 8
    t = np.asarray(laspy.read(path).classification) == 14
    p = np.asarray(laspy.read(tmp_path / "c.laz").classification) == 14
    assert (t & p).sum() / p.sum() >= 0.998 and (t & p).sum() / t.sum() >= 0.99



def test_a_wire_seen_from_one_side_gets_its_own_heading(tmp_path):
    """A mobile double circuit (seed 4): the Hough's line through the far wire of line B leaned
    0.4 degrees off it (0.23 m across at one end, its band took 48 points of the next wire), one
    false conductor for a missed one and 12 of 15 crossings; turned onto its spans' trend, every
    conductor is found, none false, and all 15 crossings lie within 5 cm."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=4, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    assert rep["stats"]["n_lines_realigned"] >= 1
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len({i for _, i in hits})
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 15 and false_crossings(cr_xy, truth) == 0
    assert max(crossing_errors(cr_xy, truth)) <= 0.05



@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
def test_crossings_within_5_cm_of_truth(corridor_result):
    _, gpkg, _, truth = corridor_result
    cr = gpd.read_file(gpkg, layer="crossings")
    assert len(cr) == len(truth["crossings"])
    for c in truth["crossings"]:
        d = np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])
        assert d.min() <= 0.05, (c, d.min())
        k = int(np.argmin(d))
        assert cr.angle_deg[k] == pytest.approx(c["angle_deg"], abs=0.5)



@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
def test_stacked_conductors_are_separated_in_3d(corridor_result):
    _, gpkg, _, truth = corridor_result
    cond = gpd.read_file(gpkg, layer="conductors")
    c3 = gpd.read_file(gpkg, layer="conductors_3d")
    assert c3.geometry.has_z.all()
    a_phase = [i for i, g in enumerate(cond.geometry) if cond.height_max_m[i] > 15 and cond.n_wires[i] >= 2]
    assert len(a_phase) == 4  # the four plan lines of line A's phases each hold two stacked wires
    for i in a_phase:
        wires = c3[c3.conductor == i]
        heights = sorted(np.mean([p[2] for p in g.coords]) for g in wires.geometry)
        assert heights[-1] - heights[0] > 4.0  # arms 6 m apart
    # every wire is one wire across its poles and pylons: as many as in the truth
    assert c3.groupby(["conductor", "wire"]).ngroups == len(truth["wires"])
    # sags: catenaries of line A hang 2-4 m over 185 m spans, as the truth
    long_spans = c3[(c3.length_m > 150) & (c3.rms_m < 0.1)]
    assert len(long_spans) >= 8
    truth_sags = [s["sag_m"] for s in truth["spans"] if s["line"] == "A" and s["length_m"] > 150]
    assert long_spans.sag_m.between(min(truth_sags) - 0.5, max(truth_sags) + 0.5).mean() > 0.8
    assert long_spans.catenary_c_m.between(1200, 1700).mean() > 0.8



@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
def test_wire_points_on_synthetic_truth(corridor_result, corridor):
    _, _, wires, _ = corridor_result
    t = laspy.read(corridor).classification == 14
    p = laspy.read(wires).classification == 14
    precision, recall = (t & p).sum() / p.sum(), (t & p).sum() / t.sum()
    assert precision >= 0.98 and recall >= 0.99  # 0.999 / 0.995 measured



@pytest.mark.parametrize("name, min_precision, min_recall", [("07CZ2_14", 0.99, 0.99), ("12AN2_20", 0.98, 0.985)])
def test_ahn4_corridors_at_default_parameters(name, min_precision, min_recall, tmp_path):
    """Both real AHN4 tiles, no setting: wire points against the producer's class 14 (measured
    0.994 / 0.998 and 0.987 / 0.991; 12AN2_20's sparse earth wires are seen in stretches up to
    26 m apart; the producer counts the wire across a tower's footprint as tower, and so do we),
    V_max chosen from the wires' point spacing (about 0.33 m on both: 3.2-3.3 m), and the tile's one tower
    (the producer's class 15) found within 2 m, nothing else taken for one."""
    path, sub = _ahn4_real(name, tmp_path)
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", crs="EPSG:28992",
                      outputs={"classified": str(tmp_path / "w.laz")})
    assert rep["stats"]["cell_size_m_used"] == pytest.approx(0.133)  # reported
    # sparser than the method's 10 points per 2.5 m of wire: V_max scaled to the spacing
    assert rep["stats"]["v_max_m_used"] == pytest.approx(10 * rep["stats"]["wire_spacing_m"], abs=0.01)
    assert rep["stats"]["v_max_m_used"] > 2.5
    truth = np.asarray(sub.classification) == 14
    out = laspy.read(tmp_path / "w.laz").classification
    pred = out == 14
    precision, recall = (truth & pred).sum() / pred.sum(), (truth & pred).sum() / truth.sum()
    assert precision >= min_precision and recall >= min_recall, (precision, recall)
    tower = np.asarray(sub.classification) == 15
    tx, ty = np.asarray(sub.x)[tower], np.asarray(sub.y)[tower]
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    assert len(py) == 1
    # (the issue asks 2 m; measured 0.05 and 0.25 m, 0.75 and 1.0 m while a tower's base was the
    # middle of its column cells)
    assert np.hypot(py.geometry.x[0] - 0.5 * (tx.min() + tx.max()), py.geometry.y[0] - 0.5 * (ty.min() + ty.max())) <= 0.5
    t15 = out == 15
    assert (tower & t15).sum() / t15.sum() >= 0.8 and (tower & t15).sum() / tower.sum() >= 0.7



@pytest.mark.xdist_group("oakland")  # one worker runs the scans once for every test that reads them
@pytest.mark.parametrize("name, min_precision, min_recall", [("part3_an", 0.92, 0.90), ("part3_ak", 0.97, 0.9),
                                                              ("part2_ai", 0.90, 0.90)])
def test_mobile_scans_at_default_parameters(name, min_precision, min_recall, oakland_runs):
    """Oakland mobile scans (a car-mounted scanner under distribution wires), no setting: wire
    points against the CMU wire labels (class 14), the issue's 0.90 on each. part3_an: wires
    0.3-1 m above one another, a service drop, wires leaving the tile a few metres past a pole;
    part3_ak: wires seen for 5-8 m between crowns (and a truck's top edge under them); part2_ai:
    a sparse upper wire past the last pole, the lower one through crowns."""
    path, gpkg, classified, _ = oakland_run(oakland_runs, name)
    truth, pred = wire_points(path, classified)
    precision, recall = (truth & pred).sum() / pred.sum(), (truth & pred).sum() / truth.sum()
    assert precision >= min_precision and recall >= min_recall, (precision, recall)
    # every drawn span is a wire's: its catenary fits (part2_ai's pieces through crowns do not)
    c3 = gpd.read_file(gpkg, layer="conductors_3d")
    assert len(c3) and (c3.rms_m <= 0.2).all(), c3.rms_m.max()
    # the poles that carry the wires, against the CMU utility-pole label: every pole found stands
    # on one (within 0.5 m of its points' middle); part3_ak's, away from the wires scanned, are
    # not found
    src = laspy.read(path)
    labelled = np.column_stack([src.x, src.y])[np.asarray(src.cmu_label) == 1103]
    py = gpd.read_file(gpkg, layer="pylons")
    poles = py[py["kind"] == "pole"]
    assert len(poles) >= {"part3_an": 3, "part3_ak": 0, "part2_ai": 3}[name]
    # no tower on a street scan where the poles carry the wires (part2_ai: a crown where a next
    # span stopped at the scan's edge was one while that end counted as a span end)
    assert name == "part3_ak" or (py["kind"] == "tower").sum() == 0
    for g in poles.geometry:
        near = labelled[np.hypot(labelled[:, 0] - g.x, labelled[:, 1] - g.y) <= 1.0]
        assert len(near) >= 20 and np.hypot(*(near.mean(axis=0) - [g.x, g.y])) <= 0.5, (g.x, g.y)
    if len(poles):  # tower points: the poles' columns and heads, not the crowns beside them (P 0.06 before)
        out = np.asarray(laspy.read(classified).classification) == 15
        labelled_15 = np.asarray(src.classification) == 15
        assert (out & labelled_15).sum() >= 0.6 * out.sum() and (out & labelled_15).sum() >= 0.5 * labelled_15.sum()
    # a cable's end clamped to a pole's side, 4-8 m under its top, is the pole's (CMU: pole), not
    # a wire's: no wire point inside a found pole's column under its head (part2_ai had 5, part3_an 12)
    cls = np.asarray(laspy.read(classified).classification)
    x, y, z = np.asarray(src.x), np.asarray(src.y), np.asarray(src.z)
    for g, height in zip(poles.geometry, poles["height_m"] if len(poles) else []):
        column = (np.hypot(x - g.x, y - g.y) <= 0.3) & (z < g.z + height - 1.0)
        assert not (column & (cls == 14)).any(), (g.x, g.y, int((column & (cls == 14)).sum()))

@pytest.mark.xdist_group("oakland")
@pytest.mark.xfail(strict=True, reason="#77 open (README, docs/powerlines.md): crowns' single rows are taken for "
                   "wires and sparse service drops are missed; pooled P 0.714 / R 0.869, part2_ae 368 and part3_aj "
                   "554 false points")
def test_oakland_street_scans_reach_the_issues_targets(oakland_runs):
    """#77's targets over the eight Oakland scans in ../shared, at default parameters: pooled
    wire-point P >= 0.92 and R >= 0.90, at most 20 false wire points on each scan without a wire."""
    runs = [oakland_run(oakland_runs, name) for name in OAKLAND_SCANS]
    tp = n_pred = n_true = 0
    for path, _, classified, _ in runs:
        truth, pred = wire_points(path, classified)
        tp, n_pred, n_true = tp + (truth & pred).sum(), n_pred + pred.sum(), n_true + truth.sum()
        if not truth.any():
            assert pred.sum() <= 20, (path.name, pred.sum())
    assert tp / n_pred >= 0.92 and tp / n_true >= 0.90, (tp / n_pred, tp / n_true)




@pytest.mark.parametrize("rel, crs", [("ahn3_amsterdam/ahn_2386_9702.laz", "EPSG:7415"),
                                      ("pdal_autzen/autzen_trim.las", None), ("lidR/Topography.laz", None)])
def test_no_power_line_is_found_on_real_surveys_without_one(rel, crs, tmp_path):
    """Real surveys with no power line in them (AHN3 Amsterdam: streets, roofs and trees; Autzen:
    a suburb in US feet; lidR's Topography: forest on a hillside), at the defaults: no conductor,
    no crossing, no pylon, and no point classified as wire."""
    path = shared_file(rel)
    kw = {"crs": crs} if crs else {}
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")}, **kw)
    for layer in ("conductors", "crossings", "pylons"):
        assert len(gpd.read_file(tmp_path / "pl.gpkg", layer=layer)) == 0, layer
    assert not (np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14).any()



def test_ahn4_corridor_wire_points_and_lines(tmp_path):
    path, sub = _ahn4_real("07CZ2_14", tmp_path)
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", crs="EPSG:28992",
                      outputs={"classified": str(tmp_path / "w.laz")})
    truth = np.asarray(sub.classification) == 14
    # the 3D conductor lines lie on the producer's class-14 points
    from scipy.spatial import cKDTree

    wires = np.column_stack([sub.x, sub.y, sub.z])[truth]
    c3 = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors_3d")
    import shapely

    samples = np.concatenate([shapely.get_coordinates(g.interpolate(np.arange(0, g.length, 0.05)), include_z=True)
                              for g in c3.geometry])
    # every producer wire point lies close to a fitted conductor (the model's residual)...
    d, _ = cKDTree(samples).query(wires)
    assert np.median(d) <= 0.1, np.median(d)
    # ...and the conductors run along the points (bounded below by the along-wire point spacing)
    d_back, _ = cKDTree(wires).query(samples)
    assert np.median(d_back) <= 0.2, np.median(d_back)
    assert rep["stats"]["n_wires_3d"] >= 8  # four conductor levels on each of the two circuits



def test_the_methods_cell_on_side_by_side_conductors_says_what_to_do(tmp_path, caplog):
    """The method's 0.5 m top-hat cell, asked for explicitly, loses AHN4's side-by-side conductors
    (the top-hat keeps few of their points); the run says so and names the parameter instead of
    returning an empty or thin file silently."""
    import logging

    path, las = _ahn4_real("07CZ2_14", tmp_path)
    with caplog.at_level(logging.WARNING):
        rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", crs="EPSG:28992", cell_size_m=0.5)
    assert rep["stats"]["n_wire_points"] < 0.3 * int(np.sum(las.classification == 14))
    assert any("leave cell_size_m automatic" in r.getMessage() for r in caplog.records)


# the core decisions that take a rules record, by the stage modules that call them
RULED = {"plan_lines": ("conductors_3d", "ribbon_lines"), "more_wires": ("short_wires", "sibling_wires", "grow_span_ends"),
         "next_spans": ("next_spans",), "supports": ("find_pylons", "find_poles", "find_towers_passed_through",
                                                     "grow_span_ends"),
         "cleaning": ("in_foliage", "in_a_surface", "along_a_surface", "sibling_wires")}


@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
def test_the_chain_stopped_at_a_stage_and_resumed_gives_the_whole_runs_layers(corridor, corridor_result, monkeypatch):
    """The stage API: the chain run up to the rejection stage hands on labels per candidate; the
    stages after it, resumed on that state, switch them to labels per input point (at the
    cleaning stage), and the layers stage then gives the conductors and crossings of the whole
    run (``toolbox run powerlines``) on the same file. Every core decision called gets its record
    of the run's ``settings.rules`` (copies here: the plugin's own would pass unnoticed)."""
    import dataclasses
    import importlib

    from toolbox_plugins.powerlines.settings import Rules
    from toolbox_plugins.powerlines.stages import layers, run_stages
    from toolbox_plugins.powerlines.state import CandidateLabels, PointLabels

    given = {}
    for module, names in RULED.items():
        mod = importlib.import_module(f"toolbox_plugins.powerlines.stages.{module}")
        for name in names:
            def spy(*a, _f=getattr(mod, name), _name=name, **kw):
                given.setdefault(_name, []).append(kw.get("rules"))
                return _f(*a, **kw)
            monkeypatch.setattr(mod, name, spy)
    plugin_rules = Rules()
    rules = Rules(**{f.name: dataclasses.replace(getattr(plugin_rules, f.name)) for f in dataclasses.fields(Rules)})
    scene, st, settings, ctx = chain_until(corridor, "rejection", rules=rules)
    assert isinstance(st.labels, CandidateLabels) and st.supports is None
    assert len(st.labels.points) == len(st.labels.line) and (st.labels.line >= 0).any()
    st = run_stages(scene, st, settings, ctx, first="next_spans", last="supports")
    assert st.supports is not None and st.conductor_of.shape == (len(scene.pc),)
    st = run_stages(scene, st, settings, ctx, first="pole_wires")
    assert isinstance(st.labels, PointLabels) and st.labels.conductor.shape == (len(scene.pc),)
    got = layers.stage(scene, st, settings, ctx).outputs["lines"]
    whole = corridor_result[1]
    for name in ("conductors", "crossings"):
        ref = gpd.read_file(whole, layer=name)
        assert len(got[name]) == len(ref) > 0
    ref = gpd.read_file(whole, layer="conductors")
    assert np.allclose(sorted(got["conductors"].length), sorted(ref.length), atol=1e-6)
    with pytest.raises(ValueError, match="no stage 'tophat'"):
        run_stages(scene, st, settings, ctx, first="tophat")
    record = {"conductors_3d": rules.wires, "ribbon_lines": rules.ribbons, "short_wires": rules.short_wires,
              "sibling_wires": rules.siblings, "grow_span_ends": rules.grow, "find_pylons": rules.towers,
              "find_poles": rules.poles, "find_towers_passed_through": rules.passed_through,
              "in_foliage": rules.foliage, "in_a_surface": rules.surface, "along_a_surface": rules.along_surface,
              "next_spans": rules.next_spans}
    assert {"conductors_3d", "ribbon_lines", "find_pylons", "find_poles", "in_foliage"} <= set(given)
    for name, got_rules in given.items():
        assert all(r is record[name] for r in got_rules), name

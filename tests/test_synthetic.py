"""Synthetic scenes: deterministic, plausible, and their truth agrees with their points."""

import hashlib
import json

import numpy as np
import pytest

import toolbox
from toolbox_plugins.synthetic_scene.generator import make_scene
from toolbox_plugins.synthetic_scene.generator.objects import catenary_z


@pytest.fixture(scope="session")  # (an xdist worker tears module fixtures down when its queue runs dry)
def corridor():
    return make_scene("corridor", seed=5, density_ppm2=6.0)


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path):
    digests = []
    for name, seed in (("a", 11), ("b", 11), ("c", 12)):
        toolbox.run("synthetic-scene", output=tmp_path / f"{name}.laz", kind="roofs", seed=seed, density_ppm2=3.0)
        digests.append(hashlib.sha256((tmp_path / f"{name}.laz").read_bytes()).hexdigest())
    assert digests[0] == digests[1]
    assert digests[0] != digests[2]
    ja = json.loads((tmp_path / "a_truth.json").read_text())
    jb = json.loads((tmp_path / "b_truth.json").read_text())
    assert ja == jb


@pytest.mark.parametrize("kind", ["terrain", "corridor", "roofs"])
@pytest.mark.parametrize("size", [(50.0, 50.0), (60.0, 50.0)])
def test_the_smallest_scenes_are_made(kind, size):
    # the parameters allow 50 m; buildings too large for the scene are left out, not a crash
    W, H = size
    scene = make_scene(kind, seed=1, density_ppm2=2.0, width_m=W, height_m=H)
    assert len(scene.x) > 0.5 * 2.0 * W * H
    for b in scene.truth["buildings"]:
        fp = np.asarray(b["footprint"]) - np.asarray(scene.origin)
        assert fp.min() >= 0 and (fp[:, 0] <= W).all() and (fp[:, 1] <= H).all()


def test_density_class_shares_and_returns_are_plausible(corridor):
    s = corridor
    W, H = s.extent
    n = len(s.x)
    # pulses at the asked density; points a little more (multiple returns, wires, towers)
    assert s.truth["n_pulses"] / (W * H) == pytest.approx(6.0, rel=0.02)
    assert 1.0 < n / s.truth["n_pulses"] < 1.25
    cls = s.fields["classification"]
    share = {c: np.mean(cls == c) for c in (2, 3, 4, 5, 6, 7, 9, 14, 15, 17)}
    assert 0.75 < share[2] < 0.95
    assert 0.02 < share[5] < 0.15 and share[3] > 0 and share[4] > 0
    assert 0.01 < share[6] < 0.06
    assert 0 < share[7] < 0.001
    assert share[9] < 0.002  # water returns are rare
    assert share[14] > 0.002 and share[15] > 0 and share[17] > 0
    rn, nr = s.fields["return_number"], s.fields["number_of_returns"]
    assert np.all((rn >= 1) & (rn <= nr) & (nr <= 4))
    veg = np.isin(cls, [3, 4, 5])
    assert np.mean(nr[veg] > 1) > 0.6  # crowns give multiple returns
    assert np.all(nr[cls == 6] == 1)  # roofs single
    # every pulse's returns come in order, last returns of vegetation pulses reach the ground
    gt = s.fields["gps_time"]
    assert np.all(np.diff(gt) >= 0)
    last_in_veg_pulse = (rn == nr) & (nr > 1) & (cls == 2)
    assert last_in_veg_pulse.sum() > 0.2 * np.sum((rn == 1) & (nr > 1) & veg)


def test_ground_points_lie_on_the_true_dtm(corridor):
    s = corridor
    g = s.fields["classification"] == 2
    zt = s.terrain.height(s.x[g] - s.origin[0], s.y[g] - s.origin[1])
    d = s.z[g] - zt
    assert abs(d.mean()) < 0.003 and d.std() == pytest.approx(0.03, rel=0.05)
    # the raster is the same function at the cell centres
    r, c = 37, 211
    u = (c + 0.5) * s.dtm_resolution_m
    v = s.extent[1] - (r + 0.5) * s.dtm_resolution_m
    assert s.dtm[r, c] == pytest.approx(s.terrain.height(u, v), abs=1e-3)
    # below-ground outliers really are below
    low = (s.fields["classification"] == 7) & (s.z < s.terrain.height(s.x - s.origin[0], s.y - s.origin[1]))
    assert low.sum() >= 3


def test_terrain_has_the_hard_cases():
    s = make_scene("terrain", seed=2, density_ppm2=1.0)
    dz_dy, dz_dx = np.gradient(s.dtm.astype(float), s.dtm_resolution_m)
    slope = np.degrees(np.arctan(np.hypot(dz_dx, dz_dy)))
    assert slope.max() > 35  # steep slope / embankment sides
    assert s.truth["bridge"] is not None and np.sum(s.fields["classification"] == 17) > 0
    assert s.truth["water"] is not None
    lengths = sorted(b["length_m"] for b in s.truth["buildings"])
    assert lengths[0] <= 4 and lengths[-1] >= 60  # sheds to 60 m halls
    assert {b["roof"] for b in s.truth["buildings"]} == {"flat", "gable", "hip", "hip_dormer"}


def test_every_roof_plane_refits_from_its_points(corridor):
    s = corridor
    pid = s.fields["plane_id"]
    checked = 0
    for p in s.truth["roof_planes"]:
        m = pid == p["plane_id"]
        if m.sum() < 10:
            continue
        P = np.column_stack([s.x[m], s.y[m], s.z[m]])
        c = P.mean(0)
        n = np.linalg.svd(P - c)[2][-1]
        n = n if n[2] > 0 else -n
        # the truth plane explains the points down to the range noise (0.03 m)...
        resid = P @ np.asarray(p["normal"]) - p["offset"]
        assert np.sqrt(np.mean(resid ** 2)) < 0.04, p
        # ...and a plane fitted to them has the truth's normal (small dormer faces: few points, wider)
        ang = np.degrees(np.arccos(np.clip(np.dot(n, p["normal"]), -1, 1)))
        assert ang < (1.0 if m.sum() > 200 else 3.0), (p, ang)
        assert np.dot(p["normal"], c) == pytest.approx(p["offset"], abs=0.05)
        # and the plane's polygon holds its points
        from shapely import contains_xy, wkt

        poly = wkt.loads(p["polygon_wkt"]).buffer(0.01)
        assert contains_xy(poly, s.x[m], s.y[m]).mean() > 0.999
        checked += 1
    assert checked >= 25


def test_test_building_has_hip_roof_with_gable_dormer(corridor):
    dormer = [b for b in corridor.truth["buildings"] if b["roof"] == "hip_dormer"]
    assert len(dormer) == 1
    faces = {p["face"]: p for p in corridor.truth["roof_planes"] if p["building_id"] == dormer[0]["id"]}
    assert set(faces) == {"south", "north", "west", "east", "dormer_west", "dormer_east"}
    # main faces face east and west (the method's test building), the hips north and south
    assert abs(faces["south"]["normal"][0]) > 0.5 and abs(faces["west"]["normal"][1]) > 0.5
    # every face has points (the dormer's are small: about 2.6 m2 each)
    assert all(f["n_points"] >= 3 for f in faces.values())
    assert faces["north"]["n_points"] > 100


def test_every_catenary_refits_from_its_points(corridor):
    s = corridor
    obj = s.fields["object_id"]
    wire = s.fields["classification"] == 14
    checked = 0
    for span in s.truth["spans"]:
        a, b = np.array(span["a"]), np.array(span["b"])
        d = (b[:2] - a[:2]) / span["length_m"]
        m = wire & (obj == span["wire_id"])
        t = (s.x[m] - a[0]) * d[0] + (s.y[m] - a[1]) * d[1]
        m_idx = np.flatnonzero(m)[(t >= 0) & (t <= span["length_m"])]
        if len(m_idx) < 50:
            continue
        t = (s.x[m_idx] - a[0]) * d[0] + (s.y[m_idx] - a[1]) * d[1]
        lateral = -(s.x[m_idx] - a[0]) * d[1] + (s.y[m_idx] - a[1]) * d[0]
        assert np.abs(lateral).max() < 0.25  # within the footprint scatter
        # least-squares catenary parameter: scan c, compare with the truth
        cs = np.linspace(span["catenary_c_m"] * 0.7, span["catenary_c_m"] * 1.3, 121)
        rms = [np.sqrt(np.mean((s.z[m_idx] - catenary_z(t, span["length_m"], a[2], b[2], c)) ** 2)) for c in cs]
        best = cs[int(np.argmin(rms))]
        assert min(rms) < 0.05  # the truth curve explains the points down to the range noise
        if span["sag_m"] >= 0.5:  # short spans barely sag: their c is not determined by the points
            assert best == pytest.approx(span["catenary_c_m"], rel=0.03)
        checked += 1
    assert checked >= 20


def test_crossings_lie_on_both_conductor_lines(corridor):
    s = corridor
    lines = s.truth["conductor_lines_2d"]
    assert {l["line"] for l in lines} == {"A", "B"}
    assert len(s.truth["crossings"]) == sum(l["line"] == "A" for l in lines) * sum(l["line"] == "B" for l in lines)
    for c in s.truth["crossings"]:
        for i in c["lines"]:
            a, b = np.array(lines[i]["a"]), np.array(lines[i]["b"])
            d = (b - a) / np.linalg.norm(b - a)
            off = -(c["x"] - a[0]) * d[1] + (c["y"] - a[1]) * d[0]
            assert abs(off) < 1e-6
        assert 15 < c["angle_deg"] < 35  # a sharp crossing angle


def test_bundles_and_stacked_conductors(corridor):
    wires = [w for w in corridor.truth["wires"] if w["line"] == "A"]
    offsets = sorted(w["offset_m"] for w in wires if w["kind"] == "phase")
    # two sub-conductors 0.6 m apart per phase, two phases stacked per side
    assert np.allclose(offsets, [-7.3, -7.3, -6.7, -6.7, 6.7, 6.7, 7.3, 7.3], atol=1e-6)
    assert sum(w["kind"] == "earth" for w in wires) == 1
    spans = corridor.truth["spans"]
    assert all(1.0 < sp["sag_m"] < 6.0 for sp in spans if sp["line"] == "A")


def test_ribbon_variant_has_phases_side_by_side_at_one_height():
    s = make_scene("corridor", seed=2, density_ppm2=4.0, line_variant="ribbon", phase_spacing_m=0.8)
    a = [w for w in s.truth["wires"] if w["line"] == "A"]
    assert sorted(round(w["offset_m"], 6) for w in a) == [-0.8, 0.0, 0.8]
    obj, wire = s.fields["object_id"], s.fields["classification"] == 14
    # at mid-span the three phases hang at one height (same attachments, same tension)
    span = [sp for sp in s.truth["spans"] if sp["line"] == "A"]
    assert len(span) >= 3 * 5
    heights = {}
    for sp in span:
        heights.setdefault(sp["span"], []).append(sp["sag_m"])
    assert all(np.ptp(v) < 0.05 for v in heights.values())
    for w in a:  # every phase is sampled along its whole length, 11 m up (poles of 11.5 m)
        m = wire & (obj == w["id"])
        assert m.sum() > 300
    assert {l["line"] for l in s.truth["conductor_lines_2d"]} == {"A", "B"}
    assert len(s.truth["crossings"]) == 6
    assert all(28 < c["angle_deg"] < 42 for c in s.truth["crossings"])
    with pytest.raises(ValueError):
        make_scene("corridor", seed=2, line_variant="nonsense")


def test_distribution_variant_trees_under_and_beside_the_line():
    s = make_scene("corridor", seed=4, density_ppm2=3.0, line_variant="distribution")
    wires = s.truth["wires"]
    assert sorted((w["line"], w["attach"]) for w in wires) == [("A", "C"), ("A", "L"), ("A", "R"), ("B", "L"),
                                                               ("B", "R")]
    a_pylons = [p for p in s.truth["pylons"] if p["line"] == "A"]
    assert all(p["height_m"] == 9.0 for p in a_pylons) and len(a_pylons) >= 10
    lines = {l["line"]: l for l in s.truth["conductor_lines_2d"]}
    a, b = np.array(lines["A"]["a"]), np.array(lines["A"]["b"])
    d = (b - a) / np.linalg.norm(b - a)
    trees = s.truth["trees"]
    lateral = np.array([abs((t["x"] - a[0]) * -d[1] + (t["y"] - a[1]) * d[0]) for t in trees])
    height = np.array([t["top_z"] - t["ground_z"] for t in trees])
    under = lateral < 2.0
    assert under.sum() >= 3 and height[under].max() <= 6.0  # trimmed 2-3 m below the 8-9 m wires
    beside = (lateral > 3.0) & (lateral < 9.0) & (height > 6.0)
    assert beside.sum() >= 10  # the row beside the line, taller than its wires
    assert all(55 < c["angle_deg"] < 85 for c in s.truth["crossings"])


def test_joint_use_poles_carry_a_stack_of_communication_cables():
    """comm_cables: the low-voltage line's poles carry cables one above another, comm_spacing_m
    apart, under its wires and clear of the road (4.5 m over the ground at the poles at least);
    they share one 2D line and cross under line A's wires."""
    s = make_scene("corridor", seed=4, density_ppm2=3.0, line_variant="distribution", comm_cables=3,
                   comm_spacing_m=0.3)
    comm = [w for w in s.truth["wires"] if w["kind"] == "communication"]
    assert [w["line"] for w in comm] == ["B"] * 3 and len({round(w["offset_m"], 3) for w in comm}) == 1
    span0 = {sp["wire_id"]: sp for sp in s.truth["spans"] if sp["span"] == 0 and sp["line"] == "B"}
    z = sorted(span0[w["id"]]["a"][2] for w in comm)
    assert np.allclose(np.diff(z), 0.3) and max(z) < min(span0[w["id"]]["a"][2] for w in s.truth["wires"]
                                                         if w["line"] == "B" and w["kind"] == "phase")
    pole = next(p for p in s.truth["pylons"] if p["line"] == "B")
    ends = [sp for sp in s.truth["spans"] if sp["line"] == "B" and sp["wire_id"] in span0
            and np.hypot(sp["a"][0] - pole["x"], sp["a"][1] - pole["y"]) < 1.0]
    assert ends and min(sp["a"][2] for sp in ends) - pole["z"] >= 4.5
    assert len([l for l in s.truth["conductor_lines_2d"] if l["line"] == "B"]) == 3  # L, R and the stack
    plain = make_scene("corridor", seed=4, density_ppm2=3.0, line_variant="distribution")
    assert len(s.truth["crossings"]) == len(plain.truth["crossings"]) + 3


@pytest.mark.parametrize("n, shape", [(1, "single"), (3, "triangle"), (4, "square")])
def test_bundle_variants(n, shape):
    s = make_scene("corridor", seed=3, density_ppm2=3.0, bundle=n, bundle_spacing_m=0.4)
    phases = [w for w in s.truth["wires"] if w["line"] == "A" and w["kind"] == "phase"]
    assert len(phases) == 4 * n
    arm = [w for w in phases if w["attach"] == "arm0_L"]
    pts = sorted((round(w["offset_m"] - np.mean([v["offset_m"] for v in arm]), 3), round(w["dz_m"], 3)) for w in arm)
    if shape == "triangle":  # two below 0.4 m apart, one above them
        assert pts == [(-0.2, 0.0), (0.0, round(0.4 * np.sqrt(3) / 2, 3)), (0.2, 0.0)]
    if shape == "square":
        assert pts == [(-0.2, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.2, 0.4)]
    # sub-conductors stacked in plan share one 2D line: one per distinct plan offset
    offsets = {round(w["offset_m"], 3) for w in s.truth["wires"] if w["line"] == "A"}
    assert len([l for l in s.truth["conductor_lines_2d"] if l["line"] == "A"]) == len(offsets)
    # each 2D line knows its bundle's centre in plan (one conductor per phase is a right answer)
    centre = round(float(np.mean([w["offset_m"] for w in arm])), 3)
    for line in s.truth["conductor_lines_2d"]:
        if any(i in {w["id"] for w in arm} for i in line["wire_ids"]):
            assert line["bundle_offset_m"] == centre and abs(line["offset_m"] - centre) <= 0.2 + 1e-9


def test_truth_geopackage_layers(tmp_path):
    import geopandas as gpd

    toolbox.run("synthetic-scene", output=tmp_path / "c.laz", kind="corridor", density_ppm2=0.5, seed=1,
                width_m=300, height_m=150)
    from toolbox.io.vectors import read_vectors

    layers = read_vectors(tmp_path / "c_truth.gpkg")
    assert set(layers) == {"truth_conductors_2d", "truth_catenaries", "truth_crossings", "truth_roof_planes",
                           "truth_buildings", "truth_pylons", "truth_trees", "truth_water"}
    assert all(isinstance(g, gpd.GeoDataFrame) and g.crs.to_epsg() == 25832 for g in layers.values())
    assert layers["truth_catenaries"].geometry.has_z.all()
    assert len(layers["truth_crossings"]) > 0


def test_a_tower_outside_the_scene_holds_its_wires_but_is_not_surveyed():
    """60 m spans (seed 1): line A's last tower stands past the scene's east edge. Its wires' ends
    are there, but no point of it (nor of anything) lies outside the scene, and the truth says it
    stands outside, so a scorer does not ask for it."""
    s = make_scene("corridor", seed=1, density_ppm2=3.0, span_m=60.0)
    W, H = s.extent
    u, v = s.x - s.origin[0], s.y - s.origin[1]
    assert u.min() >= 0 and u.max() <= W and v.min() >= 0 and v.max() <= H
    flags = [(p["in_scene"], 0 <= p["x"] - s.origin[0] <= W and 0 <= p["y"] - s.origin[1] <= H)
             for p in s.truth["pylons"]]
    assert all(a == b for a, b in flags)
    assert sum(not a for a, _ in flags) >= 1 and sum(a for a, _ in flags) >= 15
    # the towers inside keep their points: each has tower points within 6 m of its base
    tower = s.fields["classification"] == 15
    for p in s.truth["pylons"]:
        if p["in_scene"] and p["line"] == "A":
            assert (np.hypot(s.x[tower] - p["x"], s.y[tower] - p["y"]) < 6.0).sum() > 20


@pytest.mark.parametrize("seed", [1, 4, 7])
def test_a_support_stands_at_the_brow_where_no_tightening_keeps_a_span_clear(seed):
    """Line B of the distribution variant climbs an escarpment on seeds 1, 4 and 7 (13-18 m in
    about 50 m): however tight, a wire strung straight between its poles passes 1.5-2.7 m over the
    brow. A line designer puts a pole there; so does the generator (same model, on the
    slope), and every wire keeps at least 3 m over the ground (the 3.6-4 m left over a road
    embankment, where no pole may stand, is the least)."""
    s = make_scene("corridor", seed=seed, density_ppm2=1.0, line_variant="distribution")
    (ox, oy), res = s.origin, s.dtm_resolution_m
    rows, cols = s.dtm.shape

    def ground(x, y):  # bilinear in the 1 m DTM (cell centres)
        fx, fy = (x - ox) / res - 0.5, (oy + rows * res - y) / res - 0.5
        c0, r0 = np.clip(np.floor(fx).astype(int), 0, cols - 2), np.clip(np.floor(fy).astype(int), 0, rows - 2)
        a, b = np.clip(fx - c0, 0, 1), np.clip(fy - r0, 0, 1)
        d = s.dtm
        return ((1 - a) * (1 - b) * d[r0, c0] + a * (1 - b) * d[r0, c0 + 1] + (1 - a) * b * d[r0 + 1, c0]
                + a * b * d[r0 + 1, c0 + 1])

    inside = [sp for sp in s.truth["spans"] if sp["line"] in ("A", "B")]
    lowest = min(float(np.min(np.array(sp["curve"])[:, 2] - ground(np.array(sp["curve"])[:, 0],
                                                                   np.array(sp["curve"])[:, 1])))
                 for sp in inside if all(0 < c[0] - ox < cols * res and 0 < oy + rows * res - c[1] < rows * res
                                         for c in sp["curve"]))
    assert lowest >= 3.0, lowest
    assert all(p["height_m"] == {"A": 9.0, "B": 7.0}[p["line"]] for p in s.truth["pylons"])

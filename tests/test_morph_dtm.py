"""Morphological DTM plugin: ground filter and DTM accuracy against exact truth (synthetic) and
reference labels (ISPRS), hillshade against gdaldem's formula on closed-form surfaces, object
classes, batch and preview."""

import json

import laspy
import numpy as np
from scipy import ndimage
import pytest
import rasterio
from affine import Affine

import toolbox
from conftest import shared_file
from toolbox.io.points import read_points
from toolbox.io.rasters import Raster, read_raster, write_raster
from toolbox_plugins.morph_dtm import core
from toolbox_plugins.morph_dtm.evaluation import ground_errors


@pytest.fixture(scope="session")  # (an xdist worker tears module fixtures down when its queue runs dry)
def terrain_scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("terrain")
    toolbox.run("synthetic-scene", output=d / "t.laz", kind="terrain", seed=21)
    return d / "t.laz"


def test_ground_and_dtm_accuracy_on_synthetic_truth(terrain_scene, tmp_path):
    rep = toolbox.run("dtm", terrain_scene, tmp_path / "dtm.tif")
    truth = laspy.read(terrain_scene).classification
    pred = laspy.read(tmp_path / "dtm_classified.laz").classification
    e = ground_errors(truth == 2, pred == 2)
    assert e["total_pct"] <= 1.0, e  # issue target: ground total error <= 1 %
    assert e["kappa"] >= 0.97
    # the DTM against the true DTM, cell for cell (same 1 m grid)
    dtm = read_raster(tmp_path / "dtm.tif")
    ref = read_raster(str(terrain_scene).replace(".laz", "_dtm.tif"))
    assert dtm.transform == ref.transform and dtm.shape == ref.shape
    d = dtm.data.astype(float) - ref.data
    assert np.isfinite(d).all()
    rmse = float(np.sqrt(np.mean(d ** 2)))
    assert rmse <= 0.08, rmse  # the method's published figure, over all cells (slopes, embankment, holes)
    assert rep["stats"]["n_noise"] >= 3  # the scene's low outliers
    # the bridge's deck continues the road at both ends: the refinement passes must not climb onto it
    deck = truth == 17
    assert deck.sum() > 1000 and (pred[deck] == 2).mean() < 0.25  # 0.21 measured


def test_low_outliers_become_noise(terrain_scene, tmp_path):
    toolbox.run("dtm", terrain_scene, tmp_path / "d.tif")
    truth = laspy.read(terrain_scene)
    pred = laspy.read(tmp_path / "d_classified.laz").classification
    ref = read_raster(str(terrain_scene).replace(".laz", "_dtm.tif"))
    col = ((np.asarray(truth.x) - ref.transform.c) / ref.cell_size).astype(int)
    row = ((ref.transform.f - np.asarray(truth.y)) / ref.cell_size).astype(int)
    depth = ref.data[row.clip(0, ref.shape[0] - 1), col.clip(0, ref.shape[1] - 1)] - np.asarray(truth.z)
    low = (truth.classification == 7) & (depth > 2.5)  # clearly below the 2 m outlier threshold
    assert low.sum() >= 20
    assert (pred[low] == 7).mean() >= 0.95
    assert not np.any(pred[truth.classification == 7] == 2) or (pred[low] == 2).sum() == 0


ISPRS_SAMPLES = ("samp11", "samp12", "samp21_f32", "samp23_f32", "samp24_f32", "samp31_f32", "samp41_f32",
                 "samp51_f32", "samp52_f32", "samp53_f32", "samp61_f32", "samp71_f32")


from conftest import SHARED_DATA

SHARED_DATA_ISPRS = SHARED_DATA / "isprs_filtertest"


def _isprs_scores(tmp_path):
    from conftest import SHARED_DATA

    present = [s for s in ISPRS_SAMPLES if (SHARED_DATA / "isprs_filtertest" / f"{s}.txt").exists()]
    if not present:
        shared_file("isprs_filtertest/samp11.txt")  # skips with the reason
    scores = {}
    for s in present:
        rep = toolbox.run("dtm", SHARED_DATA / "isprs_filtertest" / f"{s}.txt", tmp_path / f"{s}.tif",
                          crs="EPSG:32632")
        scores[s] = rep["stats"]
    return scores


def test_isprs_reference_samples_with_one_default_parameter_set(tmp_path):
    """Every ISPRS filter-test sample present, one parameter set (the defaults), against the
    reference labels. The bounds are this filter's measured figures with a small margin (12-sample
    mean 4.09 %, kappa 0.843; SMRF with PDAL's defaults: 5.06 %, 0.823): a regression fails. (The
    connected-operator rule that took the mean to 3.99 % went: it gained nothing out of sample.)"""
    scores = _isprs_scores(tmp_path)
    for s, st in scores.items():
        assert st["isprs_total_pct"] <= 10.0, (s, st)
        # the last refinement's cell follows the point spacing: 1.25 x it, at most the filter cell
        assert st["refine_cell_m_used"] == pytest.approx(min(1.25 * st["point_spacing_m"], 2.0), abs=0.002), st
    if "samp11" in scores:
        assert scores["samp11"]["isprs_total_pct"] <= 9.0
        assert 1.0 < scores["samp11"]["point_spacing_m"] < 1.1  # the sample's documented ~1 m spacing
    if "samp12" in scores:
        assert scores["samp12"]["isprs_total_pct"] <= 3.3
    if "samp41_f32" in scores:  # ground on a terrace between buildings, cut away by the opening
        assert scores["samp41_f32"]["isprs_total_pct"] <= 6.2
    if "samp23_f32" in scores:  # a raised square, cut away by the opening
        assert scores["samp23_f32"]["isprs_total_pct"] <= 7.1
    if "samp52_f32" in scores:  # trees on the rims of data gaps (a river): gaps refilled from ground
        assert scores["samp52_f32"]["isprs_total_pct"] <= 4.1
        assert scores["samp52_f32"]["refine_cell_m_used"] == 2.0  # sparse (2.4 m spacing): the filter cell
    if len(scores) < len(ISPRS_SAMPLES):
        pytest.skip(f"the 12-sample mean needs all of {ISPRS_SAMPLES}; only {sorted(scores)} are present")
    mean = np.mean([st["isprs_total_pct"] for st in scores.values()])
    kappa = np.mean([st["isprs_kappa"] for st in scores.values()])
    assert mean <= 4.15, {s: st["isprs_total_pct"] for s, st in scores.items()}
    assert kappa >= 0.84


def test_refine_cell_follows_the_point_spacing():
    rng = np.random.default_rng(2)
    for density in (0.2, 1.0, 8.0):  # points per m2: spacing 2.24, 1.0, 0.35 m
        n = int(100 * 80 * density)
        x, y = rng.uniform(0, 100, n), rng.uniform(0, 80, n)
        r = core.ground_filter(x, y, 0.02 * x + rng.normal(0, 0.02, n),
                               core.GroundSettings(2.0, 30.0, 0.08, 0.45, 0.25, 1.0, 2.0, min_refine_cell=1.0))
        assert r.point_spacing == pytest.approx(density ** -0.5, rel=0.06)
        assert r.surface_grid.cell == pytest.approx(np.clip(1.25 * r.point_spacing, 1.0, 2.0))
        assert r.ground.mean() > 0.999  # a plain slope is all ground on every grid
    assert core.refine_cell_size(0.4, 2.0, 0.5) == 0.5 and core.refine_cell_size(3.0, 2.0, 0.5) == 2.0


def test_ground_errors_definitions():
    t = np.array([1, 1, 1, 1, 0, 0, 0, 0, 0, 0], bool)
    p = np.array([1, 1, 1, 0, 1, 0, 0, 0, 0, 0], bool)
    e = ground_errors(t, p)
    assert e["type1_pct"] == 25.0 and e["type2_pct"] == pytest.approx(100 / 6, abs=1e-3)
    assert e["total_pct"] == 20.0
    assert e["kappa"] == pytest.approx((0.8 - 0.52) / 0.48, abs=1e-4)


def test_fill_holes_is_exact_on_planes_and_smooth():
    yy, xx = np.mgrid[0:40, 0:50].astype(float)
    plane = 3.0 + 0.2 * xx - 0.1 * yy
    holes = plane.copy()
    holes[10:25, 5:30] = np.nan
    holes[0:3, 45:50] = np.nan  # touching the edge
    filled = core.fill_holes(holes)
    np.testing.assert_allclose(filled[10:25, 5:30], plane[10:25, 5:30], atol=1e-6)
    assert np.isfinite(filled).all()


def test_fill_holes_inside_a_footprint_only():
    """A diagonal strip of data: holes inside it are solved exactly on a plane; cells outside
    take the nearest value; a footprint island without any known cell does not break the solve."""
    yy, xx = np.mgrid[0:60, 0:60].astype(float)
    plane = 3.0 + 0.2 * xx - 0.1 * yy
    strip = np.abs(xx - yy) < 8
    known = strip.copy()
    known[27:33, 27:33] = False  # a building inside the strip
    island = (xx > 50) & (yy < 6)  # in the footprint, but with no data at all
    domain = strip | island
    filled = core.fill_holes(np.where(known, plane, np.nan), known, domain)
    np.testing.assert_allclose(filled[27:33, 27:33], plane[27:33, 27:33], atol=1e-6)
    assert np.isfinite(filled).all()
    outside = ~domain
    near = ndimage.distance_transform_edt(~strip, return_distances=False, return_indices=True)
    np.testing.assert_allclose(filled[outside], filled[near[0][outside], near[1][outside]])
    # the same holes without a domain: the same values inside the strip
    whole = core.fill_holes(np.where(known, plane, np.nan), known)
    np.testing.assert_allclose(filled[strip], whole[strip], atol=1e-6)
    # leaving the outside alone: the same inside the footprint (the island too), NaN outside
    inside_only = core.fill_holes(np.where(known, plane, np.nan), known, domain, fill_outside=False)
    np.testing.assert_array_equal(inside_only[domain], filled[domain])
    assert np.isnan(inside_only[outside]).all()


def test_dtm_from_ground_is_unbiased_on_a_steep_plane():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 50, 40000)
    y = rng.uniform(0, 50, 40000)
    z = 100 + 0.9 * x - 0.4 * y  # 44 degrees
    grid = core.Grid(0.0, 50.0, 1.0, 50, 50)
    dtm, support = core.dtm_from_ground(grid, x, y, z)
    xs, ys = grid.centres()
    truth = 100 + 0.9 * xs[None, :] - 0.4 * ys[:, None]
    assert support.all()
    np.testing.assert_allclose(dtm, truth, atol=1e-6)


def test_dtm_from_ground_fits_each_cells_3x3_block_like_lstsq():
    """Cells with few own points (< 6) take the least-squares plane of their 3x3 block's points,
    evaluated at the cell centre: the box-sum moments must give what a direct fit gives, also
    far from the origin (a grid 40 km east)."""
    rng = np.random.default_rng(1)
    west, north, cell = 40000.0, 5000.0, 1.0
    n_cells = 20
    x = west + rng.uniform(0, n_cells, 1600)
    y = north - rng.uniform(0, n_cells, 1600)  # about 4 points per cell
    z = 50 + 0.3 * (x - west) - 0.2 * (y - north) + 0.01 * (x - west) * (y - north) + rng.normal(0, 0.02, len(x))
    grid = core.Grid(west, north, cell, n_cells, n_cells)
    dtm, support = core.dtm_from_ground(grid, x, y, z)
    r, c = grid.index(x, y)
    own = np.bincount(r * n_cells + c, minlength=n_cells * n_cells).reshape(n_cells, n_cells)
    xs, ys = grid.centres()
    checked = 0
    for i in range(1, n_cells - 1):
        for j in range(1, n_cells - 1):
            if own[i, j] >= 6 or own[i, j] == 0:
                continue
            m = (np.abs(r - i) <= 1) & (np.abs(c - j) <= 1)
            A = np.column_stack([np.ones(m.sum()), x[m] - xs[j], y[m] - ys[i]])
            coef = np.linalg.lstsq(A, z[m], rcond=None)[0]
            assert dtm[i, j] == pytest.approx(coef[0], abs=1e-9)
            checked += 1
    assert checked >= 100 and support.all()


def test_multiscale_opening_removes_by_size_and_height():
    surf = np.zeros((100, 100))
    surf[20:30, 20:30] = 5.0  # a 10 m building, 5 m high: removed
    surf[60:62, 60:62] = 0.3  # a 2 m bump of 0.3 m: kept (below n)
    yy, xx = np.mgrid[0:100, 0:100]
    ridge = np.clip(3 - np.abs(xx - 80) * 0.3, 0, None)  # a broad ridge: kept
    obj, dh, size = core.multiscale_opening(surf + ridge, 1.0, 30.0, k=0.08, n=0.45)
    assert obj[20:30, 20:30].all()
    assert not obj[60:62, 60:62].any()
    assert not obj[:, 75:86].any()
    assert np.allclose(dh[22:28, 22:28], 5.0, atol=1e-9) and np.all(size[22:28, 22:28] == 11.0)


def _hillshade_closed_form(p, q, az, alt, z=1.0):
    """gdaldem's shade of the plane z = p*E + q*N: 1 + 254 * max(0, n . L)."""
    a, al = np.radians(az), np.radians(alt)
    cang = (np.sin(al) - z * np.cos(al) * (p * np.sin(a) + q * np.cos(a))) / np.sqrt(1 + z * z * (p * p + q * q))
    return np.floor(1 + 254 * max(cang, 0.0) + 0.5) if cang > 0 else 1.0


@pytest.mark.parametrize("p, q", [(0.0, 0.0), (0.5, 0.0), (0.0, -0.7), (0.3, 0.4), (-1.2, 0.8), (2.0, 2.0)])
@pytest.mark.parametrize("az, alt", [(315, 45), (90, 30), (200, 60)])
def test_hillshade_matches_gdaldem_formula_on_planes(p, q, az, alt):
    res = 2.0
    rows, cols = 20, 30
    E = (np.arange(cols) + 0.5) * res
    N = 1000 - (np.arange(rows) + 0.5) * res
    dem = p * E[None, :] + q * N[:, None]
    hs = core.hillshade(dem, res, -res, az, alt)
    want = _hillshade_closed_form(p, q, az, alt)
    assert np.all(np.abs(hs[1:-1, 1:-1].astype(int) - want) <= 1)
    # edges are computed too (-compute_edges: missing neighbours take the centre's value)
    assert hs[0].min() >= 1 and hs[:, -1].min() >= 1
    hs2 = core.hillshade(dem, res, -res, az, alt, z_factor=2.0)
    assert abs(int(hs2[5, 5]) - _hillshade_closed_form(p, q, az, alt, z=2.0)) <= 1


def test_hillshade_multidirectional_flat_and_nodata():
    dem = np.full((10, 10), 50.0)
    dem[4, 4] = np.nan
    hs = core.hillshade(dem, 1.0, -1.0, multidirectional=True)
    assert hs[4, 4] == 0
    assert hs[0, 0] == int(np.floor(1 + 254 * np.sin(np.radians(45)) + 0.5))
    hs = core.hillshade(dem, 1.0, -1.0, compute_edges=False)
    assert (hs[0, :] == 0).all() and (hs[:, -1] == 0).all()


def test_hillshade_algorithm_writes_styled_geotiff(tmp_path):
    dem = Raster(np.add.outer(np.arange(50.0), np.arange(60.0)).astype(np.float32),
                 Affine(1, 0, 512000, 0, -1, 5404000), crs=None, nodata=-9999.0)
    write_raster(dem, tmp_path / "dem.tif")
    toolbox.run("hillshade", tmp_path / "dem.tif", tmp_path / "hs.tif", azimuth_deg=90.0)
    with rasterio.open(tmp_path / "hs.tif") as ds:
        hs = ds.read(1)
        assert ds.dtypes[0] == "uint8" and ds.nodata == 0
    assert abs(int(hs[10, 10]) - _hillshade_closed_form(1.0, -1.0, 90, 45)) <= 1
    assert "singlebandgray" in (tmp_path / "hs.qml").read_text()


def test_classify_buildings_and_vegetation_on_synthetic_truth(terrain_scene, tmp_path):
    rep = toolbox.run("classify", terrain_scene, tmp_path / "c.laz")
    truth = laspy.read(terrain_scene).classification
    pred = laspy.read(tmp_path / "c.laz").classification
    obj = np.isin(truth, [3, 4, 5, 6])
    building_vs_veg = np.where(truth[obj] == 6, pred[obj] == 6, np.isin(pred[obj], [3, 4, 5]))
    assert building_vs_veg.mean() >= 0.95  # issue target
    assert (truth[obj] == pred[obj]).mean() >= 0.95  # low / medium / high too
    b, pb = truth == 6, pred == 6
    assert (b & pb).sum() / b.sum() >= 0.98
    # classify writes 1-7; the scene's own water (9) and bridge decks (17) pass through (#75)
    theirs = truth >= 8
    assert np.array_equal(pred[theirs], truth[theirs])
    assert set(rep["stats"]["classes"]) <= {1, 2, 3, 4, 5, 6, 7} | set(np.unique(truth[theirs]).tolist())


def test_classify_reports_on_ahn3_buildings(tmp_path):
    path = shared_file("ahn3_amsterdam/ahn_2386_9702.laz")
    toolbox.run("classify", path, tmp_path / "a.laz", crs="EPSG:28992")
    truth = laspy.read(path).classification
    pred = laspy.read(tmp_path / "a.laz").classification
    b, pb = truth == 6, pred == 6
    precision = (b & pb).sum() / pb.sum()
    recall = (b & pb).sum() / b.sum()
    # measured 0.997 / 0.92 (0.68 before facades under roof edges joined their building): keep
    # what we have, catch regressions
    assert precision >= 0.99 and recall >= 0.9


def _box_building_with_facades_and_a_tree(rng):
    """A 12 x 8 m flat roof 9 m up (11 points/m²) with rough walls under it (windows, sills: 0.15 m
    scatter; sparser, as scanners see walls obliquely), eaves 0.4 m out, and a 10 m tree crown
    1.5-7.5 m from the west wall. Returns xyz, height, truth."""
    pts, truth = [], []
    gx, gy = np.meshgrid(np.arange(-0.4, 12.4, 0.3), np.arange(-0.4, 8.4, 0.3))
    roof = np.column_stack([gx.ravel(), gy.ravel(), 9.0 + rng.normal(0, 0.02, gx.size)])
    pts.append(roof), truth.append(np.full(len(roof), 6))
    for (x0, y0), (x1, y1) in (((0, 0), (12, 0)), ((12, 0), (12, 8)), ((12, 8), (0, 8)), ((0, 8), (0, 0))):
        t, z = np.meshgrid(np.linspace(0, 1, 25), np.arange(0.5, 8.8, 0.6))
        n = np.array([y1 - y0, x0 - x1], float) / np.hypot(x1 - x0, y1 - y0)  # outward normal
        off = rng.normal(0, 0.15, t.size)  # recesses and sills
        wall = np.column_stack([x0 + (x1 - x0) * t.ravel() + n[0] * off, y0 + (y1 - y0) * t.ravel() + n[1] * off,
                                z.ravel()])
        pts.append(wall), truth.append(np.full(len(wall), 6))
    c = np.array([-4.5, 4.0, 7.0])  # crown centre: its edge 1.5 m from the west wall, under the roof level
    d = rng.normal(size=(1500, 3))
    crown = c + 3.0 * d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.6, 1.0, (1500, 1)) ** 0.5
    pts.append(crown), truth.append(np.full(len(crown), 5))
    xyz = np.vstack(pts)
    return xyz, xyz[:, 2].copy(), np.concatenate(truth)


def test_a_bundle_of_parallel_wires_is_no_roof():
    from toolbox_plugins.morph_dtm.objects import classify_objects

    rng = np.random.default_rng(5)
    gx, gy = np.meshgrid(np.arange(0, 10, 0.3), np.arange(0, 6, 0.3))  # a 10 x 6 m roof, 7 m up
    roof = np.column_stack([gx.ravel(), gy.ravel(), 7.0 + rng.normal(0, 0.02, gx.size)])
    s = np.arange(0, 60, 0.25)  # two conductors 0.45 m apart at 12 m, 34 m from the roof: a flat strip
    wires = np.vstack([np.column_stack([s, np.full_like(s, 40.0 + dy), 12.0 + 0.002 * (s - 30) ** 2])
                       for dy in (0.0, 0.45)])
    xyz = np.vstack([roof, wires])
    cls = classify_objects(xyz, xyz[:, 2].copy())
    assert (cls[:len(roof)] == 6).mean() >= 0.98
    assert not np.any(cls[len(roof):] == 6)  # planar-looking, but 0.45 m wide and 60 m long


def test_facades_under_a_roof_edge_join_their_building_and_a_tree_beside_it_does_not():
    from toolbox_plugins.morph_dtm.objects import classify_objects

    xyz, height, truth = _box_building_with_facades_and_a_tree(np.random.default_rng(4))
    walls = (truth == 6) & (xyz[:, 2] < 8.9)
    with_rule = classify_objects(xyz, height)
    plane_rule_only = classify_objects(xyz, height, wall_reach=0.0)
    assert (plane_rule_only[walls] == 6).mean() < 0.5  # rough walls fail the plane test alone
    assert (with_rule[walls] == 6).mean() >= 0.98
    assert (with_rule[(truth == 6) & ~walls] == 6).mean() >= 0.98  # the roof
    assert np.isin(with_rule[truth == 5], [3, 4, 5]).mean() >= 0.98  # the crown stays a tree


def test_classify_gives_the_same_classes_to_a_survey_in_feet(terrain_scene, tmp_path):
    from pyproj import CRS

    from toolbox.io.points import PointCloud, write_points

    ft = 0.3048
    pc = read_points(terrain_scene)
    fields = {k: np.asarray(pc.fields[k]) for k in ("classification", "return_number", "number_of_returns")}
    pc_ft = PointCloud(pc.x / ft, pc.y / ft, pc.z / ft, fields,
                       crs=CRS.from_epsg(2992))  # NAD83 / Oregon GIC Lambert, international feet
    write_points(pc_ft, tmp_path / "feet.laz")
    assert read_points(tmp_path / "feet.laz").horizontal_unit_m == pytest.approx(ft)
    toolbox.run("classify", terrain_scene, tmp_path / "m.laz")
    toolbox.run("classify", tmp_path / "feet.laz", tmp_path / "f.laz")
    in_m = laspy.read(tmp_path / "m.laz").classification
    in_ft = laspy.read(tmp_path / "f.laz").classification
    obj = np.isin(in_m, [3, 4, 5, 6])
    # every length and height of the rules is in metres whatever the file's unit (vegetation
    # classes at 2 and 5 m, not 2 and 5 feet): only the files' 1 mm / 1 mft rounding differs
    # (measured 0.99998; 0.968 with the height classes taken in feet)
    assert (in_m[obj] == in_ft[obj]).mean() >= 0.999
    assert (in_m == in_ft).mean() >= 0.999


def test_feet_input_gives_dtm_in_feet(tmp_path):
    path = shared_file("pdal_autzen/autzen_trim.las")
    toolbox.run("dtm", path, tmp_path / "a.tif", resolution_m=1.0)
    dtm = read_raster(tmp_path / "a.tif")
    assert dtm.cell_size == pytest.approx(1 / 0.3048)  # 1 m expressed in the file's feet
    from pyproj import CRS

    assert CRS.from_user_input(dtm.crs) == read_points(path).crs  # its ESRI-style Lambert, kept in the GeoTIFF
    zs = read_points(path).z
    assert np.nanmin(dtm.data) >= zs.min() - 1 and np.nanmax(dtm.data) <= zs.max()
    assert read_points(tmp_path / "a_classified.laz").crs == read_points(path).crs  # a non-EPSG CRS kept
    # The vendor's class 2 here is a thinned subset of the ground (most unclassified points lie
    # on it), so compare surfaces: our DTM against one made from the vendor's ground points.
    las = laspy.read(path)
    g = las.classification == 2
    grid = core.Grid(dtm.transform.c, dtm.transform.f, dtm.cell_size, *dtm.shape)
    ref, support = core.dtm_from_ground(grid, np.asarray(las.x)[g], np.asarray(las.y)[g], np.asarray(las.z)[g])
    both = support & np.isfinite(dtm.data)
    diff_m = np.abs(dtm.data[both] - ref[both]) * 0.3048
    assert np.median(diff_m) < 0.1 and np.mean(diff_m < 0.5) > 0.9
    pred = laspy.read(tmp_path / "a_classified.laz").classification == 2
    assert ground_errors(g, pred)["type1_pct"] < 2.0  # vendor ground is kept


def test_preview_is_a_georeferenced_rgb_png(terrain_scene, tmp_path):
    import warnings

    toolbox.run("dtm", terrain_scene, tmp_path / "d.tif", outputs={"preview": str(tmp_path / "p.png")})
    dtm = read_raster(tmp_path / "d.tif")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NotGeoreferencedWarning: it lies on the DTM's grid
        with rasterio.open(tmp_path / "p.png") as ds:
            img = ds.read()
            assert ds.transform == dtm.transform and ds.crs.to_epsg() == 25832
    assert img.shape[0] == 3 and img.shape[1:] == dtm.shape
    red = (img[0] > 150) & (img[1] < 100)
    assert 0.01 < red.mean() < 0.4  # buildings and trees drawn in red
    # the world file QGIS reads: cell size, rotations, -cell size, centre of the top-left cell
    wld = np.loadtxt(tmp_path / "p.wld")
    t = dtm.transform
    np.testing.assert_allclose(wld, [t.a, 0, 0, t.e, t.c + t.a / 2, t.f + t.e / 2])
    assert not [p.name for p in tmp_path.iterdir() if "partial" in p.name]


def test_image_written_without_georeference_drops_stale_sidecars(tmp_path):
    from affine import Affine

    from toolbox.io.rasters import Raster, write_image

    rgb = np.zeros((3, 4, 5), np.uint8)
    write_image(Raster(rgb, Affine(1, 0, 100, 0, -1, 200), crs=None), tmp_path / "a.png")
    assert (tmp_path / "a.wld").exists()
    write_image(np.zeros((4, 5, 3), np.uint8), tmp_path / "a.png", overwrite=True)  # a plain picture now
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]


def test_grids_too_big_for_memory_are_refused_before_work(tmp_path, cli):
    from toolbox.io.points import PointCloud, parse_crs, write_points

    rng = np.random.default_rng(1)
    x = np.r_[rng.uniform(0, 10, 50), 200000.0]  # one stray point 200 km away
    y = np.r_[rng.uniform(0, 10, 50), 200000.0]
    write_points(PointCloud(x, y, rng.uniform(0, 1, 51), crs=parse_crs("EPSG:25832")), tmp_path / "far.laz")
    r = cli("run", "dtm", tmp_path / "far.laz", "-o", tmp_path / "d.tif")
    assert r.returncode == 2
    assert "million cells" in r.stderr and "GiB" in r.stderr and "filter_cell_m" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["far.laz"]


def test_batch_of_tiles_in_parallel(terrain_scene, tmp_path, cli):
    src = tmp_path / "tiles"
    src.mkdir()
    pc = read_points(terrain_scene)
    from toolbox.io.points import write_points

    x0 = pc.x.min()
    for i in range(3):
        m = (pc.x >= x0 + i * 130) & (pc.x < x0 + (i + 1) * 130)
        write_points(pc.subset(m), src / f"tile{i}.laz")
    (src / "broken.laz").write_bytes((src / "tile0.laz").read_bytes()[:5000])
    out = tmp_path / "out"
    out.mkdir()
    r = cli("run", "dtm", src, "-o", out, "--json", "-j", "2")
    assert r.returncode == 1
    rep = json.loads(r.stdout)
    assert rep["n_done"] == 3 and rep["n_failed"] == 1 and "broken.laz" in rep["failed"][0]["input"]
    assert sorted(p.name for p in out.glob("*.tif")) == ["tile0.tif", "tile1.tif", "tile2.tif"]
    assert sorted(p.name for p in out.glob("*.laz")) == ["tile0_classified.laz", "tile1_classified.laz", "tile2_classified.laz"]


def test_a_fresh_process_takes_the_kernels_only_once_numpy_would_have_paid_for_their_start_up(monkeypatch):
    from toolbox_plugins.morph_dtm import plugin as P

    monkeypatch.setattr(P, "_numpy_extra_s", [0.0])
    per_point = P.NUMPY_EXTRA_S_PER_POINT
    cold = P.KERNELS_FIRST_USE_S + P.TAICHI_START_S
    small = int(0.4 * cold / per_point)  # one such cloud costs 40 % of the start-up in numpy
    assert small >= P.KERNEL_MIN_POINTS
    fresh = dict(kernels_used=False, taichi_started=False, requested=False)
    assert not P.use_kernels(small, **fresh)  # 40 % lost
    assert not P.use_kernels(small, **fresh)  # 80 %
    assert P.use_kernels(small, **fresh)  # the third would pass the start-up: buy
    monkeypatch.setattr(P, "_numpy_extra_s", [0.0])
    assert P.use_kernels(int(1.01 * cold / per_point), **fresh)  # a large tile at once
    # taichi already running (another algorithm started it): only the kernels' front end is left
    assert P.use_kernels(int(1.01 * P.KERNELS_FIRST_USE_S / per_point), False, True, False)
    assert not P.use_kernels(int(1.01 * P.KERNELS_FIRST_USE_S / per_point), False, False, False)
    # kernels already built, or asked for by name (--arch cuda): from the size where they win
    monkeypatch.setattr(P, "_numpy_extra_s", [0.0])
    assert P.use_kernels(P.KERNEL_MIN_POINTS, True, False, False)
    assert P.use_kernels(P.KERNEL_MIN_POINTS, False, False, True)
    assert not P.use_kernels(P.KERNEL_MIN_POINTS - 1, True, True, True)
    assert P._numpy_extra_s == [0.0]  # clouds numpy takes anyway count no loss


def test_dtm_kernels_match_their_numpy_references():
    from toolbox import kernels
    from toolbox_plugins.morph_dtm.kernels import TaichiAccel

    acc = TaichiAccel(kernels.taichi())
    rng = np.random.default_rng(3)
    x = rng.uniform(1000, 1100, 200_000)
    y = rng.uniform(2000, 2080, 200_000)
    z = 300 + 0.3 * x - 0.1 * y + rng.normal(0, 0.2, len(x))
    grid = core.Grid.around(x, y, 1.5)
    ref = core.cell_moments(grid, x, y, z)
    # the points split into 2, 1 and 3 per-thread slices; 0: the shared-grid kernel with atomic
    # adds that a GPU runs (run here on the CPU)
    threads0 = acc._threads
    for threads in (threads0, 1, 3, 0):
        acc._threads = threads
        got = acc.moments(grid, x, y, z)
        for name in core.MOMENTS:  # same sums, another order of addition
            assert got[name].flags.c_contiguous
            np.testing.assert_allclose(got[name], ref[name], rtol=1e-9, atol=1e-6)
    some = rng.random(len(x)) < 0.6  # the moments of a subset, by mask
    ref_some = core.cell_moments(grid, x[some], y[some], z[some])
    masked_ref = core.cell_moments(grid, x, y, z, some)
    for threads in (2, 1, 0):
        acc._threads = threads
        got = acc.moments(grid, x, y, z, some)
        for name in core.MOMENTS:
            np.testing.assert_array_equal(masked_ref[name], ref_some[name])
            np.testing.assert_allclose(got[name], ref_some[name], rtol=1e-9, atol=1e-6)
    acc._threads = threads0
    zmin_ref, flat_ref = core.minimum_surface(grid, x, y, z)
    zmin, flat = acc.minimum_surface(grid, x, y, z)
    np.testing.assert_array_equal(flat, flat_ref)
    np.testing.assert_array_equal(zmin, zmin_ref)  # a minimum is exact
    surface = 300 + 0.3 * grid.centres()[0][None, :] - 0.1 * grid.centres()[1][:, None] + rng.normal(0, 0.1, (grid.rows, grid.cols))
    slope = core.surface_slope(surface, grid.cell)
    near_ref, dz_ref = core._near_surface(core.Sampler(grid, x, y), grid.cell, surface, z, 0.05, 0.2, 0.3)
    near, dz = acc.near_surface(grid, x, y, z, surface, slope, 0.05, 0.2, 0.3)
    np.testing.assert_allclose(dz, dz_ref, rtol=0, atol=1e-9)
    assert 0.2 < near_ref.mean() < 0.95 and (near != near_ref).sum() <= 2  # both sides of the test occur
    # the whole filter gives the same labels either way
    settings = core.GroundSettings(2.0, 30.0, 0.08, 0.45, 0.25, 1.0, 2.0)
    a = core.ground_filter(x, y, z, settings)
    b = core.ground_filter(x, y, z, settings, accel=acc)
    assert (a.ground != b.ground).sum() <= 2  # only float-rounding ties at the tolerance may differ


@pytest.mark.parametrize("multidirectional", [False, True])
def test_hillshade_in_row_blocks_equals_whole(multidirectional):
    rng = np.random.default_rng(0)
    dem = rng.normal(0, 5, (700, 531)).cumsum(0).cumsum(1) * 0.01
    dem[100:120, 50:60] = np.nan
    whole = core.hillshade(dem, 1.0, -1.0, multidirectional=multidirectional, block_rows=10**9)
    blocks = core.hillshade(dem, 1.0, -1.0, multidirectional=multidirectional, block_rows=64)
    assert np.array_equal(whole, blocks)


def test_low_outliers_and_the_minimum_without_them_match_full_recomputation():
    rng = np.random.default_rng(11)
    x, y = rng.uniform(0, 200, 60_000), rng.uniform(0, 150, 60_000)
    z = 100 + 0.05 * x + rng.normal(0, 0.1, len(x))
    pits = rng.choice(len(x), 40, replace=False)
    z[pits] -= rng.uniform(3, 20, len(pits))  # isolated low outliers
    grid = core.Grid.around(x, y, 2.0)
    zmin, flat = core.minimum_surface(grid, x, y, z)
    noise = core.low_outliers(grid, z, flat, zmin, 2.0)
    # the definition, over every point
    filled = np.where(np.isnan(zmin), np.inf, zmin)
    second = ndimage.rank_filter(filled, 1, size=3, mode="nearest")
    bad = (np.isfinite(second) & (filled < second - 2.0)).ravel()[flat] & (z < second.ravel()[flat] - 2.0)
    np.testing.assert_array_equal(noise, bad)
    assert 30 <= noise.sum() <= 40 and noise[pits].mean() > 0.7
    got = core.minimum_surface_without(grid, zmin, flat, z, noise)
    want, _ = core.minimum_surface(grid, None, None, z[~noise], flat[~noise])
    np.testing.assert_array_equal(got, want)  # NaN where a cell held only removed points


def test_a_cell_holding_only_low_outliers_is_outside_the_footprint_in_the_split_pass_counts_too():
    """The survey's point spacing from per-cell statistics (``spacing_counts_from_cells``) is the
    run's: a cell beside the data whose only point is a low outlier holds no point for the
    footprint in ``lowest_points``, and must not in the cell statistics either."""
    from toolbox.survey_read import CellStats
    from toolbox_plugins.morph_dtm.plugin import _settings_in_units, survey_cell_summary

    gx, gy = np.meshgrid(np.arange(0.5, 40, 1.0), np.arange(0.5, 40, 1.0))
    x, y = np.r_[gx.ravel(), 41.0], np.r_[gy.ravel(), 20.5]  # the last: in the cell east of the data
    z = np.r_[np.zeros(gx.size), -10.0]
    p = toolbox.algorithms()["dtm"].validate_params({})
    whole = core.spacing_counts(x, y, z, _settings_in_units(p, 1.0, 1.0), (-np.inf, -np.inf, np.inf, np.inf))
    stats = CellStats.empty(0.0, 40.0, 2.0, 20, 20)
    stats.add(x, y, z)
    got = survey_cell_summary(stats.finished(), p)
    assert (got["n_points"], got["n_footprint_cells"]) == whole
    assert whole[1] == 400  # the 20 x 20 cells of the data; not the outlier's

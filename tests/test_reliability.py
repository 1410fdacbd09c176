"""Nothing lost, nothing silently wrong (#75): non-finite input, inputs never overwritten, the
producer's classes kept, CRS warnings and refusals, interrupts, plugins that exit, sidecars as
outputs, memory checked before allocation, empty results, usage errors caught early, reports that
reproduce the run. Each test here failed on the code before #75."""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import TOOLBOX, run_cli, shared_file


def one_line_error(r, max_lines=1):
    lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
    assert 1 <= len(lines) <= max_lines, r.stderr
    assert "Traceback" not in r.stderr
    assert lines[-1].startswith("toolbox: error: "), r.stderr
    return lines[-1]


def files_in(folder: Path) -> list[str]:
    return sorted(p.name for p in Path(folder).iterdir())


def write_las(path: Path, x, y, z, classification=None, point_format=6, crs=None):
    import laspy

    hdr = laspy.LasHeader(version="1.4" if point_format >= 6 else "1.2", point_format=point_format)
    hdr.scales = [0.001, 0.001, 0.001]
    hdr.offsets = [np.floor(np.min(x)), np.floor(np.min(y)), np.floor(np.min(z))]
    if crs is not None:
        import pyproj

        hdr.add_crs(pyproj.CRS.from_user_input(crs))
    las = laspy.LasData(hdr)
    las.x, las.y, las.z = x, y, z
    if classification is not None:
        las.classification = classification
    las.write(path)
    return path


def flat_field(n=4000, size=60.0, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, size, n) + 500000.0
    y = rng.uniform(0, size, n) + 5400000.0
    z = 100.0 + 0.02 * (x - 500000.0) + rng.normal(0, 0.03, n)
    return x, y, z


def site_with_plugin(folder: Path, module: str, source: str, dist: str = "bad-plugin") -> Path:
    """A site folder holding one plugin module and the dist-info that registers it, as pip lays out
    an installed wheel (importlib.metadata finds it on PYTHONPATH)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{module}.py").write_text(textwrap.dedent(source))
    info = folder / f"{dist.replace('-', '_')}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[toolbox.plugins]\n{module} = {module}\n")
    return folder


# --- 1. non-finite input ------------------------------------------------------------------------

def test_nan_height_in_an_ascii_file_is_dropped_counted_and_never_written(tmp_path):
    x, y, z = flat_field()
    z[17] = np.nan
    x[40] = np.inf
    src = tmp_path / "f.txt"
    np.savetxt(src, np.column_stack([x, y, z]), fmt="%.3f")
    r = run_cli("run", "dtm", src, "-o", tmp_path / "d.tif", "--crs", "EPSG:25832", "--json")
    assert r.returncode == 0, r.stderr
    assert "2 of 4000 points have a NaN or infinite x, y or z" in r.stderr
    rep = json.loads(r.stdout)
    assert rep["dropped_points"] == {"points": 2}
    import laspy
    import rasterio

    las = laspy.read(tmp_path / "d_classified.laz")
    assert len(las) == 3998
    assert np.isfinite(las.header.offsets).all() and np.isfinite(np.asarray(las.z)).all()
    with rasterio.open(tmp_path / "d.tif") as ds:
        assert np.isfinite(ds.read(1)).mean() > 0.9  # the DTM was computed, not NaN everywhere


@pytest.mark.parametrize("field,value", [("scale", 0.0), ("scale", float("nan")), ("offset", float("inf"))])
def test_las_header_with_a_zero_nan_or_infinite_scale_or_offset_is_refused(tmp_path, field, value):
    src = write_las(tmp_path / "h.las", *flat_field(200))
    data = bytearray(src.read_bytes())
    at = 131 if field == "scale" else 155  # the header's z scale / x offset (LAS 1.x, byte offsets)
    data[at + (16 if field == "scale" else 0): at + (16 if field == "scale" else 0) + 8] = struct.pack("<d", value)
    src.write_bytes(bytes(data))
    out = tmp_path / "out"
    out.mkdir()
    r = run_cli("run", "dtm", src, "-o", out / "d.tif", "--crs", "EPSG:25832")
    assert r.returncode == 1
    msg = one_line_error(r)
    assert "h.las" in msg and ("scale factors" in msg or "offsets" in msg) and "repair the header" in msg
    assert files_in(out) == []
    r = run_cli("run", "dtm", src, "-o", out / "survey", "--tile-size-m", "50", "--crs", "EPSG:25832")
    assert r.returncode == 1 and "repair the header" in one_line_error(r)  # a survey reads headers first
    assert files_in(out) == []


# --- 2. an output is never an input --------------------------------------------------------------

def test_output_equal_to_input_is_refused_even_with_overwrite(tmp_path):
    src = write_las(tmp_path / "a.laz", *flat_field(), classification=np.ones(4000, np.uint8))
    before = src.read_bytes()
    r = run_cli("run", "classify", src, "-o", src, "--overwrite", "--crs", "EPSG:25832")
    assert r.returncode == 2
    msg = one_line_error(r)
    assert "is the input" in msg and "--overwrite" not in msg
    assert src.read_bytes() == before
    # a batch whose output folder is the input folder: classify writes <stem>.laz there
    write_las(tmp_path / "b.laz", *flat_field(seed=1))
    r = run_cli("run", "classify", tmp_path, "-o", tmp_path, "--overwrite", "--crs", "EPSG:25832")
    assert r.returncode == 2
    assert "is the input" in one_line_error(r)
    assert src.read_bytes() == before and files_in(tmp_path) == ["a.laz", "b.laz"]


# --- 3. the producer's classes --------------------------------------------------------------------

@pytest.fixture(scope="session")  # (an xdist worker tears module fixtures down when its queue runs dry)
def ahn4_crop(tmp_path_factory):
    """AHN4 07CZ2_14 around its pylon (200 m of corridor: wires 14, the tower 15, water 9), with
    all its classes as delivered."""
    import laspy

    las = laspy.read(shared_file("ahn4_corridor/07CZ2_14.laz"))
    cls = np.asarray(las.classification)
    cx, cy = np.asarray(las.x)[cls == 15].mean(), np.asarray(las.y)[cls == 15].mean()
    keep = (np.abs(np.asarray(las.x) - cx) < 100) & (np.abs(np.asarray(las.y) - cy) < 100)
    out = tmp_path_factory.mktemp("ahn4") / "crop.laz"
    sub = laspy.LasData(las.header)
    sub.points = las.points[keep]
    sub.write(out)
    return out


def test_dtm_keeps_every_class_it_does_not_decide(tmp_path):
    import laspy

    src = shared_file("ahn3_amsterdam/ahn_2386_9702.laz")
    r = run_cli("run", "dtm", src, "-o", tmp_path / "d.tif", "--crs", "EPSG:28992", "-q")
    assert r.returncode == 0, r.stderr
    before = np.asarray(laspy.read(src).classification)
    after = np.asarray(laspy.read(tmp_path / "d_classified.laz").classification)
    undecided = (after != 2) & (after != 7)
    assert np.array_equal(after[undecided & (before != 2)], before[undecided & (before != 2)])
    assert np.all(after[undecided & (before == 2)] == 1)  # a former ground point not kept is 1
    assert (after == 6).sum() >= 11_000  # of 11,992 buildings (0 before: every class was set to 1)


def test_classify_keeps_water_wires_and_towers_unless_told(ahn4_crop, tmp_path):
    import laspy

    before = np.asarray(laspy.read(ahn4_crop).classification)
    assert {9, 14, 15} <= set(np.unique(before))
    r = run_cli("run", "classify", ahn4_crop, "-o", tmp_path / "c.laz", "--crs", "EPSG:28992", "-q")
    assert r.returncode == 0, r.stderr
    after = np.asarray(laspy.read(tmp_path / "c.laz").classification)
    theirs = before >= 8
    assert np.array_equal(after[theirs], before[theirs])
    assert set(np.unique(after[~theirs])) <= {1, 2, 3, 4, 5, 6, 7}
    r = run_cli("run", "classify", ahn4_crop, "-o", tmp_path / "all.laz", "--crs", "EPSG:28992", "-q",
                "--set", "reclassify=all")
    assert r.returncode == 0, r.stderr
    assert set(np.unique(laspy.read(tmp_path / "all.laz").classification)) <= {1, 2, 3, 4, 5, 6, 7}
    r = run_cli("help", "classify")
    assert "classes 8 and above" in r.stdout and "reclassify" in r.stdout


def test_powerlines_keeps_the_classes_it_does_not_decide(ahn4_crop, tmp_path):
    import laspy

    before = np.asarray(laspy.read(ahn4_crop).classification)
    r = run_cli("run", "powerlines", ahn4_crop, "-o", tmp_path / "p.gpkg", "--crs", "EPSG:28992", "-q",
                "--output-path", f"classified={tmp_path / 'w.laz'}")
    assert r.returncode == 0, r.stderr
    after = np.asarray(laspy.read(tmp_path / "w.laz").classification)
    water = before == 9
    assert water.sum() > 100 and np.all(after[water] == 9)  # (before: water became ground or 1)
    wires = before == 14
    assert (after[wires] == 14).mean() > 0.95  # the wires are found, and written as 14
    undecided = ~np.isin(after, (2, 7, 14, 15))  # the crop's synthetic 5 and 26 too: not this run's to change
    expected = np.where(np.isin(before, (2, 14, 15)), 1, before)
    assert np.array_equal(after[undecided], expected[undecided])
    assert {5, 26} <= set(np.unique(after).tolist())


# --- 4. CRS ------------------------------------------------------------------------------------------

def test_a_file_without_crs_is_warned_about_by_default(tmp_path):
    src = write_las(tmp_path / "nocrs.laz", *flat_field())
    r = run_cli("run", "dtm", src, "-o", tmp_path / "d.tif")
    assert r.returncode == 0, r.stderr
    assert "nocrs.laz has no CRS" in r.stderr and "--crs" in r.stderr


@pytest.mark.parametrize("crs", ["EPSG:4978", "EPSG:4979"])
def test_geocentric_or_geographic_crs_is_refused_for_point_algorithms(tmp_path, crs):
    src = write_las(tmp_path / "p.laz", *flat_field())
    r = run_cli("run", "dtm", src, "-o", tmp_path / "d.tif", "--crs", crs)
    assert r.returncode in (1, 2)
    msg = one_line_error(r)
    assert "projected CRS" in msg
    assert files_in(tmp_path) == ["p.laz"]


def _write_dem(path, z, transform, crs, count=1):
    import rasterio

    with rasterio.open(path, "w", driver="GTiff", width=z.shape[-1], height=z.shape[-2], count=count,
                       dtype=z.dtype.name, transform=transform, crs=crs) as ds:
        ds.write(z if count > 1 else z[np.newaxis])


def test_hillshade_of_a_dem_in_degrees_matches_the_same_dem_in_metres(tmp_path):
    import rasterio
    from affine import Affine

    from toolbox_plugins.morph_dtm.plugin import metres_per_degree

    lat0, lon0, n = 60.0, 10.0, 120
    m_lon, m_lat = metres_per_degree(lat0)
    dx_m = 2.0
    rows, cols = np.mgrid[0:n, 0:n]
    z = (30 * np.sin(cols * dx_m / 40.0) + 0.2 * rows * dx_m).astype(np.float32)  # hills, a 0.2 slope north-south
    _write_dem(tmp_path / "deg.tif", z, Affine(dx_m / m_lon, 0, lon0, 0, -dx_m / m_lat, lat0 + n * dx_m / m_lat / 2),
               "EPSG:4326")
    _write_dem(tmp_path / "m.tif", z, Affine(dx_m, 0, 500000, 0, -dx_m, 6650000), "EPSG:32632")
    for name in ("deg", "m"):
        r = run_cli("run", "hillshade", tmp_path / f"{name}.tif", "-o", tmp_path / f"{name}_hs.tif")
        assert r.returncode == 0, r.stderr
    with rasterio.open(tmp_path / "deg_hs.tif") as a, rasterio.open(tmp_path / "m_hs.tif") as b:
        hd, hm = a.read(1).astype(int), b.read(1).astype(int)
    assert hm.std() > 20  # the metric one is a real relief
    assert np.abs(hd - hm)[1:-1, 1:-1].max() <= 2  # (before: a flat image, all about 181)


def test_hillshade_refuses_an_rgb_image_and_an_all_nan_dem(tmp_path):
    from affine import Affine

    t = Affine(1, 0, 0, 0, -1, 100)
    _write_dem(tmp_path / "rgb.tif", np.zeros((3, 50, 50), np.uint8), t, "EPSG:25832", count=3)
    _write_dem(tmp_path / "nan.tif", np.full((50, 50), np.nan, np.float32), t, "EPSG:25832")
    r = run_cli("run", "hillshade", tmp_path / "rgb.tif", "-o", tmp_path / "h1.tif")
    assert r.returncode == 1 and "3 bands" in one_line_error(r)
    r = run_cli("run", "hillshade", tmp_path / "nan.tif", "-o", tmp_path / "h2.tif")
    assert r.returncode == 1 and "every cell is nodata" in one_line_error(r)
    assert files_in(tmp_path) == ["nan.tif", "rgb.tif"]


# --- 5. interrupts and kills --------------------------------------------------------------------------

INTERRUPTING_PLUGIN = """
    import os, signal, threading, time
    from pathlib import Path
    import numpy as np
    import toolbox
    from toolbox import Algorithm, Input, Output, Parameter

    def _run(inputs, params, ctx):
        pc = inputs["points"]
        big = pc.subset(np.repeat(np.arange(len(pc)), 600))  # a LAZ that takes a while to compress
        folder = Path(params["folder"])
        def send_when_the_laz_is_being_written():
            end = time.time() + 120
            while time.time() < end:
                if any(p.suffix == ".laz" and ".partial" in p.name for p in folder.iterdir()):
                    os.kill(os.getpid(), getattr(signal, params["signal"]))
                    return
                time.sleep(0.002)
        threading.Thread(target=send_when_the_laz_is_being_written, daemon=True).start()
        from toolbox.io.rasters import Raster
        from affine import Affine
        dem = Raster(np.zeros((10, 10), np.float32), Affine(1, 0, 0, 0, -1, 10), style="dtm")
        return {"dem": dem, "points": big.with_fields(classification=np.full(len(big), 2, np.uint8))}

    @toolbox.hookimpl
    def toolbox_algorithms():
        return [Algorithm(id="slow-writer", title="t", description="t", run=_run,
                          parameters=[Parameter("folder", str, ".", "d"), Parameter("signal", str, "SIGINT", "d")],
                          inputs=[Input("points", "points", "p")],
                          outputs=[Output("dem", "raster", "a styled raster (sidecar .qml)", style="dtm"),
                                   Output("points", "points", "p")])]
"""


@pytest.mark.parametrize("sig,code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_a_signal_while_the_laz_is_written_exits_with_one_line_and_leaves_nothing(tmp_path, sig, code):
    site = site_with_plugin(tmp_path / "site", "slow_writer_plugin", INTERRUPTING_PLUGIN, "slow-writer")
    src = write_las(tmp_path / "in.laz", *flat_field(5000))
    out = tmp_path / "out"
    out.mkdir()
    r = run_cli("run", "slow-writer", src, "-o", out / "r.tif", "--crs", "EPSG:25832",
                "--set", f"folder={out}", "--set", f"signal={sig}", site=site)
    assert r.returncode == code, r.stderr
    lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and ("interrupted" in lines[0] or "terminated" in lines[0]), r.stderr
    assert files_in(out) == []  # no .tif, no .qml, no temporary file


def test_a_resumed_survey_removes_what_a_killed_run_left(tmp_path):
    x, y, z = flat_field(6000, size=120)
    src = write_las(tmp_path / "s.laz", x, y, z, crs="EPSG:25832")
    out = tmp_path / "survey"
    args = ("run", "dtm", src, "-o", out, "--tile-size-m", "60", "-j", "1", "-q")
    r = run_cli(*args)
    assert r.returncode == 0, r.stderr
    left = [out / "classified" / ".t_0_0.1a2b3c4d.partial.laz", out / ".dtm.1a2b3c4d.partial.tif"]
    for p in left:
        p.write_bytes(b"half a file")  # what a SIGKILL mid-write leaves
    tiles = [p for p in (out / ".tiles").iterdir() if p.is_dir()]
    (tiles[0] / ".dtm.9f8e7d6c.partial.tif").write_bytes(b"half")
    r = run_cli(*args)
    assert r.returncode == 0, r.stderr
    assert not [p for p in out.rglob("*") if ".partial" in p.name]


# --- 6. plugins that exit -------------------------------------------------------------------------------

@pytest.mark.parametrize("body,reason", [("import sys\nsys.exit(3)\n", "sys.exit(3)"),
                                         ("raise KeyboardInterrupt\n", "KeyboardInterrupt")])
def test_a_plugin_that_exits_at_import_is_isolated(tmp_path, body, reason):
    site = site_with_plugin(tmp_path / "site", "exiting_plugin", body)
    r = run_cli("list", site=site)
    assert r.returncode == 0, r.stderr
    assert "BROKEN plugin exiting_plugin" in r.stdout and reason in r.stdout
    assert "dtm" in r.stdout
    r = run_cli("help", "dtm", site=site)
    assert r.returncode == 0


def test_a_base_exception_in_a_hook_is_isolated():
    from importlib.metadata import EntryPoint

    from toolbox.registry import discover

    reg = discover([EntryPoint(name="good", value="plugins_for_tests.fakes:good", group="toolbox.plugins"),
                    EntryPoint(name="exits", value="plugins_for_tests.fakes:exits_in_hook", group="toolbox.plugins")])
    assert "echo-class" in reg.algorithms
    assert [b.name for b in reg.broken] == ["exits"] and "sys.exit(4)" in reg.broken[0].reason


# --- 7. sidecars are outputs -------------------------------------------------------------------------------

def test_a_hand_edited_style_beside_the_output_is_not_replaced(tmp_path):
    src = write_las(tmp_path / "p.laz", *flat_field())
    (tmp_path / "dtm.qml").write_text("<qgis>my own colours</qgis>")
    r = run_cli("run", "dtm", src, "-o", tmp_path / "dtm.tif", "--crs", "EPSG:25832")
    assert r.returncode == 2
    assert "dtm.qml' exists" in one_line_error(r)
    assert (tmp_path / "dtm.qml").read_text() == "<qgis>my own colours</qgis>"
    assert not (tmp_path / "dtm.tif").exists()


# --- 8. memory before allocation ---------------------------------------------------------------------------

def _roof_and_a_far_point(far_m):
    rng = np.random.default_rng(3)
    n = 3000
    x = rng.uniform(0, 20, n)
    y = rng.uniform(0, 12, n)
    z = 10 + 0.5 * np.abs(y - 6)  # a gable roof
    gx, gy = rng.uniform(-10, 30, 2000), rng.uniform(-10, 22, 2000)
    x, y, z = np.r_[x, gx, far_m], np.r_[y, gy, far_m], np.r_[z, rng.normal(0, 0.02, 2000), 0.0]
    cls = np.r_[np.full(n, 6), np.full(2000, 2), 1].astype(np.uint8)
    return x + 300000.0, y + 5000000.0, z, cls


def test_roof_planes_over_a_roof_and_one_far_point_stays_small(tmp_path):
    import tracemalloc

    import toolbox

    x, y, z, cls = _roof_and_a_far_point(15_000.0)
    src = write_las(tmp_path / "r.laz", x, y, z, classification=cls, crs="EPSG:25832")
    tracemalloc.start()
    try:
        rep = toolbox.run("roof-planes", [src], tmp_path / "r.gpkg", source="all")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert rep["stats"]["n_planes"] >= 2
    assert peak < 150 * 2**20, f"peak {peak / 2**20:.0f} MiB"  # before: a 15 km grid, over 1 GiB


@pytest.mark.parametrize("alg,own", [("building-edges", "cell_size_m"), ("powerlines", "cell_size_m")])
def test_a_grid_too_large_names_what_the_algorithm_has(tmp_path, alg, own):
    x, y, z, cls = _roof_and_a_far_point(400_000.0)
    src = write_las(tmp_path / "r.laz", x, y, z, classification=np.ones(len(x), np.uint8), crs="EPSG:25832")
    r = run_cli("run", alg, src, "-o", tmp_path / "o.gpkg")
    assert r.returncode in (1, 2)
    msg = one_line_error(r)
    params = {p["name"] for p in json.loads(run_cli("help", alg, "--json").stdout)["parameters"]}
    named = {w.strip(";,.()'") for w in msg.split() if w.strip(";,.()'").endswith("_m")}
    assert named <= params, f"{msg} names {named - params}, which {alg} does not have"
    assert "--tile-size-m" in msg
    assert files_in(tmp_path) == ["r.laz"]


# --- 9. nothing to find is no error ----------------------------------------------------------------------------

def test_powerlines_on_a_bare_field_writes_empty_layers_and_a_note(tmp_path):
    import pyogrio

    src = write_las(tmp_path / "field.laz", *flat_field(20000, size=150), crs="EPSG:25832")
    r = run_cli("run", "powerlines", src, "-o", tmp_path / "f.gpkg", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert "no wire" in rep["stats"]["note"]
    layers = {n: t for n, t in pyogrio.list_layers(tmp_path / "f.gpkg") if n != "layer_styles"}
    assert layers == {"conductors": "LineString", "conductor_segments": "LineString", "crossings": "Point",
                      "conductors_3d": "LineString Z", "pylons": "Point Z"}
    assert all(v == 0 for v in rep["outputs"]["lines"]["layers"].values())
    assert rep["parameters"]["height_max_m"] is not None


# --- 10. usage errors early, output folders made ------------------------------------------------------------------

@pytest.mark.parametrize("jobs", ["0", "-3"])
def test_worker_counts_below_one_are_refused(tmp_path, jobs):
    src = write_las(tmp_path / "p.laz", *flat_field())
    r = run_cli("run", "dtm", src, src, "-o", tmp_path / "out", "-j", jobs)
    assert r.returncode == 2 and "give 1 or more" in one_line_error(r)
    assert not (tmp_path / "out").exists()


def _pipeline(tmp_path, stages) -> Path:
    p = tmp_path / "p.json"
    p.write_text(json.dumps({"pipeline": stages}))
    return p


@pytest.mark.parametrize("second,expect", [
    ({"algorithm": "hillshade", "inputs": ["@nosuch"]}, "does not run before it"),
    ({"algorithm": "hillshade", "inputs": ["@scene.nosuch"]}, "writes no output 'nosuch'"),
    ({"algorithm": "dtm", "inputs": ["@scene.dtm"]}, "expects a point cloud"),
    ({"algorithm": "hillshade", "inputs": ["@scene.dtm"], "output": "SCENE"}, "both write"),
])
def test_a_pipeline_is_checked_whole_before_its_first_stage_writes(tmp_path, second, expect):
    scene = str(tmp_path / "work" / "scene.laz")
    if second.get("output") == "SCENE":
        second = dict(second, output=str(tmp_path / "work" / "scene_dtm.tif"))
    p = _pipeline(tmp_path, [{"algorithm": "synthetic-scene", "name": "scene", "output": scene,
                              "params": {"kind": "terrain", "width_m": 60, "height_m": 60}}, second])
    r = run_cli("pipeline", p)
    assert r.returncode == 2
    assert expect in one_line_error(r)
    assert not (tmp_path / "work").exists()


def test_batch_and_synthetic_scene_make_their_output_folder(tmp_path):
    a = write_las(tmp_path / "a.laz", *flat_field(), crs="EPSG:25832")
    b = write_las(tmp_path / "b.laz", *flat_field(seed=2), crs="EPSG:25832")
    r = run_cli("run", "dtm", a, b, "-o", tmp_path / "new" / "out", "-j", "2", "-q")
    assert r.returncode == 0, r.stderr
    assert {"a.tif", "b.tif", "a_classified.laz", "b_classified.laz"} <= set(files_in(tmp_path / "new" / "out"))
    r = run_cli("run", "synthetic-scene", "-o", tmp_path / "made" / "s.laz", "--set", "kind=terrain",
                "--set", "width_m=60", "--set", "height_m=60", "-q")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "made" / "s.laz").exists()


def test_a_failed_run_removes_the_folder_it_made(tmp_path):
    src = tmp_path / "few.txt"
    src.write_text("0 0 0\n1 1 1\n")
    r = run_cli("run", "dtm", src, "-o", tmp_path / "new" / "deeper" / "d.tif")
    assert r.returncode == 1
    assert files_in(tmp_path) == ["few.txt"]


# --- 11. the report reproduces the run -------------------------------------------------------------------------------

def test_the_report_gives_the_value_used_for_every_parameter_and_the_crs(tmp_path):
    src = write_las(tmp_path / "p.laz", *flat_field())
    r = run_cli("run", "dtm", src, "-o", tmp_path / "d.tif", "--crs", "EPSG:25832", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert all(v is not None for v in rep["parameters"].values()), rep["parameters"]
    assert rep["parameters_auto"] == ["refine_cell_m"]
    assert rep["parameters"]["refine_cell_m"] == rep["stats"]["refine_cell_m_used"]
    assert rep["crs"] == {"given": "EPSG:25832", "inputs": {"points": "EPSG:25832"}}


def test_auto_parameters_of_roofs_and_scenes_are_reported_as_used(roofs_scene, tmp_path):
    import toolbox

    rep = toolbox.run("roof-planes", [roofs_scene], tmp_path / "r.gpkg")
    assert all(v is not None for v in rep["parameters"].values()), rep["parameters"]
    rep = toolbox.run("synthetic-scene", [], tmp_path / "s.laz", kind="terrain", width_m=60.0)
    assert rep["parameters"]["width_m"] == 60.0 and rep["parameters"]["height_m"] == 300.0
    assert rep["parameters_auto"] == ["height_m", "span_m"]


# --- 12. small things ----------------------------------------------------------------------------------------------------

def test_small_messages(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    r = run_cli("run", "dtm", empty, empty, "-o", tmp_path / "o")
    assert "holds no point cloud files" in one_line_error(r)
    src = write_las(tmp_path / "p.laz", *flat_field(), crs="EPSG:25832")
    r = run_cli("run", "dtm", src, "-o", tmp_path / ("x" * 300 + ".tif"))
    assert r.returncode == 2 and "choose a shorter name" in one_line_error(r)
    head = tmp_path / "head.txt"
    head.write_text("X Y Z\n1 2 3\n4 5 6\n")
    r = run_cli("run", "dtm", head, "-o", tmp_path / "h.tif")
    assert r.returncode == 1 and "looks like a header row" in one_line_error(r)


def test_arch_cuda_without_a_gpu_says_so(tmp_path):
    from toolbox.kernels import _cuda_present

    if _cuda_present():
        pytest.skip("this machine has a CUDA driver")
    src = write_las(tmp_path / "p.laz", *flat_field(), crs="EPSG:25832")
    r = run_cli("run", "dtm", src, "-o", tmp_path / "d.tif", "--arch", "cuda")
    assert r.returncode == 0, r.stderr
    assert "no CUDA driver found here" in r.stderr

"""Survey runs (--tile-size-m): catalog, tiles with buffers, merge, executors, resuming.

The reference is always one run of the same algorithm over the whole (merged) file."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import geopandas as gpd
import numpy as np
import pytest
import rasterio
from shapely.geometry import LineString, Point

import toolbox
from toolbox import DataError, LayerMerge, UsageError
from toolbox.survey import Tile, clip_polyline, crop_raster, cut_layer, merge_layers, run_survey, split_file

from conftest import TOOLBOX

pytestmark = pytest.mark.xdist_group("survey")  # one worker: the runs below use 2 processes each


# session scope: an xdist worker tears a module fixture down whenever its queue runs dry (the
# scene and the powerlines runs were made twice)
@pytest.fixture(scope="session")
def survey(tmp_path_factory):
    """A corridor scene (about 0.6 M points), the same split into 3 x 3 files, and one dtm run
    over the whole file (the reference)."""
    d = tmp_path_factory.mktemp("survey")
    whole = d / "corridor.laz"
    toolbox.run("synthetic-scene", [], whole, kind="corridor", seed=4, density_ppm2=8.0, width_m=420.0, height_m=180.0)
    (d / "split").mkdir()
    files = split_file(whole, d / "split", 3, 3)
    ref = d / "ref"
    ref.mkdir()
    toolbox.run("dtm", whole, ref / "dtm.tif")
    return {"dir": d, "whole": whole, "split": d / "split", "files": files, "dtm": ref / "dtm.tif"}


def _grid_diff(ref_path, path):
    """Max abs difference where both rasters have data, and cells with data in only one."""
    with rasterio.open(ref_path) as a, rasterio.open(path) as b:
        assert a.res == b.res and a.crs == b.crs
        A, B = a.read(1), b.read(1)
        dx = round((b.transform.c - a.transform.c) / a.res[0])
        dy = round((a.transform.f - b.transform.f) / a.res[1])
        # both on one lattice: place B into A's frame
        full = np.full(A.shape, np.nan, np.float32)
        r0, c0 = max(dy, 0), max(dx, 0)
        r1, c1 = min(dy + B.shape[0], A.shape[0]), min(dx + B.shape[1], A.shape[1])
        full[r0:r1, c0:c1] = B[r0 - dy:r1 - dy, c0 - dx:c1 - dx]
        both = np.isfinite(A) & np.isfinite(full)
        only = int((np.isfinite(A) != np.isfinite(full)).sum())
        return float(np.abs(A - full)[both].max()), only, int(both.sum())


# --------------------------------------------------------------------------------------------
# pieces
# --------------------------------------------------------------------------------------------

def test_clip_polyline_interpolates_height_and_marks_cut_ends():
    line = np.array([[-10.0, 5.0, 100.0], [30.0, 5.0, 140.0]])
    [(c, cut0, cut1)] = clip_polyline(line, (0.0, 0.0, 20.0, 10.0))
    assert np.allclose(c, [[0, 5, 110], [20, 5, 130]])
    assert cut0 and cut1
    [(c, cut0, cut1)] = clip_polyline(np.array([[5.0, 5.0], [25.0, 5.0]]), (0.0, 0.0, 20.0, 10.0))
    assert np.allclose(c, [[5, 5], [20, 5]]) and not cut0 and cut1
    # leaving and coming back: two pieces
    zig = np.array([[1.0, 1.0], [1.0, 15.0], [5.0, 15.0], [5.0, 1.0]])
    pieces = clip_polyline(zig, (0.0, 0.0, 10.0, 10.0))
    assert len(pieces) == 2 and pieces[0][2] and pieces[1][1]
    assert clip_polyline(np.array([[30.0, 0.0], [40.0, 0.0]]), (0.0, 0.0, 10.0, 10.0)) == []


def test_each_feature_is_kept_by_exactly_one_tile_and_cut_lines_join_again():
    crs = "EPSG:25832"
    tiles = [Tile(i, j, i * 100.0, j * 100.0, (i + 1) * 100.0, (j + 1) * 100.0) for i in range(2) for j in range(2)]
    pts = gpd.GeoDataFrame({"pylon": [7, 8, 9]}, geometry=[Point(100.0, 50.0), Point(99.999, 100.0), Point(150, 150)], crs=crs)
    owners = [sum(len(cut_layer(pts, t)[lambda g: g.pylon == k]) for t in tiles) for k in (7, 8, 9)]
    assert owners == [1, 1, 1]  # a point on a border belongs to one tile only
    # a conductor across all four tiles, and another one crossing it; each tile saw them (with a
    # buffer) and numbered them its own way
    a = LineString([(10, 20, 50), (190, 180, 68)])
    b = LineString([(10, 180, 60), (190, 40, 60)])
    per_tile = []
    for n, t in enumerate(tiles):
        ids = [5, 2] if n % 2 else [1, 3]
        cond = gpd.GeoDataFrame({"conductor": ids, "n_wires": [1 + n, 2]}, geometry=[a, b], crs=crs)
        x = a.intersection(b)  # inside a tile: a crossing exactly on a tile's corner has no piece of either there
        cross = gpd.GeoDataFrame({"conductors": [f"{ids[0]},{ids[1]}"]}, geometry=[Point(x.x, x.y)], crs=crs)
        per_tile.append((f"t{n}", {"conductors": cut_layer(cond, t), "crossings": cut_layer(cross, t)}))
    rules = {"conductors": LayerMerge(id_field="conductor", combine={"n_wires": "max"}),
             "crossings": LayerMerge(refs={"conductors": "conductors"})}
    out = merge_layers(per_tile, rules, {"conductors": "LineString Z", "crossings": "Point"})
    cond = out["conductors"]
    assert len(cond) == 2 and sorted(cond.conductor) == [0, 1]
    for g, want in zip(cond.geometry, (a, b)):
        c, w = np.asarray(g.coords), np.asarray(want.coords)
        assert np.allclose(c[[0, -1]], w) or np.allclose(c[[-1, 0]], w)  # one feature, end to end, z kept
        assert g.length == pytest.approx(want.length)
    assert set(cond.n_wires) == {4, 2}  # combined over the pieces
    assert len(out["crossings"]) == 1 and out["crossings"].conductors[0] == "0,1"


def test_polygons_wider_than_a_tile_dissolve_and_those_seen_whole_stay_exact():
    """``LayerMerge(dissolve=True)``: a long roof that each tile drew from its own part (their
    borders 0.4 m apart at the core border) is one feature; a building both tiles saw whole is the
    same polygon again; a building wholly inside one core is kept as it is; ids are unique and the
    area is the union's."""
    from shapely.geometry import box

    crs = "EPSG:25832"
    t0, t1 = Tile(0, 0, 0.0, 0.0, 100.0, 100.0), Tile(1, 0, 100.0, 0.0, 200.0, 100.0)
    # each tile's own drawing of it, to the edges of what it read: b's stops 0.4 m short of the core border
    long_a, long_b = box(-60, 10, 160, 30), box(100.4, 10.4, 260, 30.4)
    small = box(90, 60, 110, 75)  # across the border, seen whole by both
    inside = box(150, 80, 160, 90)
    layers = {"a": [long_a, small, inside], "b": [long_b, small, inside]}
    per_tile = []
    for name, t in (("a", t0), ("b", t1)):
        gdf = gpd.GeoDataFrame({"building_id": [1, 2, 3], "area_m2": [g.area for g in layers[name]]},
                               geometry=layers[name], crs=crs)
        per_tile.append((name, {"o": cut_layer(gdf, t, dissolve=True)}))
    rules = {"o": LayerMerge(id_field="building_id", dissolve=True, join_tolerance_m=1.0, combine={"area_m2": "area_m2"})}
    out = merge_layers(per_tile, rules, {"o": "Polygon"})["o"]
    assert len(out) == 3 and sorted(out.building_id) == [0, 1, 2] and set(out.geom_type) == {"Polygon"}
    joined = out.geometry[out.area.idxmax()]
    assert joined.bounds == pytest.approx((0, 10, 200, 30.4))  # each tile's part clipped to its core
    assert joined.contains(box(0, 10, 100, 30).buffer(-1e-6)) and joined.contains(box(100.4, 10.4, 200, 30.4).buffer(-1e-6))
    assert 2000 + 99.6 * 20 < joined.area < 2000 + 99.6 * 20 + 0.4 * 20.4  # the gap closed, nothing else added
    assert sum(g.symmetric_difference(small).area < 1e-9 for g in out.geometry) == 1
    assert sum(g.equals(inside) for g in out.geometry) == 1
    assert sorted(out.area_m2) == sorted(round(g.area, 2) for g in out.geometry)


def test_wires_stacked_over_one_another_join_with_their_own_piece():
    crs = "EPSG:25832"
    t0, t1 = Tile(0, 0, 0.0, 0.0, 100.0, 100.0), Tile(1, 0, 100.0, 0.0, 200.0, 100.0)
    low = LineString([(10, 50, 20.0), (190, 50, 20.0)])
    high = LineString([(10, 50, 20.5), (190, 50.02, 20.5)])
    per_tile = [(n, {"w": cut_layer(gpd.GeoDataFrame({"z": [20.0, 20.5]}, geometry=[low, high], crs=crs), t)})
                for n, t in (("a", t0), ("b", t1))]
    out = merge_layers(per_tile, {}, {"w": "LineString Z"})["w"]
    assert len(out) == 2
    for g in out.geometry:
        z = np.asarray(g.coords)[:, 2]
        assert np.ptp(z) < 1e-9  # never a low piece joined to a high one


def test_cropped_rasters_partition_the_grid(survey, tmp_path):
    from toolbox.io.rasters import read_raster
    from toolbox.survey import merge_rasters
    from toolbox.io.rasters import write_raster

    r = read_raster(survey["dtm"])
    t = r.transform
    parts = []
    size = 70.0  # not a multiple of anything in the scene
    i0, j0 = int(np.floor(t.c / size)), int(np.floor((t.f + r.shape[0] * t.e) / size))
    for i in range(i0, i0 + 8):
        for j in range(j0, j0 + 5):
            part = crop_raster(r, Tile(i, j, i * size, j * size, (i + 1) * size, (j + 1) * size))
            if part is not None:
                p = tmp_path / f"{i}_{j}.tif"
                write_raster(part, p)
                parts.append(p)
    assert sum(rasterio.open(p).width * rasterio.open(p).height for p in parts) == r.shape[0] * r.shape[1]
    from toolbox.registry import registry

    merge_rasters(parts, tmp_path / "m.tif", "dtm", registry().style_dirs, overwrite=False)
    diff, only, both = _grid_diff(survey["dtm"], tmp_path / "m.tif")
    assert diff == 0.0 and only == 0 and both > 0
    with rasterio.open(tmp_path / "m.tif") as ds:
        assert ds.profile["tiled"] and ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"
    assert (tmp_path / "m.qml").exists()  # with its style


# --------------------------------------------------------------------------------------------
# catalog and bad input
# --------------------------------------------------------------------------------------------

def test_files_in_different_crs_are_one_line_error(survey, tmp_path):
    from toolbox.io.points import read_points, write_points

    pc = read_points(survey["files"][0])
    from toolbox.io.points import parse_crs

    pc.crs = parse_crs("EPSG:28992")
    other = tmp_path / "other_crs.laz"
    write_points(pc, other)
    with pytest.raises(DataError, match=r"other_crs\.laz' is in EPSG:28992 but .* is in EPSG:25832; .*reproject"):
        run_survey("dtm", [survey["files"][1], other], tmp_path / "out", tile_size_m=100)
    # --crs says what they all are in
    rep = run_survey("dtm", [survey["files"][1], other], tmp_path / "out2", tile_size_m=200, crs="EPSG:25832",
                     buffer_m=0)
    assert rep["n_failed"] == 0


def test_bad_survey_inputs_fail_before_any_work(survey, tmp_path):
    bad = tmp_path / "bad.laz"
    bad.write_bytes(b"not a las file at all" * 10)
    with pytest.raises(DataError, match=r"bad\.laz' is not a readable LAS/LAZ file"):
        run_survey("dtm", [survey["files"][0], bad], tmp_path / "o1", tile_size_m=100)
    with pytest.raises(UsageError, match="tile-size-m"):
        run_survey("dtm", [survey["files"][0]], tmp_path / "o2", tile_size_m=0)
    with pytest.raises(UsageError, match="one point cloud input"):
        run_survey("hillshade", [survey["files"][0]], tmp_path / "o3", tile_size_m=100)
    with pytest.raises(UsageError, match="a picture of one run"):
        run_survey("dtm", [survey["files"][0]], tmp_path / "o4", tile_size_m=100, outputs={"preview": "p.png"})
    assert not (tmp_path / "o1" / "dtm.tif").exists()


def test_a_truncated_file_fails_its_tiles_only_and_nothing_is_merged(survey, tmp_path):
    files = list(survey["files"])
    cut = tmp_path / "truncated.laz"
    data = Path(files[0]).read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    files[0] = cut
    r = subprocess.run([str(TOOLBOX), "run", "dtm", *map(str, files), "-o", str(tmp_path / "out"), "--tile-size-m", "100",
                        "-j", "2", "-q"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 1, r.stderr
    assert "FAILED tile" in r.stdout and "truncated.laz" in r.stdout and "nothing merged" in r.stdout
    state = json.loads((tmp_path / "out" / "survey.json").read_text())
    statuses = [t["status"] for t in state["tiles"].values()]
    assert "failed" in statuses and "done" in statuses  # the others completed
    assert not (tmp_path / "out" / "dtm.tif").exists()


# --------------------------------------------------------------------------------------------
# the whole against its tiles
# --------------------------------------------------------------------------------------------

def test_dtm_survey_over_split_files_equals_one_run_on_the_whole(survey, tmp_path):
    rep = run_survey("dtm", [survey["split"]], tmp_path / "out", tile_size_m=100, workers=2)
    assert rep["n_failed"] == 0 and rep["n_tiles"] >= 8
    assert rep["survey"]["buffer_m"] == rep["survey"]["buffer_declared_m"] == 60.0  # the algorithm's declaration
    diff, only, both = _grid_diff(survey["dtm"], tmp_path / "out" / "dtm.tif")
    assert diff <= 0.01 and only == 0 and both > 50_000
    # the classified points: one LAZ per tile, buffer points dropped, every point once
    import laspy

    n = sum(len(laspy.read(p).points) for p in (tmp_path / "out" / "classified").glob("*.laz"))
    assert n == len(laspy.read(survey["whole"]).points)
    # the same again: everything is done, nothing runs
    again = run_survey("dtm", [survey["split"]], tmp_path / "out", tile_size_m=100, workers=2)
    assert again["n_skipped"] == again["n_tiles"]
    # other settings in the same folder: refused unless --overwrite
    with pytest.raises(UsageError, match="other settings .*buffer_m differ.*--overwrite"):
        run_survey("dtm", [survey["split"]], tmp_path / "out", tile_size_m=100, buffer_m=10)


def test_dtm_survey_on_a_two_worker_dask_cluster_equals_the_whole(survey, tmp_path):
    distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed (the [cluster] extra)")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        rep = run_survey("dtm", [survey["split"]], tmp_path / "out", tile_size_m=100,
                         scheduler=cluster.scheduler_address)
    assert rep["n_failed"] == 0 and rep["execution"]["scheduler"].startswith("tcp://127.0.0.1")
    assert len(rep["execution"]["worker_peak_rss_mb"]) == 2  # both workers ran tiles
    diff, only, both = _grid_diff(survey["dtm"], tmp_path / "out" / "dtm.tif")
    assert diff <= 0.01 and only == 0


def _write_copc(src: Path, dst: Path, depth: int = 3) -> int:
    """``src`` as a COPC file (an octree of ``depth`` levels, more points deeper, each in the node
    that holds it at its level) through copclib; returns the number of nodes."""
    import copclib
    import laspy

    full = laspy.read(src)
    rec = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))  # the standard fields only
    rec.header.scales, rec.header.offsets = full.header.scales, full.header.offsets
    for name in laspy.PointFormat(6).dimension_names:
        rec[name] = full[name]
    records = rec.points.array
    h = full.header
    mins, maxs = np.asarray(h.mins), np.asarray(h.maxs)
    half = float((maxs - mins).max()) / 2 + 1.0
    scale, offset = copclib.Vector3(*map(float, h.scales)), copclib.Vector3(*map(float, h.offsets))
    wkt = h.parse_crs().to_wkt()
    writer = copclib.FileWriter(str(dst), copclib.CopcConfigWriter(6, scale, offset, wkt))
    info = writer.copc_config.copc_info
    info.center_x, info.center_y, info.center_z = map(float, mins + half)  # the cube from the minimum corner
    info.halfsize, info.spacing = half, 2 * half / 128
    writer.copc_config.las_header.min = copclib.Vector3(*map(float, mins))
    writer.copc_config.las_header.max = copclib.Vector3(*map(float, maxs))
    xyz = np.c_[full.x, full.y, full.z]
    share = 8.0 ** np.arange(depth + 1)
    level = np.random.default_rng(0).choice(depth + 1, size=len(xyz), p=share / share.sum())
    n_nodes = 0
    for d in range(depth + 1):
        ijk = np.clip(np.floor((xyz - mins) / (2 * half / 2 ** d)).astype(np.int64), 0, 2 ** d - 1)
        sel = np.flatnonzero(level == d)
        keys, inv = np.unique(ijk[sel], axis=0, return_inverse=True)
        for k, (i, j, kk) in enumerate(keys):
            raw = np.frombuffer(records[sel[inv.ravel() == k]].tobytes(), np.int8)
            points = copclib.Points.Unpack(copclib.VectorChar(raw), 6, 0, scale, offset)
            writer.AddNode(copclib.VoxelKey(d, int(i), int(j), int(kk)), points)
            n_nodes += 1
    writer.Close()
    return n_nodes


def test_copc_survey_reads_each_tile_by_bounds_and_equals_the_whole(survey, tmp_path):
    """A COPC file in a survey: each tile decodes only the octree nodes that reach it and its
    buffer, and the DTM is the one of a run over the whole LAZ file."""
    pytest.importorskip("copclib", reason="copclib (test extra) writes the COPC file; laspy writes none")
    import laspy

    copc = tmp_path / "corridor.copc.laz"
    assert _write_copc(survey["whole"], copc) > 9
    with laspy.CopcReader.open(copc) as r:
        n = len(r.query())  # what the octree holds (copclib drops a point lying on a node's face now and then)
    assert n >= len(laspy.read(survey["whole"]).points) - 2
    rep = run_survey("dtm", [copc], tmp_path / "out", tile_size_m=100, workers=2)
    assert rep["n_failed"] == 0 and rep["survey_values_from"] == "the tiles' summaries"  # no split pass to take them from
    tiles = json.loads((tmp_path / "out" / "survey.json").read_text())["tiles"].values()
    decoded = [t["stats"]["n_decoded_points"] for t in tiles if t["status"] == "done"]
    assert max(decoded) < 0.8 * n  # no tile decodes the whole file
    assert sum(t["stats"]["n_core_points"] for t in tiles if t["status"] == "done") == n
    diff, only, both = _grid_diff(survey["dtm"], tmp_path / "out" / "dtm.tif")
    assert diff <= 0.01 and only == 0 and both > 50_000


def _children(pid: int) -> dict[int, bytes]:
    kids = {}
    for p in Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            stat = (p / "stat").read_text()
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                kids[int(p.name)] = (p / "cmdline").read_bytes()
        except (OSError, ValueError, IndexError):
            continue
    return kids


def _workers(pid: int) -> list[int]:
    """The pool's worker processes of a run: the children of its fork server."""
    servers = [k for k, cmd in _children(pid).items() if b"forkserver" in cmd]
    return [w for s in servers for w in _children(s)]


def _wait_for_done_tiles(manifest: Path, n: int, proc, timeout: float = 300.0) -> None:
    t0 = time.time()
    while time.time() - t0 < timeout:
        assert proc.poll() is None, "the run ended before the test could interrupt it"
        try:
            state = json.loads(manifest.read_text())
            if sum(t["status"] == "done" for t in state["tiles"].values()) >= n:
                return
        except (OSError, ValueError):
            pass
        time.sleep(0.05)
    raise AssertionError("no tile finished in time")


@pytest.mark.skipif(not Path("/proc").exists(), reason="finds the worker processes through /proc (Linux)")
def test_killed_worker_is_retried_and_killed_run_resumes_with_the_same_outputs(survey, tmp_path):
    cmd = [str(TOOLBOX), "run", "dtm", str(survey["split"]), "--tile-size-m", "50", "-j", "2", "-q"]
    # a worker killed mid-run: its tile is retried, the run completes
    out1 = tmp_path / "killed_worker"
    proc = subprocess.Popen([*cmd, "-o", str(out1)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_done_tiles(out1 / "survey.json", 1, proc)
    os.kill(_workers(proc.pid)[0], signal.SIGKILL)
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr
    assert "worker died; retrying" in stderr
    state = json.loads((out1 / "survey.json").read_text())
    assert max(t["attempts"] for t in state["tiles"].values()) >= 1 and state["merged"]
    diff, only, _ = _grid_diff(survey["dtm"], out1 / "dtm.tif")
    assert diff <= 0.01 and only == 0
    # the whole run killed half-way (driver and workers), then run again: it goes on and ends the same
    out2 = tmp_path / "killed_run"
    proc = subprocess.Popen([*cmd, "-o", str(out2)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    _wait_for_done_tiles(out2 / "survey.json", 3, proc)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out2 / "dtm.tif").exists()
    r = subprocess.run([*cmd, "-o", str(out2), "--json"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["n_skipped"] >= 3 and rep["n_done"] == rep["n_tiles"]
    with rasterio.open(out1 / "dtm.tif") as a, rasterio.open(out2 / "dtm.tif") as b:
        assert np.array_equal(a.read(1), b.read(1), equal_nan=True)


@pytest.fixture(scope="session")
def powerlines_runs(survey, tmp_path_factory):
    """powerlines over the whole file, and as a survey of its 3 x 3 files in 100 m tiles."""
    d = tmp_path_factory.mktemp("powerlines")
    toolbox.run("powerlines", survey["whole"], d / "whole.gpkg")
    rep = run_survey("powerlines", [survey["split"]], d / "local", tile_size_m=100, workers=2)
    return {"whole": d / "whole.gpkg", "local": d / "local" / "lines.gpkg", "report": rep}


def test_powerlines_survey_merges_its_layers_by_their_declarations(powerlines_runs):
    """The merge as the plugin declares it: every layer there, conductors renumbered over the
    survey, crossings referring to them, nothing kept twice where tiles overlap."""
    rep = powerlines_runs["report"]
    # the declared buffer: a Hough tile (100 m) and the density window around its points (205 m)
    assert rep["n_failed"] == 0 and rep["survey"]["buffer_m"] == 305.0
    got = powerlines_runs["local"]
    import pyogrio

    assert {n for n, _ in pyogrio.list_layers(got)} >= {"conductors", "conductor_segments", "crossings",
                                                         "conductors_3d", "pylons", "layer_styles"}
    cond = gpd.read_file(got, layer="conductors")
    assert len(cond) >= 5 and sorted(cond.conductor) == list(range(len(cond)))
    cross = gpd.read_file(got, layer="crossings")
    assert len(cross) >= 5
    ids = {int(i) for s in cross.conductors for i in s.split(",")}
    assert ids <= set(cond.conductor)
    xy = np.c_[cross.geometry.x, cross.geometry.y]
    assert np.min(np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) + np.eye(len(xy)) * 1e9) > 0.05
    py = gpd.read_file(got, layer="pylons")
    assert sorted(py.pylon) == list(range(len(py)))


def _same_conductors_and_crossings(ref, got):
    """Every conductor of ``ref`` in ``got`` with both ends within 0.05 m and none more; every
    crossing once, within 0.05 m."""
    a, b = gpd.read_file(ref, layer="conductors"), gpd.read_file(got, layer="conductors")
    assert len(a) == len(b) >= 5
    ends_b = [np.asarray(h.coords)[[0, -1], :2] for h in b.geometry]
    matched = set()
    for g in a.geometry:
        e = np.asarray(g.coords)[[0, -1], :2]
        errs = [min(np.hypot(*(e - f).T).max(), np.hypot(*(e - f[::-1]).T).max()) for f in ends_b]
        j = int(np.argmin(errs))
        assert errs[j] <= 0.05, (g, errs[j])
        matched.add(j)
    assert len(matched) == len(b)
    xa, xb = gpd.read_file(ref, layer="crossings"), gpd.read_file(got, layer="crossings")
    assert len(xa) == len(xb) >= 5
    pa, pb = np.c_[xa.geometry.x, xa.geometry.y], np.c_[xb.geometry.x, xb.geometry.y]
    d = np.hypot(*(pa[:, None] - pb[None]).transpose(2, 0, 1))
    assert (d.min(axis=1) <= 0.05).all() and len(set(d.argmin(axis=1))) == len(pa)


def test_powerlines_survey_gives_the_conductors_of_one_run_on_the_whole(powerlines_runs):
    """Hough tiles on a fixed grid, the surface density measured on fixed cells around each point,
    the tower search on fixed cells: a tile decides as the whole run does."""
    _same_conductors_and_crossings(powerlines_runs["whole"], powerlines_runs["local"])

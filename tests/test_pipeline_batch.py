"""Pipelines (data only, stages chained) and batches (a bad file never stops the others)."""

import json
import os
import sys

import laspy
import numpy as np
import pytest

from importlib.metadata import EntryPoint

from toolbox.registry import discover
from toolbox import runner
from toolbox.runner import run_algorithm


def test_pipeline_chains_stages_by_reference(cli, example_plugin_site, tmp_path):
    p = tmp_path / "p.yml"
    p.write_text(f"""
pipeline:
  - algorithm: synthetic-scene
    name: scene
    output: {tmp_path}/scene.laz
    params: {{kind: roofs, seed: 4, density_ppm2: 2}}
  - algorithm: point-density
    inputs: ["@scene"]
    output: {tmp_path}/density.tif
    params: {{cell_size_m: 4}}
  - algorithm: point-density
    inputs: ["@scene.points"]
    params: {{returns: first}}
""")
    r = cli("pipeline", p, "--json", site=example_plugin_site)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert [s["algorithm"] for s in rep["stages"]] == ["synthetic-scene", "point-density", "point-density"]
    assert rep["stages"][1]["inputs"]["points"] == str(tmp_path / "scene.laz")
    assert rep["stages"][2]["outputs"]["density"]["path"] is None  # no output given: temporary
    assert (tmp_path / "density.tif").exists()
    assert sorted(x.name for x in tmp_path.iterdir()) == sorted(
        ["p.yml", "scene.laz", "scene_truth.gpkg", "scene_truth.json", "scene_dtm.tif", "scene_dtm.qml",
         "density.tif", "density.qml"])


def test_pipeline_default_input_is_previous_output_and_json_works(cli, example_plugin_site, tmp_path):
    p = tmp_path / "p.json"
    p.write_text(json.dumps([
        {"algorithm": "synthetic-scene", "output": str(tmp_path / "s.laz"), "params": {"kind": "roofs", "density_ppm2": 1}},
        {"algorithm": "point-density", "output": str(tmp_path / "d.tif")},
    ]))
    r = cli("pipeline", p, site=example_plugin_site)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "d.tif").exists()


def test_pipeline_file_is_data_only(cli, tmp_path):
    p = tmp_path / "evil.yml"
    p.write_text(f"""
pipeline:
  - algorithm: !!python/object/apply:os.system ["touch {tmp_path}/pwned"]
""")
    r = cli("pipeline", p)
    assert r.returncode == 2
    assert "not valid YAML/JSON" in r.stderr
    assert not (tmp_path / "pwned").exists()


def test_pipeline_is_validated_before_the_first_stage_runs(cli, tmp_path):
    p = tmp_path / "p.yml"
    p.write_text(f"""
pipeline:
  - algorithm: synthetic-scene
    output: {tmp_path}/s.laz
  - algorithm: synthetic-scene
    output: {tmp_path}/t.laz
    params: {{densty_ppm2: 3}}
""")
    r = cli("pipeline", p)
    assert r.returncode == 2
    assert "stage 2" in r.stderr and "did you mean 'density_ppm2'" in r.stderr
    assert not (tmp_path / "s.laz").exists()
    p.write_text("pipeline:\n  - algorithm: synthetic-scene\n    command: rm -rf /\n")
    r = cli("pipeline", p)
    assert r.returncode == 2 and "unknown key(s) ['command']" in r.stderr


def test_batch_runs_every_file_and_reports_the_bad_one(cli, example_plugin_site, small_scene, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    las = laspy.read(small_scene)
    for i in range(3):
        las.write(src / f"tile{i}.laz")
    (src / "tile_bad.laz").write_bytes(b"garbage" * 100)
    out = tmp_path / "out"
    out.mkdir()
    r = cli("run", "point-density", src, "-o", out, "--json", "--set", "cell_size_m=10", site=example_plugin_site)
    assert r.returncode == 1  # one failed
    rep = json.loads(r.stdout)
    assert rep["n_files"] == 4 and rep["n_done"] == 3 and rep["n_failed"] == 1
    assert rep["failed"][0]["input"].endswith("tile_bad.laz")
    assert "not a LAS/LAZ file" in rep["failed"][0]["error"]
    assert sorted(p.name for p in out.glob("*.tif")) == ["tile0.tif", "tile1.tif", "tile2.tif"]
    assert not list(out.glob("tile_bad*"))
    r = cli("run", "point-density", src / "tile0.laz", src / "tile_bad.laz", "-o", out, "--overwrite", site=example_plugin_site)
    assert r.returncode == 1
    assert "1 of 2 files done, 1 failed" in r.stdout and "FAILED" in r.stdout


def test_algorithm_failing_midway_leaves_no_output(small_scene, tmp_path):
    reg = discover([EntryPoint(name="good", value="plugins_for_tests.fakes:good", group="toolbox.plugins")])
    out = tmp_path / "x.laz"
    try:
        run_algorithm("fail-midway", [str(small_scene)], out, {}, reg=reg)
    except RuntimeError as e:
        assert "boom" in str(e)
    assert list(tmp_path.iterdir()) == []
    rep = run_algorithm("echo-class", [str(small_scene)], out, {"value": 7}, reg=reg)
    assert rep["outputs"]["points"]["classes"] == {7: rep["outputs"]["points"]["n_points"]}


def test_an_output_emitted_early_is_removed_when_the_run_fails(small_scene, tmp_path):
    reg = discover([EntryPoint(name="emitting", value="plugins_for_tests.fakes:emitting", group="toolbox.plugins")])
    out = tmp_path / "x.laz"
    with pytest.raises(RuntimeError, match="boom after emitting"):
        run_algorithm("emit-then-fail", [str(small_scene)], out, {}, reg=reg)
    assert list(tmp_path.iterdir()) == []
    rep = run_algorithm("emit-then-finish", [str(small_scene)], out, {"value": 9}, reg=reg)
    assert rep["outputs"]["points"]["classes"] == {9: rep["outputs"]["points"]["n_points"]}
    back = laspy.read(out)
    src = laspy.read(small_scene)
    assert np.all(back.classification == 9)
    assert np.array_equal(back.intensity, src.intensity) and np.array_equal(back.gps_time, src.gps_time)


def test_a_raster_emitted_early_is_written_in_the_background_and_removed_when_the_run_fails(small_scene, tmp_path):
    import threading

    reg = discover([EntryPoint(name="emitting", value="plugins_for_tests.fakes:emitting", group="toolbox.plugins")])
    out = tmp_path / "x.laz"
    with pytest.raises(RuntimeError, match="boom after emitting a raster"):
        run_algorithm("emit-raster", [str(small_scene)], out, {"mode": "exact"}, reg=reg)
    assert list(tmp_path.iterdir()) == []
    seen = []
    real = runner.write_output

    def spy(kind, *args, **kw):
        seen.append((kind, threading.current_thread() is threading.main_thread()))
        return real(kind, *args, **kw)

    runner.write_output = spy
    try:
        rep = run_algorithm("emit-raster", [str(small_scene)], out, {}, reg=reg)
    finally:
        runner.write_output = real
    # the emitted raster went to a writer thread; the points (lazrs holds the GIL) were written here
    assert sorted(seen) == [("points", True), ("raster", False)]
    assert rep["outputs"]["grid"]["width"] == 8 and (tmp_path / "x_grid.tif").exists()
    assert np.all(laspy.read(out).classification == 4)


def test_python_api_mirrors_the_cli(tmp_path):
    import toolbox

    rep = toolbox.run("synthetic-scene", output=tmp_path / "s.laz", kind="roofs", density_ppm2=1.0, seed=9)
    assert rep["parameters"]["seed"] == 9 and rep["parameters"]["noise_m"] == 0.03
    pc = laspy.read(tmp_path / "s.laz")
    assert len(pc.points) == rep["outputs"]["points"]["n_points"]
    assert np.all(np.isin(np.unique(pc.classification), [2, 3, 4, 5, 6, 7, 9, 17]))


def test_taichi_is_initialised_lazily_in_one_place():
    import subprocess
    import sys

    code = ("import toolbox.kernels as k; assert k.arch_used() is None; "
            "import sys; assert 'taichi' not in sys.modules; ti = k.taichi(); "
            "assert k.taichi() is ti; print('ARCH', k.arch_used())")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={"TOOLBOX_ARCH": "cpu"})  # no HOME either: a bare service environment
    assert r.returncode == 0, r.stderr
    assert "ARCH x64" in r.stdout
    r = subprocess.run([sys.executable, "-c", "import toolbox.kernels as k; k.taichi()"], capture_output=True, text=True,
                       env=dict(os.environ, TOOLBOX_ARCH="tpu"))
    assert r.returncode != 0 and "TOOLBOX_ARCH='tpu' is not known" in r.stderr


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the allocator settings are glibc's (Linux)")
def test_allocator_is_tuned_once_per_run_process_unless_the_user_says_otherwise():
    """mallopt goes through on glibc; TOOLBOX_MALLOC_TUNE=0 or the user's own MALLOC_*_ tunables
    leave the allocator alone."""
    import subprocess

    code = "import toolbox.memory as m; print('TUNED', m.tune_allocator(), m.tune_allocator())"
    base = {k: v for k, v in os.environ.items() if not (k.startswith("MALLOC_") and k.endswith("_"))}
    for extra, want in (({}, "TUNED True True"), ({"TOOLBOX_MALLOC_TUNE": "0"}, "TUNED False False"),
                        ({"MALLOC_ARENA_MAX": "2"}, "TUNED True True"),
                        ({"MALLOC_TRIM_THRESHOLD_": "1000000"}, "TUNED False False"),
                        ({"GLIBC_TUNABLES": "glibc.malloc.mmap_threshold=65536"}, "TUNED False False")):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**base, **extra})
        assert r.returncode == 0, r.stderr
        assert want in r.stdout, (extra, r.stdout)


def test_taichi_start_up_shortcut_gives_taichi_the_same_answers():
    """taichi's decorators read the decorating frame's source line; toolbox serves it from
    linecache (quicker than inspect's module scan). Same line as inspect gives, inspect itself
    restored, and a kernel defined in a class is still recognised as one."""
    import inspect

    from toolbox import kernels as tk

    ti = tk.taichi()
    assert inspect.getframeinfo.__module__ == "inspect"  # the import-time patch did not leak
    frame = sys._getframe()
    assert tk._frame_line(frame) == inspect.getframeinfo(frame)[3][0]

    @ti.data_oriented
    class Filler:
        def __init__(self):
            self.f = ti.field(ti.i32, 4)

        @ti.kernel
        def fill(self, v: ti.i32):
            for i in self.f:
                self.f[i] = v

    @ti.kernel
    def plain(a: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for i in a:
            a[i] = i

    f = Filler()
    f.fill(3)
    assert f.f.to_numpy().tolist() == [3, 3, 3, 3]
    arr = np.zeros(3, np.int32)
    plain(arr)
    assert arr.tolist() == [0, 1, 2]

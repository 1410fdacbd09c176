"""Bad input through the command line: one line naming the thing and the fix, exit code 2 for
usage errors and 1 for data errors, and no output file left behind."""

import json
import shutil

import pytest


def one_line_error(r):
    lines = [l for l in r.stderr.strip().splitlines() if l.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("toolbox: error: ")
    return lines[0]


def assert_empty(folder):
    assert [p.name for p in folder.iterdir()] == []


def test_unknown_algorithm_suggests_nearest(cli, tmp_path):
    r = cli("run", "synthetic-scen", "-o", tmp_path / "x.laz")
    assert r.returncode == 2
    assert "did you mean 'synthetic-scene'" in one_line_error(r)


def test_unknown_parameter_lists_the_valid_ones(cli, tmp_path):
    r = cli("run", "synthetic-scene", "-o", tmp_path / "x.laz", "--set", "sed=3")
    assert r.returncode == 2
    msg = one_line_error(r)
    assert "unknown parameter 'sed'" in msg and "did you mean 'seed'" in msg and "density_ppm2" in msg
    assert_empty(tmp_path)


def test_value_out_of_range(cli, tmp_path):
    r = cli("run", "synthetic-scene", "-o", tmp_path / "x.laz", "--set", "density_ppm2=-3")
    assert r.returncode == 2
    assert "density_ppm2: -3.0 is out of range; allowed (0, 400]" in one_line_error(r)
    assert_empty(tmp_path)


def test_absurd_size_is_refused_before_work(cli, tmp_path):
    r = cli("run", "synthetic-scene", "-o", tmp_path / "x.laz", "--set", "width_m=20000", "--set", "height_m=20000")
    assert r.returncode == 2
    assert "million points" in one_line_error(r)
    assert_empty(tmp_path)


def test_missing_input_file(cli, example_plugin_site, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    r = cli("run", "point-density", tmp_path / "nope.laz", "-o", out / "d.tif", site=example_plugin_site)
    assert r.returncode == 1
    assert "nope.laz' does not exist" in one_line_error(r)
    assert_empty(out)


def test_file_that_is_not_las(cli, example_plugin_site, tmp_path):
    bad = tmp_path / "text.las"
    bad.write_text("this is not a LAS file\n" * 50)
    out = tmp_path / "out"
    out.mkdir()
    r = cli("run", "point-density", bad, "-o", out / "d.tif", site=example_plugin_site)
    assert r.returncode == 1
    assert "is not a LAS/LAZ file" in one_line_error(r)
    assert_empty(out)


@pytest.mark.parametrize("fraction", [0.5, 0.97])
def test_truncated_laz(cli, example_plugin_site, small_scene, tmp_path, fraction):
    data = small_scene.read_bytes()
    bad = tmp_path / "cut.laz"
    bad.write_bytes(data[: int(len(data) * fraction)])
    out = tmp_path / "out"
    out.mkdir()
    r = cli("run", "point-density", bad, "-o", out / "d.tif", site=example_plugin_site)
    assert r.returncode == 1
    msg = one_line_error(r)
    assert "cut.laz" in msg and ("truncated" in msg or "corrupt" in msg)
    assert_empty(out)


def test_truncated_las(cli, example_plugin_site, small_scene, tmp_path):
    import laspy

    las = laspy.read(small_scene)
    full = tmp_path / "full.las"
    las.write(full)
    data = full.read_bytes()
    bad = tmp_path / "cut.las"
    bad.write_bytes(data[: len(data) - 1000])
    out = tmp_path / "out"
    out.mkdir()
    r = cli("run", "point-density", bad, "-o", out / "d.tif", site=example_plugin_site)
    assert r.returncode == 1
    assert "truncated" in one_line_error(r)
    assert_empty(out)


def test_input_of_the_wrong_kind(cli, example_plugin_site, tmp_path):
    tif = tmp_path / "dem.tif"
    tif.write_bytes(b"II*\x00")
    r = cli("run", "point-density", tif, "-o", tmp_path / "d.tif", site=example_plugin_site)
    assert r.returncode == 2
    assert "is a raster, but point-density expects a point cloud" in one_line_error(r)


def test_output_of_the_wrong_kind(cli, example_plugin_site, small_scene, tmp_path):
    r = cli("run", "point-density", small_scene, "-o", tmp_path / "d.laz", site=example_plugin_site)
    assert r.returncode == 2
    assert "writes raster here, so use .tif" in one_line_error(r)


def test_unwritable_output(cli, example_plugin_site, small_scene, tmp_path):
    # a missing output folder is made for the run (#75)
    r = cli("run", "point-density", small_scene, "-o", tmp_path / "no" / "such" / "dir" / "d.tif", site=example_plugin_site)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "no" / "such" / "dir" / "d.tif").exists()
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    r = cli("run", "point-density", small_scene, "-o", blocker / "d.tif", site=example_plugin_site)
    assert r.returncode == 1
    assert "is a file, not a folder" in one_line_error(r)
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        import os

        if os.access(ro, os.W_OK):
            pytest.skip("running as a user who can write anywhere (root)")
        r = cli("run", "point-density", small_scene, "-o", ro / "d.tif", site=example_plugin_site)
        assert r.returncode == 1
        assert "not writable" in one_line_error(r)
    finally:
        ro.chmod(0o700)


def test_existing_output_needs_overwrite(cli, example_plugin_site, small_scene, tmp_path):
    out = tmp_path / "d.tif"
    out.write_bytes(b"keep me")
    r = cli("run", "point-density", small_scene, "-o", out, site=example_plugin_site)
    assert r.returncode == 2
    assert "--overwrite" in one_line_error(r)
    assert out.read_bytes() == b"keep me"
    r = cli("run", "point-density", small_scene, "-o", out, "--overwrite", site=example_plugin_site)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:2] == b"II"


def test_empty_cloud_is_a_data_error(cli, example_plugin_site, tmp_path):
    empty = tmp_path / "empty.txt"
    empty.write_text("# no points\n")
    r = cli("run", "point-density", empty, "-o", tmp_path / "d.tif", site=example_plugin_site)
    assert r.returncode == 1
    assert "has 0 points" in one_line_error(r)
    assert not (tmp_path / "d.tif").exists()


def test_bad_crs(cli, example_plugin_site, small_scene, tmp_path):
    r = cli("run", "point-density", small_scene, "-o", tmp_path / "d.tif", "--crs", "EPSG:999999", site=example_plugin_site)
    assert r.returncode == 2
    assert "is not a CRS" in one_line_error(r)
    r = cli("run", "point-density", small_scene, "-o", tmp_path / "d.tif", "--crs", "EPSG:4326", site=example_plugin_site)
    assert r.returncode == 1
    assert "geographic" in one_line_error(r)


def test_json_report_has_every_parameter_and_timings(cli, example_plugin_site, small_scene, tmp_path):
    r = cli("run", "point-density", small_scene, "-o", tmp_path / "d.tif", "--json", site=example_plugin_site)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)  # nothing else on stdout (no taichi banner, no progress)
    assert rep["parameters"] == {"cell_size_m": 1.0, "returns": "all"}
    assert set(rep["timings_s"]) == {"read", "compute", "write", "total"}
    assert rep["outputs"]["density"]["path"] == str(tmp_path / "d.tif")
    assert rep["outputs"]["density"]["width"] > 0


def test_help_lists_parameters_with_units_and_ranges(cli):
    r = cli("help", "synthetic-scene")
    assert r.returncode == 0
    assert "density_ppm2 (float [pts/m2]) default 12.0; allowed (0, 400]" in r.stdout
    assert "kind (str) default corridor; allowed one of corridor, terrain, roofs" in r.stdout
    r = cli("help", "synthetic-scene", "--json")
    d = json.loads(r.stdout)
    assert {p["name"] for p in d["parameters"]} >= {"kind", "seed", "density_ppm2"}


def test_broken_third_party_plugin_shows_in_list_and_host_survives(cli, example_plugin_site, tmp_path):
    site = tmp_path / "site"
    shutil.copytree(example_plugin_site, site)
    # break the installed plugin: its module now fails to import
    (site / "toolbox_density" / "plugin.py").write_text("import numpy\nraise ImportError('simulated broken release')\n")
    r = cli("list", site=site)
    assert r.returncode == 0
    assert "BROKEN plugin density (toolbox-density 1.0.0): failed to load: ImportError: simulated broken release" in r.stdout
    assert "synthetic-scene" in r.stdout

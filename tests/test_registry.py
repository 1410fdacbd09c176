"""Discovery through entry points, broken-plugin isolation, id clashes."""

from importlib.metadata import EntryPoint

import pytest

import toolbox
from toolbox.errors import PluginError, UsageError
from toolbox.registry import discover


def ep(name, value):
    return EntryPoint(name=name, value=value, group="toolbox.plugins")


def test_builtin_plugins_come_through_entry_points():
    from importlib.metadata import entry_points

    names = {e.name: e.value for e in entry_points(group="toolbox.plugins")}
    assert names.get("synthetic_scene") == "toolbox_plugins.synthetic_scene.plugin"
    algs = toolbox.algorithms()
    assert "synthetic-scene" in algs
    assert algs["synthetic-scene"].plugin == "synthetic_scene"
    assert algs["synthetic-scene"].distribution == "lidar-toolbox"


def test_broken_plugins_are_isolated_and_reported():
    reg = discover([
        ep("good", "plugins_for_tests.fakes:good"),
        ep("missing_dep", "plugins_for_tests.import_error"),
        ep("raises", "plugins_for_tests.fakes:raises"),
        ep("wrong_type", "plugins_for_tests.fakes:wrong_type"),
        ep("nonexistent", "no_such_package.plugin"),
    ])
    assert set(reg.algorithms) == {"echo-class", "fail-midway"}
    broken = {b.name: b.reason for b in reg.broken}
    assert set(broken) == {"missing_dep", "raises", "wrong_type", "nonexistent"}
    assert "a_module_that_does_not_exist" in broken["missing_dep"]
    assert "broken on purpose" in broken["raises"]
    assert "not toolbox.Algorithm" in broken["wrong_type"]


def test_two_plugins_claiming_one_id_is_an_error_naming_both():
    reg = discover([ep("good", "plugins_for_tests.fakes:good"), ep("clash", "plugins_for_tests.fakes:clash")])
    assert "fail-midway" in reg.algorithms  # the rest of the plugin still works
    with pytest.raises(PluginError) as e:
        reg.get("echo-class")
    assert "good" in str(e.value) and "clash" in str(e.value)


def test_unknown_algorithm_suggests_the_nearest():
    reg = discover([ep("good", "plugins_for_tests.fakes:good")])
    with pytest.raises(UsageError, match="did you mean 'echo-class'"):
        reg.get("echo-clas")


def test_example_plugin_installed_for_real_runs_through_the_cli(example_plugin_site, cli, small_scene, tmp_path):
    # installed by pip as a wheel: entry point metadata in a .dist-info folder
    assert list(example_plugin_site.glob("toolbox_density-1.0.0.dist-info/entry_points.txt"))
    r = cli("list", site=example_plugin_site)
    assert r.returncode == 0, r.stderr
    line = next(l for l in r.stdout.splitlines() if l.startswith("point-density"))
    assert "toolbox-density 1.0.0" in line
    out = tmp_path / "density.tif"
    r = cli("run", "point-density", small_scene, "-o", out, "--set", "cell_size_m=5", "--json", site=example_plugin_site)
    assert r.returncode == 0, r.stderr
    import json

    import numpy as np
    import rasterio

    rep = json.loads(r.stdout)
    assert rep["distribution"] == "toolbox-density"
    assert rep["parameters"] == {"cell_size_m": 5.0, "returns": "all"}
    with rasterio.open(out) as ds:
        total = ds.read(1).sum() * 25.0
    import laspy

    assert total == pytest.approx(laspy.read(small_scene).header.point_count, rel=1e-6)
    # the plugin's own style came through its toolbox_style_dirs hook
    assert "Point density" in out.with_suffix(".qml").read_text()
    assert np.isfinite(rep["stats"]["mean_density_ppm2"])


def test_list_is_fast_and_does_not_import_heavy_modules():
    import subprocess
    import sys

    code = ("import sys, toolbox.cli as c; c.main(['list']); "
            "heavy=[m for m in ('taichi','rasterio','geopandas','laspy') if m in sys.modules]; "
            "print('HEAVY', heavy)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "HEAVY []" in r.stdout

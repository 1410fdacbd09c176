"""The QGIS plugin (#78): installed into a temporary profile, listed, described and run through
QGIS's own ``qgis_process`` (headless), against the command line's outputs."""

from __future__ import annotations

import json
from pathlib import Path
import os
import shutil
import subprocess

import pytest

from conftest import TOOLBOX, shared_file

QGIS = shutil.which("qgis_process.bin")  # Debian's qgis_process wrapper passes an option 3.22 rejects
pytestmark = [pytest.mark.skipif(QGIS is None, reason="QGIS is not installed (apt-get install qgis python3-qgis)"),
              pytest.mark.xdist_group("qgis")]


@pytest.fixture(scope="module")
def qgis_env(tmp_path_factory):
    cfg = tmp_path_factory.mktemp("qgis_config")
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "QGIS_CUSTOM_CONFIG_PATH": str(cfg),
           "XDG_RUNTIME_DIR": str(cfg)}
    r = subprocess.run([str(TOOLBOX), "qgis", "install", "--profile-dir", str(cfg / "profiles" / "default")],
                       capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([QGIS, "plugins"], capture_output=True, text=True, env=env)
    assert "* lidar_toolbox" in r.stdout, r.stdout + r.stderr  # installed and enabled (the star)
    return env


@pytest.fixture(scope="module")
def powerlines_cli(tmp_path_factory):
    """One command-line powerlines run on Oakland part2_ag (the reference of two tests)."""
    src = shared_file("oakland_mls/oakland_part2_ag.laz")
    out = tmp_path_factory.mktemp("pl_cli") / "c.gpkg"
    c = subprocess.run([str(TOOLBOX), "run", "powerlines", str(src), "-o", str(out), "--quiet"], capture_output=True,
                       text=True)
    assert c.returncode == 0, c.stderr
    return src, out


def _qgis(env, *args, timeout=300):
    return subprocess.run([QGIS, *args], capture_output=True, text=True, env=env, timeout=timeout)


def test_every_toolbox_algorithm_is_listed_in_qgis(qgis_env):
    r = _qgis(qgis_env, "list")
    assert r.returncode == 0, r.stderr
    ours = json.loads(subprocess.run([str(TOOLBOX), "list", "--json"], capture_output=True, text=True).stdout)
    for a in ours["algorithms"]:
        assert f"lidartoolbox:{a['id'].replace('-', '')}\t{a['title']}" in r.stdout


def test_the_help_shows_the_parameters_with_units_and_ranges(qgis_env):
    r = _qgis(qgis_env, "help", "lidartoolbox:dtm")
    assert r.returncode == 0, r.stderr
    assert "RESOLUTION_M [m] (0.05 to 1000.0): DTM cell size" in r.stdout
    assert "REFINE_CELL_M [m] (0.1 to 50.0)" in r.stdout and "empty: auto" in r.stdout
    assert "Mongus" in r.stdout  # the method's reference
    for name in ("INPUT", "OUTPUT", "OUTPUT_CLASSIFIED", "GROUND"):
        assert f"\n{name}: " in r.stdout


def test_dtm_through_qgis_writes_what_the_command_line_writes(qgis_env, tmp_path):
    src = shared_file("lidR/Topography.laz")
    r = _qgis(qgis_env, "run", "lidartoolbox:dtm", "--", f"INPUT={src}", "RESOLUTION_M=0.5",
              f"OUTPUT={tmp_path / 'q.tif'}", f"OUTPUT_CLASSIFIED={tmp_path / 'q.laz'}")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    c = subprocess.run([str(TOOLBOX), "run", "dtm", str(src), "-o", str(tmp_path / "c.tif"), "--set", "resolution_m=0.5",
                        "--output-path", f"classified={tmp_path / 'c.laz'}", "--quiet"], capture_output=True, text=True)
    assert c.returncode == 0, c.stderr
    assert (tmp_path / "q.tif").read_bytes() == (tmp_path / "c.tif").read_bytes()
    import laspy
    import numpy as np

    a, b = laspy.read(tmp_path / "q.laz"), laspy.read(tmp_path / "c.laz")
    assert np.array_equal(a.classification, b.classification) and np.array_equal(a.X, b.X)


def test_powerlines_through_qgis_gives_the_command_lines_layers(qgis_env, powerlines_cli, tmp_path):
    import geopandas as gpd
    import pyogrio

    src, cli = powerlines_cli
    r = _qgis(qgis_env, "run", "lidartoolbox:powerlines", "--", f"INPUT={src}", f"OUTPUT={tmp_path / 'q.gpkg'}")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    layers = [n for n, _ in pyogrio.list_layers(cli) if n != "layer_styles"]
    assert "conductors" in layers
    for name in layers:
        a = gpd.read_file(tmp_path / "q.gpkg", layer=name)
        b = gpd.read_file(cli, layer=name)
        assert len(a) == len(b)
        assert all(x.equals(y) for x, y in zip(a.geometry, b.geometry))


def test_a_missing_input_fails_with_the_toolboxs_line_and_writes_nothing(qgis_env, tmp_path):
    r = _qgis(qgis_env, "run", "lidartoolbox:dtm", "--", f"INPUT={tmp_path / 'nothere.laz'}",
              f"OUTPUT={tmp_path / 'q.tif'}")
    assert r.returncode != 0
    assert "nothere.laz" in r.stdout + r.stderr and "does not exist" in r.stdout + r.stderr
    assert not list(tmp_path.glob("q*"))


def test_a_zip_for_install_from_zip_holds_the_plugin(tmp_path):
    import zipfile

    r = subprocess.run([str(TOOLBOX), "qgis", "package", "-o", str(tmp_path / "lidar_toolbox.zip")], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    names = zipfile.ZipFile(tmp_path / "lidar_toolbox.zip").namelist()
    for f in ("metadata.txt", "__init__.py", "provider.py", "algorithms.json", "toolbox.json"):
        assert f"lidar_toolbox/{f}" in names
    meta = zipfile.ZipFile(tmp_path / "lidar_toolbox.zip").read("lidar_toolbox/metadata.txt").decode()
    assert "hasProcessingProvider=yes" in meta and "qgisMinimumVersion=3.22" in meta


CANCEL_SCRIPT = r"""
import sys, threading
sys.path.insert(0, sys.argv[1])
from qgis.core import QgsApplication, QgsProcessingFeedback
app = QgsApplication([], False)
app.initQgis()
from lidar_toolbox.provider import run_toolbox
fb = QgsProcessingFeedback()
seen = []
fb.progressChanged.connect(lambda p: seen.append(p))
threading.Timer(float(sys.argv[2]), fb.cancel).start()  # a powerlines run on AHN4 takes 10 s or more
try:
    run_toolbox(sys.argv[3:], fb)
    print("FINISHED")
except Exception as exc:
    print("RAISED", type(exc).__name__, exc, "after", len(seen), "progress updates")
"""


@pytest.mark.skipif(shutil.which("python3") is None, reason="QGIS's Python (python3 with python3-qgis) is absent")
def test_cancel_ends_the_run_and_leaves_nothing(qgis_env, tmp_path):
    """The provider's runner with QGIS's own feedback object: cancelled a few seconds into a
    powerlines run, the toolbox is terminated and keeps nothing of the run."""
    src = shared_file("ahn4_corridor/07CZ2_14.laz")
    plugins = Path(qgis_env["QGIS_CUSTOM_CONFIG_PATH"]) / "profiles" / "default" / "python" / "plugins"
    (tmp_path / "out").mkdir()
    cmd = [str(TOOLBOX), "run", "powerlines", str(src), "-o", str(tmp_path / "out" / "lines.gpkg"), "--json",
           "--progress-json"]
    env = {k: v for k, v in qgis_env.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    r = subprocess.run(["/usr/bin/python3", "-c", CANCEL_SCRIPT, str(plugins), "4", *cmd], capture_output=True,
                       text=True, env=env, timeout=300)
    assert "RAISED QgsProcessingException cancelled" in r.stdout, r.stdout + r.stderr[-2000:]
    assert list((tmp_path / "out").iterdir()) == []  # no output, no temporary file


LOAD_SCRIPT = r"""
import sys
sys.path.insert(0, sys.argv[1])
from qgis.core import QgsApplication, QgsProcessingContext, QgsProject
app = QgsApplication([], False)
app.initQgis()
from lidar_toolbox.provider import _load_layers
ctx = QgsProcessingContext()
ctx.setProject(QgsProject.instance())
_load_layers(sys.argv[2], ctx)
print(sorted(k.split("layername=")[1] for k in ctx.layersToLoadOnCompletion()))
"""


def test_from_the_gui_every_layer_of_a_geopackage_output_is_loaded(qgis_env, powerlines_cli):
    """Run from the GUI (a context with a project), each layer of a vector output is added to
    the project (its style comes from the GeoPackage's layer_styles)."""
    import pyogrio

    _, cli = powerlines_cli
    plugins = Path(qgis_env["QGIS_CUSTOM_CONFIG_PATH"]) / "profiles" / "default" / "python" / "plugins"
    r = subprocess.run(["/usr/bin/python3", "-c", LOAD_SCRIPT, str(plugins), str(cli)],
                       capture_output=True, text=True, env=qgis_env, timeout=120)
    want = sorted(n for n, _ in pyogrio.list_layers(cli) if n != "layer_styles")
    assert r.stdout.strip().splitlines()[-1] == str(want), r.stdout + r.stderr[-1500:]


def test_a_third_party_plugin_appears_in_qgis_once_install_runs_again(qgis_env, tmp_path):
    """examples/third_party_plugin, made visible as an installed distribution (its dist-info and
    package on the path, as pip would leave them), shows up after ``toolbox qgis install``."""
    root = Path(__file__).resolve().parents[1]
    site = tmp_path / "site"
    info = site / "toolbox_density-1.0.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toolbox-density\nVersion: 1.0.0\n")
    (info / "entry_points.txt").write_text("[toolbox.plugins]\ndensity = toolbox_density.plugin\n")
    env = {**qgis_env, "PYTHONPATH": os.pathsep.join([str(site), str(root / "examples" / "third_party_plugin")])}
    profile = Path(qgis_env["QGIS_CUSTOM_CONFIG_PATH"]) / "profiles" / "default"
    before = _qgis(qgis_env, "list").stdout
    assert "lidartoolbox:pointdensity" not in before
    try:
        r = subprocess.run([str(TOOLBOX), "qgis", "install", "--profile-dir", str(profile)], capture_output=True,
                           text=True, env=env)
        assert r.returncode == 0, r.stderr
        assert "lidartoolbox:pointdensity\tPoint density raster" in _qgis(qgis_env, "list").stdout
    finally:  # the other tests' profile without it again
        subprocess.run([str(TOOLBOX), "qgis", "install", "--profile-dir", str(profile)], check=True, env=qgis_env,
                       capture_output=True)

"""Shared fixtures: the real data beside the checkout, the example plugin installed for real,
small synthetic scenes, and a CLI runner."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"
TOOLBOX = Path(sys.executable).parent / "toolbox"


def shared_file(rel: str) -> Path:
    """A file of ../shared/data, or skip the test with the reason."""
    p = SHARED_DATA / rel
    if not p.exists():
        pytest.skip(f"real data {rel} is absent (expected in {SHARED_DATA}); it lives in ../shared beside the checkout")
    return p


@pytest.fixture(scope="session")
def example_plugin_site(tmp_path_factory) -> Path:
    """The example third-party plugin installed with pip into its own site folder (for real:
    a built wheel with its entry point metadata, not a path hack)."""
    import shutil

    target = tmp_path_factory.mktemp("site")
    # build from a private copy: setuptools writes build/ and *.egg-info into the source folder,
    # and test workers running in parallel would race on them
    src = tmp_path_factory.mktemp("plugin-src") / "third_party_plugin"
    shutil.copytree(ROOT / "examples" / "third_party_plugin", src,
                    ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    r = subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index",
         "--target", str(target), str(src)],
        capture_output=True, text=True,
    )
    assert r.returncode == 0, f"installing the example plugin failed:\n{r.stdout}\n{r.stderr}"
    return target


def run_cli(*args, site: Path | None = None, env: dict | None = None, cwd=None) -> subprocess.CompletedProcess:
    e = dict(os.environ)
    e.pop("TOOLBOX_ARCH", None)
    if site is not None:
        e["PYTHONPATH"] = str(site) + os.pathsep + e.get("PYTHONPATH", "")
    e.update(env or {})
    return subprocess.run([str(TOOLBOX), *map(str, args)], capture_output=True, text=True, env=e, cwd=cwd, timeout=600)


@pytest.fixture
def cli():
    return run_cli


@pytest.fixture(scope="session")
def small_scene(tmp_path_factory) -> Path:
    """A small corridor scene (about 150 k points) written by the synthetic-scene algorithm."""
    import toolbox

    out = tmp_path_factory.mktemp("scene") / "scene.laz"
    toolbox.run("synthetic-scene", [], out, kind="corridor", seed=3, density_ppm2=4.0, width_m=300.0, height_m=140.0)
    return out


@pytest.fixture(scope="session")
def roofs_scene(tmp_path_factory) -> Path:
    import toolbox

    out = tmp_path_factory.mktemp("roofs") / "roofs.laz"
    toolbox.run("synthetic-scene", [], out, kind="roofs", seed=2, density_ppm2=8.0)
    return out


# in a conftest: a session fixture imported into two test modules is set up once per module
@pytest.fixture(scope="session")
def oakland_runs(tmp_path_factory):
    """``powerlines`` at default parameters on each Oakland street scan in ../shared, once for the
    tests that read them: {name: (source, gpkg, classified, report)} (a scan absent is left out)."""
    import toolbox

    from pl_helpers import OAKLAND_SCANS

    d = tmp_path_factory.mktemp("oakland")
    out = {}
    for name in OAKLAND_SCANS:
        path = SHARED_DATA / f"oakland_mls/oakland_{name}.laz"
        if path.exists():
            rep = toolbox.run("powerlines", path, d / f"{name}.gpkg", outputs={"classified": str(d / f"{name}_w.laz")})
            out[name] = (path, d / f"{name}.gpkg", d / f"{name}_w.laz", rep)
    return out

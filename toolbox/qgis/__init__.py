"""The QGIS plugin of the toolbox (``lidar_toolbox/``, pure PyQGIS) and the commands that install
and package it: ``toolbox qgis install [--profile-dir DIR]`` and ``toolbox qgis package -o ZIP``.

The plugin imports nothing of the toolbox (QGIS's Python has none of its stack): it reads the
algorithms' descriptions and the ``toolbox`` command to call from two files written here, so a
toolbox plugin installed later appears in QGIS once ``toolbox qgis install`` runs again."""

from __future__ import annotations

import configparser
import json
import os
import shutil
import sys
import zipfile
from pathlib import Path

from ..errors import UsageError

PLUGIN = "lidar_toolbox"
SOURCE = Path(__file__).resolve().parent / PLUGIN


def default_profile() -> Path:
    """The default QGIS profile (``$QGIS_CUSTOM_CONFIG_PATH`` honoured, as QGIS does)."""
    base = os.environ.get("QGIS_CUSTOM_CONFIG_PATH")
    if base:
        return Path(base) / "profiles" / "default"
    if sys.platform == "win32":
        return Path(os.environ.get("APPDATA", "~")).expanduser() / "QGIS" / "QGIS3" / "profiles" / "default"
    if sys.platform == "darwin":
        return Path("~/Library/Application Support/QGIS/QGIS3/profiles/default").expanduser()
    return Path("~/.local/share/QGIS/QGIS3/profiles/default").expanduser()


def toolbox_command() -> str:
    """The ``toolbox`` console script of this environment (what the plugin runs)."""
    here = Path(sys.executable).parent / ("toolbox.exe" if sys.platform == "win32" else "toolbox")
    found = str(here) if here.exists() else shutil.which("toolbox")
    if not found:
        raise UsageError("no 'toolbox' command found beside this Python; install the toolbox (pip install -e .) first")
    return found


def descriptions() -> dict:
    """Every algorithm's description, as ``toolbox help ALG --json`` gives it."""
    from ..registry import registry

    algs = sorted(registry().algorithms.values(), key=lambda a: a.id)
    return {"algorithms": [a.to_dict() for a in algs]}


def _write_plugin(folder: Path) -> None:
    shutil.copytree(SOURCE, folder, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    (folder / "toolbox.json").write_text(json.dumps({"toolbox": toolbox_command()}, indent=1), encoding="utf-8")
    (folder / "algorithms.json").write_text(json.dumps(descriptions(), indent=1, default=str), encoding="utf-8")


def install(profile_dir: str | os.PathLike | None = None) -> Path:
    """Copy the plugin into a QGIS profile (its ``python/plugins``), with the descriptions and the
    command, and enable it there. Returns the plugin's folder."""
    profile = Path(profile_dir).expanduser() if profile_dir else default_profile()
    plugins = profile / "python" / "plugins"
    plugins.mkdir(parents=True, exist_ok=True)
    target = plugins / PLUGIN
    staging = plugins / f".{PLUGIN}.partial"
    shutil.rmtree(staging, ignore_errors=True)
    _write_plugin(staging)
    shutil.rmtree(target, ignore_errors=True)
    os.replace(staging, target)
    _enable(profile)
    return target


def _enable(profile: Path) -> None:
    """``[PythonPlugins] lidar_toolbox=true`` in the profile's QGIS3.ini, the rest kept."""
    ini = profile / "QGIS" / "QGIS3.ini"
    ini.parent.mkdir(parents=True, exist_ok=True)
    cfg = configparser.RawConfigParser(strict=False, interpolation=None)
    cfg.optionxform = str  # QGIS's keys are case-sensitive
    if ini.exists():
        cfg.read(ini, encoding="utf-8")
    if not cfg.has_section("PythonPlugins"):
        cfg.add_section("PythonPlugins")
    cfg.set("PythonPlugins", PLUGIN, "true")
    with open(ini, "w", encoding="utf-8") as fh:
        cfg.write(fh, space_around_delimiters=False)


def package(out: str | os.PathLike) -> Path:
    """The plugin as a zip for QGIS's 'Install from ZIP' (with this environment's command)."""
    import tempfile

    out = Path(out)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / PLUGIN
        _write_plugin(folder)
        part = out.with_name(f".{out.name}.partial")
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
            for p in sorted(folder.rglob("*")):
                if p.is_file():
                    z.write(p, Path(PLUGIN) / p.relative_to(folder))
        os.replace(part, out)
    return out

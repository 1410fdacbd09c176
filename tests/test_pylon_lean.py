"""Leaning pylons (#79): the generator's exact leans, and pylon-pose measuring them from COLMAP's
binary model. Its own xdist group: the survey is its own, so it runs beside test_pylon_pose's."""

import numpy as np
import pytest

from toolbox.io.cameras import colmap_form
from toolbox_plugins.pylon_pose import core

pytestmark = pytest.mark.xdist_group("pylon_lean")


LEANS = {0: (1.0, "along"), 1: (2.5, "across"), 2: (5.0, "along"), 3: (5.0, "across")}


@pytest.fixture(scope="session")
def leaning_survey(tmp_path_factory):
    """Four pylons leaning 1, 2.5 and 5 degrees along and across the line (#79), six photos each,
    its cameras as COLMAP's binary model."""
    from toolbox.io.points import parse_crs
    from toolbox.io.rasters import Raster, write_raster
    from toolbox_plugins.synthetic_scene.generator.pylons import make_pylon_survey, survey_files

    d = tmp_path_factory.mktemp("leaning_survey")
    s = make_pylon_survey(61, n_pylons=4, photos_per_pylon=6, leans=LEANS)
    for rel, data in survey_files(s).items():
        (d / rel).parent.mkdir(parents=True, exist_ok=True)
        (d / rel).write_bytes(data) if isinstance(data, bytes) else (d / rel).write_text(data)
    write_raster(Raster(s.dem, s.dem_transform, crs=parse_crs(s.crs), nodata=float("nan")), d / "dem.tif")
    return d, s.truth()


def test_generator_leans_pylons_by_exactly_the_given_tilt_along_and_across_the_line(leaning_survey):
    _, truth = leaning_survey
    p = truth["pylons"]
    line = np.degrees(np.arctan2(p[-1]["x"] - p[0]["x"], p[-1]["y"] - p[0]["y"])) % 180.0  # compass, mod 180
    for i, (tilt, direction) in LEANS.items():
        assert p[i]["tilt_deg"] == pytest.approx(tilt, abs=1e-5)
        off = (p[i]["tilt_azimuth_deg"] - line) % 180.0  # along: 0 (or 180), across: 90
        assert min(off, 180.0 - off) == pytest.approx(0.0 if direction == "along" else 90.0, abs=3.0)  # the line bends 2 m


def test_pylon_pose_measures_leaning_pylons_from_a_binary_colmap_model(leaning_survey, tmp_path):
    """#79: tilt ≤ 0.2° off for leans of 1-5°, the base ≤ 0.15 m, the direction of the lean,
    and the leaning flag; from rough positions 2.5 m off."""
    import geopandas as gpd
    from shapely.geometry import Point

    from toolbox.runner import run_algorithm

    d, truth = leaning_survey
    assert colmap_form(d / "colmap_bin") == "binary"
    pylons = truth["pylons"]
    rough = gpd.GeoDataFrame(geometry=[Point(p["x"] + 1.5, p["y"] - 2.0) for p in pylons], crs=truth["crs"])
    rough.to_file(tmp_path / "rough.gpkg", layer="pylons")
    out = tmp_path / "found.gpkg"
    rep = run_algorithm("pylon-pose", {"photos": str(d / "photos"), "cameras": str(d / "colmap_bin"),
                                       "dem": str(d / "dem.tif"), "rough": str(tmp_path / "rough.gpkg")}, out,
                        {"radius_m": 4.0})  # the rough positions are 2.5 m off
    got = gpd.read_file(out, layer="pylons")
    assert len(got) == len(pylons) and rep["stats"]["n_leaning"] == len(pylons)
    for p in pylons:
        dist = np.hypot(got.geometry.x - p["x"], got.geometry.y - p["y"])
        r = got.iloc[int(np.argmin(dist))]
        assert dist.min() < 0.15 and abs(r.geometry.z - p["z"]) < 0.15 and r.model == p["model"]
        sym = p["symmetry_deg"]
        assert abs((r.heading_deg - p["heading_deg"] + sym / 2) % sym - sym / 2) < 0.5
        up = core.rotation(r.heading_deg, r.pitch_deg, r.roll_deg)[:, 2] @ core.rotation(
            p["heading_deg"], p["pitch_deg"], p["roll_deg"])[:, 2]
        assert np.degrees(np.arccos(min(up, 1.0))) < 0.2
        assert abs(r.tilt_deg - p["tilt_deg"]) < 0.2 and r.leaning
        assert abs((r.tilt_azimuth_deg - p["tilt_azimuth_deg"] + 180) % 360 - 180) < 5.0

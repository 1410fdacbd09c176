"""Survey runs on real files (#81): each point decoded once, virtual point clouds in and out, a
file too large for memory refused, and tiles against one run over the whole file.

The survey is lidR's Topography.laz (hilly forest with a lake, 0.9 points/m²) split into 2 x 2
delivery files, run in 100 m tiles; the reference is one run over the file."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import laspy
import numpy as np
import pytest
import rasterio

import toolbox
from toolbox import DataError, UsageError
from toolbox.io.vpc import read_vpc, write_vpc
from toolbox.survey import build_catalog, expand_survey_inputs, plan_tiles, run_survey, split_file
from toolbox.survey_read import chunk_cell_size, read_tile, split_points

from conftest import shared_file

pytestmark = pytest.mark.xdist_group("survey_real")  # one worker: the runs below use 2 processes each


@pytest.fixture(scope="session")
def topography(tmp_path_factory):
    src = shared_file("lidR/Topography.laz")
    d = tmp_path_factory.mktemp("topography")
    (d / "split").mkdir()
    files = split_file(src, d / "split", 2, 2)
    ref = d / "ref"
    ref.mkdir()
    whole = toolbox.run("dtm", src, ref / "dtm.tif")
    run = run_survey("dtm", [d / "split"], d / "survey", tile_size_m=100, workers=2)
    return {"src": src, "dir": d, "split": d / "split", "files": files, "dtm": ref / "dtm.tif", "survey": d / "survey",
            "report": run, "whole": whole}


def _dtm_diff(ref_path, path):
    """(cells over 1 cm apart, max difference, cells with data in one only) on one lattice."""
    with rasterio.open(ref_path) as a, rasterio.open(path) as b:
        assert a.res == b.res and a.crs == b.crs and a.shape == b.shape and a.transform == b.transform
        A, B = a.read(1, masked=True).filled(np.nan), b.read(1, masked=True).filled(np.nan)
    both = np.isfinite(A) & np.isfinite(B)
    d = np.abs(A - B)[both]
    return int((d > 0.01).sum()), float(d.max()), int((np.isfinite(A) != np.isfinite(B)).sum())


def test_a_tile_read_through_the_split_holds_the_points_a_scan_gives(topography, tmp_path):
    """The split files give each tile the same points, in the same order, with every dimension,
    as scanning the files; and reading whole chunk cells takes at most 1.5 x the tile's points."""
    catalog = build_catalog(expand_survey_inputs([topography["split"]]))
    cell = chunk_cell_size(100.0, 60.0)
    splits = {}
    for i, f in enumerate(catalog.files):
        res = split_points({"name": f"split {i}", "file": asdict(f), "folder": str(tmp_path / str(i)), "cell": cell})
        assert res["status"] == "done" and res["n_decoded_points"] == f.count
        splits[f.path] = str(tmp_path / str(i))
    tiles = plan_tiles(catalog, 100.0)
    assert len(tiles) == 16
    for t in tiles:
        files = catalog.files_in(t.box(60.0))
        a, core_a, dec_a, read_a = read_tile(files, t, 60.0)
        b, core_b, dec_b, read_b = read_tile(files, t, 60.0, splits=splits)
        assert np.array_equal(a.x, b.x) and np.array_equal(a.y, b.y) and np.array_equal(a.z, b.z)
        assert sorted(a.fields) == sorted(b.fields) and all(np.array_equal(a.fields[k], b.fields[k]) for k in a.fields)
        assert np.array_equal(core_a, core_b)
        assert dec_a == sum(f.count for f in files) and dec_b == 0  # a scan decodes every file it touches
        assert len(b) <= read_b <= 1.3 * len(b)  # whole chunk cells: (1 + 2/16)² of the box's area


def test_a_truncated_file_is_not_split_and_its_tiles_fail_with_the_reason(topography, tmp_path):
    bad = tmp_path / "cut.laz"
    data = Path(topography["files"][0]).read_bytes()
    bad.write_bytes(data[: len(data) // 2])
    f = build_catalog([str(bad)]).files[0]
    res = split_points({"name": "split cut", "file": asdict(f), "folder": str(tmp_path / "s"), "cell": 25.0})
    assert res["status"] == "failed" and "cut.laz" in res["error"] and "re-download" in res["error"]
    assert not (tmp_path / "s").exists()  # no partial split is left to be mistaken for one


def test_a_survey_of_plain_files_decodes_each_point_once(topography):
    rep = topography["report"]
    assert rep["n_failed"] == 0 and rep["n_tiles"] == 16
    split = rep["execution"]["split"]
    assert split["n_files"] == 4 and split["n_decoded_points"] == rep["survey"]["n_points"] == 73_403
    tiles = json.loads((topography["survey"] / "survey.json").read_text())["tiles"].values()
    assert sum(t["stats"]["n_decoded_points"] for t in tiles) == 0  # no tile decodes a file again
    in_boxes = sum(t["stats"]["n_points"] for t in tiles)
    assert sum(t["stats"]["n_read_points"] for t in tiles) <= 1.3 * in_boxes
    assert sum(t["stats"]["n_core_points"] for t in tiles) == 73_403
    assert not (topography["survey"] / ".tiles" / "chunks").exists()  # the scratch split is gone after the merge


def test_vpc_in_gives_the_survey_of_its_files_and_vpc_out_lists_the_tiles(topography, tmp_path):
    """A .vpc beside other folders (hrefs ../split/...) reads as its files; the survey writes
    classified.vpc over its per-tile LAZ files, which reads back as the same points."""
    (tmp_path / "vpcs").mkdir()
    vpc = write_vpc(tmp_path / "vpcs" / "topography.vpc", topography["files"])
    doc = json.loads(vpc.read_text())
    assert doc["type"] == "FeatureCollection" and len(doc["features"]) == 4
    item = doc["features"][0]
    assert item["stac_version"] == "1.0.0" and item["assets"]["data"]["href"].startswith("./")
    assert "EPSG" in item["properties"]["proj:wkt2"] and len(item["properties"]["proj:bbox"]) == 6
    assert -71.0 < item["bbox"][0] < -70.8 and 47.5 < item["bbox"][1] < 47.7  # WGS 84 (MTM zone 7, Québec)
    assert [v.path for v in read_vpc(vpc)] == [str(Path(f).resolve()) for f in topography["files"]]
    rep = run_survey("dtm", [vpc], tmp_path / "out", tile_size_m=100, workers=2)
    assert rep["survey"]["n_files"] == 4 and rep["n_failed"] == 0
    assert (tmp_path / "out" / "dtm.tif").read_bytes() == (topography["survey"] / "dtm.tif").read_bytes()
    out_vpc = Path(rep["outputs"]["classified"]["vpc"])
    assert out_vpc == tmp_path / "out" / "classified.vpc"
    items = read_vpc(out_vpc)
    assert len(items) == 16 and sum(i.count for i in items) == 73_403
    assert all(Path(i.path).parent == tmp_path / "out" / "classified" for i in items)
    for i in items:  # each item's bounds are its file's
        hdr = laspy.open(i.path).header
        assert i.count == hdr.point_count and np.allclose(i.bbox[:3], hdr.mins) and np.allclose(i.bbox[3:], hdr.maxs)


def test_vpc_errors_name_the_file_and_the_fix(topography, tmp_path):
    gone = tmp_path / "gone.vpc"
    write_vpc(gone, topography["files"][:1])
    doc = json.loads(gone.read_text())
    doc["features"][0]["assets"]["data"]["href"] = "./missing.laz"
    gone.write_text(json.dumps(doc))
    with pytest.raises(DataError, match=r"gone.vpc.*lists './missing.laz', which does not exist"):
        expand_survey_inputs([str(gone)])
    other = tmp_path / "other.vpc"
    other.write_text(json.dumps({"type": "Feature"}))
    with pytest.raises(DataError, match=r"other.vpc.*is not a virtual point cloud.*build_vpc"):
        expand_survey_inputs([str(other)])


def test_a_file_without_crs_takes_the_one_its_vpc_gives(tmp_path):
    src = shared_file("ahn3_amsterdam/ahn_2386_9702.laz")  # no CRS in the file (RD New per its source)
    assert build_catalog([str(src)]).crs is None
    vpc = write_vpc(tmp_path / "ahn3.vpc", [src])
    doc = json.loads(vpc.read_text())
    doc["features"][0]["properties"]["proj:epsg"] = 28992
    doc["features"][0]["properties"]["proj:wkt2"] = ""
    vpc.write_text(json.dumps(doc))
    from toolbox.survey import listed_crs

    catalog = build_catalog(expand_survey_inputs([str(vpc)]), listed=listed_crs([str(vpc)]))
    assert catalog.crs.to_epsg() == 28992


def test_a_file_larger_than_memory_is_refused_before_reading(topography, tmp_path, monkeypatch):
    import toolbox.memory

    monkeypatch.setattr(toolbox.memory, "available_ram_bytes", lambda: 8 << 20)  # 8 MiB free
    with pytest.raises(UsageError, match=r"Topography.laz' holds 73,403 points: dtm needs about .* GiB .* "
                                         r"run it in tiles: toolbox run dtm .* --tile-size-m"):
        toolbox.run("dtm", topography["src"], tmp_path / "dtm.tif")
    assert list(tmp_path.iterdir()) == []  # nothing written


# real files split into 2 x 2 delivery files, each at two tile sizes (CRS units: Autzen is in feet)
REAL_SURVEYS = [("lidR/Topography.laz", 250), ("pdal_autzen/autzen_trim.las", 150),
                ("pdal_autzen/autzen_trim.las", 250), ("ahn3_amsterdam/ahn_2386_9702.laz", 25),
                ("ahn3_amsterdam/ahn_2386_9702.laz", 50), ("ahn4_corridor/07CZ2_14.laz", 150),
                ("ahn4_corridor/07CZ2_14.laz", 250), ("isprs_filtertest/samp11.txt", 100),
                ("isprs_filtertest/samp11.txt", 250)]


@pytest.fixture(scope="session")
def real_splits(tmp_path_factory):
    """Each real file as 2 x 2 LAZ files, with one dtm run over the whole (made on first use)."""
    made = {}

    def get(rel):
        if rel not in made:
            src = shared_file(rel)
            d = tmp_path_factory.mktemp(Path(rel).stem)
            if src.suffix == ".txt":  # the ISPRS samples are ASCII: as LAZ, as a survey's files are
                from toolbox.io.points import read_points, write_points

                write_points(read_points(src), d / f"{src.stem}.laz")
                src = d / f"{src.stem}.laz"
            (d / "split").mkdir()
            split_file(src, d / "split", 2, 2)
            toolbox.run("dtm", src, d / "dtm.tif")
            made[rel] = d
        return made[rel]
    return get


def test_dtm_in_tiles_equals_the_whole_run_on_a_sparse_real_survey(topography):
    """Topography: the lake is wider than max_gap_m, so it is nodata in both; the point spacing
    behind refine_cell_m is the survey's (summed over the tiles), not each tile's own."""
    over, worst, only = _dtm_diff(topography["dtm"], topography["survey"] / "dtm.tif")
    assert over == 0 and only == 0, (over, worst, only)
    values = topography["report"]["survey_values"]
    assert set(values) == {"refine_cell_m"} and topography["report"]["survey_values_from"] == "the split pass"
    assert round(values["refine_cell_m"], 3) == topography["whole"]["stats"]["refine_cell_m_used"]
    a = laspy.read(topography["dir"] / "ref" / "dtm_classified.laz")
    parts = [laspy.read(p) for p in sorted((topography["survey"] / "classified").glob("*.laz"))]
    assert sum(len(p.points) for p in parts) == len(a.points)
    key = lambda las: np.lexsort((np.asarray(las.Z), np.asarray(las.Y), np.asarray(las.X)))  # noqa: E731
    b_x = np.concatenate([np.asarray(p.X) for p in parts])
    b_y = np.concatenate([np.asarray(p.Y) for p in parts])
    b_z = np.concatenate([np.asarray(p.Z) for p in parts])
    b_c = np.concatenate([np.asarray(p.classification) for p in parts])
    ia, ib = key(a), np.lexsort((b_z, b_y, b_x))
    assert np.array_equal(np.asarray(a.X)[ia], b_x[ib])
    assert np.array_equal(np.asarray(a.classification)[ia], b_c[ib])  # every point's class, as the whole run's


@pytest.mark.parametrize("rel", ["lidR/Topography.laz", "pdal_autzen/autzen_trim.las", "ahn4_corridor/07CZ2_14.laz",
                                 "isprs_filtertest/samp53_f32.txt", "isprs_filtertest/samp11.txt"])
def test_the_split_pass_cell_statistics_give_the_whole_runs_spacing_counts(rel):
    """``survey_cell_summary`` on CellStats gathered in chunks, in another order and on a raster of
    another origin than the run's own grid, gives the counts one run over the file takes its
    point spacing from (feet on Autzen; ISPRS's steep samples with low outliers)."""
    from toolbox.io.points import read_points
    from toolbox.survey_read import CellStats
    from toolbox_plugins.morph_dtm.core import spacing_counts
    from toolbox_plugins.morph_dtm.plugin import _ground_settings, survey_cell_summary, survey_cells

    pc = read_points(shared_file(rel))
    p = toolbox.algorithms()["dtm"].validate_params({})
    whole = spacing_counts(pc.x, pc.y, pc.z, _ground_settings(pc, p), (-np.inf, -np.inf, np.inf, np.inf))
    cell = survey_cells(p, pc.horizontal_unit_m)
    stats = CellStats.empty(np.floor(pc.x.min() / cell) * cell + 5 * cell, np.floor(pc.y.max() / cell) * cell - 7 * cell,
                            cell, 2, 2, horizontal_unit_m=pc.horizontal_unit_m, vertical_unit_m=pc.vertical_unit_m)
    for part in np.array_split(np.random.default_rng(0).permutation(len(pc.x)), 5):
        stats.add(pc.x[part], pc.y[part], pc.z[part])
    got = survey_cell_summary(stats.finished(), p)
    assert (got["n_points"], got["n_footprint_cells"]) == whole


@pytest.mark.parametrize("rel,tile", REAL_SURVEYS, ids=[f"{Path(r).stem}-{t}" for r, t in REAL_SURVEYS])
def test_dtm_survey_equals_the_whole_run_on_real_files(real_splits, tmp_path, rel, tile):
    d = real_splits(rel)
    rep = run_survey("dtm", [d / "split"], tmp_path / "out", tile_size_m=tile, workers=2)
    assert rep["n_failed"] == 0 and rep["n_tiles"] >= 2
    over, worst, only = _dtm_diff(d / "dtm.tif", tmp_path / "out" / "dtm.tif")
    assert over == 0 and only == 0, (over, worst, only)


def test_tophat_survey_gives_the_whole_runs_cells_once(real_splits, tmp_path):
    """Points the algorithm makes (cell centroids) are kept by the tile whose core holds them: every
    centroid of the whole run once, within the LAS coordinates' 1 mm."""
    from scipy.spatial import cKDTree

    d = real_splits("ahn4_corridor/07CZ2_14.laz")
    src = shared_file("ahn4_corridor/07CZ2_14.laz")
    toolbox.run("tophat", src, tmp_path / "whole.laz")
    rep = run_survey("tophat", [d / "split"], tmp_path / "out", tile_size_m=100, workers=2)
    assert rep["n_failed"] == 0 and rep["survey"]["buffer_m"] == rep["survey"]["buffer_declared_m"] == 1.5
    whole = laspy.read(tmp_path / "whole.laz")
    parts = [laspy.read(p) for p in sorted((tmp_path / "out" / "points").glob("*.laz"))]
    a = np.c_[whole.x, whole.y, whole.z]
    b = np.concatenate([np.c_[p.x, p.y, p.z] for p in parts])
    assert len(a) == len(b) > 1000
    dist, j = cKDTree(b).query(a)
    assert dist.max() <= 0.0018 and len(np.unique(j)) == len(b)  # one to one, within a quantum per axis


def test_building_edges_survey_gives_the_whole_runs_outlines_and_tiles_without_buildings_are_empty(real_splits,
                                                                                                   tmp_path):
    import geopandas as gpd

    d = real_splits("pdal_autzen/autzen_trim.las")
    src = shared_file("pdal_autzen/autzen_trim.las")
    toolbox.run("building-edges", src, tmp_path / "whole.gpkg")
    rep = run_survey("building-edges", [d / "split"], tmp_path / "out", tile_size_m=100, workers=2)
    assert rep["n_failed"] == 0 and rep["survey"]["buffer_m"] == 60.0
    a = gpd.read_file(tmp_path / "whole.gpkg", layer="building_outlines")
    b = gpd.read_file(tmp_path / "out" / "outlines.gpkg", layer="building_outlines")
    assert len(a) == len(b) == 20
    assert abs(a.area.sum() - b.area.sum()) < 1e-6 * a.area.sum()
    for g in a.geometry:  # each outline once, the same
        same = b.geometry[b.geometry.intersects(g)]
        assert len(same) == 1 and same.iloc[0].symmetric_difference(g).area < 1e-6 * g.area
    states = json.loads((tmp_path / "out" / "survey.json").read_text())["tiles"].values()
    empty = [t for t in states if t["status"] == "empty" and "no building points" in t.get("reason", "")]
    assert empty, "no tile without buildings: the test no longer shows that such a tile is empty, not failed"


def test_a_building_wider_than_the_buffer_is_one_outline_made_of_its_tiles_parts(real_splits, tmp_path):
    """AHN4 07CZ2_14 in 100 m tiles: one roof 155 m x 340 m is wider than the 60 m buffer, so each
    tile sees a part of it. The parts, clipped to their cores, become one outline (before: four
    overlapping outlines, 33 features for 30); every other outline is the whole run's; building
    ids are unique and the roof edges refer to them."""
    import geopandas as gpd

    d = real_splits("ahn4_corridor/07CZ2_14.laz")
    toolbox.run("building-edges", shared_file("ahn4_corridor/07CZ2_14.laz"), tmp_path / "whole.gpkg")
    rep = run_survey("building-edges", [d / "split"], tmp_path / "out", tile_size_m=100, workers=2)
    assert rep["n_failed"] == 0
    a = gpd.read_file(tmp_path / "whole.gpkg", layer="building_outlines")
    b = gpd.read_file(tmp_path / "out" / "outlines.gpkg", layer="building_outlines")
    assert len(a) == len(b) and set(b.geom_type) == {"Polygon"} and b.building_id.is_unique
    wide = a.geometry.map(lambda g: max(g.bounds[2] - g.bounds[0], g.bounds[3] - g.bounds[1]) > 220)  # > tile + 2 buffers
    assert wide.sum() == 1
    for g, is_wide in zip(a.geometry, wide):
        same = b.geometry[b.geometry.intersects(g)]
        assert len(same) == 1
        iou = same.iloc[0].intersection(g).area / same.iloc[0].union(g).area
        assert iou > (0.9 if is_wide else 1 - 1e-6), iou  # the wide one: each part regularised on its own
    edges = gpd.read_file(tmp_path / "out" / "outlines.gpkg", layer="roof_edges")
    assert edges.building_id.isin(b.building_id).mean() > 0.95

"""Point I/O: LAS/LAZ round trip with CRS and every dimension, feet, ASCII, chunks, --crs."""

import numpy as np
import pytest

from conftest import shared_file
from toolbox.errors import DataError
from toolbox.io.points import PointCloud, iter_points, parse_crs, read_points, write_points


def test_laz_round_trip_keeps_every_dimension_and_crs(small_scene, tmp_path):
    pc = read_points(small_scene)
    assert pc.crs.to_epsg() == 25832
    assert pc.horizontal_unit_m == 1.0 and pc.vertical_unit_m == 1.0
    new_cls = np.where(pc.classification == 2, 2, 1).astype(np.uint8)
    score = np.linspace(0, 1, len(pc)).astype(np.float32)
    out = write_points(pc.with_fields(classification=new_cls, score=score), tmp_path / "rt.laz")
    back = read_points(out)
    assert back.crs.to_epsg() == 25832
    np.testing.assert_allclose(back.x, pc.x, atol=0.0005)
    np.testing.assert_allclose(back.z, pc.z, atol=0.0005)
    for name in ("return_number", "number_of_returns", "intensity", "gps_time", "object_id", "plane_id"):
        np.testing.assert_array_equal(back.fields[name], pc.fields[name])
    np.testing.assert_array_equal(back.classification, new_cls)
    np.testing.assert_array_equal(back.fields["score"], score)


def test_writing_changed_fields_leaves_the_source_cloud_as_it_was(small_scene, tmp_path):
    """The writer reuses the source's point record in place (no copy) and must put it back."""
    pc = read_points(small_scene)
    before = pc.fields.record.array.copy()
    new_cls = np.full(len(pc), 6, np.uint8)
    moved = pc.with_fields(classification=new_cls)
    moved.z = pc.z + 1.0  # xyz edited too
    out = read_points(write_points(moved, tmp_path / "changed.laz"))
    np.testing.assert_array_equal(out.classification, new_cls)
    np.testing.assert_allclose(out.z, pc.z + 1.0, atol=0.0005)
    assert np.array_equal(pc.fields.record.array, before)  # the source record is untouched
    # and a write that fails half way restores it as well
    with pytest.raises(Exception):
        write_points(moved, tmp_path / "missing-dir" / "x.laz")
    assert np.array_equal(pc.fields.record.array, before)


def test_selective_decompression_reads_the_rest_on_demand(small_scene, tmp_path):
    """dims= decompresses only the declared layers; anything else, and writing, stay exact."""
    full = read_points(small_scene)
    part = read_points(small_scene, dims=("classification",))
    assert part.fields.selected is not None  # the scene is LAZ point format 6: a partial record
    np.testing.assert_array_equal(part.z, full.z)
    np.testing.assert_array_equal(part.classification, full.classification)
    np.testing.assert_array_equal(part.fields["return_number"], full.fields["return_number"])
    # the layer that was skipped reads as zeros in laspy's record: we must not hand that out
    skipped = np.asarray(part.fields.record["gps_time"])
    assert not np.array_equal(skipped, full.fields["gps_time"])
    sub_idx = np.flatnonzero(full.classification != 2)[::7]
    sub = part.subset(sub_idx)
    np.testing.assert_array_equal(sub.fields["gps_time"], full.fields["gps_time"][sub_idx])
    np.testing.assert_array_equal(part.fields["intensity"], full.fields["intensity"])
    # a partial cloud written out keeps every dimension
    part2 = read_points(small_scene, dims=())
    back = read_points(write_points(part2.subset(sub_idx), tmp_path / "sub.laz"))
    for name in ("gps_time", "intensity", "object_id", "classification"):
        np.testing.assert_array_equal(back.fields[name], full.fields[name][sub_idx])


def test_las_and_laz_hold_the_same_points(small_scene, tmp_path):
    pc = read_points(small_scene)
    a = read_points(write_points(pc, tmp_path / "a.las"))
    np.testing.assert_array_equal(a.z, pc.z)
    assert (tmp_path / "a.las").stat().st_size > small_scene.stat().st_size  # LAZ is compressed


def test_classes_above_31_upgrade_old_point_formats(tmp_path):
    path = shared_file("ahn3_amsterdam/ahn_2386_9702.laz")
    pc = read_points(path)
    assert pc.header.point_format.id == 1
    cls = pc.classification.copy()
    cls[:10] = 64
    back = read_points(write_points(pc.with_fields(classification=cls), tmp_path / "wide.laz"))
    assert back.header.point_format.id == 6
    np.testing.assert_array_equal(back.classification, cls)
    np.testing.assert_allclose(back.fields["gps_time"], pc.fields["gps_time"])


def test_crs_override_is_written(tmp_path):
    path = shared_file("ahn3_amsterdam/ahn_2386_9702.laz")
    pc = read_points(path)
    assert pc.crs is None  # the file has no CRS VLR
    pc2 = read_points(path, crs="EPSG:28992")
    assert pc2.crs.to_epsg() == 28992
    back = read_points(write_points(pc2, tmp_path / "crs.laz"))
    assert back.crs.to_epsg() == 28992


def test_header_crs_remembered_per_projection_records(tmp_path):
    # the parsed CRS of a file is reused for files with the same projection records, never for others
    rng = np.random.default_rng(0)
    a = write_points(PointCloud(rng.uniform(0, 9, 20), rng.uniform(0, 9, 20), rng.uniform(0, 9, 20),
                                crs=parse_crs("EPSG:25832")), tmp_path / "a.laz")
    b = write_points(PointCloud(rng.uniform(0, 9, 20), rng.uniform(0, 9, 20), rng.uniform(0, 9, 20),
                                crs=parse_crs("EPSG:28992")), tmp_path / "b.laz")
    first = read_points(a).crs
    assert read_points(b).crs.to_epsg() == 28992
    assert read_points(a).crs is first and first.to_epsg() == 25832


def test_international_feet_are_honoured():
    path = shared_file("pdal_autzen/autzen_trim.las")
    pc = read_points(path)
    assert pc.horizontal_unit_m == pytest.approx(0.3048)
    assert pc.vertical_unit_m == pytest.approx(0.3048)
    assert pc.to_units(1.0) == pytest.approx(1 / 0.3048)
    # SOURCES.md: about 359 x 172 m in metres
    w = (pc.x.max() - pc.x.min()) * pc.horizontal_unit_m
    h = (pc.y.max() - pc.y.min()) * pc.horizontal_unit_m
    assert w == pytest.approx(359, abs=2) and h == pytest.approx(172, abs=2)


def test_us_survey_feet_written_and_read_back(small_scene, tmp_path):
    # a cloud in a US-feet CRS (NAD83 / New York Long Island, ftUS) keeps its unit through a round trip
    pc = read_points(small_scene)
    ft = PointCloud(pc.x / 0.3048006, pc.y / 0.3048006, pc.z / 0.3048006, crs=parse_crs("EPSG:2263"))
    back = read_points(write_points(ft, tmp_path / "ft.laz"))
    assert back.horizontal_unit_m == pytest.approx(1200 / 3937)
    assert back.vertical_unit_m == pytest.approx(1200 / 3937)


def test_isprs_ascii_with_labels():
    path = shared_file("isprs_filtertest/samp11.txt")
    pc = read_points(path)
    assert len(pc) == 38010
    u, c = np.unique(pc.fields["label"], return_counts=True)
    assert dict(zip(u.tolist(), c.tolist())) == {0: 21786, 1: 16224}
    assert pc.z.min() == pytest.approx(295.25, abs=0.01)


def test_ascii_comma_and_extra_columns(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("# x,y,z,r,g,b\n1,2,3,10,20,30\n4,5,6,11,21,31\n")
    pc = read_points(p)
    np.testing.assert_array_equal(pc.z, [3, 6])
    np.testing.assert_array_equal(pc.fields["column_6"], [30, 31])


def test_chunked_reading_is_bounded_and_complete(small_scene):
    full = read_points(small_scene)
    sizes, zs = [], []
    for chunk in iter_points(small_scene, chunk_points=40_000):
        sizes.append(len(chunk))
        zs.append(chunk.z)
        assert chunk.crs.to_epsg() == 25832
    assert max(sizes) <= 40_000 and len(sizes) > 2
    np.testing.assert_array_equal(np.concatenate(zs), full.z)


def test_truncated_file_is_detected_in_chunks_too(small_scene, tmp_path):
    data = small_scene.read_bytes()
    bad = tmp_path / "cut.laz"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match="cut.laz"):
        for _ in iter_points(bad, chunk_points=20_000):
            pass

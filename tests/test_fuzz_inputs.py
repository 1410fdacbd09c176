"""Property-based: generated LAS headers, coordinates and parameter values fed to the readers and
the parameter checks through the command line (in this process). Whatever comes in, the run
ends with exit code 0 and a valid output, or 1 or 2 with at most three lines on stderr and no
traceback; never a partial file, never a non-finite coordinate written."""

from __future__ import annotations

import contextlib
import io
import logging
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", reason="Hypothesis is a test extra: pip install -e '.[test]'")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

ODD_FLOATS = st.sampled_from([0.0, -0.0, float("nan"), float("inf"), -float("inf"), 1e-300, 1e300, -1e12,
                              0.001, 0.01, 1.0, 123456.789])
PLAIN = st.floats(min_value=0.0, max_value=30.0)
ODD = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                st.sampled_from([float("nan"), float("inf"), -float("inf"), 1e308, -1e12]))
# mostly plain values: a point odd in one coordinate only is the case that slipped through
COORD = st.one_of(PLAIN, PLAIN, PLAIN, ODD)


def run_main(argv) -> tuple[int, str]:
    """``toolbox.cli.main`` in this process, its stderr (log lines included) captured."""
    from toolbox import cli

    err = io.StringIO()
    root = logging.getLogger()
    saved = root.handlers[:]
    root.handlers.clear()  # so that the CLI's basicConfig logs into the captured stderr
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = cli.main([str(a) for a in argv])
    finally:
        for h in root.handlers[:]:
            root.removeHandler(h)
        root.handlers.extend(saved)
    return rc, err.getvalue()


def check_outcome(rc: int, stderr: str, folder: Path, outputs: list[Path]) -> None:
    names = [p.name for p in folder.iterdir()]
    assert not [n for n in names if ".partial" in n], names  # never a temporary file left
    if rc == 0:
        import laspy
        import rasterio

        for p in outputs:
            assert p.exists(), (p, stderr)
            if p.suffix == ".tif":
                with rasterio.open(p) as ds:
                    ds.read(1)
            elif p.suffix == ".laz":
                las = laspy.read(p)
                assert np.isfinite(np.asarray(las.x)).all() and np.isfinite(np.asarray(las.z)).all()
                assert np.isfinite(las.header.offsets).all() and np.isfinite(las.header.scales).all()
        return
    assert rc in (1, 2), (rc, stderr)
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert 1 <= len(lines) <= 3, stderr
    assert "Traceback" not in stderr and lines[-1].startswith("toolbox: "), stderr
    # the host's catch-all for an exception nobody named (a bug met on the way): not an answer
    assert "failed: " not in lines[-1], stderr
    for p in outputs:
        assert not p.exists(), f"{p} written by a failed run"


def base_las(path: Path, n: int, fmt: int) -> None:
    import laspy

    rng = np.random.default_rng(n)
    hdr = laspy.LasHeader(version="1.4" if fmt >= 6 else "1.2", point_format=fmt)
    hdr.scales = [0.01, 0.01, 0.01]
    hdr.offsets = [500000.0, 5400000.0, 0.0]
    las = laspy.LasData(hdr)
    las.x = 500000.0 + rng.uniform(0, 40, n)
    las.y = 5400000.0 + rng.uniform(0, 40, n)
    las.z = 50.0 + rng.normal(0, 0.1, n)
    las.write(path)


# header fields by byte offset in LAS 1.x: scales, offsets, bounds (doubles), point count (uint32)
HEADER_DOUBLES = {"scale_x": 131, "scale_y": 139, "scale_z": 147, "offset_x": 155, "offset_y": 163,
                  "offset_z": 171, "max_x": 179, "min_x": 187, "max_y": 195, "min_y": 203, "max_z": 211, "min_z": 219}


@SETTINGS
@given(n=st.integers(0, 60), fmt=st.sampled_from([0, 1, 3, 6, 7]),
       patches=st.dictionaries(st.sampled_from(sorted(HEADER_DOUBLES)), ODD_FLOATS, max_size=3),
       count=st.one_of(st.none(), st.integers(0, 200)), laz=st.booleans())
def test_generated_las_headers(n, fmt, patches, count, laz):
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src = tmp / ("in.laz" if laz else "in.las")
        base_las(src, n, fmt)
        data = bytearray(src.read_bytes())
        for name, value in patches.items():
            at = HEADER_DOUBLES[name]
            data[at:at + 8] = struct.pack("<d", value)
        if count is not None and not laz:
            data[107:111] = struct.pack("<I", count)
        src.write_bytes(bytes(data))
        out = tmp / "out"
        out.mkdir()
        outputs = [out / "d.tif", out / "d_classified.laz"]
        rc, err = run_main(["run", "dtm", src, "-o", out / "d.tif", "--crs", "EPSG:25832", "-q"])
        check_outcome(rc, err, out, outputs)


@SETTINGS
@given(points=st.lists(st.tuples(COORD, COORD, COORD), min_size=0, max_size=4),
       label=st.booleans(), header_row=st.booleans())
def test_generated_ascii_coordinates(points, label, header_row):
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        rng = np.random.default_rng(len(points))
        base = np.column_stack([rng.uniform(0, 30, 30), rng.uniform(0, 30, 30), rng.normal(0, 0.1, 30)])
        rows = [tuple(r) for r in base] + list(points)
        lines = ["X Y Z" + (" L" if label else "")] if header_row else []
        for r in rows:
            lines.append(" ".join(repr(float(v)) for v in r) + (" 0" if label else ""))
        src = tmp / "p.txt"
        src.write_text("\n".join(lines) + "\n")
        out = tmp / "out"
        out.mkdir()
        outputs = [out / "d.tif", out / "d_classified.laz"]
        rc, err = run_main(["run", "dtm", src, "-o", out / "d.tif", "--crs", "EPSG:25832", "-q"])
        check_outcome(rc, err, out, outputs)


PARAM_VALUE = st.one_of(st.sampled_from(["nan", "inf", "-inf", "auto", "", "1e400", "-0", "0", "true", "x"]),
                        st.floats(allow_nan=True, allow_infinity=True).map(repr),
                        st.integers(-10**6, 10**6).map(str), st.text(max_size=8))


@SETTINGS
@given(values=st.dictionaries(st.sampled_from(["resolution_m", "filter_cell_m", "max_filter_size_m", "slope_k",
                                               "refine_cell_m", "ground", "min_height_n_m", "ground_threshold_m", "no_such"]),
                              PARAM_VALUE, min_size=1, max_size=3))
def test_generated_parameter_values(values, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("params")
    src = tmp / "p.laz"
    base_las(src, 400, 6)
    out = tmp / "out"
    out.mkdir()
    argv = ["run", "dtm", src, "-o", out / "d.tif", "--crs", "EPSG:25832", "-q"]
    for k, v in values.items():
        argv += ["--set", f"{k}={v}"]
    rc, err = run_main(argv)
    check_outcome(rc, err, out, [out / "d.tif", out / "d_classified.laz"])

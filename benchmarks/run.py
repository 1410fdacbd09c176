"""`make bench`: our algorithms against peers on the same inputs, in the same run.

Prints a table: case, points, our seconds, each peer's seconds, ratio (peer / ours, > 1 means we
are faster), and the accuracy of each where the input has truth. Results also go to
bench-output/results.json. Peers (benchmark extras, never runtime dependencies):
whitebox-workflows (improved ground point filter, hillshade) and cloth-simulation-filter (CSF).

    python benchmarks/run.py [--quick] [--no-10m]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import laspy
import numpy as np

import toolbox
from toolbox.io.points import read_points
from toolbox_plugins.morph_dtm.evaluation import ground_errors

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return time.perf_counter() - t, out


def whitebox_ground(las_path: Path, out: Path):
    try:
        import whitebox_workflows as wbw
    except ImportError:
        return None, None
    wbe = wbw.WbEnvironment()
    wbe.verbose = False
    t, _ = timed(lambda: wbe.lidar.filtering_classification.improved_ground_point_filter(
        input=str(las_path), classify=True, output=str(out)))
    return t, np.asarray(laspy.read(out).classification) == 2


def _quiet_c_stdout(fn):
    """CSF prints its progress from C++; keep the table readable."""
    import os

    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        return fn()
    finally:
        os.dup2(saved, 1)
        os.close(devnull)
        os.close(saved)


def csf_ground(pc):
    try:
        import CSF
    except ImportError:
        return None, None
    c = CSF.CSF()
    c.params.bSloopSmooth = True  # the option CSF recommends for steep terrain
    g, ng = CSF.VecInt(), CSF.VecInt()

    def go():
        c.setPointCloud(np.column_stack([pc.x, pc.y, pc.z]))
        c.do_filtering(g, ng, exportCloth=False)

    t, _ = timed(lambda: _quiet_c_stdout(go))
    mask = np.zeros(len(pc), bool)
    mask[np.asarray(g, dtype=np.int64)] = True
    return t, mask


def ground_cases(tmp: Path, with_10m: bool, quick: bool):
    cases = []
    for rel, label, crs in [("isprs_filtertest/samp11.txt", "isprs samp11", "EPSG:32632"),
                            ("isprs_filtertest/samp12.txt", "isprs samp12", "EPSG:32632"),
                            ("lidR/Topography.laz", "lidR Topography", None),
                            ("ahn3_amsterdam/ahn_2386_9702.laz", "AHN3 Amsterdam", "EPSG:28992"),
                            ("ahn4_corridor/07CZ2_14.laz", "AHN4 corridor", "EPSG:28992"),
                            ("pdal_autzen/autzen_trim.las", "Autzen (feet)", None)]:
        p = SHARED / rel
        if p.exists():
            cases.append((label, p, crs, "label" if rel.endswith(".txt") else "class2"))
        else:
            print(f"  (skipping {rel}: ../shared/data is absent)")
    scenes = [("synthetic corridor 1.9M", dict(kind="corridor", seed=1))]
    if with_10m and not quick:
        scenes.append(("synthetic tile 10M", dict(kind="terrain", seed=2, width_m=1000.0, height_m=830.0)))
    for label, kw in scenes:
        path = tmp / (label.replace(" ", "_") + ".laz")
        toolbox.run("synthetic-scene", output=path, overwrite=True, **kw)
        cases.append((label, path, None, "truth"))
    return cases


def bench_ground(tmp: Path, with_10m: bool, quick: bool) -> list[dict]:
    rows = []
    for label, path, crs, truth_kind in ground_cases(tmp, with_10m, quick):
        pc = read_points(path, crs=crs)
        if truth_kind == "label":
            truth = pc.fields["label"] == 0
        elif truth_kind == "truth":
            truth = pc.classification == 2
        else:
            truth = None  # producer classes are not a reference for every file (see notes)
        out = tmp / "ours.tif"
        t_ours, rep = timed(lambda: toolbox.run("dtm", path, out, overwrite=True, crs=crs))
        ours = np.asarray(laspy.read(tmp / "ours_classified.laz").classification) == 2
        # whitebox reads LAS/LAZ only (and not compressed point format 6+): give it plain LAS
        las_in = tmp / "peer_input.las"
        from toolbox.io.points import write_points

        write_points(pc, las_in, overwrite=True)
        t_wb, wb = whitebox_ground(las_in, tmp / "wb.las")
        t_csf, csf = csf_ground(pc)
        row = {"case": f"ground/DTM: {label}", "points": len(pc), "ours_s": t_ours,
               "ours_filter_s": rep["stats"]["filter_s"], "whitebox_s": t_wb, "csf_s": t_csf}
        if truth is not None:
            row["ours_total_err_pct"] = ground_errors(truth, ours)["total_pct"]
            if wb is not None:
                row["whitebox_total_err_pct"] = ground_errors(truth, wb)["total_pct"]
            if csf is not None:
                row["csf_total_err_pct"] = ground_errors(truth, csf)["total_pct"]
        rows.append(row)
        print_row(row)
    return rows


def bench_hillshade(tmp: Path) -> list[dict]:
    from affine import Affine

    from toolbox.io.rasters import Raster, write_raster

    yy, xx = np.mgrid[0:3000, 0:3000].astype(np.float32)
    dem = (50 * np.sin(xx / 200) * np.cos(yy / 300) + 0.01 * xx).astype(np.float32)
    write_raster(Raster(dem, Affine(1, 0, 0, 0, -1, 3000), crs=None, nodata=-9999.0), tmp / "dem.tif", overwrite=True)
    t_ours, _ = timed(lambda: toolbox.run("hillshade", tmp / "dem.tif", tmp / "hs.tif", overwrite=True))
    from toolbox_plugins.morph_dtm.core import hillshade

    t_core, _ = timed(lambda: hillshade(dem, 1.0, -1.0))
    t_wb = None
    try:
        import whitebox_workflows as wbw

        wbe = wbw.WbEnvironment()
        wbe.verbose = False
        r = wbe.read_raster(str(tmp / "dem.tif"))
        t_wb, hs = timed(lambda: wbe.hillshade(r) if hasattr(wbe, "hillshade") else None)
    except Exception as exc:  # peer API differences must not stop the bench
        print(f"  whitebox hillshade unavailable: {exc}")
        t_wb = None
    rows = [{"case": "hillshade 3000x3000 in memory", "points": 9_000_000, "ours_s": t_core,
             "whitebox_s": t_wb, "csf_s": None},
            {"case": "hillshade 3000x3000 file to COG + style", "points": 9_000_000, "ours_s": t_ours,
             "whitebox_s": None, "csf_s": None}]
    for row in rows:
        print_row(row)
    return rows


def fmt(v, w=8, d=2):
    return f"{v:{w}.{d}f}" if isinstance(v, (int, float)) and v is not None else f"{'-':>{w}}"


def print_header():
    print(f"{'case':<44} {'points':>10} {'ours s':>8} {'Mpt/s':>6} {'wbw s':>8} {'ratio':>6} {'CSF s':>8} {'ratio':>6}"
          f"  {'err% ours/wbw/CSF':>20}")


def print_row(r):
    ratio_wb = r["whitebox_s"] / r["ours_s"] if r.get("whitebox_s") else None
    ratio_csf = r["csf_s"] / r["ours_s"] if r.get("csf_s") else None
    err = "/".join(fmt(r.get(k), 0, 2).strip() for k in ("ours_total_err_pct", "whitebox_total_err_pct", "csf_total_err_pct")) \
        if "ours_total_err_pct" in r else ""
    print(f"{r['case']:<44} {r['points']:>10,} {fmt(r['ours_s'])} {fmt(r['points'] / r['ours_s'] / 1e6, 6)} "
          f"{fmt(r.get('whitebox_s'))} {fmt(ratio_wb, 6)} {fmt(r.get('csf_s'))} {fmt(ratio_csf, 6)}  {err:>20}", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="small inputs only")
    ap.add_argument("--no-10m", action="store_true", help="skip the 10-million-point synthetic tile")
    args = ap.parse_args(argv)
    out_dir = ROOT / "bench-output"
    out_dir.mkdir(exist_ok=True)
    print("ours = end to end (read, filter, DTM, write GeoTIFF + classified LAZ); whitebox = file to file; "
          "CSF = filter on arrays only. ratio = peer s / ours s.")
    print_header()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rows += bench_ground(tmp, not args.no_10m, args.quick)
        rows += bench_hillshade(tmp)
    (out_dir / "results.json").write_text(json.dumps(rows, indent=2))
    print(f"results in {out_dir / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

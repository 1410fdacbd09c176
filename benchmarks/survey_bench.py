"""Survey runs at growing size: peak memory of the driver and of each worker, and throughput with
1 and 2 local workers and a 2-worker Dask LocalCluster (issue #19).

A synthetic survey of up to ten 640 m x 640 m terrain files (about 5 M points each, in a row of
five by two; cached in bench-output/cache/survey), run as the survey of its first 1, 3 and 10
files: `toolbox run dtm FILES -o OUT --tile-size-m 320` in a fresh process each time, so the
driver's peak is the run's own. Memory should stay flat while the survey grows: a worker holds
one tile and its buffer, the driver the catalog and the manifest.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "bench-output" / "cache" / "survey"
FILE_M = 640.0
TILE_M = 320.0
COLUMNS = 5
TOOLBOX = [str(Path(sys.executable).parent / "toolbox")]  # the console script of this environment


def survey_files(n: int = 10, density_ppm2: float = 12.0) -> list[Path]:
    """The survey's files (generated once, two at a time, then reused)."""
    CACHE.mkdir(parents=True, exist_ok=True)

    def make(i: int) -> Path:
        path = CACHE / f"terrain_{i:02d}.laz"
        if not path.exists():
            part = path.with_suffix(".part.laz")
            col, row = i % COLUMNS, i // COLUMNS
            subprocess.run([*TOOLBOX, "run", "synthetic-scene", "-o", str(part), "--quiet", "--overwrite",
                            "--set", "kind=terrain", "--set", f"seed={100 + i}",
                            "--set", f"width_m={FILE_M}", "--set", f"height_m={FILE_M}",
                            "--set", f"density_ppm2={density_ppm2}",
                            "--set", f"origin_x={512000.0 + col * FILE_M}",
                            "--set", f"origin_y={5403000.0 + row * FILE_M}"], check=True, capture_output=True)
            for extra in part.parent.glob(part.stem.replace(".part", "") + ".part*"):
                if extra != part:
                    extra.unlink()  # the truth files next to it: not needed here
            part.rename(path)
        return path

    with ThreadPoolExecutor(2) as pool:
        return list(pool.map(make, range(n)))


def merged_file(files: list[Path]) -> Path:
    """The survey's files as one LAZ (cached), written a chunk at a time: the reference run."""
    import laspy

    path = CACHE / f"merged_{len(files):02d}.laz"
    if path.exists():
        return path
    part = path.with_suffix(".part.laz")
    with laspy.open(files[0]) as first:
        header = first.header
    with laspy.open(part, mode="w", header=laspy.LasHeader(point_format=header.point_format,
                                                           version=header.version)) as out:
        out.header.scales, out.header.offsets = header.scales, header.offsets
        for f in files:
            with laspy.open(f) as r:
                for chunk in r.chunk_iterator(1_000_000):
                    out.write_points(chunk)
    part.rename(path)
    return path


def run_whole_cli(path: Path, out: Path) -> dict:
    """One plain run over the merged file, in a fresh process (its peak is its own)."""
    out.mkdir(parents=True, exist_ok=True)
    cmd = [*TOOLBOX, "run", "dtm", str(path), "-o", str(out / "dtm.tif"), "--json", "--quiet", "--overwrite"]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    if r.returncode != 0:
        raise RuntimeError(f"whole run failed: {r.stderr.strip()[-500:]}")
    return {"seconds": time.perf_counter() - t0}


def run_survey_cli(files: list[Path], out: Path, workers: int | None = None, scheduler: str | None = None,
                   tile_m: float = TILE_M) -> dict:
    cmd = [*TOOLBOX, "run", "dtm", *map(str, files), "-o", str(out), "--tile-size-m", str(tile_m),
           "--json", "--quiet", "--overwrite"]
    cmd += ["--scheduler", scheduler] if scheduler else ["--workers", str(workers)]
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    if r.returncode != 0:
        raise RuntimeError(f"survey run failed: {r.stderr.strip()[-500:]}")
    rep = json.loads(r.stdout)
    tiles = json.loads((out / "survey.json").read_text())["tiles"].values()
    rep["max_tile_points"] = max(t.get("stats", {}).get("n_points", 0) for t in tiles)
    stats = [t.get("stats", {}) for t in tiles]
    rep["decoded_points"] = rep["execution"]["split"]["n_decoded_points"] + sum(t.get("n_decoded_points", 0) for t in stats)
    rep["read_per_box_point"] = sum(t.get("n_read_points", 0) for t in stats) / max(1, sum(t.get("n_points", 0) for t in stats))
    return rep


def bench_survey(tmp: Path, quick: bool = False) -> list[dict]:
    sizes = (1, 3) if quick else (1, 3, 10)
    files = survey_files(max(sizes))
    rows = []
    print("\nsurvey runs: dtm over 640 m terrain files (~5 M points each), 320 m tiles, buffer as declared; "
          "peak RSS of the driver and the largest worker (MB); Mpt/s = survey points / wall seconds")
    print("  whole s: one plain run over the survey merged into one file, in the same bench run; ratio = survey / "
          "whole; decoded = points decoded from LAZ / survey points; read = records read / points in tiles' boxes")
    print(f"{'case':40s} {'points':>11s} {'tiles':>5s} {'tile+buf pts':>12s} {'seconds':>8s} {'whole s':>7s} "
          f"{'ratio':>5s} {'Mpt/s':>6s} {'decoded':>7s} {'read':>5s} {'driver MB':>9s} {'worker MB':>9s}")

    def row(case, rep, whole=None):
        ex, n = rep["execution"], rep["survey"]["n_points"]
        secs = rep["timings_s"]["total"]
        r = {"case": case, "points": n, "tiles": rep["n_tiles"], "max_tile_points": rep["max_tile_points"],
             "seconds": secs, "mpts_per_s": n / secs / 1e6, "driver_peak_rss_mb": ex["driver_peak_rss_mb"],
             "worker_peak_rss_mb": max(ex["worker_peak_rss_mb"].values()),
             "workers_seen": len(ex["worker_peak_rss_mb"]), "decoded_per_point": rep["decoded_points"] / n,
             "read_per_box_point": rep["read_per_box_point"],
             "whole_seconds": whole["seconds"] if whole else None,
             "ratio_to_whole": secs / whole["seconds"] if whole else None}
        w = f"{whole['seconds']:7.1f} {r['ratio_to_whole']:5.2f}" if whole else f"{'':7s} {'':5s}"
        print(f"{case:40s} {n:11,d} {r['tiles']:5d} {r['max_tile_points']:12,d} {secs:8.1f} {w} "
              f"{r['mpts_per_s']:6.2f} {r['decoded_per_point']:7.2f} {r['read_per_box_point']:5.2f} "
              f"{r['driver_peak_rss_mb']:9.0f} {r['worker_peak_rss_mb']:9.0f}", flush=True)
        rows.append(r)

    for k in sizes:
        whole = run_whole_cli(merged_file(files[:k]), tmp / f"whole_{k}")
        row(f"survey {k:2d}x, 2 local workers", run_survey_cli(files[:k], tmp / f"survey_{k}", workers=2), whole)
    k = 3
    row(f"survey {k:2d}x, 500 m tiles, 2 workers", run_survey_cli(files[:k], tmp / "survey_500", workers=2, tile_m=500.0),
        run_whole_cli(merged_file(files[:k]), tmp / "whole_500"))
    row(f"survey {k:2d}x, 1 local worker", run_survey_cli(files[:k], tmp / "survey_w1", workers=1))
    try:
        import distributed
    except ImportError:
        print("  (dask.distributed not installed: no cluster row; pip install '.[cluster]')")
        return rows
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        row(f"survey {k:2d}x, 2-worker Dask LocalCluster",
            run_survey_cli(files[:k], tmp / "survey_dask", scheduler=cluster.scheduler_address))
    base = [r for r in rows if r["case"].startswith(f"survey {sizes[0]:2d}x")][0]
    top = rows[len(sizes) - 1]
    print(f"  growth {sizes[0]}x -> {sizes[-1]}x: points x{top['points'] / base['points']:.1f}, driver peak "
          f"x{top['driver_peak_rss_mb'] / base['driver_peak_rss_mb']:.2f}, worker peak "
          f"x{top['worker_peak_rss_mb'] / base['worker_peak_rss_mb']:.2f}")
    return rows


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        bench_survey(Path(d), quick="--quick" in sys.argv)

"""The power-line chain's golden outputs (#76): a guard for restructuring that must not change results.

Runs `powerlines` at default parameters on eight synthetic scenes (one per kind of line: corridor,
ribbon, stacked, distribution, mobile, joint-use, slope, bundle; generator seed 1) and on the real
files in ../shared (the two AHN4 corridor tiles as delivered, the eight Oakland street scans), and
hashes everything a run writes: every GeoPackage layer (geometry as WKB and every attribute, in
row order), the classified cloud's classes, and the report's stats other than timings.

    python benchmarks/powerlines_golden.py record   # writes benchmarks/golden/powerlines.json
    python benchmarks/powerlines_golden.py check    # exit 1 and the differences when any output moved

Hashes are exact: a restructuring that reorders a floating-point sum shows here, as it should.
They hold on the machine they were recorded on (numpy, GEOS and taichi builds fixed).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
GOLDEN = ROOT / "benchmarks" / "golden" / "powerlines.json"
SCENES = ("corridor", "ribbon", "stacked", "distribution", "mobile_dist", "comm2", "slope25", "bundle3")
STAMPS = ("update_time",)  # when a style was written (layer_styles): not a result
REAL = tuple(f"ahn4_corridor/{n}.laz" for n in ("07CZ2_14", "12AN2_20")) + tuple(
    f"oakland_mls/oakland_part{n}.laz" for n in ("3_an", "3_ak", "2_ai", "2_aj", "2_ag", "2_al", "2_ae", "3_aj"))


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def layer_hashes(gpkg: Path) -> dict:
    """Per layer: rows, and a hash of its geometries (WKB) and of its attributes (exact repr)."""
    import geopandas as gpd
    import pyogrio

    out = {}
    for name, _ in pyogrio.list_layers(gpkg):
        df = gpd.read_file(gpkg, layer=name)
        has_geometry = isinstance(df, gpd.GeoDataFrame) and df._geometry_column_name in df
        geom = b"".join(g.wkb if g is not None else b"-" for g in df.geometry) if has_geometry else b""
        attrs = df.drop(columns=df.geometry.name) if has_geometry else df
        attrs = attrs.drop(columns=[c for c in STAMPS if c in attrs])
        text = json.dumps([list(attrs.columns)] + [[repr(v) for v in row] for row in attrs.itertuples(index=False)])
        out[name] = {"rows": len(df), "geometry": _sha(geom), "attributes": _sha(text.encode())}
    return out


def one(job) -> tuple[str, dict]:
    import laspy

    import toolbox

    name, work = job
    work = Path(work)
    if name in SCENES:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from powerline_family import VARIANTS

        src = work / f"{name}_s1.laz"
        if not src.exists():
            toolbox.run("synthetic-scene", output=src, overwrite=True, kind="corridor", seed=1, **VARIANTS[name])
    else:
        src = SHARED / name
        if not src.exists():
            return name, {"skipped": f"{src} is absent"}
    stem = name.replace("/", "_").removesuffix(".laz")
    gpkg, cls = work / "out" / f"{stem}.gpkg", work / "out" / f"{stem}_cls.laz"
    gpkg.parent.mkdir(parents=True, exist_ok=True)
    rep = toolbox.run("powerlines", src, gpkg, overwrite=True, outputs={"classified": cls})
    stats = {k: v for k, v in rep["stats"].items() if not k.endswith("_s")}
    classes = np.asarray(laspy.read(cls).classification)
    return name, {"layers": layer_hashes(gpkg), "classes": _sha(classes.tobytes()),
                  "classes_count": {int(c): int(n) for c, n in zip(*np.unique(classes, return_counts=True))},
                  "stats": stats}


def run_all(work: Path, jobs: int) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    names = SCENES + REAL
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        return dict(pool.map(one, [(n, str(work)) for n in names]))


def differences(old: dict, new: dict, path: str = "") -> list[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new), key=str):
            out += differences(old.get(k, "<absent>"), new.get(k, "<absent>"), f"{path}/{k}")
        return out
    return [] if old == new else [f"{path}: {old} -> {new}"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=("record", "check"))
    ap.add_argument("--work", default=str(ROOT / "bench-output" / "golden"), help="scenes and outputs")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    result = run_all(Path(args.work), args.jobs)
    if args.mode == "record":
        GOLDEN.parent.mkdir(parents=True, exist_ok=True)
        GOLDEN.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
        print(f"recorded {len(result)} runs in {GOLDEN} (digest {_sha(GOLDEN.read_bytes())})")
        return 0
    diff = differences(json.loads(GOLDEN.read_text()), json.loads(json.dumps(result, sort_keys=True)))
    for line in diff:
        print(line)
    print(f"{len(result)} runs: " + ("identical to the golden outputs" if not diff else f"{len(diff)} differences"))
    return 1 if diff else 0


if __name__ == "__main__":
    raise SystemExit(main())

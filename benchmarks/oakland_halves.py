"""The eight Oakland street scans of ../shared in two fixed halves, for #77's protocol: change a
rule looking at one half only, then score the other; never tune to a scan reported as evidence.

    python benchmarks/oakland_halves.py [--set name=value ...]

Prints per scan the wire points (class 14 against CMU's wire labels) found, P and R, the false
ones and the CMU labels they carry; then each half pooled and all eight pooled (#77's targets:
P >= 0.92, R >= 0.90, at most 20 false wire points on a scan without wires)."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import laspy
import numpy as np

import toolbox

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "oakland_mls"
# each half holds a scan without wires, one the defaults were built on, and the rest
HALVES = {"develop": ("2_ae", "2_al", "2_aj", "3_ak"), "check": ("3_aj", "2_ag", "2_ai", "3_an")}


def score(scan: str, params: dict, tmp: Path) -> tuple[int, int, int]:
    path = DATA / f"oakland_part{scan}.laz"
    toolbox.run("powerlines", path, tmp / f"{scan}.gpkg", overwrite=True,
                outputs={"classified": tmp / f"{scan}_c.laz"}, **params)
    las = laspy.read(path)
    truth = np.asarray(las.classification) == 14
    found = np.asarray(laspy.read(tmp / f"{scan}_c.laz").classification) == 14
    tp, fp, fn = int((truth & found).sum()), int((found & ~truth).sum()), int((truth & ~found).sum())
    labels = dict(zip(*np.unique(np.asarray(las.cmu_label)[found & ~truth], return_counts=True)))
    print(f"  part{scan}: {int(truth.sum())} wire points, found {int(found.sum())}: P {tp / max(tp + fp, 1):.3f} "
          f"R {tp / max(tp + fn, 1):.3f}, {fp} false (CMU labels {({int(k): int(v) for k, v in labels.items()})})")
    return tp, fp, fn


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a powerlines parameter")
    args = ap.parse_args(argv)
    if not DATA.exists():
        print(f"the Oakland scans are absent (expected in {DATA})")
        return 1
    params = {}
    for item in args.set:
        k, v = item.split("=", 1)
        params[k] = {"true": True, "false": False}.get(v.lower(), v)
    total = np.zeros(3, np.int64)
    with tempfile.TemporaryDirectory() as d:
        for half, scans in HALVES.items():
            print(f"{half} half:")
            got = np.sum([score(s, params, Path(d)) for s in scans], axis=0)
            total += got
            tp, fp, fn = got
            print(f"  pooled: P {tp / max(tp + fp, 1):.3f} R {tp / max(tp + fn, 1):.3f}")
    tp, fp, fn = total
    print(f"all eight pooled: P {tp / max(tp + fp, 1):.3f} R {tp / max(tp + fn, 1):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The demo behind `make demo`: generate the default synthetic corridor scene, run every
algorithm on it through the public API, compare with the scene's exact truth and draw a picture.

    python examples/demo.py --out demo-output
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import laspy
import numpy as np

import toolbox
from toolbox.io.rasters import Raster, read_raster, write_image

# class colours of the overview picture (ASPRS)
COLOURS = {1: (150, 150, 150), 2: None, 3: (170, 220, 120), 4: (90, 180, 80), 5: (30, 120, 50),
           6: (210, 70, 60), 7: (40, 80, 255), 9: (80, 160, 230), 14: (255, 200, 0), 15: (255, 120, 0), 17: (160, 90, 200)}


def step(name, fn, report):
    t = time.perf_counter()
    out = fn()
    report["timings_s"][name] = round(time.perf_counter() - t, 2)
    print(f"  {name:<16} {report['timings_s'][name]:6.2f} s")
    return out


def draw(hs_path: Path, classified: Path, out_png: Path, wires: Path | None = None):
    hs = read_raster(hs_path)
    base = hs.data.astype(np.float32)
    t = hs.transform
    rgb = np.repeat(base[..., None], 3, axis=2) * 0.9 + 20
    las = laspy.read(classified)
    x, y, z, c = np.asarray(las.x), np.asarray(las.y), np.asarray(las.z), np.asarray(las.classification).copy()
    if wires is not None:  # the conductors found by `powerlines` drawn as wires (class 14)
        c[np.asarray(laspy.read(wires).classification) == 14] = 14
    col = ((x - t.c) / t.a).astype(int).clip(0, base.shape[1] - 1)
    row = ((t.f - y) / -t.e).astype(int).clip(0, base.shape[0] - 1)
    order = np.argsort(z)  # highest point per cell drawn last
    for cls, colour in COLOURS.items():
        if colour is None:
            continue
        sel = order[c[order] == cls]
        if len(sel):
            rgb[row[sel], col[sel]] = 0.25 * rgb[row[sel], col[sel]] + 0.75 * np.array(colour, np.float32)
    # georeferenced (world file + CRS): it opens in place over the map in QGIS
    write_image(Raster(np.moveaxis(np.clip(rgb, 0, 255).astype(np.uint8), -1, 0), t, crs=hs.crs), out_png,
                overwrite=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default="demo-output")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    algs = toolbox.algorithms()
    report = {"timings_s": {}, "algorithms_run": []}
    print(f"lidar-toolbox demo: {len(algs)} algorithms available ({', '.join(algs)})")
    print("steps:")
    scene = out / "scene.laz"
    step("synthetic-scene", lambda: toolbox.run("synthetic-scene", output=scene, overwrite=True, seed=args.seed), report)
    report["algorithms_run"].append("synthetic-scene")
    truth = json.loads((out / "scene_truth.json").read_text())
    las = laspy.read(scene)
    truth_cls = np.asarray(las.classification)
    print(f"  scene: {len(truth_cls):,} points, {len(truth['buildings'])} buildings, {len(truth['trees'])} trees, "
          f"{len(truth['wires'])} wires on {len(truth['pylons'])} pylons, {len(truth['crossings'])} crossings")

    summary = {}
    if "dtm" in algs:
        rep = step("dtm", lambda: toolbox.run("dtm", scene, out / "dtm.tif", overwrite=True,
                                             outputs={"preview": str(out / "dtm_preview.png")}), report)
        report["algorithms_run"].append("dtm")
        pred = np.asarray(laspy.read(out / "dtm_classified.laz").classification)
        from toolbox_plugins.morph_dtm.evaluation import ground_errors

        e = ground_errors(truth_cls == 2, pred == 2)
        d = read_raster(out / "dtm.tif").data.astype(float) - read_raster(out / "scene_dtm.tif").data
        summary["ground total error %"] = e["total_pct"]
        summary["ground kappa"] = e["kappa"]
        summary["DTM RMSE m (1 m cells)"] = round(float(np.sqrt(np.nanmean(d ** 2))), 3)
        summary["dtm points/s"] = round(len(truth_cls) / rep["timings_s"]["total"])
    if "hillshade" in algs and (out / "dtm.tif").exists():
        step("hillshade", lambda: toolbox.run("hillshade", out / "dtm.tif", out / "hillshade.tif", overwrite=True,
                                              multidirectional=True), report)
        report["algorithms_run"].append("hillshade")
    if "classify" in algs:
        step("classify", lambda: toolbox.run("classify", scene, out / "classified.laz", overwrite=True), report)
        report["algorithms_run"].append("classify")
        pred = np.asarray(laspy.read(out / "classified.laz").classification)
        obj = np.isin(truth_cls, [3, 4, 5, 6])
        ok = np.where(truth_cls[obj] == 6, pred[obj] == 6, np.isin(pred[obj], [3, 4, 5]))
        b, pb = truth_cls == 6, pred == 6
        summary["building/vegetation correct %"] = round(100 * float(ok.mean()), 2)
        summary["vegetation class (low/med/high) correct %"] = round(
            100 * float(np.mean(pred[np.isin(truth_cls, [3, 4, 5])] == truth_cls[np.isin(truth_cls, [3, 4, 5])])), 2)
        summary["building precision"] = round(float((b & pb).sum() / max(pb.sum(), 1)), 3)
        summary["building recall"] = round(float((b & pb).sum() / max(b.sum(), 1)), 3)
    if "powerlines" in algs:
        rep = step("powerlines", lambda: toolbox.run("powerlines", scene, out / "powerlines.gpkg", overwrite=True,
                                                    outputs={"classified": str(out / "powerlines_wires.laz")}), report)
        report["algorithms_run"].append("powerlines")
        import geopandas as gpd

        cond = gpd.read_file(out / "powerlines.gpkg", layer="conductors")
        cross = gpd.read_file(out / "powerlines.gpkg", layer="crossings")
        found = 0
        for t in truth["conductor_lines_2d"]:
            a, b = np.array(t["a"]), np.array(t["b"])
            td = (b - a) / np.linalg.norm(b - a)
            for g in cond.geometry:
                (ax, ay), (bx, by) = g.coords[0], g.coords[-1]
                d = np.array([bx - ax, by - ay]) / g.length
                if abs(d @ td) > np.cos(np.radians(0.5)) and abs((ax - a[0]) * -td[1] + (ay - a[1]) * td[0]) < 0.1:
                    found += 1
                    break
        errs = [float(np.min(np.hypot(cross.geometry.x - c["x"], cross.geometry.y - c["y"]))) if len(cross) else np.inf
                for c in truth["crossings"]]
        wires = np.asarray(laspy.read(out / "powerlines_wires.laz").classification) == 14
        tw = truth_cls == 14
        summary["conductors found (2D lines)"] = f"{found}/{len(truth['conductor_lines_2d'])} (+{len(cond) - found} false)"
        summary["wires in 3D"] = f"{rep['stats']['n_wires_3d']} (truth {len(truth['wires'])})"
        summary["crossings found"] = f"{sum(e <= 0.05 for e in errs)}/{len(errs)}"
        summary["crossing error max m"] = round(max(errs), 3) if errs else None
        summary["wire points precision / recall"] = (f"{(wires & tw).sum() / max(wires.sum(), 1):.3f} / "
                                                     f"{(wires & tw).sum() / max(tw.sum(), 1):.3f}")
        pyl = gpd.read_file(out / "powerlines.gpkg", layer="pylons")
        near = [float(np.min(np.hypot(pyl.geometry.x - p["x"], pyl.geometry.y - p["y"]))) if len(pyl) else np.inf
                for p in truth["pylons"]]
        false = sum(float(np.min([np.hypot(x - p["x"], y - p["y"]) for p in truth["pylons"]])) > 2.0
                    for x, y in zip(pyl.geometry.x, pyl.geometry.y))
        summary["pylons found within 2 m"] = f"{sum(d <= 2.0 for d in near)}/{len(near)} (+{false} false)"
        summary["powerlines s per million points"] = round(rep["timings_s"]["total"] / len(truth_cls) * 1e6, 2)
    if "powerlines" in report["algorithms_run"]:  # its stages ran through the host
        report["algorithms_run"] += [a for a in ("tophat", "hough-lines") if a in algs]
    missing = sorted(set(algs) - set(report["algorithms_run"]) - {"tophat-raster"})
    if missing:
        print(f"  (not part of the demo chain: {', '.join(missing)})")
    if (out / "hillshade.tif").exists() and (out / "classified.laz").exists():
        draw(out / "hillshade.tif", out / "classified.laz", out / "overview.png",
             out / "powerlines_wires.laz" if (out / "powerlines_wires.laz").exists() else None)
    report["found_vs_truth"] = summary
    (out / "demo_report.json").write_text(json.dumps(report, indent=2))
    print("found versus truth:")
    for k, v in summary.items():
        print(f"  {k:<42} {v}")
    print(f"outputs in {out.resolve()}/:")
    for p in sorted(out.iterdir()):
        if p.is_file():
            print(f"  {p.name:<28} {p.stat().st_size / 1e6:8.2f} MB")
    print("open the .tif and .gpkg files in QGIS: they come styled (sidecar .qml, embedded layer styles); "
          "overview.png shows the classes over the hillshade (georeferenced, it opens in place)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

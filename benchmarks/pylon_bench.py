"""pylon-pose bench: the rendered similarity A_s, taichi kernel against its numpy reference on the
same photo descriptor and the same candidate poses (a lattice tower of a few hundred beams, a
2400 x 1600 photo from 120 m with the tower's segments and 1500 clutter segments, 8 px cells).
Prints candidate poses scored per second by each, the ratio, and whether the scores agree."""

from __future__ import annotations

import time

import numpy as np


def lattice_tower(height_m=30.0, base_m=8.0, top_m=2.0, panels=8, arm_m=8.0):
    """Beams (ends A, B) of a square lattice tower with X bracing on every face and two cross arms."""
    segs = []
    zs = np.linspace(0.0, height_m * 0.75, panels + 1)
    half = np.interp(zs, [0.0, zs[-1]], [base_m / 2, top_m / 2])
    corners = [np.array([[sx * h, sy * h, z] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]) for z, h in zip(zs, half)]
    for lo, hi in zip(corners[:-1], corners[1:]):
        for k in range(4):
            j = (k + 1) % 4
            segs += [(lo[k], hi[k]), (hi[k], hi[j]), (lo[k], hi[j]), (lo[j], hi[k])]
    top = corners[-1]
    for sx in (-1, 1):  # the arms
        tip = np.array([sx * (top_m / 2 + arm_m), 0.0, zs[-1]])
        segs += [(top[k], tip) for k in range(4)]
    apex = np.array([0.0, 0.0, height_m])
    segs += [(top[k], apex) for k in range(4)]
    a = np.array([s[0] for s in segs], np.float32)
    b = np.array([s[1] for s in segs], np.float32)
    return a, b


def bench_pylon(n_poses: int = 4096, n_reference: int = 128) -> list[dict]:
    from toolbox.kernels import arch_used, taichi
    from toolbox_plugins.pylon_pose import core, reference
    from toolbox_plugins.pylon_pose.kernels import TaichiSimilarity

    A, B = lattice_tower()
    K = np.array([[2400.0, 0, 1200], [0, 2400, 800], [0, 0, 1]])
    centre = np.array([40.0, -100.0, 70.0])
    z = np.array([0.0, 0.0, 15.0]) - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    t = -R @ centre
    truth = core.pose_matrices(K, R, t, 0.0, 0.0, 0.0, 20.0)
    ua, va, _ = reference.project_fixed(truth, A)
    ub, vb, _ = reference.project_fixed(truth, B)
    rng = np.random.default_rng(0)
    start = rng.uniform(0, 1, (1500, 2)) * [2400, 1600]
    ang = rng.uniform(0, np.pi, 1500)
    length = rng.uniform(10, 80, 1500)
    clutter = np.column_stack([start, start + np.column_stack([np.cos(ang), np.sin(ang)]) * length[:, None]])
    photo = np.vstack([np.column_stack([ua[0], va[0], ub[0], vb[0]]) / reference.SUBPIXEL, clutter])
    b, table = core.photo_descriptor(photo, (2400, 1600), cell_px=8)
    P = core.pose_matrices(K, R, t, rng.normal(0, 1.5, n_poses), rng.normal(0, 1.5, n_poses),
                           rng.normal(0, 0.5, n_poses), 20.0 + rng.normal(0, 3.0, n_poses),
                           rng.normal(0, 0.2, n_poses), rng.normal(0, 0.2, n_poses))
    kernel = TaichiSimilarity(taichi())
    kernel(b, P[:8], A, B, 8, table)  # compile
    t_ti = min(_timed(lambda: kernel(b, P, A, B, 8, table))[0] for _ in range(3))
    got = kernel(b, P, A, B, 8, table)
    t_np, ref = _timed(lambda: reference.similarity(b, P[:n_reference], A, B, 8, table))
    rate_ti, rate_np = n_poses / t_ti, n_reference / t_np
    equal = bool(np.array_equal(got[:n_reference], ref))
    print(f"  similarity A_s, {len(A)} beams x {n_poses:,} poses on {arch_used()}: taichi {rate_ti:,.0f} poses/s "
          f"({t_ti * 1e3:.1f} ms), numpy reference {rate_np:,.0f} poses/s ({n_reference} poses, {t_np:.2f} s): "
          f"{rate_ti / rate_np:.0f}x; scores equal: {equal}", flush=True)
    return [{"case": "pylon-pose similarity", "arch": arch_used(), "beams": len(A), "poses": n_poses,
             "taichi_poses_per_s": rate_ti, "reference_poses_per_s": rate_np, "ratio": rate_ti / rate_np,
             "equal": equal}]


def _timed(fn):
    t = time.perf_counter()
    out = fn()
    return time.perf_counter() - t, out


def bench_search(seeds=(2, 3, 4), n_pylons: int = 3, photos_per_pylon: int = 10, perturbed=((2, 0.05, 0.05),),
                 hypotheses=("grid", "triangles")) -> list[dict]:
    """The whole pylon-pose run on synthetic photo surveys the tests do not use, once per way of
    making the first hypotheses (``hypotheses``): per pylon the position, height, heading and tilt
    errors against the truth, false pylons, seconds per photo.
    ``perturbed``: (seed, metres, degrees) runs whose COLMAP cameras carry an alignment's error, each
    centre moved and each orientation turned by exactly that much in a random direction."""
    import json
    import tempfile
    from pathlib import Path

    import geopandas as gpd

    from toolbox.runner import run_algorithm
    from toolbox_plugins.pylon_pose.core import rotation

    from toolbox.io.cameras import read_colmap, write_colmap
    from toolbox_plugins.synthetic_scene.generator.pylons import perturb_images

    rows = []
    for seed, shift_m, turn_deg in [(s_, 0.0, 0.0) for s_ in seeds] + list(perturbed):
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            run_algorithm("synthetic-scene", [], d, {"kind": "pylons", "seed": seed, "n_pylons": n_pylons,
                                                     "photos_per_pylon": photos_per_pylon})
            cams = d / "colmap"
            label = f"seed {seed}"
            if shift_m or turn_deg:
                cameras, images = read_colmap(cams)
                cams = d / "colmap_perturbed"
                cams.mkdir()
                write_colmap(cams, cameras, perturb_images(images, shift_m, turn_deg, seed=seed))
                label = f"seed {seed} cameras off {shift_m} m {turn_deg} deg"
            for how in hypotheses:
                t0 = time.perf_counter()
                rep = run_algorithm("pylon-pose", {"photos": str(d / "photos"), "cameras": str(cams),
                                                   "dem": str(d / "points_dem.tif")}, d / f"found_{how}.gpkg",
                                    {"hypotheses": how})
                secs = time.perf_counter() - t0
                truth = json.loads((d / "points_truth.json").read_text())["pylons"]
                got = gpd.read_file(d / f"found_{how}.gpkg", layer="pylons")
                matched = 0
                for p in truth:
                    dist = np.hypot(got.geometry.x - p["x"], got.geometry.y - p["y"]) if len(got) else np.array([np.inf])
                    i = int(np.argmin(dist))
                    if dist[i] > 2.0:
                        print(f"  {label} {how} {p['model']}: MISSED", flush=True)
                        continue
                    matched += 1
                    r, sym = got.iloc[i], p["symmetry_deg"]
                    dh = (r.heading_deg - p["heading_deg"] + sym / 2) % sym - sym / 2
                    # tilt: the angle between the found and the true vertical axes of the model (a symmetric
                    # type found 180 degrees round has pitch and roll of the opposite sign, and the same axis)
                    up = [rotation(h_, p_, r_)[:, 2] for h_, p_, r_ in ((r.heading_deg, r.pitch_deg, r.roll_deg),
                                                                         (p["heading_deg"], p["pitch_deg"], p["roll_deg"]))]
                    tilt = float(np.degrees(np.arccos(np.clip(up[0] @ up[1], -1.0, 1.0))))
                    row = {"case": "pylon-pose search", "seed": seed, "cameras_off_m": shift_m, "cameras_off_deg": turn_deg,
                           "hypotheses": how, "model": p["model"], "found_as": r.model,
                           "xy_m": float(dist[i]), "z_m": float(r.geometry.z - p["z"]), "heading_deg": float(dh),
                           "tilt_deg": tilt, "score": float(r.score), "rms_px": float(r.rms_px)}
                    rows.append(row)
                    print(f"  {label} {how} {p['model']:5s} (as {r.model}): xy {row['xy_m']:.3f} m, z {row['z_m']:+.3f} m, "
                          f"heading {dh:+.3f} deg, tilt {tilt:.3f} deg, score {r.score:.3f}, rms {r.rms_px:.2f} px", flush=True)
                n_photos = rep["stats"]["n_photos"]
                print(f"  {label} {how}: {matched} of {len(truth)} pylons found, {len(got) - matched} false, "
                      f"{rep['stats'].get('n_candidates')} candidates; {secs:.1f} s for {n_photos} photos = "
                      f"{secs / n_photos:.2f} s per photo", flush=True)
                rows.append({"case": "pylon-pose run", "seed": seed, "cameras_off_m": shift_m, "hypotheses": how,
                             "found": matched, "truth": len(truth), "false": len(got) - matched,
                             "s_per_photo": secs / n_photos})
    return rows


if __name__ == "__main__":
    bench_pylon()
    bench_search()

"""pylon-pose bench: the rendered similarity A_s, taichi kernel against its numpy reference on the
same photo descriptor and the same candidate poses (a lattice tower of a few hundred beams, a
2400 x 1600 photo from 120 m with the tower's segments and 1500 clutter segments, 8 px cells).
Prints candidate poses scored per second by each, the ratio, and whether the scores agree."""

from __future__ import annotations

import time
from pathlib import Path

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


def _score(d: Path, out: Path, label: str, how: str) -> tuple[list[dict], int, int, int]:
    """Per truth pylon the errors of the found one (within 2 m): xy, z, heading, tilt (the angle
    between the found and the true vertical axes), the tilt's size; (rows, matched, false, truth)."""
    import json

    import geopandas as gpd

    from toolbox_plugins.pylon_pose.core import rotation

    truth = json.loads((d / "points_truth.json").read_text())["pylons"]
    got = gpd.read_file(out, layer="pylons")
    rows, matched = [], 0
    for p in truth:
        dist = np.hypot(got.geometry.x - p["x"], got.geometry.y - p["y"]) if len(got) else np.array([np.inf])
        i = int(np.argmin(dist))
        if dist[i] > 2.0:
            print(f"  {label} {how} {p['model']}: MISSED", flush=True)
            continue
        matched += 1
        r, sym = got.iloc[i], p["symmetry_deg"]
        dh = (r.heading_deg - p["heading_deg"] + sym / 2) % sym - sym / 2
        # a symmetric type found 180 degrees round has pitch and roll of the opposite sign, and the same axis
        up = [rotation(h_, p_, r_)[:, 2] for h_, p_, r_ in ((r.heading_deg, r.pitch_deg, r.roll_deg),
                                                             (p["heading_deg"], p["pitch_deg"], p["roll_deg"]))]
        tilt = float(np.degrees(np.arccos(np.clip(up[0] @ up[1], -1.0, 1.0))))
        rows.append({"model": p["model"], "found_as": r.model, "xy_m": float(dist[i]), "z_m": float(r.geometry.z - p["z"]),
                     "heading_deg": float(dh), "tilt_deg": tilt, "true_tilt_deg": p["tilt_deg"],
                     "found_tilt_deg": float(r.tilt_deg), "leaning": bool(r.leaning), "score": float(r.score),
                     "rms_px": float(r.rms_px), "pose": [float(r.geometry.x), float(r.geometry.y), float(r.geometry.z),
                                                         float(r.heading_deg), float(r.pitch_deg), float(r.roll_deg)]})
        print(f"  {label} {how} {p['model']:5s} (as {r.model}) leaning {p['tilt_deg']:.2f} deg: xy {dist[i]:.3f} m, "
              f"z {rows[-1]['z_m']:+.3f} m, heading {dh:+.3f} deg, tilt error {tilt:.3f} deg (found {r.tilt_deg:.2f}, "
              f"{'leaning' if r.leaning else 'upright'}), score {r.score:.3f}, rms {r.rms_px:.2f} px", flush=True)
    return rows, matched, len(got) - matched, len(truth)


# (seed, lean_deg, lean_direction): the leaning surveys of #79, the middle pylon of three leaning
LEANING = ((6, 2.5, "across"), (8, 5.0, "along"), (10, 1.0, "random"))


def bench_search(seeds=(2, 3, 4), n_pylons: int = 3, photos_per_pylon: int = 10,
                 perturbed=((2, 0.05, 0.05), (2, 0.1, 0.1)), hypotheses=("grid", "triangles"), leaning=LEANING,
                 upright_peer: bool = True, binary_check: bool = True) -> list[dict]:
    """The whole pylon-pose run on synthetic photo surveys the tests do not use, once per way of
    making the first hypotheses (``hypotheses``): per pylon the position, height, heading and tilt
    errors against the truth, false pylons, seconds per photo.
    ``perturbed``: (seed, metres, degrees) runs whose COLMAP cameras carry an alignment's error, each
    centre moved and each orientation turned by exactly that much in a random direction.
    ``leaning``: (seed, degrees, direction) surveys whose middle pylon leans (grid hypotheses).
    ``upright_peer``: each upright survey also with ``max_tilt_deg=0`` (the method's upright
    search, the search before #79): seconds per photo of both and the ratio, same run.
    ``binary_check``: the first seed also from its binary COLMAP model: the largest pose difference."""
    import tempfile

    from toolbox.io.cameras import read_colmap, write_colmap
    from toolbox.runner import run_algorithm
    from toolbox_plugins.synthetic_scene.generator.pylons import perturb_images

    rows = []
    runs = [(s_, 0.0, 0.0, 0.0, "random") for s_ in seeds] + [(s_, m, d_, 0.0, "random") for s_, m, d_ in perturbed]
    runs += [(s_, 0.0, 0.0, lean, direction) for s_, lean, direction in leaning]
    for seed, shift_m, turn_deg, lean, direction in runs:
        with tempfile.TemporaryDirectory() as tmp:
            d = Path(tmp)
            run_algorithm("synthetic-scene", [], d, {"kind": "pylons", "seed": seed, "n_pylons": n_pylons,
                                                     "photos_per_pylon": photos_per_pylon, "lean_deg": lean,
                                                     "lean_share": 0.34 if lean else 0.0, "lean_direction": direction})
            cams = d / "colmap"
            label = f"seed {seed}" + (f" leaning {lean} deg {direction}" if lean else "")
            if shift_m or turn_deg:
                cameras, images = read_colmap(cams)
                cams = d / "colmap_perturbed"
                cams.mkdir()
                write_colmap(cams, cameras, perturb_images(images, shift_m, turn_deg, seed=seed))
                label = f"seed {seed} cameras off {shift_m} m {turn_deg} deg"
            ways = [(h, {"hypotheses": h}, cams) for h in (hypotheses if not lean else ("grid",))]
            if upright_peer and not lean and not shift_m:
                ways.append(("grid upright", {"hypotheses": "grid", "max_tilt_deg": 0.0}, cams))
            if binary_check and seed == seeds[0] and not lean and not shift_m:
                ways.append(("grid binary", {"hypotheses": "grid"}, d / "colmap_bin"))
            found, per_photo = {}, {}
            for how, params, cam_dir in ways:
                out = d / f"found_{how.replace(' ', '_')}.gpkg"
                t0 = time.perf_counter()
                rep = run_algorithm("pylon-pose", {"photos": str(d / "photos"), "cameras": str(cam_dir),
                                                   "dem": str(d / "points_dem.tif")}, out, params)
                secs = time.perf_counter() - t0
                per, matched, false, n_truth = _score(d, out, label, how)
                found[how] = per
                n_photos = rep["stats"]["n_photos"]
                per_photo[how] = secs / n_photos
                for row in per:
                    rows.append({"case": "pylon-pose search", "seed": seed, "cameras_off_m": shift_m,
                                 "cameras_off_deg": turn_deg, "lean_deg": lean, "hypotheses": how, **row})
                print(f"  {label} {how}: {matched} of {n_truth} pylons found, {false} false, "
                      f"{rep['stats'].get('n_candidates')} candidates; {secs:.1f} s for {n_photos} photos = "
                      f"{secs / n_photos:.2f} s per photo", flush=True)
                rows.append({"case": "pylon-pose run", "seed": seed, "cameras_off_m": shift_m, "lean_deg": lean,
                             "hypotheses": how, "found": matched, "false": false, "s_per_photo": secs / n_photos})
            if "grid upright" in found:
                ours, peer = per_photo["grid"], per_photo["grid upright"]
                rows.append({"case": "pylon-pose tilt cost", "seed": seed, "s_per_photo": ours, "upright_s_per_photo": peer,
                             "ratio": ours / peer})
                print(f"  {label}: tilt searched {ours:.2f} s per photo, upright only {peer:.2f}: "
                      f"{ours / peer:.2f}x", flush=True)
            if "grid binary" in found:
                diff = max((np.abs(np.subtract(p["pose"], q["pose"])).max() for p, q in zip(found["grid"], found["grid binary"])),
                           default=float("nan"))
                print(f"  {label}: binary and text COLMAP models, largest pose difference {diff:.2e}", flush=True)
    return rows


if __name__ == "__main__":
    bench_pylon()
    bench_search()

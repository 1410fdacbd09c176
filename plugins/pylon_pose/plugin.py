"""Adapter of ``pylon-pose``: reads the photos, cameras, DEM and pylon models, runs the detection
and the pose search of ``search`` (pure functions; the similarity in ``kernels`` / ``reference``)
and writes the layers. I/O lives here only."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, DataError, Input, Output, Parameter

REFERENCE = ("Serebro (2017), Determining the position and orientation of power-line pylons by computer vision, "
             "master's thesis, St Petersburg Academic University / Geoscan (METHODS.md §4)")


def _views(photos_dir, cameras, images, origin, ctx):
    """Line segments of every photo the cameras name (LSD, undistorted), as search.View."""
    from concurrent.futures import ThreadPoolExecutor
    from pathlib import Path

    import cv2
    import numpy as np

    from .search import View

    folder = Path(photos_dir)
    if not folder.is_dir():
        raise DataError(f"photos {str(folder)!r} is not a folder; give the folder holding the photos the cameras name")
    items = sorted(images.values(), key=lambda i: i.name)
    for im in items:
        if not (folder / im.name).is_file():
            raise DataError(f"photo {im.name!r} of the cameras is missing from {str(folder)!r}; copy it there or remove "
                            "its camera")

    def one(im):
        cam = cameras[im.camera_id]
        gray = cv2.imread(str(folder / im.name), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise DataError(f"photo {str(folder / im.name)!r} cannot be read as an image; replace it")
        if gray.shape != (cam.height, cam.width):
            raise DataError(f"photo {im.name!r} is {gray.shape[1]} x {gray.shape[0]} px but its camera {cam.id} is "
                            f"{cam.width} x {cam.height}; give the photos the cameras were calibrated on")
        lines = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD).detect(gray)[0]
        L = np.empty((0, 4)) if lines is None else lines.reshape(-1, 4).astype(np.float64) + 0.5  # COLMAP pixel centres
        seg = np.hstack([cam.undistort_pixels(L[:, :2]), cam.undistort_pixels(L[:, 2:])]) if len(L) else L
        R = im.R
        return View(im.name, cam.K, R, np.asarray(im.tvec, float) + R @ origin, cam.width, cam.height, seg)

    with ThreadPoolExecutor(max_workers=2) as pool:  # LSD and undistortion run outside the GIL
        futs = [pool.submit(one, im) for im in items]
        return [f.result() for f in ctx.progress(futs, total=len(futs), desc="line segments", unit="photo")]


def _models(path):
    """{name: (A, B, height_m, symmetry_deg)} of the model input, or the built-in library."""
    from toolbox.io.wireframes import read_wireframes, rotational_symmetry_deg

    if path is None:
        from .models import builtin_models

        lib = {n: (m.a, m.b) for n, m in builtin_models().items()}
    else:
        lib = read_wireframes(path)
    out = {}
    for n, (a, b) in lib.items():
        h = float(max(a[:, 2].max(), b[:, 2].max()))
        if h <= 0:
            raise DataError(f"model {n!r} has no height above its origin; its origin must be the centre of the base, z up")
        out[n] = (a, b, h, rotational_symmetry_deg(a, b))
    return out


def _run(inputs, params, ctx):
    import numpy as np

    from toolbox.io.cameras import read_cameras
    from toolbox.kernels import taichi

    from . import search
    from .kernels import TaichiSimilarity

    dem = inputs["dem"]
    if dem.crs is None:
        raise DataError(f"DEM {dem.source or inputs.get('dem')!r} has no CRS; the cameras' world coordinates are in it")
    cameras, images = read_cameras(inputs["cameras"], crs=dem.crs.to_string() if hasattr(dem.crs, "to_string") else dem.crs)
    models = _models(inputs.get("model"))
    centres = np.array([im.centre for im in images.values()])
    origin = np.array([np.median(centres[:, 0]), np.median(centres[:, 1]), 0.0])

    def ground(x, y):
        return dem.sample(np.asarray(x) + origin[0], np.asarray(y) + origin[1])

    t = dem.transform
    rows, cols = dem.shape
    x0, x1 = t.c - origin[0], t.c + t.a * cols - origin[0]
    y1, y0 = t.f - origin[1], t.f + t.e * rows - origin[1]
    for im in sorted(images.values(), key=lambda i: i.name):  # before any photo is read
        K = cameras[im.camera_id].K
        v = search.View(im.name, K, im.R, np.asarray(im.tvec, float) + im.R @ origin, 0, 0, np.empty((0, 4)))
        d = v.rays(K[:2, 2][None])
        c = search.ray_terrain(v.centre, d, ground)[0]
        p = v.centre + c * d[0] if np.isfinite(c) else None
        if p is None or not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            raise DataError(f"the DEM does not cover the view of photo {im.name!r} (its centre ray meets no terrain inside "
                            "the DEM); give a DEM of the whole surveyed area in the cameras' CRS")
    views = _views(inputs["photos"], cameras, images, origin, ctx)
    height = max(m[2] for m in models.values())
    kernel = TaichiSimilarity(taichi())
    stats = {"n_photos": len(views), "model_types": sorted(models), "search_radius_m": params["radius_m"],
             "hypotheses": params["hypotheses"]}
    if inputs.get("rough") is not None:
        layer = next(iter(inputs["rough"].values())) if isinstance(inputs["rough"], dict) else inputs["rough"]
        rough = np.array([[g.x - origin[0], g.y - origin[1], 0.0] for g in layer.geometry if g is not None], float)
        stats["rough_from"] = "input"
    else:
        sides = [search.model_triangle_sides(a, b) for a, b, _, _ in models.values()]
        smin, smax = min(s[0] for s in sides), max(s[1] for s in sides)
        tris = []
        for v in ctx.progress(views, desc="triangles", unit="photo"):
            seg = v.segments
            alpha = search.ray_terrain(v.centre, v.rays(0.5 * (seg[:, :2] + seg[:, 2:])), ground, above_m=height / 2)
            ok = np.isfinite(alpha)
            f = v.K[0, 0]
            if params["detector"] == "triangles":
                tris.append(search.photo_triangles(seg[ok], 0.5 * smin * f / alpha[ok], 2 * smax * f / alpha[ok]))
            else:
                tris.append(search.photo_corners(seg[ok], 2 * smax * f / alpha[ok]))
        per_photo = params["min_per_photo"] or (1 if params["detector"] == "triangles" else 3)
        votes, gx, gy, cell = search.vote_columns(views, tris, ground, height, min_per_photo=per_photo)
        rough = search.column_peaks(votes, gx, gy, cell, min_photos=params["min_photos"])
        # a pylon's joints vote from nearly every photo that sees it; wires and clutter from some
        seen = np.array([search.seen_by(views, r[:2], ground, height) for r in rough])
        rough = rough[rough[:, 2] >= params["min_vote_share"] * np.maximum(seen, 1)]
        stats.update(model_triangle_side_m=[round(smin, 3), round(smax, 3)],
                     detector=params["detector"], min_per_photo=per_photo, min_per_photo_used=per_photo,
                     n_features=int(sum(len(t_) for t_ in tris)), n_candidates=int(len(rough)))
    settings = search.SearchSettings(radius_m=params["radius_m"], mode=params["mode"], min_score=params["min_score"],
                                     hypotheses=params["hypotheses"], max_tilt_deg=params["max_tilt_deg"],
                                     min_photo_share=params["min_photo_share"])
    found, cand_scores, inconsistent = [], [], []
    for xy in ctx.progress(list(rough), desc="pose search", unit="pylon"):
        # a candidate this close to a pylon already found would converge onto it
        if any(np.hypot(*(r.pose[:2] - xy[:2])) <= params["radius_m"] for _, r in found):
            cand_scores.append(None)
            continue
        best = None
        for name, (a, b, h, sym) in models.items():
            r = search.find_pose(views, xy[:2], ground, a, b, h, sym, kernel, settings)
            if r is not None and (best is None or r.score > best[1].score):
                best = (name, r)
        cand_scores.append(best[1].score if best is not None else 0.0)
        if best is None or best[1].score < params["min_score"]:
            continue
        # a pylon shows in every photo that sees it; clutter lines up with the model in one or two
        if best[1].photo_share(params["min_score"] / 2) < params["min_photo_share"]:
            inconsistent.append(round(best[1].score, 3))
            continue
        if not np.isfinite(best[1].mad).all():
            continue
        found.append(best)
    kept = []  # two searches that ended on one pylon: the better-scoring one stays
    for name, r in sorted(found, key=lambda f: -f[1].score):
        if all(np.hypot(*(r.pose[:2] - q.pose[:2])) > params["radius_m"] for _, q in kept):
            kept.append((name, r))
    found = kept
    stats["candidate_scores"] = [None if c is None else round(c, 3) for c in cand_scores]
    stats["rejected_in_few_photos"] = inconsistent
    stats["n_pylons"] = len(found)
    stats["started_from"] = {k: sum(r.start == k for _, r in found) for k in ("grid", "triangles")}
    stats["scores"] = [round(r.score, 3) for _, r in found]
    layers = _layers(found, models, origin, dem.crs, params["min_score"], params["leaning_deg"])
    stats["n_leaning"] = int(layers["pylons"]["leaning"].sum())
    overlays = _overlays(found, models, views, cameras, images, inputs["photos"]) if ctx.wants("overlays") else None
    return toolbox.Result(outputs={"pylons": layers, "overlays": overlays}, stats=stats)


def _layers(found, models, origin, crs, min_score, leaning_deg):
    import geopandas as gpd
    import numpy as np
    from shapely.geometry import Point, Polygon

    from . import core, search

    rows, pts, feet = [], [], []
    for name, r in found:
        x, y, z, h, p, ro = r.pose
        X = np.array([x, y, z]) + origin
        tilt, azimuth = search.tilt_of(r.pose)
        rows.append({"heading_deg": round(float(h), 3), "roll_deg": round(float(ro), 3), "pitch_deg": round(float(p), 3),
                     "tilt_deg": round(tilt, 3), "tilt_azimuth_deg": round(azimuth, 1), "leaning": bool(tilt > leaning_deg),
                     "score": round(r.score, 4), "mad_x_m": round(float(r.mad[0]), 3), "mad_y_m": round(float(r.mad[1]), 3),
                     "mad_z_m": round(float(r.mad[2]), 3), "mad_heading_deg": round(float(r.mad[3]), 3),
                     "n_photos": int(r.n_photos), "photo_share": round(r.photo_share(min_score / 2), 3),
                     "rms_px": round(float(r.rms_px), 3),
                     "edge_share": round(float(r.edge_share), 3), "model": name})
        pts.append(Point(*X))
        a, b = models[name][0], models[name][1]
        ends = np.vstack([a, b])
        base = ends[np.abs(ends[:, 2]) < 1e-6]
        if len(base) >= 3:
            from scipy.spatial import ConvexHull

            hull = base[ConvexHull(base[:, :2]).vertices]
            W = hull @ core.rotation(h, p, ro).T + X
            feet.append(Polygon(W[:, :2]))
        else:
            feet.append(None)
    cols = ["heading_deg", "roll_deg", "pitch_deg", "tilt_deg", "tilt_azimuth_deg", "leaning", "score", "mad_x_m", "mad_y_m", "mad_z_m", "mad_heading_deg", "n_photos",
            "photo_share", "rms_px", "edge_share", "model"]
    import pandas as pd

    df = pd.DataFrame(rows, columns=cols)
    return {"pylons": gpd.GeoDataFrame(df, geometry=gpd.GeoSeries(pts, crs=crs), crs=crs),
            "pylon_footprints": gpd.GeoDataFrame(df[["model", "score"]].copy(), geometry=gpd.GeoSeries(feet, crs=crs), crs=crs)}


def _overlays(found, models, views, cameras, images, photos_dir):
    """PNG of each photo that sees a found pylon, the model drawn at its pose (half size)."""
    from pathlib import Path

    import cv2
    import numpy as np

    from . import core

    by_name = {im.name: im for im in images.values()}
    files = {}
    for v in views:
        im = by_name[v.name]
        cam = cameras[im.camera_id]
        img = None
        for name, r in found:
            a, b = models[name][0], models[name][1]
            R = core.rotation(r.pose[3], r.pose[4], r.pose[5])
            A, B = a @ R.T + r.pose[:3], b @ R.T + r.pose[:3]
            ca, cb = A @ v.R.T + v.t, B @ v.R.T + v.t
            if np.any(ca[:, 2] < 1) or np.any(cb[:, 2] < 1):
                continue
            ua, ub = cam.project(ca), cam.project(cb)
            if not np.any((ua[:, 0] > 0) & (ua[:, 0] < cam.width) & (ua[:, 1] > 0) & (ua[:, 1] < cam.height)):
                continue
            if img is None:
                img = cv2.imread(str(Path(photos_dir) / v.name))
            for p, q in zip(ua - 0.5, ub - 0.5):
                cv2.line(img, tuple(int(c) for c in np.round(p * 4)), tuple(int(c) for c in np.round(q * 4)), (0, 0, 255),
                         2, cv2.LINE_AA, shift=2)
        if img is not None:
            ok, buf = cv2.imencode(".png", cv2.resize(img, (img.shape[1] // 2, img.shape[0] // 2), interpolation=cv2.INTER_AREA))
            files[f"overlays/{Path(v.name).stem}.png"] = buf.tobytes()
    return files


@toolbox.hookimpl
def toolbox_algorithms():
    return [Algorithm(
        id="pylon-pose",
        title="Pylon position and orientation from aligned UAV photos",
        run=_run,
        description=(
            "Finds lattice pylons in aligned photos and estimates each one's pose (x, y, z of the base centre, "
            "heading, pitch, roll): LSD line segments per photo, the lattice's joints (or the method's triangles) "
            "among them, their rays voted into "
            "terrain columns (a pylon where at least min_photos photos agree), then a render-and-compare search of "
            "the pylon model's beams against each photo's segments (the similarity A_s, a taichi kernel): first "
            "poses from a coarse exhaustive and a finer grid (hypotheses=grid) or from the method's MatchByTriangles "
            "(hypotheses=triangles: P3P on photo triangles matched to the model's), then the method's MatchSeparate with MAD-weighted merging across photos, a joint "
            "refinement, and last a continuous one past the similarity's cells: points along the projected beams "
            "matched to the two edges LSD finds of each beam, the 6 pose parameters solved by robust least squares "
            "over all photos (rms_px, edge_share in the layer). A candidate must match in min_photo_share of the "
            "photos that see it. Two searches that end within radius_m of each "
            "other are one pylon. With a model library (a folder of OBJ/JSON models) the type is chosen per pylon by score. "
            "World convention: x east, y north, z up in the DEM's CRS; X_cam = R·X_world + t (COLMAP); pose M = "
            "T·Rz(heading)·Ry(pitch)·Rx(roll) on model coordinates whose origin is the centre of the base; angles "
            "counter-clockwise in degrees, heading 0 leaves the model's x axis pointing east."
        ),
        reference=REFERENCE,
        parameters=[
            Parameter("radius_m", float, 8.0, "how far from the rough position the pose is searched", unit="m",
                      minimum=1.0, maximum=50.0),
            Parameter("min_photos", int, 3, "detection: photos whose triangle rays must meet in one terrain column "
                      "(the method's tau_c)", minimum=2, maximum=100),
            Parameter("detector", str, "corners", "detection features: corners (meeting points of short segments, "
                      "the lattice's joints) or triangles (the method's: three segments meeting pairwise; few per "
                      "pylon on our photos)", choices=("corners", "triangles")),
            Parameter("min_per_photo", int, None, "detection: features of one photo whose rays must cross a column "
                      "for that photo's vote (auto: 3 corners, 1 triangle)", minimum=1, maximum=100, allow_auto=True),
            Parameter("min_vote_share", float, 0.6, "detection: share of the photos that see a column which must "
                      "vote for it", minimum=0.0, maximum=1.0),
            Parameter("min_score", float, 0.042, "share of the model's beam cells that must match photo segments "
                      "of their direction at the found pose; below it a candidate is no pylon", minimum=0.0, maximum=1.0),
            Parameter("hypotheses", str, "grid", "first poses of the search: grid (an exhaustive x, y, heading search "
                      "within radius_m, the method's fallback) or triangles (the method's MatchByTriangles: P3P on photo "
                      "triangles matched to the model's, the grid where fewer than two photos give one)",
                      choices=("grid", "triangles")),
            Parameter("min_photo_share", float, 0.5, "share of the photos that see a candidate in which it must match "
                      "at least half of min_score: a pylon shows in every photo that sees it, clutter that lines up "
                      "with the model in one or two", minimum=0.0, maximum=1.0),
            Parameter("max_tilt_deg", float, 5.0, "the most a pylon may lean: its tilt is searched and fitted up "
                      "to this (0: upright, as the method)", unit="deg", minimum=0.0, maximum=10.0),
            Parameter("leaning_deg", float, 0.5, "a pylon tilted more than this is flagged leaning (the usual "
                      "erection tolerance of a lattice tower)", unit="deg", minimum=0.0, maximum=10.0),
            Parameter("mode", str, "max", "direction smoothing of the photo descriptor: max (the thesis's text) or "
                      "sum (its listing)", choices=("max", "sum")),
        ],
        inputs=[
            Input("photos", "photos", "the folder of photos the cameras name"),
            Input("cameras", "file", "a COLMAP model folder, binary or text (cameras.bin, images.bin or cameras.txt, "
                  "images.txt), or a Metashape camera XML, "
                  "georeferenced in the DEM's CRS"),
            Input("dem", "raster", "terrain heights (GeoTIFF) covering the photos' views"),
            Input("model", "file", "a pylon model (Wavefront OBJ with 'l' beams, or JSON), or a folder of them as a "
                  "library of types (default: the built-in VL-220 and U-110 types)", optional=True),
            Input("rough", "vector", "rough pylon positions (points), e.g. powerlines' pylons; skips the detection",
                  optional=True),
        ],
        outputs=[
            Output("pylons", "vector", "layers pylons (PointZ at the base: heading_deg, roll_deg, pitch_deg, "
                   "tilt_deg: the axis's angle from the plumb line, tilt_azimuth_deg: the compass direction its top "
                   "leans toward (clockwise from grid north), leaning: tilt_deg above leaning_deg, score, "
                   "mad_x_m, mad_y_m, mad_z_m, mad_heading_deg, n_photos, photo_share: the share of them in which it matches "
                   "at least half of min_score, rms_px: the matched beam points' distance "
                   "to their photo edges, edge_share: their share of the beam points in view, model) and "
                   "pylon_footprints (the model's base at the found pose)"),
            Output("overlays", "folder", "overlays/*.png: each photo with the found pylons drawn (half size), to check "
                   "by eye", optional=True),
        ],
    )]

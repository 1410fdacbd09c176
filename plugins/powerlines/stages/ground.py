"""Stage 1, ground and candidates: the ground and each point's height above it (through the
``dtm`` algorithm), the candidates (off the ground, in the height window, first returns where
the file has them), the density of the surfaces around them and the eigenvalue shape test."""

from __future__ import annotations

import time

import numpy as np

from ..core import height_window_top, local_surface_density, shape_classes
from ..rules import GROW_FROM_M, MIN_CANDIDATES, V_MAX_METHOD_M
from ..state import Scene


def stage(pc, settings, ctx, timings: dict) -> Scene:
    params = settings.params
    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    t = time.perf_counter()
    # the filter's ground and noise alone (the input's own classes would pass through the DTM's output)
    ground_in = pc if params["ground"] == "file" else pc.with_fields(classification=np.ones(len(pc), np.uint8))
    dres = ctx.call("dtm", {"points": ground_in}, ground=params["ground"], resolution_m=1.0)
    dtm = dres.outputs["dtm"]
    ground_cls = dres.outputs["classified"].classification
    # height above ground (metres) where it is needed: off-ground points (most points are ground)
    off = np.flatnonzero((ground_cls != 2) & (ground_cls != 7))
    hag = np.full(len(pc), -np.inf)
    hag[off] = (pc.z[off] - dtm.sample(pc.x[off], pc.y[off])) * vu
    timings["ground_s"] = time.perf_counter() - t

    t = time.perf_counter()
    cand = hag >= params["height_min_m"]
    h_max = params["height_max_m"]
    if h_max is None:  # automatic: everything above the window's floor, birds and lone returns left out
        above = np.flatnonzero(cand)
        h_max = height_window_top(hag[above], np.column_stack([pc.x[above] * hu, pc.y[above] * hu,
                                                               pc.z[above] * vu]), link_m=V_MAX_METHOD_M)
    cand &= hag <= h_max
    rn = pc.fields.get("return_number")
    if params["first_returns_only"] and rn is not None and np.any(rn > 0):
        cand &= rn == 1
    idx = np.flatnonzero(cand)
    low = off[hag[off] >= GROW_FROM_M]
    none = np.zeros(len(idx), bool)
    if len(idx) < MIN_CANDIDATES:
        return Scene(pc, dtm, ground_cls, hag, off, low, idx, none, none, np.zeros(len(idx)), float(h_max))
    xyz = np.column_stack([pc.x[idx] * hu, pc.y[idx] * hu, pc.z[idx] * vu])
    # the density of the surfaces around each candidate: first returns per occupied square metre
    # within density_radius_m (roofs and crowns are that dense, wires are not)
    first = (rn == 1) if rn is not None and np.any(rn > 0) and params["first_returns_only"] else None
    density = local_surface_density(pc.x * hu, pc.y * hu, first, radius_m=params["density_radius_m"])
    surface_density = density[idx]
    linear, planar, rugged, steep = shape_classes(xyz - xyz.min(axis=0), params["neighbours"], params["rugged_share"],
                                                  params["planar_share"], surface_density)
    timings["candidates_s"] = time.perf_counter() - t
    return Scene(pc, dtm, ground_cls, hag, off, low, idx, linear, steep, surface_density, float(h_max))

"""Stage 9, plan split: wires the 3D step told apart across one Hough line (a ribbon's phases
closer than band_m) become conductors of their own in plan; points alone in the air right beside
a wire are its; a wire point inside a pole's column is the pole's; each plan line settles on its
wires' trend."""

from __future__ import annotations

import time

import numpy as np

from ..core import alone_beside_wires, in_pole_columns
from ..plan_geometry import main_wire_spans, realign, side_by_side
from ..rules import (
    ALONE_AROUND_M,
    ALONE_MAX_AROUND,
    ALONE_REACH_M,
    POLE_CORE_M,
    POLE_FOOTPRINT_M,
    POLE_HEAD_M,
    SETTLE_DRIFT_M,
)
from ..state import State, Wires


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu, params, hag = scene.pc, scene.hu, settings.params, scene.hag
    lines, geo, spans = st.wires.as_tuple()
    conductor_of, wire_of_input = st.labels.conductor, st.labels.wire
    tower_pt, found, around = st.supports.tower_pt, st.supports.found, st.around
    lines, geo, spans, conductor_of, wire_of_input, n_side = side_by_side(lines, geo, spans, conductor_of,
                                                                          wire_of_input, pc.x * hu, pc.y * hu,
                                                                          params, hu)
    n_alone, max_around = 0, None
    fitted_of = conductor_of  # the lone points taken next do not reach a line any further
    if params["alone_beside_wires"] and (conductor_of >= 0).any():
        # points alone in the air right beside a wire are its (or a wire's hanging beside it): the
        # fits' tolerance left them out; not those the foliage and trend tests just took off
        t = time.perf_counter()
        free = (conductor_of[around] < 0) & ~tower_pt[around]
        free[np.isin(around, np.r_[st.foliage, st.off_trend])] = False
        # alone: fewer others than a quarter of what a surface of the survey's density through
        # the ball holds (a sparse survey's crown edges are as empty as a dense one's wires)
        max_around = min(ALONE_MAX_AROUND, int(np.median(scene.surface_density) * np.pi * ALONE_AROUND_M ** 2 / 4))
        taken, via = alone_beside_wires(st.around_xyz, conductor_of[around] >= 0, free, reach_m=ALONE_REACH_M,
                                        around_m=ALONE_AROUND_M, max_around=max_around, tree=st.around_tree)
        conductor_of = conductor_of.copy()
        conductor_of[around[taken]] = conductor_of[around[via]]
        wire_of_input[around[taken]] = wire_of_input[around[via]]
        n_alone = len(taken)
        st.timings["alone_beside_wires_s"] = time.perf_counter() - t
    n_pole_column = 0
    poles = [p for p in found if p.extent_m() <= POLE_FOOTPRINT_M]
    if poles and (conductor_of >= 0).any():
        # a wire point inside a pole's column under its head is the pole's: a cable's end clamped
        # to its side, which the span's growth or the lone points carried onto the pole
        wire_pt = np.flatnonzero(conductor_of >= 0)
        inside = wire_pt[in_pole_columns([(p.x, p.y, p.height_m) for p in poles], pc.x[wire_pt] * hu,
                                         pc.y[wire_pt] * hu, hag[wire_pt], core_m=POLE_CORE_M, head_m=POLE_HEAD_M)]
        conductor_of = conductor_of.copy()
        conductor_of[inside] = -1
        tower_pt[inside] = True
        n_pole_column = len(inside)
    # the plan layers (and so the crossings) of a line one span holds settle on that span's trend
    # where it drifts off the line by more than the crossings' tolerance: a wire seen over one
    # stretch from one side, leant by the points of a line crossing it in its band (the 3D step
    # told those apart by height). Over several spans the Hough's fit is as good, and their pooled
    # trends turned ribbons' and bundles' lines the wrong way. The 3D layer keeps its frame
    lines = realign(lines, geo, spans, params, hu, min_drift_m=SETTLE_DRIFT_M, max_spans=1)[0]
    # over several spans, a drift of a quarter band_m is the Hough's line between a ribbon's
    # phases (their points in its band): the trend of the line's own wire, not the others' pieces
    # it holds, settles it
    lines = realign(lines, geo, main_wire_spans(spans, params["max_rms_3d_m"]), params, hu,
                    min_drift_m=params["band_m"] / 4)[0]
    st.counts.update(n_side_by_side=n_side, n_alone_points=n_alone, alone_max_around_used=max_around,
                     n_pole_column_points=n_pole_column)
    st.fitted_of = fitted_of
    st.wires = Wires(lines, geo, spans)
    st.labels.conductor, st.labels.wire = conductor_of, wire_of_input
    return st

"""Scenes, fixtures and helpers the power-line, Hough and top-hat tests share."""


import json
from pathlib import Path

import geopandas as gpd
import laspy
import numpy as np
import pytest
from conftest import shared_file
from toolbox_plugins.powerlines.core import (
    catenary,
    conductors_3d,
    ends_at_supports,
    fit_catenary,
)

import toolbox
from toolbox.crossings import crossings


@pytest.fixture(scope="session")  # the chain's and the Hough's tests read the same scene
def corridor(tmp_path_factory):
    d = tmp_path_factory.mktemp("corridor")
    toolbox.run("synthetic-scene", output=d / "c.laz", kind="corridor", seed=1)
    return d / "c.laz"


@pytest.fixture(scope="session")
def corridor_result(corridor, tmp_path_factory):
    d = tmp_path_factory.mktemp("pl")
    rep = toolbox.run("powerlines", corridor, d / "pl.gpkg", outputs={"classified": str(d / "wires.laz")})
    return rep, d / "pl.gpkg", d / "wires.laz", json.loads(str(corridor).replace(".laz", "_truth.json") and
                                                          open(str(corridor).replace(".laz", "_truth.json")).read())


def crossings_at_supports(lines, segments, supports=None):
    """The host's crossings with the power lines' rule at the supports found."""
    return crossings(lines, segments, excluded=ends_at_supports(lines, segments, supports))


def _bundle(rng, offsets, per_m=4.0, length=60.0, c=900.0, noise=0.03):
    """Points of sub-conductors at (across, up) ``offsets`` of one sagging span: s, off, z, label."""
    s, off, z, lab = [], [], [], []
    for k, (dx, dz) in enumerate(offsets):
        sk = np.sort(rng.uniform(0, length, int(per_m * length)))
        s.append(sk)
        off.append(dx + rng.normal(0, noise, len(sk)))
        z.append(catenary(sk, 20.0 + dz, length / 2, c) + rng.normal(0, noise, len(sk)))
        lab.append(np.full(len(sk), k))
    return np.concatenate(s), np.concatenate(off), np.concatenate(z), np.concatenate(lab)


def _one_line_layers(length_m):
    """The Hough layers and geometry of one conductor along x from 0 to ``length_m``."""
    from shapely.geometry import LineString

    line = LineString([(0.0, 0.0), (length_m, 0.0)])
    cond = gpd.GeoDataFrame({"conductor": [0], "azimuth_deg": [90.0], "n_points": [1000]}, geometry=[line])
    seg = gpd.GeoDataFrame({"conductor": [0]}, geometry=[line])
    return {"conductors": cond, "conductor_segments": seg}, [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0,
                                                              length_m)]


def _ribbon_points(rng, offsets, length_m=500.0, per_m=2.0, sd_m=0.04, heading_deg=20.0):
    """Plan points of wires side by side (``offsets`` across a line at ``heading_deg``), and the
    line's frame (anchor, direction, normal)."""
    d = np.array([np.cos(np.radians(heading_deg)), np.sin(np.radians(heading_deg))])
    n = np.array([-d[1], d[0]])
    a = np.array([1000.0, 2000.0])
    pts, lab = [], []
    for k, o in enumerate(offsets):
        s = rng.uniform(0.0, length_m, int(per_m * length_m))
        pts.append(a + s[:, None] * d + (o + rng.normal(0, sd_m, len(s)))[:, None] * n)
        lab.append(np.full(len(s), k))
    return np.vstack(pts), np.concatenate(lab), (a, d, n)


def _line_between(frame, off_from, off_to, length_m):
    """A line of the frame (anchor, direction, normal) leaning from ``off_from`` to ``off_to``
    across over ``length_m``: (anchor, direction, 0, length)."""
    a, d, n = frame
    b = a + off_from * n
    e = a + length_m * d + off_to * n
    u = (e - b) / np.linalg.norm(e - b)
    return (b, u, 0.0, float(np.linalg.norm(e - b)))


def _segment(rng, a, b, n, noise=0.02):
    t = np.sort(rng.uniform(0, 1, n))
    return np.asarray(a, float) + t[:, None] * (np.asarray(b, float) - np.asarray(a, float)) + rng.normal(0, noise, (n, 3))


def _short_wire_scene(rng):
    """A line of wires along x at 8 m with a pole at x = 20 (steep points), a wire leaving the
    pole top across the line, a tower arm (body at x = 60, tip 5 m out, the conductor 2.5 m
    under the tip), a cross arm under the wires at x = 40 and a scan row of a facade that
    stands across the line."""
    from toolbox.io.points import PointCloud

    main = np.vstack([_segment(rng, (0, y, 8.0), (100, y, 8.0), 400) for y in (-1.0, 0.0, 1.0)])
    pole = _segment(rng, (20, -0.3, 0.5), (20, -0.3, 8.5), 80, noise=0.03)
    across = _segment(rng, (20.2, -0.4, 8.3), (20.8, -6.5, 8.2), 40)
    body = _segment(rng, (60, 6.0, 0.5), (60, 6.0, 12.0), 120, noise=0.1)
    arm = _segment(rng, (60, 6.2, 10.5), (60, 1.2, 10.5), 40)
    tower_wire = _segment(rng, (30, 1.0, 8.0), (90, 1.0, 8.0), 240)  # under the arm's tip at y = 1.2
    crossarm = _segment(rng, (40, -1.5, 7.6), (40, 3.0, 7.6), 40)
    rows = [_segment(rng, (70, -3, 5 + k * 0.35), (70, -9, 5 + k * 0.35), 40) for k in range(8)]  # across too
    parts = {"main": main, "pole": pole, "across": across, "body": body, "arm": arm, "tower_wire": tower_wire,
             "crossarm": crossarm, "facade_row": rows[4], "facade": np.vstack(rows[:4] + rows[5:])}
    xyz = np.vstack(list(parts.values()))
    label = np.concatenate([[k] * len(v) for k, v in parts.items()])
    return PointCloud(xyz[:, 0], xyz[:, 1], xyz[:, 2]), label


def _in_ball(rng, centre, radius_m, n):
    p = rng.normal(size=(n, 3))
    return np.asarray(centre) + p / np.linalg.norm(p, axis=1, keepdims=True) * radius_m * rng.random((n, 1)) ** (1 / 3)


def _pole_points(rng, x, y, height_m, radius_m=0.15, per_m=60):
    """A pole's surface as a street scanner sees it: the half facing the road, from 0.3 m up."""
    n = int(height_m * per_m)
    a = rng.uniform(0.0, np.pi, n)
    h = rng.uniform(0.3, height_m, n)
    return np.column_stack([x + radius_m * np.cos(a), y - radius_m * np.sin(a), h]) + rng.normal(0, 0.01, (n, 3))


def _earth_wire_scene(rng, facade=False):
    """A phase along x (3 points per metre, sag 7 m over 290 m) and, 7 m over it, an earth wire
    the survey hit in stretches up to 26 m apart, about 0.6 points per metre in them, swinging
    0.5 m across the line (AHN4 12AN2_20's); with ``facade``, instead of the wire, five scan
    rows 0.25 m one over another in stretches of 6 m, 15 m apart. Returns the 3D step's result
    with V_max 3.2 m (12AN2_20's) and how many of the points are the phase's."""
    s_p = np.sort(rng.uniform(0, 290, 870))
    phase = np.column_stack([s_p, rng.normal(0, 0.03, len(s_p)), catenary(s_p, 29.0, 145.0, 1500.0)])
    if facade:
        rows = []
        for lo in np.arange(0.0, 290.0, 21.0):
            for k in range(5):
                s_r = np.sort(rng.uniform(lo, lo + 6.0, 30))
                rows.append(np.column_stack([s_r, 0.3 + rng.normal(0, 0.03, len(s_r)),
                                             34.0 + 0.25 * k + rng.normal(0, 0.02, len(s_r))]))
        other = np.concatenate(rows)
    else:
        stretches = [(0, 24), (50, 60), (77, 89), (105, 130), (147, 186), (207, 215), (250, 260), (273, 284)]
        s_e = np.sort(np.concatenate([rng.uniform(a, b, int(0.6 * (b - a)) + 1) for a, b in stretches]))
        other = np.column_stack([s_e, -0.5 + 0.5 * ((s_e - 145.0) / 145.0) ** 2 + rng.normal(0, 0.04, len(s_e)),
                                 catenary(s_e, 36.0, 145.0, 1500.0) + rng.normal(0, 0.03, len(s_e))])
    xyz = np.r_[phase, other]
    lines = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 290.0)]
    return conductors_3d(lines, xyz[:, 0], xyz[:, 1], xyz[:, 2], band=1.0, z_link=1.0, s_link=6.42, min_span=8.0,
                         max_rms=0.2), len(phase)


def _sibling_scene(rng, stub=False):
    """A fitted 60 m span along x (sag 0.75 m) and beside it, 1.2 m across and 0.3 m up, a
    sparse phase of the same line (clumps of 3 points every 2-6 m; with ``stub``, 15 points
    over 40-46 m only) over a crown 1.5-4 m across and 1-3 m down."""
    from toolbox_plugins.powerlines.core import Span

    sp = Span(0, 0, 0, 30.0, 600.0, 10.0, 0.0, 60.0, 0.03, 300, 0.75)
    centres = np.cumsum(rng.uniform(2.0, 6.0, 40))
    s_w = np.concatenate([c + rng.uniform(-0.2, 0.2, 3) for c in centres[centres <= 60.0]])
    if stub:
        s_w = np.arange(40.0, 46.0, 0.4)
    wire = np.column_stack([s_w, 1.2 + rng.normal(0, 0.03, len(s_w)),
                            catenary(s_w, 10.3, 30.0, 600.0) + rng.normal(0, 0.02, len(s_w))])
    crown = rng.uniform([0, 1.5, 0], [60, 4, 1], (400, 3))
    crown[:, 2] = catenary(crown[:, 0], 10.0, 30.0, 600.0) - 1.0 - 2.0 * crown[:, 2]
    lines = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 60.0)]
    return sp, lines, wire, crown


def _next_span_scene(rng, wire_from=40.0, wire_to=72.0, step_m=0.0):
    """A fitted span along x from 0 to 40 m ending at a support 10 m up, and past it the next span
    seen sparsely (clumps of 2-4 points, gaps up to 3 m), turned 1.2 degrees at the support and
    hung from it ``step_m`` lower, over a crown 1-3 m under it. Returns (span, line, x, y, z,
    free, is_next)."""
    from toolbox_plugins.powerlines.core import Span

    c = 300.0
    sp = Span(0, 0, 0, 20.0, c, 9.5, 0.0, 40.0, 0.03, 160, 0.67)
    z_end = float(catenary(40.0, 9.5, 20.0, c))
    s_old = np.linspace(0.0, 40.0, 160)
    z_old = catenary(s_old, 9.5, 20.0, c)
    centres = wire_from + 0.5 + np.cumsum(rng.uniform(0.8, 3.0, 40))
    centres = centres[centres < wire_to]
    s_new = np.concatenate([k + rng.uniform(-0.25, 0.25, rng.integers(2, 5)) for k in centres])
    z0_new = z_end - step_m - float(catenary(40.0, 0.0, 56.0, c))  # hung from the support at s = 40
    z_new = catenary(s_new, z0_new, 56.0, c) + rng.normal(0, 0.02, len(s_new))
    y_new = 0.021 * (s_new - 40.0) + rng.normal(0, 0.02, len(s_new))
    crown = rng.uniform([40.0, -2.0, z_end - 3.5], [75.0, 2.0, z_end - 1.0], (3000, 3))
    x = np.r_[s_old, s_new, crown[:, 0]]
    y = np.r_[np.zeros(len(s_old)), y_new, crown[:, 1]]
    z = np.r_[z_old, z_new, crown[:, 2]]
    free = np.arange(len(x)) >= len(s_old)
    is_next = free & (np.arange(len(x)) < len(s_old) + len(s_new))
    return sp, (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 40.0), x, y, z, free, is_next


# a crown's cap between a low line's two conductors (dist_d5 seed 5, 5 pts/m2: its points, x y and
# height above ground, about its middle); its pulses' later returns stop 3.9 m up
CROWN_CAP = [[-1.02, -0.18, 6.04], [-1.01, 0.53, 4.85], [-0.86, -0.79, 5.85], [-0.84, -0.31, 6.28],
             [-0.83, -0.21, 6.25], [-0.83, -0.21, 5.55], [-0.83, -0.21, 3.89], [-0.7, 0.73, 5.5], [-0.7, 0.73, 5.39],
             [-0.7, 0.73, 4.39], [-0.22, 0.86, 5.91], [-0.22, 0.86, 5.2], [-0.16, 1.04, 5.58], [-0.16, 1.04, 5.57],
             [-0.16, 1.04, 4.82], [-0.12, 0.48, 6.45], [-0.12, 0.48, 6.36], [-0.02, 1.13, 5.3], [-0.02, 1.13, 5.24],
             [-0.02, 1.13, 5.22], [0.05, -1.07, 6.26], [0.05, -1.07, 4.87], [0.05, 0.21, 6.47], [0.16, 0.64, 6.38],
             [0.29, 0.94, 5.84], [0.29, 0.94, 5.78], [0.29, 0.94, 4.01], [0.43, -1.46, 5.16], [0.45, 0.52, 6.46],
             [0.45, 0.52, 4.94], [0.9, -0.84, 6.27], [0.92, 0.58, 5.76], [0.92, -0.75, 6.12], [0.94, -0.85, 6.06],
             [0.94, -0.85, 5.81], [0.94, -0.85, 5.18], [1.02, -1.14, 5.08], [1.08, 0.61, 5.62], [1.08, 0.61, 5.48],
             [1.11, 0.66, 5.15], [1.26, -0.92, 5.27], [1.26, -0.92, 5.05], [1.26, -0.92, 4.61], [1.34, -0.16, 5.63],
             [1.34, -0.16, 5.57]]


def _find_pylons_on(name, **kw):
    """find_pylons on a scene's inputs kept in tests/data (metres about the candidate, heights
    above ground; span i's ends are rows 2i and 2i + 1 of span_ends)."""
    from toolbox_plugins.powerlines.core import find_pylons

    d = np.load(Path(__file__).parent / "data" / name)
    p, w, e = d["points_cm"] / 100.0, d["wires_cm"] / 100.0, d["span_ends_cm"] / 100.0
    lines_xy = [(ln[:2], ln[2:]) for ln in d["lines_m"]]
    span_lines = [(e[2 * i, :2], e[2 * i + 1, :2]) for i in range(len(e) // 2)]
    found = find_pylons(*p.T, e[:, :2], e[:, 2], list(d["headings_deg"]), lines_xy, span_lines=span_lines,
                        wire_xyh=tuple(w.T), **kw)
    return p, found


def _ahn4_real(name, tmp_path):
    """An AHN4 corridor tile with the repo author's synthetic classes 5 and 26 dropped."""
    las = laspy.read(shared_file(f"ahn4_corridor/{name}.laz"))
    sub = laspy.LasData(las.header)
    sub.points = las.points[np.isin(las.classification, [1, 2, 9, 14, 15])]
    sub.write(tmp_path / f"{name}.laz")
    return tmp_path / f"{name}.laz", sub


def _bridge_scene(rng, kink=False):
    """A wire 80 m along x (points every ~0.3 m) whose candidates stop 7 m either side of a crown
    at s = 40, a second wire 0.3 m beside it (a ribbon's phase) and the crown's foliage; with
    ``kink`` the two pieces hang in catenaries of their own, meeting at a support at s = 40."""
    from toolbox_plugins.powerlines.core import make_span

    def wire(s, lateral):
        z = catenary(s, 20.0, 20.0, 900.0) if kink and lateral == 0 else catenary(s, 20.0, 40.0, 900.0)
        if kink and lateral == 0:
            z = np.where(s < 40.0, z, catenary(s, 20.0, 60.0, 900.0))
        return np.column_stack([s, lateral + rng.normal(0, 0.02, len(s)), z + rng.normal(0, 0.03, len(s))])

    w = wire(np.sort(rng.uniform(0.0, 80.0, 270)), 0.0)
    beside = wire(np.sort(rng.uniform(0.0, 80.0, 270)), 0.3)
    d = rng.normal(size=(3000, 3))
    crown = np.array([40.0, 0.0, 19.5]) + 3.0 * d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(0, 1, (3000, 1)) ** (1 / 3)
    pts = np.vstack([w, beside, crown])
    is_gap = np.r_[(w[:, 0] > 33.0) & (w[:, 0] < 47.0), np.zeros(len(beside) + len(crown), bool)]
    spans = []
    for i, (lo, hi) in enumerate(((0.0, 33.0), (47.0, 80.0))):
        m = (w[:, 0] >= lo) & (w[:, 0] <= hi)
        spans.append(make_span(0, i, 0, w[m, 0], w[m, 1], fit_catenary(w[m, 0], w[m, 2]), z=w[m, 2]))
    free = np.r_[(w[:, 0] > 33.0) & (w[:, 0] < 47.0), np.ones(len(beside) + len(crown), bool)]
    line = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 80.0)
    return spans, line, pts, free, is_gap


def chain_until(path, until: str | None, rules=None, **params):
    """The power-line chain on the cloud file ``path`` up to stage ``until`` (public stage API:
    ``stages.run_chain``): (scene, state, settings, ctx), to test a stage on what the stages
    before it hand on; ``rules`` (a ``settings.Rules``) in place of the plugin's."""
    from toolbox_plugins.powerlines.settings import Settings
    from toolbox_plugins.powerlines.stages import run_chain

    from toolbox.io.points import read_points
    from toolbox.registry import registry
    from toolbox.runner import Context

    reg = registry()
    settings = Settings.of(reg.get("powerlines").validate_params(params))
    if rules is not None:
        settings.rules = rules
    ctx = Context(reg, "powerlines", quiet=True)
    scene, st = run_chain(read_points(path), settings, ctx, until=until)
    return scene, st, settings, ctx


OAKLAND_SCANS = ("part3_an", "part3_ak", "part2_ai", "part2_aj", "part2_ag", "part2_al", "part2_ae", "part3_aj")


def oakland_run(runs, name):
    """One scan's run from ``oakland_runs``, or skip with the reason."""
    shared_file(f"oakland_mls/oakland_{name}.laz")
    return runs[name]


def wire_points(source, classified):
    """(truth, predicted) wire-point masks: class 14 of the source (the CMU labels) and of the output."""
    return (np.asarray(laspy.read(source).classification) == 14,
            np.asarray(laspy.read(classified).classification) == 14)

"""Power lines: top-hat filter, the Hough accumulator kernel against its numpy reference (vote for
vote), line detection and crossings against synthetic truth, the whole chain with 3D catenaries,
the real AHN4 corridor, and bad input."""

import json
from pathlib import Path

import geopandas as gpd
import laspy
import numpy as np
import pytest
from conftest import shared_file
from toolbox_plugins.hough_lines import core as hough
from toolbox_plugins.hough_lines import kernels as hough_kernels
from toolbox_plugins.hough_lines import reference
from toolbox_plugins.powerlines.core import (
    _split_bundles,
    _two_means_1d,
    catenary,
    conductors_3d,
    ends_at_supports,
    fit_catenary,
    kink_cut,
    line_fit,
    local_surface_density,
    parabola_fit,
    peel_catenaries,
    shape_classes,
    span_on_surface,
    split_spans,
    twin_lines,
)
from toolbox_plugins.powerlines.evaluation import conductor_hits, crossing_errors, false_crossings
from toolbox_plugins.tophat.core import tophat_points, tophat_raster

import toolbox
from toolbox import kernels
from toolbox.crossings import crossings


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    d = tmp_path_factory.mktemp("corridor")
    toolbox.run("synthetic-scene", output=d / "c.laz", kind="corridor", seed=1)
    return d / "c.laz"


@pytest.fixture(scope="module")
def corridor_result(corridor, tmp_path_factory):
    d = tmp_path_factory.mktemp("pl")
    rep = toolbox.run("powerlines", corridor, d / "pl.gpkg", outputs={"classified": str(d / "wires.laz")})
    return rep, d / "pl.gpkg", d / "wires.laz", json.loads(str(corridor).replace(".laz", "_truth.json") and
                                                          open(str(corridor).replace(".laz", "_truth.json")).read())


@pytest.mark.parametrize("n, seed, theta_step", [(50, 0, 0.1), (3000, 1, 0.1), (20000, 2, 0.1), (2000, 3, 0.7)])
def test_taichi_accumulator_equals_numpy_reference(n, seed, theta_step):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 110, n)
    y = rng.uniform(0, 110, n)
    thetas, k_min, rows = hough.accumulator_shape(x, y, 0.1, theta_step)
    c, s = np.cos(thetas), np.sin(thetas)
    a = reference.NumpyAccumulator(c, s, k_min, 10.0, rows)
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows) as b:
        a.vote(x, y, 1)
        b.vote(x, y, 1)
        assert np.array_equal(a.to_numpy(), b.to_numpy())  # count for count
        assert a.to_numpy().sum() == n * len(thetas)
        assert a.peak() == b.peak()
        # band subtraction with the same kernel restores the rest exactly
        sub = slice(0, n // 3)
        a.vote(x[sub], y[sub], -1)
        b.vote(x[sub], y[sub], -1)
        assert np.array_equal(a.to_numpy(), b.to_numpy()) and a.to_numpy().sum() == (n - n // 3) * len(thetas)
        assert a.peak() == b.peak()
        cc, r, _ = a.peak()
        a.clear_cell(cc, r)
        b.clear_cell(cc, r)
        assert a.peak() == b.peak()
        # the detection loop: peak, subtract the points near it, again (the kernel only rescans
        # rows whose peak cell lost votes)
        left = np.arange(n // 3, n)
        for _ in range(5):
            cc, r, _ = a.peak()
            near = left[np.abs(reference.bin_index(x[left], y[left], a.cs[cc], a.ss[cc], a.off) - r) <= 4]
            if len(near) == 0:
                break
            a.vote(x[near], y[near], -1)
            b.vote(x[near], y[near], -1)
            left = np.setdiff1d(left, near)
            assert a.peak() == b.peak()


def crossings_at_supports(lines, segments, supports=None):
    """The host's crossings with the power lines' rule at the supports found."""
    return crossings(lines, segments, excluded=ends_at_supports(lines, segments, supports))


def test_a_subtraction_with_a_floor_keeps_every_row_that_can_still_peak_exact():
    """Rows bounded below the floor may keep their votes (the kernel skips them); every row
    that can still hold a peak of ``floor`` votes or more counts exactly as numpy's, and so the
    peak does."""
    rng = np.random.default_rng(5)
    t = rng.uniform(0, 100, 800)
    x = np.r_[t, rng.uniform(0, 110, 1500)]
    y = np.r_[30 + 0.2 * t + rng.normal(0, 0.03, 800), rng.uniform(0, 110, 1500)]
    thetas, k_min, rows = hough.accumulator_shape(x, y, 0.1, 0.1)
    c, s = np.cos(thetas), np.sin(thetas)
    floor = 15
    a = reference.NumpyAccumulator(c, s, k_min, 10.0, rows)
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows) as b:
        a.vote(x, y)
        b.vote(x, y)
        assert a.peak() == b.peak()  # the rows' maxima are known from here on
        for sub in (slice(0, 300), slice(300, 600), slice(800, 1000)):  # 200 points of the line stay
            a.vote(x[sub], y[sub], -1, floor=floor)
            b.vote(x[sub], y[sub], -1, floor=floor)
            ref, got = a.to_numpy(), b.to_numpy()
            live = ref.max(axis=1) >= floor
            assert np.array_equal(ref[live], got[live])
            assert a.peak() == b.peak() or (a.peak()[2] < floor and b.peak()[2] < floor)
        # rows were skipped (their counts still hold the subtracted votes), never below the truth
        assert not np.array_equal(ref, got) and np.all(got >= ref)
        assert a.peak()[2] >= floor


@pytest.mark.parametrize("x0, y0", [(0, 0), (-110, 0), (-55, -55), (0, -110)])
def test_accumulator_rho_range_holds_every_vote_and_no_more(x0, y0):
    """The ρ range is the method's min/max computed ρ: every point binned at every θ falls
    inside it (a vote outside would land in the next θ row), and the outermost bins are used."""
    rng = np.random.default_rng(3)
    x = np.r_[x0 + rng.uniform(0, 110, 3000), x0, x0 + 110, x0, x0 + 110]
    y = np.r_[y0 + rng.uniform(0, 110, 3000), y0, y0, y0 + 110, y0 + 110]
    thetas, k_min, rows = hough.accumulator_shape(x, y, 0.1, 0.1)
    cs, ss, off = reference.bin_scales(np.cos(thetas), np.sin(thetas), k_min, 10.0)
    k = reference.bin_index(x[:, None], y[:, None], cs[None, :], ss[None, :], off)
    assert k.min() >= 0 and k.max() < rows
    assert k.min() <= 3 and k.max() >= rows - 4
    if (x0, y0) == (0, 0):  # a tile at its own origin: [-max y, max r], not ±max r
        assert rows < 0.9 * (2 * np.hypot(110, 110) / 0.1)


@pytest.mark.parametrize("seed", [7, 8])
def test_detection_loop_takes_the_numpy_peaks(seed):
    """The kernel keeps each row's maximum current itself (rescanning only rows whose peak cell lost
    votes): on a tile of crossing wires and scatter the whole detection loop must take the same
    peaks, in the same order, as numpy's full argmax."""
    rng = np.random.default_rng(seed)
    xs, ys = [rng.uniform(0, 110, 1500)], [rng.uniform(0, 110, 1500)]
    for a, b, ang in [(5, 10, 20.0), (0, 60, -5.0), (40, 0, 80.0), (10, 12, 21.0)]:
        t = np.arange(0, 100, 0.4) + rng.uniform(0, 0.4, 250)
        xs.append(a + t * np.cos(np.radians(ang)) + rng.normal(0, 0.05, 250))
        ys.append(b + t * np.sin(np.radians(ang)) + rng.normal(0, 0.05, 250))
    x, y = np.concatenate(xs), np.concatenate(ys)
    ref = hough.detect_lines(x, y, reference.NumpyAccumulator, min_votes=8)
    got = hough.detect_lines(x, y, lambda *a, **kw: hough_kernels.TaichiAccumulator(kernels.taichi(), *a, **kw),
                             min_votes=8)
    assert len(ref) >= 4
    assert [(L.theta_deg, L.rho, L.votes) for L in got] == [(L.theta_deg, L.rho, L.votes) for L in ref]


def test_peak_ties_resolve_as_numpy_argmax():
    """One point twice: every θ row holds one cell of 2 votes; both return the first (row 0)."""
    x = np.array([10.0, 10.0])
    y = np.array([5.0, 5.0])
    thetas, k_min, rows = hough.accumulator_shape(x, y, 0.1, 0.1)
    c, s = np.cos(thetas), np.sin(thetas)
    a = reference.NumpyAccumulator(c, s, k_min, 10.0, rows)
    a.vote(x, y)
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows) as b:
        b.vote(x, y)
        ref = np.unravel_index(np.argmax(a.to_numpy()), a.acc.shape)
        assert a.peak()[:2] == b.peak()[:2] == tuple(int(v) for v in ref)
        assert a.peak()[0] == 0 and a.peak()[2] == 2


@pytest.mark.parametrize("seed", range(4))
def test_isolated_points_and_principal_axis_match_their_definitions(seed):
    """The refit's shortcuts: isolated points (no neighbour within max_gap) against every pairwise
    distance, and the closed-form principal axis against numpy's SVD."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-np.pi, np.pi)
    d = np.array([np.cos(ang), np.sin(ang)])
    t = np.r_[rng.uniform(0, 60, 300), rng.uniform(0, 60, 8) * 3]  # a wire and scattered strays
    pts = np.outer(t, d) + np.outer(rng.normal(0, 0.3, len(t)), [-d[1], d[0]])
    pts = np.r_[pts, rng.uniform(-50, 200, (20, 2))]
    dist = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(dist, np.inf)
    truth = dist.min(axis=1) >= 2.5
    got = hough.isolated_points(pts, 2.5)
    assert truth.any() and np.array_equal(got, truth)
    c = pts - pts.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    assert abs(abs(hough.principal_axis(c) @ vt[0]) - 1.0) < 1e-12
    # one orientation per line, whichever way the points come (the 3D step measures s along it)
    d1 = hough.fit_line(pts[:300, 0], pts[:300, 1], 2.5)[1]
    d2 = hough.fit_line(pts[:300, 0][::-1], pts[:300, 1][::-1], 2.5)[1]
    assert np.allclose(d1, d2) and (d1[0] < 0 or (d1[0] == 0 and d1[1] < 0))


def test_a_line_peaks_where_it_should():
    t = np.linspace(0, 60, 200)
    theta = np.radians(30.0)
    rho = 12.3
    x = rho * np.cos(theta) - t * np.sin(theta) + 50
    y = rho * np.sin(theta) + t * np.cos(theta) + 50
    lines = hough.detect_lines(x - 50, y - 50, reference.NumpyAccumulator, fit_points="inverse")
    assert len(lines) == 1
    L = lines[0]
    assert L.votes == 200 and L.theta_deg == pytest.approx(30.0, abs=0.051) and L.rho == pytest.approx(12.3, abs=0.051)
    normal = np.array([np.cos(theta), np.sin(theta)])
    assert abs(abs(L.direction @ normal)) < 1e-6  # the refit is exact on exact points


def test_validation_rejects_short_or_gappy_runs():
    assert hough.runs_along(np.array([0, 1, 2, 3, 4, 5, 6, 7, 8.5]), 2.5, 8.0) == [(0.0, 8.5)]
    assert hough.runs_along(np.array([0, 1, 2, 3, 6, 7, 8, 9]), 2.5, 8.0) == []  # a 3 m gap splits it
    assert hough.runs_along(np.array([0.0, 2.0, 4.0, 6.0]), 2.5, 8.0) == []  # too short


def test_a_sparse_wire_is_validated_at_its_own_spacing():
    """An earth wire seen at about 1 point per metre from the street (mobile_stacked seed 8), 4 cm
    of scatter across: the peak cell holds about half its points, gaps of 2-5 m, the method's 2.5 m
    V_max validates it in short stretches only. With v_max_spacings the validated peak's runs are
    taken at its points' median gap (up to S_min / 2) and the wire is one line; a dense wire's
    V_max stays the method's."""
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0, 90, 90))
    x, y = t, 20.05 + rng.normal(0, 0.04, len(t))  # on a cell border: split between two
    method = hough.detect_lines(x, y, reference.NumpyAccumulator)
    assert all(np.ptp(L.t_range) < 30 for L in method)
    lines = hough.detect_lines(x, y, reference.NumpyAccumulator, v_max_spacings=10.0)
    assert len(lines) == 1 and lines[0].v_max == 4.0 and np.ptp(lines[0].t_range) > 80
    assert abs(lines[0].direction[1]) < 1e-3 and lines[0].anchor[1] == pytest.approx(20.05, abs=0.02)
    # the cap: three points at least in a run of S_min
    assert hough.line_v_max(np.array([0.0, 3.0, 6.0, 9.0]), 2.5, 8.0, 10.0) == 4.0
    assert hough.line_v_max(np.arange(0, 60, 0.1), 2.5, 8.0, 10.0) == 2.5
    assert hough.line_v_max(np.arange(0, 60, 1.0), 2.5, 8.0, 0.0) == 2.5


def test_the_height_window_reaches_a_sparse_earth_wire_and_not_a_bird():
    """An earth wire 38 m up, 185 points over 185 m, above 200 000 candidates up to 28 m (a stack
    seen from the street): fewer points than the top 0.05 % the percentile leaves out. Its points
    have neighbours along it within V_max and stay in the window; a bird 30 m above it does not."""
    from toolbox_plugins.powerlines.core import height_window_top

    rng = np.random.default_rng(0)
    low = np.column_stack([rng.uniform(0, 185, 200_000), rng.uniform(-10, 10, 200_000), rng.uniform(3.5, 28, 200_000)])
    s = np.sort(rng.uniform(0, 185, 185))
    wire = np.column_stack([s, np.zeros_like(s), 35.3 + 2.7 * ((s - 92.5) / 92.5) ** 2])
    bird = np.array([[90.0, 3.0, 68.0]])
    xyz = np.r_[low, wire, bird]
    top = height_window_top(xyz[:, 2], xyz)
    assert 38.0 <= top <= 39.5
    assert np.percentile(xyz[:, 2], 99.95) + 1 < 37.0  # what the percentile alone kept
    assert height_window_top(np.r_[low, bird][:, 2], np.r_[low, bird]) < 30.0


def test_tophat_keeps_lines_and_drops_blobs_and_dense_cells():
    rng = np.random.default_rng(0)
    wire_x = np.linspace(0, 50, 200)
    wire = np.column_stack([wire_x, 10 + 0.0 * wire_x])
    blob = rng.uniform([20, 30], [30, 40], (3000, 2))  # a crown / a roof
    x = np.r_[wire[:, 0], blob[:, 0]]
    y = np.r_[wire[:, 1], blob[:, 1]]
    cx, cy, _, counts, _ = tophat_points(x, y, 0.5, 45)
    on_wire = np.abs(cy - 10) < 0.5
    assert on_wire.sum() >= 90  # about 2 centroids per metre of wire
    assert (~on_wire).sum() < 0.1 * on_wire.sum()  # the blob's interior is gone
    # a dense thin structure (>= 45 points per cell) is dropped as vegetation
    cx2, *_ = tophat_points(np.repeat(wire_x, 50), np.full(200 * 50, 10.0), 0.5, 45)
    assert len(cx2) == 0
    img = np.zeros((20, 20))
    img[5, 2:18] = 1
    img[10:16, 10:16] = 1
    th = tophat_raster(img, "binary")
    assert th[5, 3:17].all() and th[12, 12] == 0


@pytest.mark.parametrize("shape, size", [("cross", 3), ("square", 3), ("disk", 5), ("cross", 4)])
def test_sparse_tophat_equals_the_raster_opening(shape, size):
    """The opening on occupied cells only gives the cells scipy's binary_opening of the mask does."""
    from scipy import ndimage
    from toolbox_plugins.tophat.core import structure

    rng = np.random.default_rng(size)
    pts = np.r_[rng.uniform(0, 30, (3000, 2)), rng.uniform(5, 9, (4000, 2)),
                np.column_stack([np.linspace(0, 30, 400), np.full(400, 20.0)])]
    x, y = pts[:, 0], pts[:, 1]
    el = structure(shape, size)
    cx, cy, cz, counts, kept_point = tophat_points(x, y, 0.5, 45, el, z=x + y)
    # the dense reference on a raster with a wide margin
    c = np.floor(x / 0.5).astype(int) + 10
    r = np.floor(y / 0.5).astype(int) + 10
    n = np.zeros((r.max() + 11, c.max() + 11), int)
    np.add.at(n, (r, c), 1)
    mask = n > 0
    keep = mask & ~ndimage.binary_opening(mask, structure=el) & (n < 45)
    assert np.array_equal(kept_point, keep[r, c])
    assert len(cx) == keep.sum() and counts.sum() == kept_point.sum()
    np.testing.assert_allclose(np.sort(cz), np.sort(cx + cy))  # means of x + y per cell


def test_catenary_fit_and_span_split():
    s = np.linspace(0, 400, 1200)
    L = 200.0
    z_att = catenary(L, 10, 100, 1000)  # the wire is continuous at the attachment point
    z = np.where(s < L, catenary(s, 10, 100, 1000), catenary(s, z_att - catenary(L, 0, 300, 900), 300, 900))
    z = z + np.random.default_rng(0).normal(0, 0.03, len(s))
    cuts = split_spans(s, z, 8.0)
    assert len(cuts) == 1 and cuts[0] == pytest.approx(200, abs=3)
    # the same wire measured the other way along its line (and shifted): the mirrored cut
    for shift in (0.0, 37.3):
        back = split_spans(shift - s[::-1], z[::-1], 8.0)
        assert back == pytest.approx([shift - c for c in cuts[::-1]], abs=1e-6)
    # three spans with uneven points: the candidate grid is centred, not tied to one end
    keep = np.random.default_rng(1).random(len(s)) > 0.3
    s3, z3 = np.r_[s[keep], 400 + s[keep][s[keep] < 150]], np.r_[z[keep], z[keep][s[keep] < 150]]
    fwd = split_spans(s3, z3, 8.0)
    rev = split_spans(-s3, z3, 8.0)
    assert len(fwd) >= 1 and rev == pytest.approx([-c for c in fwd[::-1]], abs=1e-6)
    z0, s0, c, rms = fit_catenary(s[s < 195], z[s < 195])
    assert c == pytest.approx(1000, rel=0.02) and s0 == pytest.approx(100, abs=1) and rms < 0.04


def test_a_span_climbing_from_a_pole_is_cut_there_and_a_slack_wire_is_not():
    """A low-voltage wire on flat ground to a pole at 60 m, then climbing 10 m to the next pole
    on an embankment: at the pole the slope rises far faster than any catenary's (c >= 100 m),
    so the wire is cut there, though the slope never drops. One slack catenary (c = 150 m) over
    the same length is not cut."""
    rng = np.random.default_rng(3)
    s = np.sort(rng.uniform(0, 100, 500))
    z_pole = catenary(60.0, 10.0, 30.0, 400.0)
    # second span: from (60, z_pole) to (100, z_pole + 10) with c = 400: its lowest point lies
    # before the pole, so the wire leaves the pole climbing
    c2 = 400.0
    s02 = 80.0 - c2 * np.arcsinh(10.0 / (2 * c2 * np.sinh(20.0 / c2)))
    z02 = z_pole - (catenary(60.0, 0.0, s02, c2))
    z = np.where(s < 60.0, catenary(s, 10.0, 30.0, 400.0), catenary(s, z02, s02, c2)) + rng.normal(0, 0.03, len(s))
    assert abs(catenary(100.0, z02, s02, c2) - (z_pole + 10.0)) < 1e-6
    cuts = split_spans(s, z, 8.0)
    assert len(cuts) == 1 and cuts[0] == pytest.approx(60.0, abs=3.0)
    slack = catenary(s, 10.0, 50.0, 150.0) + rng.normal(0, 0.03, len(s))
    assert split_spans(s, slack, 8.0) == []


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_wire_run_through_a_tower_uncut_is_cut_where_two_catenaries_meet(seed):
    """Two 60 m spans of one wire whose tower hides it over 10 m: cut at the tower within a metre;
    one span, a 300 m span and a span climbing a hillside are not cut, nor are two spans that do
    not meet (two wires)."""
    rng = np.random.default_rng(seed)
    s = np.sort(rng.uniform(0, 120, 400))
    s = s[np.abs(s - 60) > 5]
    two = np.where(s < 60, catenary(s, 10, 30, 1000), catenary(s, 10, 90, 1000)) + rng.normal(0, 0.03, len(s))
    assert abs(kink_cut(s, two, 20.0) - 60.0) <= 1.0
    assert kink_cut(s, catenary(s, 10, 60, 1000) + rng.normal(0, 0.03, len(s)), 20.0) is None
    assert kink_cut(s, catenary(s, 10, -40, 800) + rng.normal(0, 0.03, len(s)), 20.0) is None
    long = np.sort(rng.uniform(0, 300, 900))
    assert kink_cut(long, catenary(long, 10, 150, 1500) + rng.normal(0, 0.05, len(long)), 20.0) is None
    apart = np.where(s < 60, catenary(s, 10, 30, 1000), catenary(s, 11, 90, 1000)) + rng.normal(0, 0.03, len(s))
    assert kink_cut(s, apart, 20.0) is None


def test_peel_separates_stacked_wires_and_leaves_crowns():
    """Four wires of one span hung 0.35 m above one another (a mobile scan's distribution line,
    closer than the 3D step's height link) and a crown's scatter in the same band: each wire comes
    out as its own catenary with its points, and nothing is found in the crown."""
    rng = np.random.default_rng(3)
    truth = [(10.0 + 0.35 * k, 20.0, 120.0 + 5 * k) for k in range(4)]  # (z0, s0, c): one span, never crossing
    s, z, off, label = [], [], [], []
    for k, (z0, s0, c) in enumerate(truth):
        sk = np.sort(rng.uniform(0, 40, 150))
        s.append(sk)
        z.append(catenary(sk, z0, s0, c) + rng.normal(0, 0.02, len(sk)))
        off.append(0.3 * k - 0.45 + rng.normal(0, 0.03, len(sk)))
        label.append(np.full(len(sk), k))
    crown = rng.uniform([5, 7, -1], [25, 11, 1], (400, 3))  # under the wires, the band's width
    s, z, off = np.r_[np.concatenate(s), crown[:, 0]], np.r_[np.concatenate(z), crown[:, 1]], np.r_[np.concatenate(off), crown[:, 2]]
    label = np.r_[np.concatenate(label), np.full(len(crown), -1)]
    found = peel_catenaries(s, z, off, min_points=20, min_span=8.0, max_rms=0.2, gap_m=5.0)
    assert len(found) == 4
    got = set()
    for idx, (z0, s0, c, rms) in found:
        k = np.bincount(label[idx][label[idx] >= 0]).argmax()
        got.add(k)
        assert np.mean(label[idx] == k) >= 0.97 and np.sum(label[idx] == k) >= 0.95 * 150  # its points, and few others
        ss = np.linspace(0, 40, 50)
        assert np.max(np.abs(catenary(ss, z0, s0, c) - catenary(ss, *truth[k]))) <= 0.05 and rms <= 0.05
    assert got == {0, 1, 2, 3}
    # the crown alone: points lined up in (s, z) by chance are not thin across the band
    assert peel_catenaries(crown[:, 0], crown[:, 1], crown[:, 2], 20, 8.0, 0.2, 5.0) == []


@pytest.mark.parametrize("apart_m, twins", [(0.0, [(0, 1)]), (0.6, [])])
def test_lines_either_side_of_one_wire_are_twins(apart_m, twins):
    """Two lines 0.45 m apart, leaning 0.01 deg, with a wire between them (each band holds the
    points on its side of it: two leaning copies of one wire) are twins; the same lines each on
    a wire of its own (0.6 m apart) are not."""
    rng = np.random.default_rng(3)
    s = np.sort(rng.uniform(0, 200, 1200))
    side = np.where(np.arange(len(s)) % 2 == 0, -0.5, 0.5) * apart_m
    y = side + rng.normal(0, 0.04, len(s))
    z = catenary(s, 10.0, 100.0, 1200.0) + rng.normal(0, 0.03, len(s))
    tilt = np.radians(0.01)
    lines = [(np.array([0.0, o]), np.array([np.cos(tilt), np.sin(tilt)]), 0.0, 200.0) for o in (-0.25, 0.2)]
    kw = dict(band=1.0, z_link=1.0, s_link=5.0, min_span=8.0, max_rms=0.2)
    spans, _, _ = conductors_3d(lines, s, y, z, **kw)
    assert {sp.conductor for sp in spans if sp.s_to - sp.s_from >= 8.0} == {0, 1}  # a wire in each band
    assert twin_lines(spans, lines, 0.2, 8.0, 1.0) == twins


@pytest.mark.xfail(strict=True, reason="known limit (README, docs/powerlines.md): the 3D step links the stack into one "
                   "piece (z_link 1 m) and split_spans cuts it where the mixture's slope wanders; local layers, "
                   "heights levelled layer by layer, and one shape per span with each cable's offset pass it, "
                   "but none helped the variant family's stacks, so none is in")
def test_a_stack_of_cables_over_two_spans_is_one_wire_per_cable_per_span():
    """Three cables 0.3 m apart one above another (a joint-use pole's), two 40 m spans on a 10 %
    climb with the pole between, each cable missing its points over a different stretch (their
    mixture's slope wanders there): the 3D step gives each cable its own catenary per span and
    nearly all its points, with no points of another cable."""
    rng = np.random.default_rng(7)
    xs, zs, label = [], [], []
    for k in range(3):
        s = np.sort(rng.uniform(0, 80, 320))
        gap0 = 8.0 + 22.0 * k
        s = s[(s < gap0) | (s > gap0 + 6.0)]  # a 6 m occlusion, elsewhere on each cable
        z = 6.0 - 0.3 * k + 0.1 * s + np.where(s < 40, catenary(s, 0, 20, 400) - catenary(0, 0, 20, 400),
                                               catenary(s, 0, 60, 400) - catenary(40, 0, 60, 400))
        xs.append(s), zs.append(z + rng.normal(0, 0.03, len(s))), label.append(np.full(len(s), k))
    s, z, label = np.concatenate(xs), np.concatenate(zs), np.concatenate(label)
    py = rng.normal(0, 0.04, len(s))
    lines = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 80.0)]
    spans, line_of, wire_of = conductors_3d(lines, s, py, z, band=0.4, z_link=1.0, s_link=5.0, min_span=8.0,
                                            max_rms=0.2)
    on = wire_of >= 0
    assert on.mean() >= 0.95
    for w in np.unique(wire_of[on]):  # each wire one cable's points
        assert np.mean(label[wire_of == w] == np.bincount(label[wire_of == w]).argmax()) >= 0.99
    for k in range(3):  # each cable a wire of its own in each span
        for lo, hi in ((0, 40), (40, 80)):
            mine = (label == k) & (s > lo + 2) & (s < hi - 2)
            assert np.mean(on[mine]) >= 0.95 and len(np.unique(wire_of[mine & on])) == 1


def test_the_3d_step_on_some_lines_gives_what_the_whole_run_gives_them():
    """The realignment re-runs the 3D step on the lines whose bands changed only (``only``): a
    line's spans and wire points must be those of a run over every line."""
    rng = np.random.default_rng(5)
    xs, ys, zs = [], [], []
    lines = []
    for k, (y0, heading) in enumerate([(0.0, 0.0), (1.0, 0.3), (8.0, -0.5), (30.0, 20.0)]):
        d = np.array([np.cos(np.radians(heading)), np.sin(np.radians(heading))])
        a = np.array([0.0, y0])
        lines.append((a, d, 0.0, 80.0))
        for z0 in (12.0, 15.0):  # two wires per line
            t = rng.uniform(0, 80, 300)
            xy = a + t[:, None] * d + rng.normal(0, 0.03, (300, 2))
            xs.append(xy[:, 0]), ys.append(xy[:, 1])
            zs.append(catenary(t, z0, 40.0, 800.0) + rng.normal(0, 0.03, 300))
    clutter = rng.uniform([0, -2, 5], [80, 10, 18], (400, 3))  # crowns in the bands
    px, py, pz = np.r_[np.concatenate(xs), clutter[:, 0]], np.r_[np.concatenate(ys), clutter[:, 1]], \
        np.r_[np.concatenate(zs), clutter[:, 2]]
    kw = dict(band=0.4, z_link=1.0, s_link=5.0, min_span=10.0, max_rms=0.2)
    spans, line_of, wire_of = conductors_3d(lines, px, py, pz, **kw)
    only = {1, 3}
    some, some_line, some_wire = conductors_3d(lines, px, py, pz, only=only, **kw)
    assert len(spans) > len(some) > 0 and {sp.conductor for sp in some} <= only
    assert some == [sp for sp in spans if sp.conductor in only]
    mine = np.isin(line_of, list(only))
    assert (some_line[mine] == line_of[mine]).all() and (some_wire[mine] == wire_of[mine]).all()
    assert (some_line[~np.isin(some_line, list(only))] == -1).all()


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


@pytest.mark.parametrize("shape", ["triangle", "square"])
def test_bundle_split_separates_sub_conductors_across_and_in_height(shape):
    """A triangle (0.4 m) and a square (0.6 m) bundle, one connected piece each: split across the
    line and in height (about a running mean: the span sags 0.5 m) into one piece per
    sub-conductor; without heights only the side-by-side cut is possible."""
    rng = np.random.default_rng(5)
    offsets = {"triangle": [(-0.2, 0.0), (0.2, 0.0), (0.0, 0.35)],
               "square": [(-0.3, 0.0), (0.3, 0.0), (-0.3, 0.6), (0.3, 0.6)]}[shape]
    s, off, z, label = _bundle(rng, offsets)
    lab = _split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z)
    assert len(np.unique(lab)) == len(offsets)
    for k in np.unique(lab):  # each piece one sub-conductor's points, all of them
        assert len(np.unique(label[lab == k])) == 1
    assert len(np.unique(_split_bundles(s, off, np.zeros(len(s), np.int64), 20))) < len(offsets)


@pytest.mark.parametrize("n_wires, spacing", [(3, 0.3), (4, 0.3), (3, 0.4)])
def test_bundle_split_separates_a_ribbon_of_three_or_four_wires(n_wires, spacing):
    """A ribbon's phases side by side at one height, one connected piece: no cut in two is clean
    (one side holds two wires, as wide as a crown's layer), a cut into one group per wire is."""
    rng = np.random.default_rng(2)
    offsets = [((k - (n_wires - 1) / 2) * spacing, 0.0) for k in range(n_wires)]
    s, off, z, label = _bundle(rng, offsets)
    lab = _split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z)
    assert len(np.unique(lab)) == n_wires
    for k in np.unique(lab):  # each piece one wire's points (a 3-sigma tail point may cross over)
        assert np.bincount(label[lab == k]).max() >= 0.98 * (lab == k).sum()
        assert np.bincount(label[lab == k]).max() >= 0.98 * (label == np.argmax(np.bincount(label[lab == k]))).sum()


def test_bundle_split_follows_the_wires_trend_not_the_pieces():
    """Two phases 0.3 m apart along a Hough line that leans 0.02 deg off them (their offsets drift
    0.19 m over its 520 m), with a third phase's points at the far end only (past the end of that
    phase's own line): a trend fitted to the whole piece leans towards the third phase and smears
    each wire across the gap; the wires' own trend keeps them apart (seed 4's 0.3 m ribbon)."""
    rng = np.random.default_rng(4)
    s, off, label = [], [], []
    for k, (o, lo) in enumerate([(0.15, 0.0), (-0.15, 0.0), (-0.45, 430.0)]):
        sk = rng.uniform(lo, 520.0, int(2.6 * (520.0 - lo)))
        s.append(sk), off.append(o + 3.6e-4 * sk + rng.normal(0, 0.04, len(sk))), label.append(np.full(len(sk), k))
    s, off, label = np.concatenate(s), np.concatenate(off), np.concatenate(label)
    z = 10.0 + rng.normal(0, 0.03, len(s))
    lab = _split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z)
    for k in (0, 1):  # each of the two long phases nearly whole in a piece of its own
        mine = lab[label == k]
        main = np.bincount(mine).argmax()
        assert np.mean(mine == main) >= 0.97 and np.mean(label[lab == main] == k) >= 0.97


@pytest.mark.parametrize("spacing, n_conductors", [(0.2, 1), (0.4, 3)])
def test_side_by_side_is_not_chained_by_a_piece_drifting_across_the_gap(spacing, n_conductors):
    """Three wires ``spacing`` apart along one Hough line, three spans each, and a 21 m piece at a
    tower whose offset drifts 0.27 m along it (0.7 deg: within the 1 deg left to jumpers), its
    middle half-way between two wires. A triangle bundle's sub-conductors 0.2 m apart in plan stay
    one conductor; a ribbon's phases 0.4 m apart become one each. How it failed (held-out seed 19,
    bundle3_d5): the piece's middle chained two sub-conductors' groups, and the bundle came out
    as two conductors beside its phase (9 of 10, crossings 15 of 21); the ribbon here gave two
    too, one holding two phases."""
    import geopandas as gpd
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.plan_geometry import side_by_side

    offsets = [-spacing, 0.0, spacing]
    spans, xs, ys, wire = [], [], [], []
    for w, o in enumerate(offsets):
        for k, (s0, s1) in enumerate([(0.0, 185.0), (185.5, 370.0), (370.5, 554.0)]):
            spans.append(Span(0, w, k, 0.5 * (s0 + s1), 1500.0, 20.0, s0, s1, 0.03, 300, 2.5, offset=o,
                              offset_rms=0.04, lateral_tol=0.12))
        s = np.arange(0.0, 554.0, 0.5)
        xs.append(s), ys.append(np.full(len(s), o)), wire.append(np.full(len(s), w))
    spans.append(Span(0, 3, 0, 11.0, 1500.0, 20.0, 0.3, 21.8, 0.04, 25, 0.1, offset=spacing / 2 - 0.0125 * 11.0,
                      offset_slope=0.0125, offset_rms=0.04, lateral_tol=0.12))
    x, y, wire_of = np.concatenate(xs), np.concatenate(ys), np.concatenate(wire)
    line = LineString([(0.0, 0.0), (554.0, 0.0)])
    cond = gpd.GeoDataFrame({"conductor": [0], "azimuth_deg": [90.0], "n_points": [len(x)]}, geometry=[line])
    seg = gpd.GeoDataFrame({"conductor": [0]}, geometry=[line])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 554.0)]
    params = {"max_rms_3d_m": 0.15, "s_min_m": 8.0}
    lines, geo, spans, conductor_of, wire_of, added = side_by_side(
        {"conductors": cond, "conductor_segments": seg}, geo, spans, np.zeros(len(x), np.int64), wire_of, x, y,
        params, 1.0)
    assert added == n_conductors - 1 and len(lines["conductors"]) == n_conductors
    # each conductor holds one wire's points, or the whole bundle's
    for k in range(n_conductors):
        assert np.ptp(y[conductor_of == k]) == (2 * spacing if n_conductors == 1 else 0.0)
    got = sorted(float(np.median(y[conductor_of == k])) for k in range(n_conductors))
    want = [0.0] if n_conductors == 1 else offsets
    assert np.allclose(got, want, atol=0.01)


def _one_line_layers(length_m):
    """The Hough layers and geometry of one conductor along x from 0 to ``length_m``."""
    from shapely.geometry import LineString

    line = LineString([(0.0, 0.0), (length_m, 0.0)])
    cond = gpd.GeoDataFrame({"conductor": [0], "azimuth_deg": [90.0], "n_points": [1000]}, geometry=[line])
    seg = gpd.GeoDataFrame({"conductor": [0]}, geometry=[line])
    return {"conductors": cond, "conductor_segments": seg}, [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0,
                                                              length_m)]


@pytest.mark.parametrize("leaning", [False, True])
def test_realign_turns_a_line_its_wire_leaves_not_one_its_spans_slopes_lean(leaning):
    """Fourteen 40 m spans of one wire along a 573 m line, each span's own offset slope 4e-4 (a
    drift of 0.23 m over the line, over the quarter band_m that turns it). Where the spans'
    offsets also move from one to the next, the wire leaves the line and it turns; where they
    stay put, the slopes share a bias (held-out dist_d5 seed 22: a sparse scan's pattern along
    each span) and the line, on its wire, stays (it turned 0.02 deg and missed its truth by
    0.1 m at both ends)."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.plan_geometry import realign

    slope = 4e-4
    spans = []
    for k in range(14):
        s0, s1 = 1.0 + 41.0 * k, 40.0 + 41.0 * k
        mid = 0.5 * (s0 + s1)
        at_mid = slope * mid if leaning else 0.0
        spans.append(Span(0, 0, k, mid, 1500.0, 20.0, s0, s1, 0.03, 60, 0.1, offset=at_mid - slope * mid,
                          offset_slope=slope, offset_rms=0.04, lateral_tol=0.12))
    lines, geo = _one_line_layers(573.0)
    params = {"max_rms_3d_m": 0.15, "s_min_m": 8.0, "band_m": 0.4}
    out, geo2, turned = realign(lines, geo, spans, params, 1.0, min_drift_m=0.1)
    assert turned == int(leaning)
    end = np.array(out["conductors"].geometry[0].coords)[-1]
    assert end[1] == pytest.approx(slope * 573.0 if leaning else 0.0, abs=0.005)  # on the wire


def test_a_triangle_bundles_line_runs_through_the_middle_of_its_sub_conductors():
    """A triangle bundle kept as one conductor (its sub-conductors 0.2 m apart in plan, under the
    0.25 m that splits) whose Hough line lies 4 cm off its middle sub-conductor (the bottom left
    one held more points; held-out bundle3_d5 seed 22, whose crossings at 24 deg were 7 cm off):
    the line moves onto the middle of the outermost. A single wire with a 20 m piece of another
    0.15 m beside it stays on its wire."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.plan_geometry import side_by_side

    params = {"max_rms_3d_m": 0.15, "s_min_m": 8.0}
    for offsets, pieces, want in (([-0.24, -0.04, 0.16], [], -0.04), ([0.0], [(100.0, 120.0, 0.15)], 0.0)):
        spans, xs, ys = [], [], []
        for w, o in enumerate(offsets):
            for k, (s0, s1) in enumerate([(0.0, 185.0), (185.5, 370.0), (370.5, 554.0)]):
                spans.append(Span(0, w, k, 0.5 * (s0 + s1), 1500.0, 20.0, s0, s1, 0.03, 300, 2.5, offset=o,
                                  offset_rms=0.04, lateral_tol=0.12))
            xs.append(np.arange(0.0, 554.0, 0.5)), ys.append(np.full(1108, o))
        for s0, s1, o in pieces:
            spans.append(Span(0, 9, 0, 0.5 * (s0 + s1), 1500.0, 20.0, s0, s1, 0.03, 40, 0.1, offset=o,
                              offset_rms=0.04, lateral_tol=0.12))
        x, y = np.concatenate(xs), np.concatenate(ys)
        lines, geo = _one_line_layers(554.0)
        lines, geo, spans, conductor_of, _, added = side_by_side(
            lines, geo, spans, np.zeros(len(x), np.int64), np.zeros(len(x), np.int64), x, y, params, 1.0)
        assert added == 0 and (conductor_of == 0).all()
        coords = np.array(lines["conductors"].geometry[0].coords)
        assert np.allclose(coords[:, 1], want, atol=0.005)


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


def test_ribbon_lines_redraw_the_houghs_lines_between_three_wires_one_per_wire():
    """Three wires 0.3 m apart over 500 m (a horizontal three-phase line) and the Hough's two
    lines drawn between them, one leaning from the middle wire to the outer one (0.3 m over the
    corridor, 0.03 deg): one line per wire, each within 3 cm of its wire at both ends."""
    from toolbox_plugins.powerlines.core import ribbon_lines

    rng = np.random.default_rng(3)
    offsets = [-0.3, 0.0, 0.3]
    pts, _, frame = _ribbon_points(rng, offsets)
    lines = [_line_between(frame, 0.3, 0.0, 500.0), _line_between(frame, -0.15, -0.15, 500.0)]
    got = ribbon_lines(lines, pts[:, 0], pts[:, 1], 0.4, 8.0, 5.0)
    assert got is not None
    new, source, held = got
    assert len(new) == 3 and set(source) <= {0, 1}
    # each wire holds its own points within 6 cm (1.5 sd) of its peak: 87 % of its 1000
    assert all(820 <= h <= 920 for h in held), held
    a, d, n = frame
    for o in offsets:
        ends = [np.array([(b + t * u - a) @ n for t in (t0, t1)]) for b, u, t0, t1 in new]
        assert sum(np.all(np.abs(e - o) <= 0.03) for e in ends) == 1
    for b, u, t0, t1 in new:  # each over the ribbon's length
        assert t1 - t0 >= 490.0


def test_ribbon_lines_leave_lines_on_their_wires_and_a_scattered_bundle_alone():
    """Lines already one per wire are left as they are; so are a pair of sub-conductors 0.46 m
    apart whose scatter across (0.1 m, an airborne survey's) fills the gap between them (the
    Hough's line between them is as good as any), and short lines (a tower's members)."""
    from toolbox_plugins.powerlines.core import ribbon_lines

    rng = np.random.default_rng(4)
    pts, _, frame = _ribbon_points(rng, [-0.3, 0.0, 0.3])
    lines = [_line_between(frame, o, o, 500.0) for o in (-0.3, 0.0, 0.3)]
    assert ribbon_lines(lines, pts[:, 0], pts[:, 1], 0.4, 8.0, 5.0) is None
    pts, _, frame = _ribbon_points(rng, [-0.23, 0.23, 5.0, 5.46, 10.0, 10.46], sd_m=0.1)
    lines = [_line_between(frame, o, o, 500.0) for o in (0.0, 5.23, 10.23)]
    assert ribbon_lines(lines, pts[:, 0], pts[:, 1], 0.4, 8.0, 5.0) is None
    pts, _, frame = _ribbon_points(rng, [-0.3, 0.0, 0.3], length_m=25.0, per_m=20.0)
    lines = [_line_between(frame, 0.3, 0.0, 25.0), _line_between(frame, -0.15, -0.15, 25.0)]
    assert ribbon_lines(lines, pts[:, 0], pts[:, 1], 0.4, 8.0, 5.0) is None


def test_windowed_groups_link_wires_that_move_together():
    """Three wires 0.4 m apart whose offsets swing together 0.3 m along 300 m (the third over its
    first 80 m only): window by window (50 m) each cuts cleanly about its own straight trend and
    the groups link across the windows' borders into one per wire; a window holding a crown's
    scatter (no clean cut) gives none."""
    from toolbox_plugins.powerlines.core import _windowed_groups

    rng = np.random.default_rng(5)
    s, off, label = [], [], []
    for k, (o, hi) in enumerate([(0.0, 300.0), (0.4, 300.0), (-0.4, 80.0)]):
        sk = rng.uniform(0.0, hi, int(2.0 * hi))
        s.append(sk), off.append(o + 0.3 * np.sin(sk / 300.0 * 2 * np.pi) + rng.normal(0, 0.04, len(sk)))
        label.append(np.full(len(sk), k))
    s, off, label = np.concatenate(s), np.concatenate(off), np.concatenate(label)
    g = _windowed_groups(s, off, 20, 0.25, 0.15, 50.0)
    assert g is not None
    for k in range(3):
        main = np.bincount(g[label == k]).argmax()
        assert np.mean(g[label == k] == main) >= 0.97 and np.mean(label[g == main] == k) >= 0.97
    crown = rng.uniform([120.0, -1.0], [160.0, 1.0], (400, 2))
    assert _windowed_groups(np.r_[s, crown[:, 0]], np.r_[off, crown[:, 1]], 20, 0.25, 0.15, 50.0) is None


def test_bundle_split_leaves_a_wire_with_a_crown_under_it():
    """A wire with a crown's scatter linked to it from below: bimodal in height, but the crown's
    layer is wider than a wire (pooled spread over WIRE_LATERAL_RMS_M): not cut."""
    rng = np.random.default_rng(2)
    s, off, z, _ = _bundle(rng, [(0.0, 0.0)])
    crown = rng.uniform([10, -1, 0], [40, 1, 1], (300, 3))
    s = np.r_[s, crown[:, 0]]
    off = np.r_[off, crown[:, 1]]
    z = np.r_[z, catenary(crown[:, 0], 20.0, 30.0, 900.0) - 1.0 - crown[:, 2]]
    assert len(np.unique(_split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z))) == 1


def test_a_scan_row_on_a_roof_lies_in_a_surface_and_wires_do_not():
    """Cross-sections about a span: rows of a 35-degree roof every 0.3 m (a mobile scanner's view
    of a far roof) are a surface; a wire with three more 0.4 m beside it (a ribbon), with a crown
    around it, or meeting a pole and a cross arm, is not."""
    rng = np.random.default_rng(0)
    L = 30.0

    def rows(starts, direction, n_per_row=150):
        pts = []
        for t in starts:
            s = rng.uniform(0, L, n_per_row)
            pts.append(np.column_stack([s, t * direction[0] + rng.normal(0, 0.02, len(s)),
                                        t * direction[1] + rng.normal(0, 0.02, len(s))]))
        return np.vstack(pts)

    roof = rows(np.arange(-0.3, 3.0, 0.3), (np.cos(np.radians(35)), np.sin(np.radians(35))))
    assert span_on_surface(roof[:, 0], roof[:, 1], roof[:, 2], 0.0, L)
    ribbon = rows([0.0, 0.4, 0.8, 1.2], (1.0, 0.0))
    assert not span_on_surface(ribbon[:, 0], ribbon[:, 1], ribbon[:, 2], 0.0, L)
    crown = np.column_stack([rng.uniform(5, 20, 3000), rng.uniform(-2, 2, 3000), rng.uniform(-2, 2, 3000)])
    wire_crown = np.vstack([rows([0.0], (1.0, 0.0)), crown])
    assert not span_on_surface(wire_crown[:, 0], wire_crown[:, 1], wire_crown[:, 2], 0.0, L)
    pole = np.column_stack([rng.uniform(29.8, 30.0, 400), rng.normal(0, 0.05, 400), rng.uniform(-2, 0, 400)])
    arm = np.column_stack([rng.uniform(29.9, 30.0, 200), rng.uniform(-1.5, 1.5, 200), rng.normal(0, 0.02, 200)])
    at_pole = np.vstack([rows([0.0], (1.0, 0.0)), pole, arm])
    assert not span_on_surface(at_pole[:, 0], at_pole[:, 1], at_pole[:, 2], 0.0, L)


def test_a_short_wire_along_two_roofs_tops_lies_in_surfaces_and_a_wire_over_them_does_not():
    """A short wire found along the top edges of two roofs a street apart (mobile_comm3 seed 6:
    a 24 m "wire" through two gables' top rows): neither roof spans 0.3 of it, nor do both lie
    at one tilt, so the whole span is in no surface; cut where its points leave a gap, each
    piece lies in a roof of its own. The same wire 1 m over the roofs, and a ribbon's wire with
    a gap in it, are in none."""
    from toolbox_plugins.powerlines.core import Span, _pieces_on_surfaces

    rng = np.random.default_rng(3)

    def roof(s_from, s_to, tilt_deg, lift=0.0, n_per_row=60):
        u = (np.cos(np.radians(tilt_deg)), -np.sin(np.radians(tilt_deg)))
        pts = [np.column_stack([rng.uniform(s_from, s_to, n_per_row), t * u[0] + rng.normal(0, 0.02, n_per_row),
                                t * u[1] - lift + rng.normal(0, 0.02, n_per_row)]) for t in np.arange(0.0, 3.0, 0.25)]
        return np.vstack(pts)

    sp = Span(0, 0, 0, 12.0, 1e6, 0.0, 0.0, 24.0, 0.03, 0, 0.0)
    two = np.vstack([roof(0.0, 6.5, 20.0), roof(17.5, 24.0, -35.0)])
    assert not span_on_surface(two[:, 0], two[:, 1], two[:, 2], 0.0, 24.0)
    assert _pieces_on_surfaces(two[:, 0], two[:, 1], two[:, 2], sp) > 0.9
    # 1 m over the roofs: its pieces are in no surface (the roofs pass a metre under them)
    wire = np.column_stack([np.r_[rng.uniform(0, 6.5, 80), rng.uniform(17.5, 24, 80)], rng.normal(0, 0.02, 160),
                            rng.normal(0, 0.02, 160)])
    below = np.vstack([roof(0.0, 6.5, 20.0, lift=1.0)[60:], roof(17.5, 24.0, -35.0, lift=1.0)[60:], wire])
    assert _pieces_on_surfaces(below[:, 0], below[:, 1], below[:, 2], sp) == 0.0
    ribbon = np.vstack([np.column_stack([wire[:, 0], wire[:, 1] + o, wire[:, 2]]) for o in (0.0, 0.4, 0.8, 1.2)])
    assert _pieces_on_surfaces(ribbon[:, 0], ribbon[:, 1], ribbon[:, 2], sp) == 0.0


def test_a_second_pass_line_along_a_first_is_folded_into_it():
    """A second-pass line 0.5 degrees off a first-pass line it runs along (the wire past the end
    of the first line's extent): its span, re-expressed in the first line's frame, describes the
    same 3D curve (within a millimetre), becomes a new wire of that line, its points go to that
    line, and the line's extent and plan geometry stretch over it."""
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.wire_sets import fold_into

    ang = np.radians(0.5)
    dg = np.array([np.cos(ang), np.sin(ang)])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 100.0)]
    geo2 = [(np.array([110.0, 0.2]), dg, 0.0, 40.0)]
    sp = Span(0, 0, 0, 20.0, 500.0, 10.0, 0.0, 40.0, 0.03, 50, 0.4, 0.05, 0.001, 0.03)
    lines = {"conductors": gpd.GeoDataFrame({"votes": [100], "length_m": [100.0]}, geometry=[LineString([(0, 0), (100, 0)])])}
    spans = [Span(0, 0, 0, 50.0, 800.0, 12.0, 0.0, 100.0, 0.03, 200, 1.0)]
    line_of, wire_of = np.array([0, 0, -1, -1, -1]), np.array([0, 0, -1, -1, -1])
    pos = np.array([2, 3, 4])  # where pass 2's points sit
    line_of2, wire2 = np.array([0, 0, -1]), np.array([0, 0, -1])
    spans, geo, lines = fold_into({0: 0}, geo2, [sp], line_of2, wire2, geo, spans, lines, line_of, wire_of, pos, 1.0)
    new = [q for q in spans if q.conductor == 0 and q.wire == 1]
    assert len(new) == 1 and list(line_of) == [0, 0, 0, 0, -1] and list(wire_of) == [0, 0, 1, 1, -1]
    q = new[0]
    t = np.linspace(0, 40, 9)
    xy = geo2[0][0] + t[:, None] * dg + (sp.offset + sp.offset_slope * t)[:, None] * np.array([-dg[1], dg[0]])
    z = catenary(t, sp.z0, sp.s0, sp.c)
    s_h, off_h = xy[:, 0], xy[:, 1]  # the first line's frame: along x from the origin
    np.testing.assert_allclose(off_h, q.offset + q.offset_slope * s_h, atol=1e-3)
    np.testing.assert_allclose(z, catenary(s_h, q.z0, q.s0, q.c), atol=1e-3)
    assert q.s_from == pytest.approx(s_h.min(), abs=1e-3) and q.s_to == pytest.approx(s_h.max(), abs=1e-3)
    assert geo[0][3] == pytest.approx(s_h.max(), abs=1e-3)
    assert lines["conductors"].geometry[0].length == pytest.approx(s_h.max(), abs=1e-3)
    assert lines["conductors"].length_m[0] == pytest.approx(s_h.max(), abs=1e-3)


def test_a_short_first_pass_line_along_a_long_one_is_folded_into_it():
    """A 20 m line the Hough fitted along a 500 m one (0.2 m aside, 0.3 degrees off: a
    sub-conductor near a tower) is a stretch of that conductor: one conductor is left, the stub's
    points and span become a wire of it. A line beside it 1 m away, or one as long, stays."""
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.wire_sets import fold_stubs

    ang = np.radians(0.3)
    d2 = np.array([np.cos(ang), np.sin(ang)])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 500.0), (np.array([470.0, 0.2]), d2, 0.0, 20.0),
           (np.array([0.0, 1.0]), np.array([1.0, 0.0]), 0.0, 500.0)]
    lines = {"conductors": gpd.GeoDataFrame({"votes": [900, 20, 800], "length_m": [500.0, 20.0, 500.0]}, geometry=[
        LineString([(0, 0), (500, 0)]), LineString([(470, 0.2), tuple(np.array([470, 0.2]) + 20 * d2)]),
        LineString([(0, 1), (500, 1)])]),
        "conductor_segments": gpd.GeoDataFrame({"conductor": [0, 1, 2]}, geometry=[LineString([(0, 0), (1, 0)])] * 3),
        "crossings": gpd.GeoDataFrame({"conductors": []}, geometry=[])}
    spans = [Span(0, 0, 0, 250.0, 1500.0, 20.0, 0.0, 470.0, 0.03, 900, 2.0),
             Span(1, 0, 0, 10.0, 1500.0, 20.0, 0.0, 20.0, 0.03, 40, 0.1),
             Span(2, 0, 0, 250.0, 1500.0, 20.0, 0.0, 500.0, 0.03, 800, 2.0)]
    line_of, wire_of = np.array([0, 0, 1, 1, 2, -1]), np.array([0, 0, 0, 0, 0, -1])
    lines, geo, spans, line_of, wire_of = fold_stubs(lines, geo, spans, line_of, wire_of, 1.0, {"band_m": 0.4})
    assert len(geo) == len(lines["conductors"]) == 2
    assert list(line_of) == [0, 0, 0, 0, 1, -1] and list(wire_of) == [0, 0, 1, 1, 0, -1]
    assert sorted((sp.conductor, sp.wire) for sp in spans) == [(0, 0), (0, 1), (1, 0)]


def test_points_of_a_crown_that_line_up_are_no_conductor():
    """A wire stands out in its cross-section (far denser within 0.1 m than 0.2-0.5 m around);
    a catenary through points of a crown that happen to line up does not: the crown's line is
    dropped, the wire kept, even with a crown touching it along a third of its span."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.stages.rejection import lines_not_wires

    rng = np.random.default_rng(4)
    L, z0, c = 40.0, 20.0, 900.0
    sw = rng.uniform(0, L, 200)
    wire = np.column_stack([sw, rng.normal(0, 0.03, 200), catenary(sw, z0, L / 2, c) + rng.normal(0, 0.03, 200)])
    touching = rng.uniform([0, -1.5, z0 - 1.5], [L / 3, 1.5, z0 + 1.0], (600, 3))
    crown = rng.uniform([0, 8.5, z0 - 1.5], [L, 11.5, z0 + 1.5], (4000, 3))  # a row of crowns at y = 10
    pts = np.vstack([wire, touching, crown])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, L), (np.array([0.0, 10.0]), np.array([1.0, 0.0]), 0.0, L)]
    spans = [Span(0, 0, 0, L / 2, c, z0, 0.0, L, 0.03, 200, 0.2), Span(1, 0, 0, L / 2, c, z0, 0.0, L, 0.1, 25, 0.2)]
    assert lines_not_wires(spans, geo, pts[:, 0], pts[:, 1], pts[:, 2], max_rms=0.2) == {1}


def test_the_top_edge_of_a_wall_is_no_conductor():
    """A straight, level line 3.5 m over the ground seen from the street, the top edge of a truck's
    side (Oakland part3_ak): the side is below the height window, so only every point off the
    ground shows it in a surface; wires stacked 0.3 m apart over one another are not a wall."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.stages.rejection import lines_not_wires

    rng = np.random.default_rng(5)
    L, z0 = 10.0, 9.7
    top = np.column_stack([np.arange(0, L, 0.15), rng.normal(0, 0.01, 67), np.full(67, z0)])
    # the side: vertical scan lines every 0.15 m along, a point every 2 cm down to 1.5 m
    sl, zz = np.meshgrid(np.arange(0, L, 0.15), np.arange(z0 - 1.5, z0, 0.02))
    side = np.column_stack([sl.ravel(), rng.normal(0, 0.01, sl.size), zz.ravel()])
    stacked = np.vstack([top + [0, 5.0, -dz] for dz in (0.0, 0.3, 0.6, 0.9)])  # four wires 5 m aside
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, L), (np.array([0.0, 5.0]), np.array([1.0, 0.0]), 0.0, L)]
    spans = [Span(0, 0, 0, L / 2, 1e6, z0, 0.0, L, 0.01, 67, 0.0), Span(1, 0, 0, L / 2, 1e6, z0, 0.0, L, 0.01, 67, 0.0)]
    cand = np.vstack([top, stacked])  # what the height window keeps
    off_ground = np.vstack([top, side, stacked])
    assert lines_not_wires(spans, geo, *cand.T, max_rms=0.2) == set()  # the window alone cannot tell
    assert lines_not_wires(spans, geo, *cand.T, max_rms=0.2, below=tuple(off_ground.T)) == {0}


def _segment(rng, a, b, n, noise=0.02):
    t = np.sort(rng.uniform(0, 1, n))
    return np.asarray(a, float) + t[:, None] * (np.asarray(b, float) - np.asarray(a, float)) + rng.normal(0, noise, (n, 3))


def test_straight_wires_finds_short_wires_fanning_from_a_pole_among_a_crown():
    """Three wires of 5-6 m leaving one pole top at three heights and azimuths (a mobile scan's
    view of wires across its street), linked by a crown to a thousand scattered points: each is
    one run holding its own points, and nothing of the crown is a run."""
    from toolbox_plugins.powerlines.core import straight_wires

    rng = np.random.default_rng(3)
    wires = [_segment(rng, (0, 0, 8.0), (0.5, -5.5, 8.1), 40), _segment(rng, (0, 0, 8.7), (-1.5, -5.0, 8.6), 40),
             _segment(rng, (0, 0, 9.4), (2.0, -5.2, 9.2), 40)]
    crown = rng.uniform([-4, 0, 6], [4, 6, 11], (1000, 3))
    xyz = np.vstack(wires + [crown])
    runs = straight_wires(xyz, 4.0, 2.5)
    label = np.repeat([0, 1, 2, -1], [40, 40, 40, 1000])
    got = sorted(np.bincount(label[r][label[r] >= 0], minlength=3).argmax() for r in runs)
    assert got == [0, 1, 2]
    for r in runs:
        k = np.bincount(label[r][label[r] >= 0]).argmax()
        assert (label[r] == k).sum() >= 36 and (label[r] == -1).sum() <= 2


def test_straight_wires_neighbourhoods_searched_once_are_those_of_a_fresh_search(monkeypatch):
    """A set's neighbourhoods, searched once and thinned as runs leave it, are those a fresh
    search of the points left finds (same neighbours, same order), so the runs drawn are the
    same as with a search per draw (the fallback where the pairs would not fit in memory)."""
    from scipy.spatial import cKDTree
    from toolbox_plugins.powerlines import core
    from toolbox_plugins.powerlines.core import _ball_pairs, _SetNeighbours, straight_wires

    rng = np.random.default_rng(4)
    pts = rng.uniform(0, 6, (800, 3))
    near = _SetNeighbours(cKDTree(pts), 1.0)
    left = np.arange(len(pts))
    for gone in (rng.choice(800, 50, replace=False), rng.choice(750, 120, replace=False)):
        near.remove(gone)
        left = np.delete(left, gone)
        i = rng.integers(0, len(left), 200)
        sid, flat = near.of(i)
        sid0, flat0 = _ball_pairs(cKDTree(pts[left]), pts[left][i], 1.0)
        assert np.array_equal(sid, sid0) and np.array_equal(flat, flat0)
    wires = [_segment(rng, (0, 0, 8.0), (0.5, -5.5, 8.1), 40), _segment(rng, (0, 0, 8.7), (-1.5, -5.0, 8.6), 40)]
    xyz = np.vstack(wires + [rng.uniform([-4, 0, 6], [4, 6, 11], (1000, 3))])
    once = straight_wires(xyz, 4.0, 2.5)
    monkeypatch.setattr(core.missed_wires, "MAX_NEIGHBOUR_PAIRS", 0)  # where straight_wires reads it
    each = straight_wires(xyz, 4.0, 2.5)
    assert len(once) == 2 and len(once) == len(each) and all(np.array_equal(a, b) for a, b in zip(once, each))


def test_straight_wires_go_on_past_a_pole_to_the_wires_it_holds():
    """A pole (a steep run of 150 points) linked to the two wires at its top: its run is the most
    populous and comes first, but being too steep it only leaves the set, and the wires it holds
    are each found; the pole is not a run."""
    from toolbox_plugins.powerlines.core import straight_wires

    rng = np.random.default_rng(8)
    pole = _segment(rng, (0, 0, 0.5), (0, 0, 9.0), 150, noise=0.02)
    wires = [_segment(rng, (0.1, 0, 8.8), (0.6, -5.5, 8.9), 40), _segment(rng, (0.1, 0, 8.3), (-5.0, 1.5, 8.2), 40)]
    xyz = np.vstack([pole] + wires)
    label = np.repeat([-1, 0, 1], [150, 40, 40])
    runs = straight_wires(xyz, 4.0, 2.5)
    assert sorted(np.bincount(label[r] + 1, minlength=3).argmax() - 1 for r in runs) == [0, 1]
    for r in runs:
        assert (label[r] == -1).sum() <= 2 and len(r) >= 36


def test_straight_wires_draw_a_wire_beside_a_denser_short_bar():
    """A cross arm (1.6 m, 120 points) at a pole top linked to a 5.5 m wire of 30 points: the line
    best supported near its drawn pair is the arm's, whose run is too short to be a wire; the
    next best lines not along it are tried, and the wire is still found (the arm is no run)."""
    from toolbox_plugins.powerlines.core import straight_wires

    found = 0
    for seed in range(5):
        rng = np.random.default_rng(seed)
        arm = _segment(rng, (-0.8, 0, 8.0), (0.8, 0, 8.0), 120, noise=0.02)
        wire = _segment(rng, (0.8, 0.1, 8.0), (1.5, 5.6, 8.1), 30)
        xyz = np.vstack([arm, wire])
        runs = straight_wires(xyz, 4.0, 2.5)
        assert all((r < 120).sum() <= 20 for r in runs)  # no run is the arm's (it meets the wire's end)
        found += sum((r >= 120).sum() >= 24 for r in runs)  # four fifths of the wire
    assert found == 5


def test_straight_wires_do_not_depend_on_point_order_or_origin():
    """A survey tile holds the same points in another order and shifted by its origin: the same
    runs come out (each linked set is searched in the order of its coordinates, with its own
    random stream)."""
    from toolbox_plugins.powerlines.core import straight_wires

    rng = np.random.default_rng(6)
    wires = [_segment(rng, (0, 0, 8.0), (0.5, -5.5, 8.1), 40), _segment(rng, (0, 0, 8.7), (-1.5, -5.0, 8.6), 40),
             _segment(rng, (30, 0, 9.0), (36, 1, 9.1), 30)]
    crown = rng.uniform([-4, 0, 6], [4, 6, 11], (800, 3))
    xyz = np.vstack(wires + [crown])
    first = {frozenset(r.tolist()) for r in straight_wires(xyz, 4.0, 2.5)}
    order = rng.permutation(len(xyz))
    moved = straight_wires(xyz[order] + [250.0, -75.0, 0.0], 4.0, 2.5)
    assert len(first) == 3 and {frozenset(order[r].tolist()) for r in moved} == first


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


def test_alone_beside_wires_takes_a_wire_beside_one_and_its_missed_points_not_a_crown():
    """The points alone in the air near a wire found are wire: a second wire 0.35 m under it (too
    close for the 2D step), its points off the fit's tolerance, a run of them past its end (one
    round further each); a crown the wire runs along, a lone point 0.8 m off it, and points not
    free (a pole's) are not."""
    from toolbox_plugins.powerlines.core import alone_beside_wires

    rng = np.random.default_rng(3)
    x = np.arange(0.0, 20.0, 0.2)
    parts = {
        "wire": np.column_stack([x, np.zeros_like(x), np.full_like(x, 8.0)]),
        "beside": np.column_stack([np.arange(0.1, 20.0, 0.5), np.zeros(40), np.full(40, 7.65)]),
        "off_fit": np.column_stack([np.arange(1.3, 19.0, 2.0), np.full(9, 0.25), np.full(9, 8.05)]),
        "past_end": np.column_stack([20.2 + 0.4 * np.arange(3), np.zeros(3), np.full(3, 8.0)]),
        "beyond": np.array([[21.8 + 0.4 * k, 0.0, 8.0] for k in range(2)]),  # a fourth round away
        "crown": _in_ball(rng, (10.0, 1.3, 8.0), 1.0, 800),  # its edge 0.3 m from the wire
        "lone": np.array([[5.0, 0.8, 8.0]]),
        "pole": np.column_stack([np.full(20, 15.0), np.full(20, 0.3), np.linspace(0, 8.2, 20)]),
    }
    xyz = np.vstack(list(parts.values()))
    label = np.concatenate([[k] * len(v) for k, v in parts.items()])
    taken, via = alone_beside_wires(xyz, label == "wire", label != "pole", reach_m=0.5)
    is_taken = np.isin(np.arange(len(xyz)), taken)
    # where the crown is within 1 m, the wire's points have too many others around them
    clear = np.hypot(xyz[:, 0] - 10.0, xyz[:, 1] - 1.3) > 2.0
    for part in ("beside", "off_fit", "past_end"):
        assert is_taken[(label == part) & clear].all(), part
    assert np.isin(label[taken], ["beside", "off_fit", "past_end"]).all(), np.unique(label[taken], return_counts=True)
    assert (label[via] == "wire").all()


def test_short_wires_keep_a_wire_leaving_a_pole_and_drop_arms_cross_arms_and_facades():
    """Of the straight runs left on no wire, only the wire that leaves the pole where the found
    wires are held and leads away from them is a short wire; a tower's arm (the end nearer the
    wires is its free tip), a cross arm under the wires (it does not lead away) and a scan row
    of a facade (the next rows around it) are not."""
    from toolbox_plugins.powerlines.stages.more_wires import short_wire_pass

    rng = np.random.default_rng(8)
    pc, label = _short_wire_scene(rng)
    wired = np.flatnonzero(np.isin(label, ["main", "tower_wire"]))
    steep = np.flatnonzero(np.isin(label, ["pole", "body"]))
    free = np.flatnonzero(np.isin(label, ["across", "arm", "crossarm", "facade_row"]))
    params = {"s_min_m": 8.0, "v_max_m": 2.5}
    found = short_wire_pass(pc, free, np.arange(len(pc)), steep, wired, params, 1.0, 1.0, wire_like=label != "facade")
    assert found is not None
    lines, geo, spans, line_of, wire_of, _ = found
    assert len(geo) == 1 and len(lines["conductors"]) == 1 and len(spans) == 1
    got = label[free[line_of == 0]]
    assert (got == "across").sum() >= 38 and (got != "across").sum() == 0
    across = np.column_stack([pc.x, pc.y])[label == "across"]
    extent = np.ptp((across - across[0]) @ geo[0][1])
    assert spans[0].rms <= 0.05 and spans[0].s_to - spans[0].s_from >= extent - 0.3


def test_short_wires_take_the_wires_stacked_with_one_and_not_a_facade_row_beside_it():
    """Three wires leave a pole top one over another, 0.3 m apart (a mobile scan's view of
    cables across its street): the top one is seen over 6 m, the two under it over 3.5 m only
    (shorter than the search's S_min / 2), and half of the lowest one's points are on no run
    the search draws (the shape test took them for the pole's). The top wire stands alone
    though the others are 0.3 m under it (wires of a stack, not clutter), and both wires under
    it are found beside it; a scan row of a facade 1.2 m beside it, as long and as parallel, is
    not taken (the facade's next rows are around it), nor is a roof's eave leaving the pole on
    the other side, though its roof's next rows rising from it are as sparse as wires."""
    from toolbox_plugins.powerlines.stages.more_wires import short_wire_pass

    from toolbox.io.points import PointCloud

    rng = np.random.default_rng(3)
    a, b = np.array([20.2, -0.4]), np.array([20.8, -6.5])
    d = (b - a) / np.linalg.norm(b - a)
    side = np.array([-d[1], d[0]])

    def along(z0, z1, length, n, shift=0.0):
        p, q = a + shift * side, a + shift * side + length * d
        return _segment(rng, (*p, z0), (*q, z1), n)

    def eave(k):  # its k-th row up the roof
        e = np.array([3.0, 5.3]) / np.hypot(3.0, 5.3)
        p = np.array([20.5, 0.2]) + k * 0.3 * np.array([-e[1], e[0]])
        return _segment(rng, (*p, 8.3 + 0.17 * k), (*(p + 6.1 * e), 8.2 + 0.17 * k), 40)

    main = np.vstack([_segment(rng, (0, y, 8.0), (100, y, 8.0), 400) for y in (-1.0, 0.0, 1.0)])
    parts = {"main": main, "pole": _segment(rng, (20, -0.3, 0.5), (20, -0.3, 8.5), 80, noise=0.03),
             "top": along(8.3, 8.2, 6.1, 40), "middle": along(8.0, 7.95, 3.5, 24),
             "low_searched": along(7.7, 7.65, 3.5, 12), "low_loose": along(7.7, 7.65, 3.5, 12),
             "facade_row": along(8.3, 8.2, 6.1, 40, shift=1.2),
             "facade": np.vstack([along(8.3 + k * 0.35, 8.2 + k * 0.35, 6.1, 40, shift=1.2) for k in (-2, -1, 1, 2)]),
             # an eave leaving the pole top on the other side, its roof rising 30 degrees from it
             "eave": eave(0), "roof": np.vstack([eave(k) for k in (1, 2, 3)])}
    xyz = np.vstack(list(parts.values()))
    label = np.concatenate([[k] * len(v) for k, v in parts.items()])
    pc = PointCloud(xyz[:, 0], xyz[:, 1], xyz[:, 2])
    searched = np.flatnonzero(np.isin(label, ["top", "middle", "low_searched", "facade_row", "eave"]))
    free = np.r_[searched, np.flatnonzero(label == "low_loose")]
    found = short_wire_pass(pc, free, np.arange(len(pc)), np.flatnonzero(label == "pole"), np.flatnonzero(label == "main"),
                         {"s_min_m": 8.0, "v_max_m": 2.5}, 1.0, 1.0, n_searched=len(searched),
                         wire_like=label != "facade")
    assert found is not None
    lines, geo, spans, line_of, wire_of, _ = found
    got = label[free[line_of >= 0]]
    assert (got == "top").sum() >= 38 and (got == "middle").sum() >= 22
    assert (got == "low_searched").sum() + (got == "low_loose").sum() >= 22 and (got == "low_loose").sum() >= 10
    assert (got == "facade_row").sum() == 0 and (got == "facade").sum() == 0
    assert (got == "eave").sum() == 0 and (got == "roof").sum() == 0
    # one conductor per wire, each of one wire's points only
    assert len(geo) == 3
    for li in range(3):
        assert len(set(label[free[line_of == li]]) - {"low_searched", "low_loose"}) <= 1


def test_short_wires_seen_over_less_than_the_minimum_length_as_a_stack():
    """Cables from a pole top to a house, one over another 0.8 m apart, seen over 3 m only (less
    than the search's S_min / 2 = 4 m): together they are wires, each one found; a single
    3 m run leaving another pole alone is not (one run that short is any edge)."""
    from toolbox_plugins.powerlines.stages.more_wires import short_wire_pass

    from toolbox.io.points import PointCloud

    rng = np.random.default_rng(5)
    main = np.vstack([_segment(rng, (0, y, 8.0), (100, y, 8.0), 400) for y in (-1.0, 0.0, 1.0)])
    parts = {"main": main, "pole": _segment(rng, (20, -0.3, 0.5), (20, -0.3, 8.5), 80, noise=0.03),
             "pole2": _segment(rng, (70, -0.3, 0.5), (70, -0.3, 8.5), 80, noise=0.03)}
    for k in range(3):  # leaving the pole across the line, 0.8 m apart in height
        parts[f"cable{k}"] = _segment(rng, (20.3, -1.2, 7.9 - 0.8 * k), (20.6, -4.2, 7.8 - 0.8 * k), 20)
    parts["alone"] = _segment(rng, (70.3, -1.2, 7.9), (70.6, -4.2, 7.8), 20)
    xyz = np.vstack(list(parts.values()))
    label = np.concatenate([[k] * len(v) for k, v in parts.items()])
    pc = PointCloud(xyz[:, 0], xyz[:, 1], xyz[:, 2])
    free = np.flatnonzero(np.char.startswith(label.astype(str), "cable") | (label == "alone"))
    found = short_wire_pass(pc, free, np.arange(len(pc)), np.flatnonzero(np.isin(label, ["pole", "pole2"])),
                         np.flatnonzero(label == "main"), {"s_min_m": 8.0, "v_max_m": 2.5}, 1.0, 1.0,
                         wire_like=np.ones(len(pc), bool))
    assert found is not None
    lines, geo, spans, line_of, wire_of, _ = found
    assert len(geo) == 3
    for k in range(3):
        got = set(line_of[label[free] == f"cable{k}"])
        assert len(got) == 1 and -1 not in got and (label[free[line_of == got.pop()]] == f"cable{k}").all()
    assert (line_of[label[free] == "alone"] == -1).all()


def test_wires_from_poles_keep_a_wire_seen_in_pieces_where_it_leaves_a_pole():
    """A pole 11 m high at the origin (found: its axis and top known). A wire leaves its cross
    arm's tip (1.3 m out, 9 m up) westward and is seen from 2.5 m out: 1 m of it, a 1.7 m gap,
    then 3 m, 18 and 6 points (the part2_ai case): neither piece is 4 m long, nor are they one
    set at the search's 1 m link, but together they are one wire leading from the pole. Not
    kept: a street light's arm (from the pole out to 2.5 m, a lamp at its tip), a run along the
    street 3 m beside the pole (it does not lead away), a wire leading away toward a point 3 m
    beside the pole (not held by it), one aimed at the pole but over its top, and a lone run
    12 m away."""
    from toolbox_plugins.powerlines.core import wires_from_poles

    rng = np.random.default_rng(11)
    parts = {
        "wire_near": _segment(rng, (-2.5, -1.3, 9.0), (-3.5, -1.3, 9.02), 6, noise=0.015),
        "wire_far": _segment(rng, (-5.2, -1.3, 9.08), (-8.2, -1.3, 9.2), 18, noise=0.015),
        "light_arm": _segment(rng, (0.2, 0.2, 7.0), (1.9, 1.6, 7.4), 20, noise=0.015),
        "lamp": rng.normal((2.0, 1.7, 7.2), 0.15, (25, 3)),
        "along": _segment(rng, (-4.0, 3.0, 8.0), (4.0, 3.0, 8.0), 40, noise=0.015),
        "aside": _segment(rng, (2.0, -3.5, 8.5), (7.0, -6.5, 8.6), 30, noise=0.015),
        "over_top": _segment(rng, (0.0, 2.0, 13.0), (0.0, 7.0, 13.2), 30, noise=0.015),
        "lone": _segment(rng, (12.0, 0.0, 8.0), (16.0, 1.0, 8.0), 30, noise=0.015),
    }
    xyz = np.vstack(list(parts.values()))
    label = np.concatenate([[k] * len(v) for k, v in parts.items()])
    pole = np.c_[rng.normal(0, 0.05, (200, 2)), rng.uniform(0.5, 11.0, 200)]
    off_ground = np.vstack([xyz, pole])
    poles = np.array([[0.0, 0.0, 0.0, 11.0]])
    searched = label != "lamp"
    runs = wires_from_poles(xyz[searched], poles, off_ground, 2.0, 2.5,
                            wire_like=np.r_[searched, np.zeros(len(pole), bool)])
    got = [set(label[searched][r]) for r in runs]
    assert got == [{"wire_near", "wire_far"}]
    assert len(runs[0]) >= 22
    # what tells the light's arm is its reach: a wire leaving the pole body where the arm does,
    # seen out to 4.6 m, is kept
    wire = _segment(rng, (0.2, 0.2, 7.0), (3.5, 3.0, 7.4), 40, noise=0.015)
    assert [len(r) for r in wires_from_poles(wire, poles, np.vstack([wire, pole]), 2.0, 2.5)] == [40]
    # no pole: nothing
    assert wires_from_poles(xyz[searched], np.zeros((0, 4)), off_ground, 2.0, 2.5) == []


def test_arms_of_a_tower_with_or_without_its_line_found():
    """A tower 8 m across (cells of 1 m): an arm across its line is a tower's arm (both ends in
    reach, a longer line across it); where the line is not found beside the tower (a gap in the
    data), an arm within the tower's own extent is still one; a wire of a pole 2 m across that
    leaves it and ends 6 m away (a wire across the street) is not."""
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.core import Pylon
    from toolbox_plugins.powerlines.stages.supports import arm_lines

    def tower(x, y, half):
        grid = (0.0, 0.0, 1.0, 200, 200)
        rr, cc = np.meshgrid(np.arange(int(y - half), int(y + half)), np.arange(int(x - half), int(x + half)), indexing="ij")
        return Pylon(x, y, 30.0, 2, 0.0, (rr * 200 + cc).ravel(), grid)

    big, pole = tower(50.0, 50.0, 4), tower(150.0, 50.0, 1)
    line = LineString([(0, 50), (30, 50)])  # the line, not found past x = 30
    arm_across = LineString([(50, 48), (50, 44)])  # its cells reach 5.9 m from the centre
    street = LineString([(150, 51), (150, 57)])  # from the pole across the street
    cond = gpd.GeoDataFrame({"conductor": range(4)}, geometry=[line, arm_across, street, LineString([(51, 52), (51, 56)])])
    assert arm_lines(cond, [big, pole], 1.0) == {1, 3}
    # the line found past the tower: the arm crosses it (the rule with the 10 m reach)
    cond2 = gpd.GeoDataFrame({"conductor": range(2)}, geometry=[LineString([(0, 50), (100, 50)]),
                                                                 LineString([(52, 41), (52, 51)])])
    assert arm_lines(cond2, [big], 1.0) == {1}
    assert arm_lines(cond2, [], 1.0) == set()
    # which towers hold arms; with own_only (a structure the wires run through) only a line that
    # never leaves its own extent is an arm, not one crossing the line within the 10 m reach
    held = []
    assert arm_lines(cond, [big, pole], 1.0, with_arms=held) == {1, 3} and held == [0]
    cond3 = gpd.GeoDataFrame({"conductor": range(3)}, geometry=[LineString([(0, 50), (100, 50)]),
                                                                 LineString([(52, 41), (52, 51)]),
                                                                 LineString([(51, 47), (51, 53)])])
    assert arm_lines(cond3, [big], 1.0) == {1, 2}
    held = []
    assert arm_lines(cond3, [big], 1.0, with_arms=held, own_only=True) == {2} and held == [0]
    # a Hough line across the tower drawn 60 m long through the wires' crossings beside it, whose
    # only fitting span is the tower's cross-arm (bundle3_d30 seed 6): its wire's ends decide
    cond4 = gpd.GeoDataFrame({"conductor": range(2)}, geometry=[LineString([(0, 50), (100, 50)]),
                                                                 LineString([(51, 20), (51, 80)])])
    assert arm_lines(cond4, [big], 1.0) == set()
    arm_ends = [None, np.array([[51.0, 46.0], [51.0, 55.0]])]
    assert arm_lines(cond4, [big], 1.0, wire_ends=arm_ends) == {1}
    # a wire of its own there, fitted 30 m past the tower, stays a conductor
    assert arm_lines(cond4, [big], 1.0, wire_ends=[None, np.array([[51.0, 46.0], [51.0, 80.0]])]) == set()


def test_a_tower_stands_under_its_lines_and_a_tree_beside_them_does_not():
    """Where wires lost in a crown end, the tree beside the line looks like a tower (a tall column
    where spans end); a tower stands under its conductors: under one, between them, or with its
    arms reaching over them."""
    from toolbox_plugins.powerlines.core import _under_its_lines

    def square(cx, cy, half):  # footprint cell centres, 1 m cells
        g = np.arange(-half + 0.5, half, 1.0)
        return np.array([(cx + x, cy + y) for x in g for y in g])

    def lines(*offsets, length=200.0):  # conductors along x, at these y
        return [(np.array([0.0, y]), np.array([length, y])) for y in offsets]

    args = dict(margin_m=10.0, under_line_m=2.0, max_side_ratio=2.0, cell_m=1.0)
    # a pole or a tower with its earth wire over its body
    assert _under_its_lines(100.0, 0.5, square(100, 0.5, 1), lines(0.0, 1.2, -1.4), **args)
    # a double circuit's tower seen from a street: its footprint short of the wires, between them
    assert _under_its_lines(100.0, 0.0, square(100, 0, 2), lines(6.6, 7.2, -6.8, -7.4), **args)
    # one circuit strung on one side: the arms reach over it
    assert _under_its_lines(100.0, 0.0, square(100, 0, 7), lines(6.6, 7.2), **args)
    # a tree 6 m beside the line, its crown 2 m from the nearest wire; another line far on the other side
    assert not _under_its_lines(100.0, -6.2, square(100, -6.2, 2), lines(0.0, -1.2, -2.4), **args)
    assert not _under_its_lines(100.0, -6.2, square(100, -6.2, 2), lines(0.0, -1.2, -2.4, 75.0), **args)
    # a line ending 5 m short of it is still its line; one ending 15 m short is not, and with no
    # line along it there is no evidence against it
    assert not _under_its_lines(100.0, -6.2, square(100, -6.2, 2), lines(0.0, length=95.0), **args)
    assert _under_its_lines(100.0, -6.2, square(100, -6.2, 2), lines(0.0, length=85.0), **args)


def test_a_pole_ending_its_line_under_another_line_is_a_pylon():
    """Line B ends at a pole that stands under line A, which crosses over it at 27 degrees (the
    synthetic mobile stacked circuit). A's spans run past the pole, and A's earth wire, lost in
    the view 6 m away at 32 m, ends near it: neither makes the pole a tree that wires pass, nor
    too short for the wires it holds. A crown the same lines pass (wires lost in it end) stays no
    pylon."""
    from toolbox_plugins.powerlines.core import find_pylons

    rng = np.random.default_rng(5)
    h = rng.uniform(0.3, 11.0, 400)
    pole = np.column_stack([rng.normal(0, 0.03, 400), rng.normal(0, 0.03, 400), h])
    b_dir = np.array([np.cos(np.radians(215.0)), np.sin(np.radians(215.0))])  # B runs away south-west
    b_across = np.array([-b_dir[1], b_dir[0]])
    arm = np.outer(rng.uniform(-1.3, 1.3, 80), b_across)
    pole = np.vstack([pole, np.column_stack([arm, rng.normal(10.0, 0.03, 80)])])
    ends, end_hag, span_lines, lines_xy = [], [], [], []
    for off in (-1.2, 0.0, 1.2):  # B's three wires end at the arm, their far ends at the next pole
        a = off * b_across
        b = a + 50.0 * b_dir
        ends += [a, b]
        end_hag += [10.0, 10.0]
        span_lines.append((a, b))
        lines_xy.append((a, b))
    a_dir = np.array([np.cos(np.radians(7.8)), np.sin(np.radians(7.8))])
    for off, hag_a in ((-0.5, 13.5), (-0.5, 18.5), (-0.5, 23.5)):  # A passes over it, stacked
        a = np.array([0.0, off]) - 150.0 * a_dir
        b = np.array([0.0, off]) + 40.0 * a_dir
        ends += [a, b]
        end_hag += [hag_a, hag_a]
        span_lines.append((a, b))
        lines_xy.append((a, b))
    earth = (np.array([4.6, -4.4]) - 20.0 * a_dir, np.array([4.6, -4.4]))  # lost in the view
    ends += list(earth)
    end_hag += [32.7, 32.7]
    span_lines.append(earth)
    headings = [float(np.degrees(np.arctan2(d[1], d[0])) % 180.0) for d in (b_dir,) * 3 + (a_dir,) * 3]
    passed = []
    found = find_pylons(pole[:, 0], pole[:, 1], pole[:, 2], np.array(ends), np.array(end_hag), headings,
                        lines_xy, span_lines=span_lines, passed_by=passed)
    assert len(found) == 1 and np.hypot(found[0].x, found[0].y) <= 1.0 and found[0].n_spans == 3, \
        [(p.x, p.y, p.n_spans) for p in found + passed]
    # a crown under A where one of A's wires ends, lost in it, while the others run past: a tree
    # (judged as if it were not rugged: the wires passing it tell)
    crown = rng.normal([60.0, 7.6, 12.0], [1.5, 1.5, 2.5], (4000, 3))
    crown = crown[crown[:, 2] > 1.0]
    at = np.array([60.0, 7.6])
    cut = [(at - 150.0 * a_dir, at - 0.5 * a_dir), (at + 0.5 * a_dir, at + 100.0 * a_dir)] + \
        [(at - 120.0 * a_dir + [0, dy], at + 90.0 * a_dir + [0, dy]) for dy in (0.8, -0.8)]
    ends2 = np.array([e for seg in cut for e in seg])
    found = find_pylons(crown[:, 0], crown[:, 1], crown[:, 2], ends2, np.full(len(ends2), 13.5), [7.8, 7.8],
                        cut[2:], span_lines=cut, max_rugged=1.0, passed_by=(passed := []))
    assert found == [] and len(passed) == 1, [(p.x, p.y, p.n_spans) for p in found]


def test_a_crown_joined_to_a_tower_through_its_arm_cells_is_split_off():
    """A crown under the outer phase, 10 m beside a lattice tower: the arm cells join the two into
    one candidate (tall cells, 8-connected), whose points' median sits in the crown (span60 seed
    8's false tower; mobile_dc seed 7's tower lost). The candidate's bodies (its column cells in
    groups) are judged apart: the crown is not shaped like a tower and goes, the arm cells stay
    with the body they hang from. Two poles under one cross-arm (an H-frame) stay one pylon."""
    from toolbox_plugins.powerlines.core import find_pylons

    rng = np.random.default_rng(3)
    legs = [(sx, sy) for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)]
    tower = np.vstack([np.column_stack([rng.normal(lx, 0.05, 600), rng.normal(ly, 0.05, 600),
                                        rng.uniform(0.5, 31.0, 600)]) for lx, ly in legs])
    arms = np.vstack([np.column_stack([rng.normal(0.0, 0.3, 400), rng.uniform(-w, w, 400), rng.normal(h, 0.1, 400)])
                      for h, w in ((16.0, 6.6), (24.0, 5.0))])
    r, a = 3.3 * np.sqrt(rng.uniform(0, 1, 5000)), rng.uniform(0, 2 * np.pi, 5000)
    crown = np.column_stack([r * np.cos(a), -10.6 + r * np.sin(a), rng.uniform(8.0, 17.0, 5000)])
    trunk = np.column_stack([rng.normal(0.0, 0.1, 300), rng.normal(-10.6, 0.1, 300), rng.uniform(0.5, 8.0, 300)])
    ends, end_hag, span_lines, lines_xy = [], [], [], []
    for y, h in ((-6.0, 16.0), (6.0, 16.0), (-4.5, 24.0), (4.5, 24.0)):
        for sign in (-1.0, 1.0):
            a, b = np.array([sign * 0.6, y]), np.array([sign * 150.0, y])
            ends += [a, b]
            end_hag += [h, h]
            span_lines.append((a, b))
        lines_xy.append((np.array([-150.0, y]), np.array([150.0, y])))
    ends, end_hag = np.array(ends), np.array(end_hag)
    headings = [0.0] * len(lines_xy)
    p = np.vstack([tower, arms, crown, trunk])
    found = find_pylons(p[:, 0], p[:, 1], p[:, 2], ends, end_hag, headings, lines_xy, span_lines=span_lines)
    assert len(found) == 1 and np.hypot(found[0].x, found[0].y) <= 1.0, [(q.x, q.y) for q in found]
    # an H-frame: two poles 6 m apart under one cross-arm, each a body of its own
    beam = np.column_stack([rng.normal(0.0, 0.05, 600), rng.uniform(-6.6, 6.6, 600), rng.normal(16.0, 0.05, 600)])
    frame = np.vstack([_pole_points(rng, 0.0, -3.0, 16.5), _pole_points(rng, 0.0, 3.0, 16.5), beam])
    found = find_pylons(frame[:, 0], frame[:, 1], frame[:, 2], ends[:8], end_hag[:8], headings[:2], lines_xy[:2],
                        span_lines=span_lines[:4])
    assert len(found) == 1 and np.hypot(found[0].x, found[0].y) <= 1.0, [(q.x, q.y) for q in found]


def test_a_stack_of_unfound_wires_running_off_a_pole_does_not_move_its_base():
    """A joint-use pole on a slope, sparse (17 points at 5 pts/m2, comm4_d5 seed 2), where the
    stack of four cables climbing to it was not found over its last 6-8 m: their cells are tall
    (as high as the span ends there) and join the pole's, and the points' median sat 3-7 m down
    the line (two false towers). Cells with no structure (under 3 layers) more than
    2.5 m along the line from the column are not where its base is; a lattice's arms, across the
    line, still are (the crown test above)."""
    from toolbox_plugins.powerlines.core import find_pylons

    rng = np.random.default_rng(5)
    pole = _pole_points(rng, 0.5, 0.5, 8.0, per_m=3)
    s = rng.uniform(0.6, 6.0, 4 * 30)
    # the wires fall away along the slope from under the pole's top
    stack = np.column_stack([0.5 - s, rng.normal(0.5, 0.04, len(s)),
                             np.repeat([5.4, 5.7, 6.0, 6.3], 30) - 0.05 * s])
    ends = np.array([[0.9, 0.5], [60.0, 0.5], [0.1, 0.5], [-60.0, 0.5]])
    end_hag = np.full(len(ends), 6.3)
    lines_xy = [(np.array([-60.0, 0.5]), np.array([60.0, 0.5]))]
    span_lines = [(ends[0], ends[1]), (ends[2], ends[3])]
    p = np.vstack([pole, stack])
    found = find_pylons(p[:, 0], p[:, 1], p[:, 2], ends, end_hag, [0.0], lines_xy, span_lines=span_lines)
    found = [(q.x - 0.5, q.y - 0.5) for q in found]
    assert len(found) == 1 and np.hypot(*found[0]) <= 1.0, found


def test_a_crown_reaching_over_a_low_line_where_its_pieces_end_is_no_pylon():
    """A distribution line 8 m up whose two wires are lost in a crown 20 m tall (their pieces end
    either side of it, none runs past): judged as if not rugged, the crown is a column under the
    line where spans end, and only its height against the wires beside it tells it (2.5 times
    theirs against the 1.5 allowed); the same ends at a 9 m pole make a pylon. Without the wire
    points the rule has nothing to go by."""
    from toolbox_plugins.powerlines.core import find_pylons

    rng = np.random.default_rng(11)
    crown = rng.normal([0.0, 0.0, 13.0], [1.2, 1.2, 3.5], (5000, 3))
    crown = crown[(crown[:, 2] > 1.0) & (crown[:, 2] < 20.0)]
    h = rng.uniform(0.3, 9.0, 400)
    pole = np.column_stack([rng.normal(0, 0.03, 400), rng.normal(0, 0.03, 400), h])
    ends, span_lines, lines_xy = [], [], []
    for off in (-0.4, 0.4):
        for sign in (-1.0, 1.0):
            a, b = np.array([sign * 1.5, off]), np.array([sign * 60.0, off])
            ends += [a, b]
            span_lines.append((a, b))
        lines_xy.append((np.array([-60.0, off]), np.array([60.0, off])))
    ends, end_hag = np.array(ends), np.full(len(ends), 8.0)
    s = np.r_[np.arange(-60.0, -1.5, 0.3), np.arange(1.5, 60.0, 0.3)]
    wx, wy = np.r_[s, s], np.r_[np.full(len(s), -0.4), np.full(len(s), 0.4)]
    args = dict(span_lines=span_lines, max_rugged=1.0, wire_xyh=(wx, wy, np.full(len(wx), 8.0)))
    assert find_pylons(crown[:, 0], crown[:, 1], crown[:, 2], ends, end_hag, [0.0, 0.0], lines_xy, **args) == []
    assert len(find_pylons(crown[:, 0], crown[:, 1], crown[:, 2], ends, end_hag, [0.0, 0.0], lines_xy,
                           max_height_share=3.0, **args)) == 1
    assert len(find_pylons(crown[:, 0], crown[:, 1], crown[:, 2], ends, end_hag, [0.0, 0.0], lines_xy,
                           **{**args, "wire_xyh": None})) == 1
    found = find_pylons(pole[:, 0], pole[:, 1], pole[:, 2], ends, end_hag, [0.0, 0.0], lines_xy, **args)
    assert len(found) == 1 and np.hypot(found[0].x, found[0].y) <= 1.0


def _pole_points(rng, x, y, height_m, radius_m=0.15, per_m=60):
    """A pole's surface as a street scanner sees it: the half facing the road, from 0.3 m up."""
    n = int(height_m * per_m)
    a = rng.uniform(0.0, np.pi, n)
    h = rng.uniform(0.3, height_m, n)
    return np.column_stack([x + radius_m * np.cos(a), y - radius_m * np.sin(a), h]) + rng.normal(0, 0.01, (n, 3))


def test_poles_are_thin_columns_that_carry_the_wires():
    """A 10.5 m pole with a crown against it from 4 to 8 m and wires at its top is a pole; a
    tree (a 2.5 m trunk under its crown) and a 6 m street light under the same wires are not;
    without wires nothing is."""
    from toolbox_plugins.powerlines.core import find_poles

    rng = np.random.default_rng(3)
    pole = _pole_points(rng, 0.0, 0.0, 10.5)
    crown_by_pole = rng.normal([1.8, 0.0, 6.0], [0.8, 0.8, 1.0], (3000, 3))
    trunk = _pole_points(rng, 15.0, 0.5, 2.5, radius_m=0.2)
    crown = rng.normal([15.0, 0.5, 5.5], [1.5, 1.5, 1.3], (6000, 3))
    light = _pole_points(rng, -12.0, 0.8, 6.0, radius_m=0.08)
    arm = np.column_stack([np.full(60, 0.1), rng.uniform(-1.2, 1.2, 60), np.full(60, 10.0)]) + rng.normal(0, 0.02, (60, 3))
    pts = np.vstack([pole, arm, crown_by_pole[crown_by_pole[:, 2] > 1.0], trunk, crown[crown[:, 2] > 2.5], light])
    s = np.arange(-30.0, 30.0, 0.1)
    wire = np.column_stack([s, np.full_like(s, 0.4), 10.2 + 0.002 * s ** 2])
    lines = [(np.array([-30.0, 0.4]), np.array([30.0, 0.4]))]
    found = find_poles(pts[:, 0], pts[:, 1], pts[:, 2], wire[:, 0], wire[:, 1], wire[:, 2], [0.0], lines,
                       span_ends=np.array([[0.0, 0.4]]))
    assert len(found) == 1, [(p.x, p.y) for p in found]
    p = found[0]
    # the axis of the face the scanner sees: within the pole's radius (and a voxel) of its centre
    assert p.kind == "pole" and np.hypot(p.x, p.y) <= 0.15 + 0.05 and p.height_m >= 10.2 and p.n_spans == 1
    # its footprint holds its column and not the crown beside it
    from toolbox_plugins.powerlines.core import pylon_points

    inside = pylon_points(p, pts[:, 0], pts[:, 1], pts[:, 2])
    n_pole = len(pole) + len(arm)
    assert inside[:n_pole].mean() >= 0.99  # the column and its cross arm (the head, its top metre)
    below_head = inside & (pts[:, 2] < p.height_m - 1.0)
    assert np.hypot(pts[below_head, 0] - p.x, pts[below_head, 1] - p.y).max() <= 0.45 + 0.1
    assert inside[n_pole:].sum() <= 0.1 * inside.sum()
    assert find_poles(pts[:, 0], pts[:, 1], pts[:, 2], wire[:0, 0], wire[:0, 1], wire[:0, 2], [0.0], lines) == []
    # another line crossing 3 m over the pole, whose wires end at it: measured against the span
    # ends there (with their heights) it still carries them; against every wire near it, not
    over = np.column_stack([s * 0.6, s * 0.8, np.full_like(s, 13.5)])
    both = np.vstack([wire, over])
    more = (pts[:, 0], pts[:, 1], pts[:, 2], both[:, 0], both[:, 1], both[:, 2], [0.0, 53.1],
            lines + [(over[0, :2], over[-1, :2])])
    at_pole = np.array([[0.0, 0.4], [0.3, 0.4]])
    assert len(find_poles(*more, span_ends=at_pole, span_end_hag=np.array([10.2, 10.2]))) == 1
    assert find_poles(*more, span_ends=at_pole) == []


def test_tubes_make_a_square_bundle_wire_like_and_leave_a_crown(monkeypatch):
    """A square bundle (four wires 0.6 m apart, ALS density) is volumetric in a 12-point
    neighbourhood; as a set it is a tube, so its points are wire candidates again. A crown
    beside it stays rugged."""
    rng = np.random.default_rng(1)
    s, off, z, _ = _bundle(rng, [(-0.3, 0.0), (0.3, 0.0), (-0.3, 0.6), (0.3, 0.6)], per_m=3.0, length=80.0, noise=0.04)
    wires = np.column_stack([s, off, z])
    crown = rng.normal([40.0, 10.0, 18.0], [2.0, 2.0, 1.5], (3000, 3))
    xyz = np.vstack([wires, crown])
    linear, planar, rugged, steep = shape_classes(xyz - xyz.min(axis=0), surface_density=12.0)
    n = len(wires)
    assert (linear | steep)[:n].mean() >= 0.8
    assert rugged[n:].mean() >= 0.5
    # without the tube rule most of the bundle is volumetric, and the crown is as it was
    import toolbox_plugins.powerlines.core as core

    monkeypatch.setattr(core.candidates, "tubes", lambda xyz, *a, **k: np.zeros(len(xyz), bool))
    linear0, _, rugged0, steep0 = shape_classes(xyz - xyz.min(axis=0), surface_density=12.0)
    assert (linear0 | steep0)[:n].mean() < 0.7
    assert np.array_equal(rugged0[n:], rugged[n:])


def test_peel_finds_a_sparse_wire_over_a_crown():
    """A mobile scan's sparse wire (clumps of points every few metres, gaps up to 7 m) over a
    crown that holds nine points in ten of the band: uniform triples almost never hold three of
    the wire's points; triples drawn along the line do, and the wire comes out with its points."""
    rng = np.random.default_rng(5)
    centres = np.cumsum(rng.uniform(2.0, 7.0, 14))  # clumps along 0-60 m
    s_w = np.concatenate([c + rng.uniform(-0.3, 0.3, 4) for c in centres])
    z_w = catenary(s_w, 10.0, 30.0, 600.0) + rng.normal(0, 0.02, len(s_w))
    o_w = rng.normal(0, 0.03, len(s_w))
    crown = rng.uniform([0, 5, -1], [centres.max(), 8.5, 1], (12 * len(s_w), 3))  # 1.5-5 m under the wire
    s, z, off = np.r_[s_w, crown[:, 0]], np.r_[z_w, crown[:, 1]], np.r_[o_w, crown[:, 2]]
    found = peel_catenaries(s, z, off, min_points=20, min_span=8.0, max_rms=0.2, gap_m=10.0)
    assert len(found) == 1
    idx, (z0, s0, c, rms) = found[0]
    assert np.mean(idx < len(s_w)) >= 0.97 and np.sum(idx < len(s_w)) >= 0.9 * len(s_w)
    assert rms <= 0.05


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


@pytest.mark.parametrize("seed", [0, 1])
def test_a_sparse_earth_wire_seen_in_stretches_far_apart_is_one_wire(seed):
    """The earth wire's stretches lie further apart than the 3D step links (and than its search
    across occlusions bridges): one wire with all its points, none of the phase's (before: its
    one stretch of 20 points a wire, the rest nothing)."""
    (spans, line_of, wire_of), n_phase = _earth_wire_scene(np.random.default_rng(seed))
    earth = np.arange(len(wire_of)) >= n_phase
    assert np.mean(wire_of[~earth] >= 0) >= 0.99
    assert np.mean(wire_of[earth] >= 0) >= 0.95
    assert len(np.unique(wire_of[earth & (wire_of >= 0)])) == 1
    assert not np.isin(wire_of[~earth], wire_of[earth & (wire_of >= 0)]).any()
    (sp,) = [sp for sp in spans if sp.wire == wire_of[earth][0]]
    assert sp.rms <= 0.05 and sp.c == pytest.approx(1500.0, rel=0.1)


def test_scan_rows_in_stretches_far_apart_are_no_sparse_wire():
    """A facade's scan rows seen in stretches as far apart as the earth wire's lie on a level
    curve too, but each has the next rows around it: no wire takes them (the phase is found)."""
    (spans, line_of, wire_of), n_phase = _earth_wire_scene(np.random.default_rng(0), facade=True)
    rows = np.arange(len(wire_of)) >= n_phase
    assert np.mean(wire_of[~rows] >= 0) >= 0.99
    assert np.mean(wire_of[rows] >= 0) <= 0.05


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


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_sparse_phase_beside_a_fitted_span_is_found_and_a_crown_is_not(seed):
    """The far phase of a line seen from a street (a few points every few metres) shares the
    fitted span's offset and sag: it comes out with its points, none of the crown's; the crown
    alone gives nothing, nor does a stretch of the phase shorter than a conductor's run (S_min)."""
    from toolbox_plugins.powerlines.core import sibling_wires

    rng = np.random.default_rng(seed)
    sp, lines, wire, crown = _sibling_scene(rng)
    p = np.vstack([wire, crown])
    found = sibling_wires([sp], lines, p[:, 0], p[:, 1], p[:, 2], max_rms=0.2, min_sep_m=0.4, min_span_m=8.0)
    assert len(found) == 1
    k, li, s, off = found[0]
    assert li == 0 and (k < len(wire)).all() and len(k) >= 0.9 * len(wire)
    assert np.median(off) == pytest.approx(1.2, abs=0.05)
    assert sibling_wires([sp], lines, crown[:, 0], crown[:, 1], crown[:, 2], 0.2, 0.4, 8.0) == []
    _, _, stub, crown = _sibling_scene(np.random.default_rng(seed), stub=True)
    p = np.vstack([stub, crown])
    sp.s_from, sp.s_to = 38.0, 48.0  # a short span: the stub covers most of it
    assert len(stub) >= 12 and sibling_wires([sp], lines, p[:, 0], p[:, 1], p[:, 2], 0.2, 0.4, 8.0) == []
    assert len(sibling_wires([sp], lines, p[:, 0], p[:, 1], p[:, 2], 0.2, 0.4, 5.0)) == 1


def test_a_sibling_search_takes_points_of_shorter_lines_only():
    """Points already on a line are searched only where that line is shorter than the span's own
    line (a stretch of the sparse phase the Hough found alone near its pole)."""
    from toolbox_plugins.powerlines.core import sibling_wires

    sp, lines, wire, crown = _sibling_scene(np.random.default_rng(3))
    p = np.vstack([wire, crown])
    owner = np.r_[np.full(len(wire), 1), np.full(len(crown), -1)]
    args = ([sp], lines + [(np.array([0.0, 1.2]), np.array([1.0, 0.0]), 0.0, 0.0)], p[:, 0], p[:, 1], p[:, 2],
            0.2, 0.4, 8.0)
    assert len(sibling_wires(*args, owner=owner, owner_length=np.where(owner == 1, 12.0, 0.0))) == 1
    assert sibling_wires(*args, owner=owner, owner_length=np.where(owner == 1, 60.0, 0.0)) == []


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cables_one_over_another_under_a_fitted_span_are_found_and_a_slice_of_crown_is_not(seed):
    """Two communication cables 0.3 and 0.6 m under a fitted span (a joint-use pole's stack, one
    sag, a point every 0.4-1 m) come out over and under it (``stacked``), each with its own
    points and none of the crown 1.5-3.5 m under the line; the search beside the span takes
    none of their points, and the crown alone gives nothing: a slice through it fits a catenary and covers
    the span, but the rest of the crown lies around it."""
    from toolbox_plugins.powerlines.core import Span, sibling_wires

    rng = np.random.default_rng(seed)
    sp = Span(0, 0, 0, 30.0, 600.0, 10.0, 0.0, 60.0, 0.03, 300, 0.75)
    cables = []
    for dz in (-0.3, -0.6):
        s = np.cumsum(rng.uniform(0.4, 1.0, 120))
        s = s[s <= 60.0]
        cables.append(np.column_stack([s, rng.normal(0, 0.03, len(s)),
                                       catenary(s, 10.0 + dz, 30.0, 600.0) + rng.normal(0, 0.02, len(s))]))
    crown = rng.uniform([0, -1.5, 0], [60, 1.5, 1], (4000, 3))
    crown[:, 2] = catenary(crown[:, 0], 10.0, 30.0, 600.0) - 1.5 - 2.0 * crown[:, 2]
    lines = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 60.0)]
    p = np.vstack(cables + [crown])
    label = np.r_[np.zeros(len(cables[0])), np.ones(len(cables[1])), np.full(len(crown), 2)]
    found = sibling_wires([sp], lines, p[:, 0], p[:, 1], p[:, 2], 0.2, 0.4, 8.0, stacked=True)
    assert len(found) == 2
    assert sorted(int(np.bincount(label[k].astype(int)).argmax()) for k, *_ in found) == [0, 1]
    for k, li, s, off in found:
        cable = int(label[k[0]])
        assert li == 0 and (label[k] == cable).all() and len(k) >= 0.9 * len(cables[cable])
    assert all((label[k] == 2).all() for k, *_ in sibling_wires([sp], lines, p[:, 0], p[:, 1], p[:, 2], 0.2, 0.4, 8.0))
    c = crown.T
    assert sibling_wires([sp], lines, *c, 0.2, 0.4, 8.0, stacked=True) == []
    assert sibling_wires([sp], lines, *c, 0.2, 0.4, 8.0, stacked=True, min_cover=0.0) == []  # as the run asks
    assert len(sibling_wires([sp], lines, *c, 0.2, 0.4, 8.0, stacked=True, max_around=np.inf)) >= 1


@pytest.mark.parametrize("order", ["reversed", "shuffled"])
def test_peel_does_not_depend_on_the_order_of_the_points(order):
    """A survey's points come in the order they were scanned, not along the line: the sparse wire
    over a crown is found whatever their order (triples are taken in order along the line)."""
    rng = np.random.default_rng(5)
    centres = np.cumsum(rng.uniform(2.0, 7.0, 14))
    s_w = np.concatenate([c + rng.uniform(-0.3, 0.3, 4) for c in centres])
    z_w = catenary(s_w, 10.0, 30.0, 600.0) + rng.normal(0, 0.02, len(s_w))
    o_w = rng.normal(0, 0.03, len(s_w))
    crown = rng.uniform([0, 5, -1], [centres.max(), 8.5, 1], (12 * len(s_w), 3))
    s, z, off = np.r_[s_w, crown[:, 0]], np.r_[z_w, crown[:, 1]], np.r_[o_w, crown[:, 2]]
    is_wire = np.arange(len(s)) < len(s_w)
    perm = np.argsort(-s, kind="stable") if order == "reversed" else rng.permutation(len(s))
    found = peel_catenaries(s[perm], z[perm], off[perm], min_points=20, min_span=8.0, max_rms=0.2, gap_m=10.0)
    assert len(found) == 1
    idx = perm[found[0][0]]
    assert np.mean(is_wire[idx]) >= 0.97 and is_wire[idx].sum() >= 0.9 * len(s_w)


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


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_wire_past_its_last_support_is_its_next_span(seed):
    """Past the support where a fitted span ends, the wire hangs on in a catenary of its own (the
    old one continued climbs away from it), turned a little and seen sparsely over a crown: it is
    found with its points, also where it has turned off the old span's plan trend by 0.6 m; a
    piece shorter than min_span_m, or one that does not start at the support's height, is not."""
    from toolbox_plugins.powerlines.core import next_spans

    rng = np.random.default_rng(seed)
    sp, line, x, y, z, free, is_next = _next_span_scene(rng)
    found = next_spans([sp], [line], x, y, z, free, 0.2, max_gap_m=5.0, reach_m=64.0, min_span_m=8.0)
    assert len(found) == 1
    li, wire, k, s, off, fit = found[0]
    assert (li, wire) == (0, 0)
    assert np.mean(is_next[k]) >= 0.97 and is_next[k].sum() >= 0.95 * is_next.sum()
    ss = np.linspace(41.0, 71.0, 30)
    assert np.max(np.abs(catenary(ss, *fit[:3]) - catenary(ss, float(catenary(40.0, 9.5, 20.0, 300.0)) -
                                                          float(catenary(40.0, 0.0, 56.0, 300.0)), 56.0, 300.0))) <= 0.1
    # a piece 5 m long past the support, and a wire hung 1.5 m lower (another support's)
    for kw in ({"wire_to": 45.5}, {"step_m": 1.5}):
        sp, line, x, y, z, free, is_next = _next_span_scene(np.random.default_rng(seed), **kw)
        assert next_spans([sp], [line], x, y, z, free, 0.2, max_gap_m=5.0, reach_m=64.0, min_span_m=8.0) == []
    # the crown alone
    keep = ~is_next
    assert next_spans([sp], [line], x[keep], y[keep], z[keep], free[keep], 0.2, max_gap_m=5.0, reach_m=64.0,
                      min_span_m=8.0) == []


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_hole_between_two_spans_of_a_wire_is_searched_from_its_ends(seed):
    """The 3D step fitted a wire's span from 0 to 40 m and another from 80 to 120 m; between them
    (past the support at 40 m) it missed the wire, seen sparsely over a crown. Searched from the
    hole's end as from a wire's last span: the span in it is found with its points, and the
    search stops where the wire's next fitted span begins. Where the 3D step fitted a piece in
    the hole and found no catenary there (its rms over max_rms), the hole is left alone."""
    from toolbox_plugins.powerlines.core import Span, next_spans

    rng = np.random.default_rng(seed)
    sp, line, x, y, z, free, is_next = _next_span_scene(rng)
    far = Span(0, 0, 2, 100.0, 300.0, 9.0, 80.0, 120.0, 0.03, 160, 0.67)
    found = next_spans([sp, far], [line], x, y, z, free, 0.2, max_gap_m=5.0, reach_m=64.0, min_span_m=8.0)
    assert len(found) == 1
    li, wire, k, s, off, fit = found[0]
    assert (li, wire) == (0, 0) and s.max() < 80.0
    assert np.mean(is_next[k]) >= 0.97 and is_next[k].sum() >= 0.95 * is_next.sum()
    failed = Span(0, 0, 1, 56.0, 300.0, 9.0, 50.0, 65.0, 0.9, 60, 0.3)
    assert next_spans([sp, failed, far], [line], x, y, z, free, 0.2, max_gap_m=5.0, reach_m=64.0,
                      min_span_m=8.0) == []


def test_no_next_span_through_a_pole_and_a_crown_at_its_support():
    """Past a mobile scan's wire (rms 3 cm), a pole's and a crown's points around the support
    (a 1.5 m blob, half a metre of heights) with a few of the wire's own points past it: a
    catenary through them fits loosely, and most of its points lie within a quarter of S_min: no
    next span. (Oakland part3_an: a span of 52 points, 31 of them pole and crown.)"""
    from toolbox_plugins.powerlines.core import Span, next_spans

    rng = np.random.default_rng(4)
    c = 300.0
    sp = Span(0, 0, 0, 20.0, c, 9.5, 0.0, 40.0, 0.03, 160, 0.67)
    z_end = float(catenary(40.0, 9.5, 20.0, c))
    blob = np.column_stack([rng.uniform(41.0, 42.5, 45), rng.normal(0, 0.05, 45), z_end + rng.uniform(-0.25, 0.25, 45)])
    few = np.column_stack([rng.uniform(44.0, 49.0, 8), rng.normal(0, 0.03, 8),
                           z_end - 0.05 * np.arange(8) + rng.normal(0, 0.03, 8)])
    pts = np.r_[blob, few]
    line = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 40.0)
    free = np.ones(len(pts), bool)
    assert next_spans([sp], [line], pts[:, 0], pts[:, 1], pts[:, 2], free, 0.2, max_gap_m=5.0, reach_m=64.0,
                      min_span_m=8.0) == []


@pytest.mark.parametrize("seed", [0, 1])
def test_a_sparse_wire_is_searched_on_from_where_its_grown_points_end(seed):
    """An earth wire a street scanner sees at about a point per metre: its fitted span ends at
    s = 40, grow_span_ends carried it on to s = 55 on the same catenary, and past a gap of 1-3 m it
    goes on to s = 150. Searched from the span's end, the rest starts 16 m away (no next span);
    from its farthest grown point (line_of / wire_of given), it is found."""
    from toolbox_plugins.powerlines.core import Span, next_spans

    rng = np.random.default_rng(seed)
    c, s0, z0 = 2000.0, 60.0, 30.0
    s_all = np.sort(np.r_[rng.uniform(0.0, 55.0, 110), 56.0 + np.cumsum(rng.uniform(0.3, 2.0, 200))])
    s_all = s_all[s_all < 150.0]
    z = catenary(s_all, z0, s0, c) + rng.normal(0, 0.02, len(s_all))
    y = rng.normal(0, 0.02, len(s_all))
    sp = Span(0, 0, 0, s0, c, z0, 0.0, 40.0, 0.02, int((s_all <= 40.0).sum()), 0.1)
    line = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 40.0)
    free = s_all > 55.0
    line_of = np.where(free, -1, 0)
    args = ([sp], [line], s_all, y, z, free, 0.2)
    kw = dict(max_gap_m=5.0, reach_m=64.0, min_span_m=8.0)
    assert next_spans(*args, **kw) == []
    found = next_spans(*args, **kw, line_of=line_of, wire_of=line_of)
    assert len(found) >= 1 and all((li, w) == (0, 0) for li, w, *_ in found)
    got = np.concatenate([f[2] for f in found])
    assert free[got].all() and len(got) >= 0.9 * free.sum()


def test_a_span_through_a_crown_on_a_line_with_wires_is_crowded():
    """On a line that holds a wire, a second catenary through points of a crown that line up is,
    on its own, no denser within 0.1 m than around it: it is listed as crowded and the line,
    whose wire stands out, is kept."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.stages.rejection import lines_not_wires

    rng = np.random.default_rng(6)
    L, z0, c = 40.0, 20.0, 900.0
    sw = rng.uniform(0, L, 300)
    wire = np.column_stack([sw, rng.normal(0, 0.03, 300), catenary(sw, z0, L / 2, c) + rng.normal(0, 0.03, 300)])
    crown = rng.uniform([0, -1.5, z0 - 4.0], [L, 1.5, z0 - 1.0], (3000, 3))  # under the wire
    pts = np.vstack([wire, crown])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, L)]
    spans = [Span(0, 0, 0, L / 2, c, z0, 0.0, L, 0.03, 300, 0.2), Span(0, 1, 0, L / 2, c, z0 - 2.0, 0.0, L, 0.05, 40, 0.2)]
    crowded = []
    assert lines_not_wires(spans, geo, *pts.T, max_rms=0.2, crowded=crowded) == set()
    assert crowded == [1]


def test_points_on_spans_take_what_lies_on_a_fitted_catenary():
    from toolbox_plugins.powerlines.core import Span, points_on_spans

    anchor, direction = np.array([100.0, 50.0]), np.array([0.6, 0.8])
    sp = Span(0, 2, 0, 20.0, 500.0, 30.0, 0.0, 40.0, 0.03, 100, 0.4, 0.1, 0.0)  # offset 0.1 m
    s = np.array([5.0, 20.0, 39.0, 20.0, 20.0, 45.0, 20.0])
    off = np.array([0.1, 0.1, 0.1, 0.5, 0.1, 0.1, 0.1])
    dz = np.array([0.0, 0.05, -0.1, 0.0, 0.3, 0.0, 0.12])
    # on it; on it; on it; 0.4 m aside; 0.3 m above; past its end; 0.12 m above (within 0.15)
    xy = anchor + s[:, None] * direction + off[:, None] * np.array([-direction[1], direction[0]])
    z = catenary(s, 30.0, 20.0, 500.0) + dz
    line_of, wire_of = points_on_spans([sp], [(anchor, direction, 0.0, 40.0)], xy[:, 0], xy[:, 1], z, 0.2)
    assert line_of.tolist() == [0, 0, 0, -1, -1, -1, 0] and wire_of.tolist() == [2, 2, 2, -1, -1, -1, 2]
    sp.rms = 0.5  # a span that is not a wire takes nothing
    assert (points_on_spans([sp], [(anchor, direction, 0.0, 40.0)], xy[:, 0], xy[:, 1], z, 0.2)[0] == -1).all()


def test_span_ends_grow_along_the_catenary_up_to_a_pole_or_a_gap():
    """A span's catenary continued past its ends takes the wire points the candidates left out
    (under the height window, beside a tower), outward from each end: not past a gap over
    max_gap_m, not into a pole (its column holds more points off the catenary than on it), not
    beyond reach_m, nothing aside or above the wire, nothing already on a wire."""
    from toolbox_plugins.powerlines.core import Span, grow_span_ends

    anchor, direction = np.array([100.0, 50.0]), np.array([0.6, 0.8])
    normal = np.array([-direction[1], direction[0]])
    sp = Span(0, 1, 0, 50.0, 500.0, 12.0, 20.0, 80.0, 0.03, 200, 0.4)
    s = np.arange(0.0, 100.0, 0.5)
    s = s[(s < 8.0) | (s > 12.0)]  # a 4.5 m gap in the wire's points before s = 12.5
    z = catenary(s, 12.0, 50.0, 500.0) + np.where(np.arange(len(s)) % 2, 0.03, -0.03)
    pole_z = np.arange(0.0, 14.0, 0.1)  # a pole at s = 90 under and above the wire
    s = np.r_[s, np.full(len(pole_z), 90.0), 85.0, 86.0]
    off = np.r_[np.zeros(len(s) - 2), 0.6, 0.0]  # then one point 0.6 m aside, one 0.4 m above
    z = np.r_[z, pole_z, catenary(np.array([85.0, 86.0]), 12.0, 50.0, 500.0) + [0.0, 0.4]]
    xy = anchor + s[:, None] * direction + off[:, None] * normal
    free = (s < 20.0) | (s > 80.0)
    lines = [(anchor, direction, 0.0, 100.0)]
    line_of, wire_of = grow_span_ends([sp], lines, xy[:, 0], xy[:, 1], z, free, 0.2, max_gap_m=2.5, reach_m=16.0)
    taken = line_of >= 0
    wire = np.arange(len(s)) < len(s) - len(pole_z) - 2
    assert (wire_of[taken] == 1).all() and not taken[~free].any()
    assert taken[wire & (s >= 12.5) & (s < 20.0)].all() and not taken[wire & (s < 8.0)].any()  # the gap
    assert taken[wire & (s > 80.0) & (s < 89.5)].all()  # up to the pole
    assert not taken[wire & (s > 90.5)].any() and not taken[~wire].any()  # the pole, what is past it, off it
    # without the pole, the reach stops it
    keep = wire
    line_of, _ = grow_span_ends([sp], lines, xy[keep, 0], xy[keep, 1], z[keep], free[keep], 0.2, max_gap_m=2.5,
                                reach_m=16.0)
    sw = s[keep]
    assert (line_of[(sw > 80.0) & (sw <= 96.0)] == 0).all() and (line_of[sw > 96.0] == -1).all()
    sp.rms = 0.5  # a span that is not a wire grows nothing
    assert (grow_span_ends([sp], lines, xy[:, 0], xy[:, 1], z, free, 0.2, 2.5, 16.0)[0] == -1).all()


def test_span_growth_measures_gaps_over_points_already_on_a_wire():
    """Points of the wire already taken (another span's, a candidate's) bridge a gap in the free
    ones: the growth takes the free points past them; a gap in both still stops it."""
    from toolbox_plugins.powerlines.core import Span, grow_span_ends

    anchor, direction = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    sp = Span(0, 0, 0, 50.0, 500.0, 12.0, 0.0, 40.0, 0.03, 200, 0.4)
    s = np.r_[np.arange(40.5, 44.0, 0.5), np.arange(44.0, 48.0, 0.5), np.arange(48.0, 50.0, 0.5),
              np.arange(53.0, 55.0, 0.5)]  # free, taken (4 m), free, a 3.5 m gap, free
    z = catenary(s, 12.0, 50.0, 500.0)
    free = ~((s >= 44.0) & (s < 48.0))
    lines = [(anchor, direction, 0.0, 60.0)]
    line_of, _ = grow_span_ends([sp], lines, s, np.zeros(len(s)), z, free, 0.2, max_gap_m=2.5, reach_m=16.0)
    taken = line_of >= 0
    assert taken[free & (s < 50.0)].all() and not taken[~free].any() and not taken[s > 52.0].any()


def test_span_ends_grow_along_a_wire_of_a_stack_up_to_its_pole():
    """The top cable of a stack of three 0.3 m apart (a joint-use pole's) has its span fitted to
    s = 40; the cables under it fill every column of its own last metres too, so they are no
    structure: its catenary takes its points on to the pole at s = 52, not the pole, nor the
    cables under it (off its curve), nor anything past the pole."""
    from toolbox_plugins.powerlines.core import Span, grow_span_ends

    anchor, direction = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    sp = Span(0, 0, 0, 50.0, 500.0, 12.0, 0.0, 40.0, 0.03, 200, 0.4)
    s = np.arange(30.0, 60.0, 0.4)
    cables = [catenary(s, 12.0 - 0.3 * k, 50.0, 500.0) + np.where(np.arange(len(s)) % 2, 0.02, -0.02) for k in range(3)]
    pole_z = np.arange(8.0, 13.0, 0.1)
    ss = np.r_[np.tile(s, 3), np.full(len(pole_z), 52.0)]
    z = np.r_[np.concatenate(cables), pole_z]
    cable = np.r_[np.repeat([0, 1, 2], len(s)), np.full(len(pole_z), -1)]
    free = ~((cable == 0) & (ss <= 40.0))
    line_of, _ = grow_span_ends([sp], [(anchor, direction, 0.0, 60.0)], ss, np.zeros(len(ss)), z, free, 0.2,
                                max_gap_m=2.5, reach_m=16.0)
    taken = line_of >= 0
    assert taken[(cable == 0) & (ss > 40.0) & (ss < 51.6)].all()
    assert not taken[cable != 0].any() and not taken[ss > 51.6].any()


def test_span_ends_of_a_sparse_stack_grow_up_to_a_support_found():
    """Four cables 0.3 m apart, about 2 points per metre each (a 5 points/m² survey's joint-use
    stack), each fitted to s = 40, a pole at s = 47.5: the other cables' few points make the columns
    too noisy for the column test. Given the pole, each cable's points are taken up to 0.5 m before
    it, by its own span; not the pole, nothing past it. An end facing no support, or a support 3 m
    aside, grows nothing; nor does a lone wire (its columns do tell the pole)."""
    from toolbox_plugins.powerlines.core import Span, grow_span_ends

    rng = np.random.default_rng(11)
    anchor, direction = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    spans = [Span(0, k, 0, 50.0, 400.0, 12.0 - 0.3 * k, 0.0, 40.0, 0.03, 80, 0.4) for k in range(4)]
    ss, z, cable = [], [], []
    for k in range(4):
        s = np.sort(rng.uniform(30.0, 60.0, 60))
        ss.append(s), z.append(catenary(s, 12.0 - 0.3 * k, 50.0, 400.0) + rng.normal(0, 0.02, len(s)))
        cable.append(np.full(len(s), k))
    pole_z = np.arange(6.0, 13.0, 0.3)
    ss, z = np.r_[np.concatenate(ss), np.full(len(pole_z), 47.5)], np.r_[np.concatenate(z), pole_z]
    cable = np.r_[np.concatenate(cable), np.full(len(pole_z), -1)]
    free = ss > 40.0
    lines = [(anchor, direction, 0.0, 60.0)]
    pole = np.array([[47.5, 0.2]])
    line_of, wire_of = grow_span_ends(spans, lines, ss, np.zeros(len(ss)), z, free, 0.2, max_gap_m=2.5,
                                      reach_m=16.0, supports=pole)
    taken = line_of >= 0
    assert taken[(cable >= 0) & (ss > 40.0) & (ss <= 47.0)].all() and (wire_of[taken] == cable[taken]).all()
    assert not taken[ss > 47.0].any()
    # the column test alone stops the top cable within a few points of its end
    line_of, _ = grow_span_ends(spans, lines, ss, np.zeros(len(ss)), z, free, 0.2, max_gap_m=2.5, reach_m=16.0)
    assert np.mean(line_of[(cable == 0) & (ss > 40.0) & (ss <= 47.0)] >= 0) < 0.5
    for support in ([[20.0, 0.0]], [[47.5, 3.0]]):  # behind the ends; beside the wires
        line_of, _ = grow_span_ends(spans, lines, ss, np.zeros(len(ss)), z, free, 0.2, max_gap_m=2.5,
                                    reach_m=16.0, supports=np.array(support))
        assert (line_of == -1).all()
    line_of, _ = grow_span_ends(spans[:1], lines, ss, np.zeros(len(ss)), z, free, 0.2, max_gap_m=2.5,
                                reach_m=16.0, supports=pole)
    assert (line_of == -1).all()


def test_a_span_records_how_thin_its_points_are_across_the_line():
    """A wire's lateral scatter about its straight plan trend is what the 3D validation tests
    (WIRE_LATERAL_RMS_M): a drifting but thin wire passes, a crown edge's spread does not."""
    from toolbox_plugins.powerlines.core import WIRE_LATERAL_RMS_M, _span

    rng = np.random.default_rng(3)
    s = np.sort(rng.uniform(0, 30, 200))
    fit = (10.0, 15.0, 300.0, 0.03)
    thin = _span(0, 0, 0, s, 0.2 + 0.01 * s + rng.normal(0, 0.04, len(s)), fit)  # drifts 0.3 m, 4 cm scatter
    assert thin.offset_slope == pytest.approx(0.01, abs=0.002) and thin.offset_rms == pytest.approx(0.04, abs=0.008)
    assert thin.offset_rms <= WIRE_LATERAL_RMS_M
    wide = _span(0, 0, 0, s, rng.uniform(-0.6, 0.6, len(s)), fit)  # spread over 1.2 m: rms 0.35
    assert wide.offset_rms > WIRE_LATERAL_RMS_M


def test_foliage_on_a_wires_catenary_is_not_wire_its_own_scatter_is():
    """A wire through a crown: the crown's points within the catenary's height tolerance are
    linked to its piece. The span's plan trend and lateral tolerance come from the points on the
    catenary, robustly (the foliage neither pulls nor widens them), and a point farther across
    than that with other points off the ground around it is foliage; a wire point as far off with
    nothing around it (a swinging span's tail) stays wire."""
    from toolbox_plugins.powerlines.core import WIRE_LATERAL_FLOOR_M, _span, off_their_spans

    rng = np.random.default_rng(7)
    s_w = np.sort(rng.uniform(0, 60, 600))
    off_w = 0.1 + rng.normal(0, 0.02, len(s_w))
    z_w = catenary(s_w, 10.0, 30.0, 600.0) + rng.normal(0, 0.02, len(s_w))
    # a crown's branch over 10-13 m along the line: 1.2 m across, 0.6 m in height about the wire
    crown = rng.uniform([10.0, -0.5, -0.3], [13.0, 0.7, 0.3], (300, 3))
    crown[:, 2] += catenary(crown[:, 0], 10.0, 30.0, 600.0)
    s, off, z = np.r_[s_w, crown[:, 0]], np.r_[off_w, crown[:, 1]], np.r_[z_w, crown[:, 2]]
    sp = _span(0, 0, 0, s, off, fit_catenary(s, z), z=z)
    assert sp.offset == pytest.approx(0.1, abs=0.02) and sp.offset_slope == pytest.approx(0.0, abs=0.002)
    assert WIRE_LATERAL_FLOOR_M <= sp.lateral_tol <= 0.1  # 3 robust sigma of 2 cm, not the crown's spread
    near = np.abs(z - catenary(s, sp.z0, sp.s0, sp.c)) <= 0.15  # what the 3D step labels wire
    tail = np.array([[40.0, 0.1 + 0.3, catenary(np.array([40.0]), 10.0, 30.0, 600.0)[0]]])  # alone, 0.3 m off
    lab = np.flatnonzero(near)
    px, py = np.r_[s[lab], tail[:, 0]], np.r_[off[lab], tail[:, 1]]  # the line's frame: x along, y across
    pz = np.r_[z[lab], tail[:, 2]]
    lines = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 60.0)]
    ones = np.zeros(len(px), np.int64)
    clutter = np.column_stack([s, off, z])[~near]  # the crown's points the 3D step left alone
    flagged = off_their_spans([sp], lines, px, py, pz, ones, ones, 0.2, clutter_xyz=clutter)
    is_crown = np.r_[lab >= len(s_w), False]
    far = np.abs(py - 0.1) > 0.15
    assert flagged[is_crown & far].mean() >= 0.95  # foliage aside the wire
    assert not flagged[~is_crown].any()  # every wire point stays, the lone tail included
    assert off_their_spans([sp], lines, px, py, pz, ones, ones, 0.2, clutter_xyz=np.zeros((0, 3)))[is_crown].sum() == 0


def test_crown_points_a_span_took_as_its_own_are_foliage_and_wires_beside_walls_or_wires_are_not():
    """A mobile scan's wire through a crown: the crown's points on its catenary are part of the
    span's fit and set its lateral tolerance, so the off-trend test keeps them. Within 1 m along
    the wire, foliage is denser 0.2-0.5 m around the curve than within 0.1 m of it and surrounds it
    on most sides; a wire beside another wire, a wall or a pole has those on a few sides only."""
    from toolbox_plugins.powerlines.core import _span, in_foliage

    rng = np.random.default_rng(11)
    s_w = np.arange(0.0, 60.0, 0.2)
    z_w = catenary(s_w, 10.0, 30.0, 600.0) + rng.normal(0, 0.01, len(s_w))
    wire = np.column_stack([s_w, rng.normal(0, 0.01, len(s_w)), z_w])
    crown = rng.uniform([20.0, -0.5, -0.5], [23.0, 0.5, 0.5], (400, 3))
    crown[:, 2] += catenary(crown[:, 0], 10.0, 30.0, 600.0)
    # beside the wire: a wall 0.2 m across (5-15 m), a second wire 0.3 m across (25-40 m), a pole
    # 0.3 m across at 45 m
    other = wire[(s_w >= 25.0) & (s_w <= 40.0)] + [0.0, 0.3, 0.0]
    ws, wz = np.meshgrid(np.arange(5.0, 15.0, 0.05), np.arange(-0.6, 0.6, 0.05))
    wall = np.column_stack([ws.ravel(), np.full(ws.size, -0.2), catenary(ws.ravel(), 10.0, 30.0, 600.0) + wz.ravel()])
    pz_ = catenary(np.array([45.0]), 10.0, 30.0, 600.0)[0] + np.arange(-3.0, 1.0, 0.03)
    pole = np.column_stack([45.0 + rng.normal(0, 0.03, len(pz_)), -0.3 + rng.normal(0, 0.03, len(pz_)), pz_])
    taken = crown[np.abs(crown[:, 2] - catenary(crown[:, 0], 10.0, 30.0, 600.0)) <= 0.15]  # the span's own
    pts = np.vstack([wire, taken])
    sp = _span(0, 0, 0, pts[:, 0], pts[:, 1], fit_catenary(pts[:, 0], pts[:, 2]), z=pts[:, 2])
    lines = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 60.0)]  # the line's frame: x along, y across
    around = np.vstack([wire, crown, other, wall, pole])
    one = np.zeros(len(pts), np.int64)
    flagged = in_foliage([sp], lines, pts[:, 0], pts[:, 1], pts[:, 2], one, one, 0.2, around)
    is_crown = np.arange(len(pts)) >= len(wire)
    assert flagged[is_crown].mean() >= 0.95
    clear = ~is_crown & ((pts[:, 0] < 19.0) | (pts[:, 0] > 24.0))  # 1 m or more from the crown
    assert not flagged[clear].any()  # the wire beside a wall (5-15 m), a wire and a pole stays wire
    # points of no wire, or on no fitting span, are never flagged
    none = np.full(len(pts), -1)
    assert not in_foliage([sp], lines, pts[:, 0], pts[:, 1], pts[:, 2], none, none, 0.2, around).any()
    assert not in_foliage([sp], lines, pts[:, 0], pts[:, 1], pts[:, 2], one, one, 0.001, around).any()


def test_a_line_on_a_crowns_top_is_a_surface_a_wire_along_one_or_in_a_stack_is_not():
    """The top of a crown (a ridge curving down 0.04 m within 0.5 m across, a point per 0.1 m)
    taken as a line: its points lie in the surface, as dense 0.2-0.5 m around their catenary as a
    surface is (contrast about 7). A wire in free space, a wire of 20 points per metre lying on such
    a surface, and four wires 0.3 m apart in a square (each in the others' ring, and they are left
    out) are wires."""
    from toolbox_plugins.powerlines.core import SURFACE_CONTRAST, WIRE_ID_BASE, _span, in_a_surface

    rng = np.random.default_rng(3)
    g_s, g_o = np.meshgrid(np.arange(0.0, 30.0, 0.1), np.arange(-1.5, 1.5, 0.1))
    g_s, g_o = g_s.ravel() + rng.uniform(-0.03, 0.03, g_s.size), g_o.ravel() + rng.uniform(-0.03, 0.03, g_s.size)

    def ridge(y0, z_top):  # a crown's top along the line at offset y0, its ridge on a catenary
        z = z_top + catenary(g_s, 0.0, 15.0, 300.0) - (g_o ** 2) / 6.0 + rng.normal(0, 0.01, g_s.size)
        return np.column_stack([g_s, y0 + g_o, z])

    def wire(y0, z_top, step=0.05):
        s = np.arange(0.0, 30.0, step)
        return np.column_stack([s, y0 + rng.normal(0, 0.01, len(s)), z_top + catenary(s, 0.0, 15.0, 300.0)
                                + rng.normal(0, 0.01, len(s))])

    crown = ridge(0.0, 10.0)
    wires = {0: crown[np.abs(crown[:, 1]) <= 0.05],  # line 0: the crown's top row
             1: wire(10.0, 10.0)}  # line 1: a wire in free space
    crown2 = ridge(20.0, 10.0)
    wires[2] = wire(20.0, 10.0)  # line 2: a wire lying along a crown's top
    square = [wire(30.0 + dy, 10.0 + dz, 0.1) for dy, dz in ((0, 0), (0.3, 0), (0, 0.3), (0.3, 0.3))]
    lines, spans, pts, line_of, wire_of = [], [], [], [], []
    for li, w in [(0, wires[0]), (1, wires[1]), (2, wires[2])] + [(3, q) for q in square]:
        if li == len(lines):
            lines.append((np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 30.0))  # x along, y across
        k = len([sp for sp in spans if sp.conductor == li])
        spans.append(_span(li, k, 0, w[:, 0], w[:, 1], fit_catenary(w[:, 0], w[:, 2]), z=w[:, 2]))
        pts.append(w), line_of.append(np.full(len(w), li)), wire_of.append(np.full(len(w), k))
    pts, line_of, wire_of = np.vstack(pts), np.concatenate(line_of), np.concatenate(wire_of)
    shared = np.abs(crown[:, 1]) <= 0.05  # the crown's row is both a line's points and the crown's
    around = np.vstack([pts, crown[~shared], crown2])
    around_wire = np.r_[line_of * WIRE_ID_BASE + wire_of, np.full(len(around) - len(pts), -1)]
    args = (spans, lines, pts[:, 0], pts[:, 1], pts[:, 2], line_of, wire_of, 0.2)
    assert in_a_surface(*args, around, around_wire) == {0}
    assert SURFACE_CONTRAST > 7.0  # a surface alone gives 7: the threshold lies above it
    # the square's wires in one another's ring, counted as clutter: a surface too
    assert 3 in in_a_surface(*args, around, np.r_[np.where(line_of == 3, -1, line_of * WIRE_ID_BASE + wire_of),
                                                  np.full(len(around) - len(pts), -1)])


def test_a_row_or_eave_of_a_sparse_roof_lies_along_a_surface_and_wires_beside_things_do_not():
    """mobile_dist_far seed 7: a far roof seen at 3 points per square metre, its scan rows and eave
    lined up in the Hough and fitting a catenary; the roof is too sparse within 0.5 m for the
    surface test, but 0.5-3 m out on one side its points lie in a plane through the line, filling
    it across and along. A wire with a crown 1-3 m beside it (a crown scatters about any plane),
    a ribbon's wire whose three neighbours 0.5 m apart were not found (a few offsets, not a
    surface) and a 40 m wire passing an 8 m roof at its height 1 m away (a fifth of its length)
    are wires."""
    from toolbox_plugins.powerlines.core import WIRE_ID_BASE, _span, along_a_surface

    rng = np.random.default_rng(7)

    def row(y0, z0, length=10.0, n=25, x0=0.0):
        s = np.sort(rng.uniform(x0, x0 + length, n))
        return np.column_stack([s, y0 + rng.normal(0, 0.02, n), z0 + 0.001 * (s - x0 - length / 2) ** 2
                                + rng.normal(0, 0.02, n)])

    def roof(y0, z0, across, tilt_deg, x_from=0.0, x_to=10.0, per_m2=3.0):
        n = int(per_m2 * (x_to - x_from) * abs(across[1] - across[0]))
        a = rng.uniform(*across, n)
        return np.column_stack([rng.uniform(x_from, x_to, n), y0 + a,
                                z0 + a * np.tan(np.radians(tilt_deg)) + rng.normal(0, 0.02, n)])

    wires = [row(0.0, 8.0), row(20.0, 8.0), row(40.0, 8.0), row(60.0, 8.0), row(80.0, 8.0, 40.0, 200, -15.0)]
    clutter = [roof(0.0, 8.0, (-4.0, 4.0), 30.0),  # line 0: a scan row across a roof
               roof(20.0, 8.0, (0.1, 5.0), 25.0),  # line 1: the eave, the roof on one side
               rng.normal([5.0, 42.0, 8.0], [1.5, 0.6, 1.0], (600, 3)),  # line 2: a crown beside the wire
               np.vstack([row(60.0 + k * 0.5, 8.0) for k in (1, 2, 3)]),  # line 3: the ribbon's others
               roof(81.0, 8.0, (0.0, 6.0), 0.0, 0.0, 8.0)]  # line 4: a flat roof beside a long wire
    lines, spans = [], []
    for li, w in enumerate(wires):
        lines.append((np.array([0.0, 0.0]), np.array([1.0, 0.0]), -20.0, 30.0))  # x along, y across
        spans.append(_span(li, 0, 0, w[:, 0], w[:, 1], fit_catenary(w[:, 0], w[:, 2]), z=w[:, 2]))
    pts = np.vstack(wires)
    line_of = np.concatenate([np.full(len(w), li) for li, w in enumerate(wires)])
    wire_of = np.zeros(len(pts), np.int64)
    around = np.vstack([pts] + clutter)
    around_wire = np.r_[line_of * WIRE_ID_BASE, np.full(len(around) - len(pts), -1)]
    got = along_a_surface(spans, lines, pts[:, 0], pts[:, 1], pts[:, 2], line_of, wire_of, 0.2, around, around_wire)
    assert got == {0, 1}, got


@pytest.mark.parametrize("pieces, turned", [
    # (from, to, points, lateral rms, offset slope): one wire seen in three spans, 0.6 m of drift
    ([(0, 60, 300, 0.03, -0.006), (60, 80, 60, 0.03, -0.006), (80, 100, 40, 0.05, -0.006)], True),
    ([(0, 100, 400, 0.03, -0.003)], False),  # 0.3 m: the line's band (0.4 m) still holds its wire
    ([(0, 10, 20, 0.14, 0.006)], False),  # 0.6 m, but 20 points 0.14 m apart over 10 m do not tell
    ([(0, 60, 300, 0.03, 0.0), (60, 100, 200, 0.03, 0.015)], False),  # a bend at a support
])
def test_a_line_leaning_off_its_wire_turns_onto_the_wires_trend(pieces, turned):
    """A Hough line leaning off its wire by a few tenths of a degree turns onto the trend its
    fitted spans measure (about their middle, onto the offset of most of their points); a drift
    within band_m or within the spans' noise, or spans that disagree, leave it as it was."""
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.plan_geometry import realign

    slope = pieces[0][4]
    # each piece lies on one wire: 0.5 m across at s = 0, drifting by its slope
    spans = [Span(0, 0, k, 50.0, 1000.0, 10.0, s0, s1, 0.03, n, 1.25, 0.5, sl, rms)
             for k, (s0, s1, n, rms, sl) in enumerate(pieces)]
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 100.0)]
    lines = {"conductors": gpd.GeoDataFrame({"conductor": [0], "azimuth_deg": [90.0]},
                                            geometry=[LineString([(0, 0), (100, 0)])]),
             "conductor_segments": gpd.GeoDataFrame({"conductor": [0]}, geometry=[LineString([(10, 0), (60, 0)])])}
    params = {"max_rms_3d_m": 0.2, "s_min_m": 8.0, "band_m": 0.4}
    lines2, geo2, n = realign(lines, geo, spans, params, 1.0)
    assert n == int(turned)
    if not turned:
        assert geo2 is geo and lines2 is lines
        return
    a, d, t0, t1 = geo2[0]
    wire = lambda s: np.array([s, 0.5 + slope * s])  # noqa: E731  the wire's trend in plan
    for s in (0.0, 50.0, 100.0):  # the turned line lies on the wire all along
        assert abs(d[0] * (wire(s) - a)[1] - d[1] * (wire(s) - a)[0]) < 1e-3
    assert (t0, t1) == (0.0, 100.0)
    # the layers' ends move onto the wire and keep their place along it (within 1 cm)
    ends = list(lines2["conductors"].geometry[0].coords) + [lines2["conductor_segments"].geometry[0].coords[0]]
    for (x, y), s in zip(ends, (0.0, 100.0, 10.0)):
        assert abs(d[0] * (y - a[1]) - d[1] * (x - a[0])) < 1e-3 and abs(x - s) < 0.01
    assert lines2["conductors"]["azimuth_deg"][0] == pytest.approx(np.degrees(np.arctan2(1.0, slope)), abs=1e-3)


def test_a_second_pass_line_along_a_found_one_is_not_another_conductor():
    from toolbox_plugins.powerlines.wire_sets import runs_along

    h = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 100.0)
    d = np.array([np.cos(np.radians(0.3)), np.sin(np.radians(0.3))])
    assert runs_along((np.array([20.0, 0.1]), d, 0.0, 30.0), h, 0.4)  # the rest of its points
    assert not runs_along((np.array([20.0, 0.6]), d, 0.0, 30.0), h, 0.4)  # a conductor beside it
    bend = np.array([np.cos(np.radians(4.0)), np.sin(np.radians(4.0))])
    assert not runs_along((np.array([100.0, 0.0]), bend, 0.0, 40.0), h, 0.4)  # past a bend


def test_catenary_fit_minimises_the_soft_l1_cost_as_scipy_does():
    # the fit runs Levenberg-Marquardt on residuals transformed so that their squares sum to the
    # soft-L1 cost: on a span with outliers (an insulator, birds) it must land where scipy's
    # robust trust-region solver lands
    from scipy.optimize import least_squares

    rng = np.random.default_rng(5)
    s = np.sort(rng.uniform(0, 180, 400))
    z = catenary(s, 320.0, 95.0, 1100.0) + rng.normal(0, 0.03, len(s))
    z[rng.choice(len(s), 30, replace=False)] += rng.uniform(0.5, 3.0, 30)  # outliers above the wire
    z0, s0, c, rms = fit_catenary(s, z)

    def res(p):
        return catenary(s, p[0], p[1], np.exp(p[2])) - z

    ref = least_squares(res, [z0 + 0.3, s0 + 5, np.log(c) + 0.1], loss="soft_l1", f_scale=0.1, xtol=1e-12,
                        ftol=1e-12, gtol=1e-12).x
    assert np.abs(catenary(s, z0, s0, c) - catenary(s, ref[0], ref[1], np.exp(ref[2]))).max() < 1e-4
    assert c == pytest.approx(1100, rel=0.02) and rms < 0.04  # the outliers did not pull it up


def test_catenary_fit_of_a_short_nearly_straight_piece_prints_no_warning():
    """A 8.5 m piece from the corridor scene whose trial steps overflow cosh: the solver rejects
    them, and no RuntimeWarning reaches the user's terminal."""
    import warnings

    s = np.array([170.86, 171.04, 171.55, 171.55, 173.1, 174.05, 174.09, 174.57, 174.77, 174.78, 175.36, 175.4,
                  175.54, 176.84, 176.9, 177.19, 177.32, 177.85, 177.94, 178.03, 178.05, 178.41, 178.54, 178.76,
                  179.34])
    z = np.array([322.0, 322.02, 322.09, 322.14, 322.06, 322.02, 322.04, 322.03, 321.99, 321.97, 322.03, 322.02,
                  321.96, 322.01, 321.98, 321.96, 322.03, 322.01, 321.96, 321.94, 321.9, 321.84, 321.97, 321.95,
                  321.92])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        z0, s0, c, rms = fit_catenary(s, z)
    assert np.isfinite([z0, s0, c]).all() and rms < 0.05


@pytest.mark.parametrize("seed", [0, 42, 82, 96, 105])  # the last four diverged from the lowest point
def test_catenary_fit_of_a_straight_piece_on_a_steep_slope(seed):
    """Ten metres of a taut cable dropping 23 % (a joint-use cable between poles on a hillside),
    20 points with a 3.7 m gap, the fit started from a straight wire with its vertex at the lowest
    point: the solver ran off to c = 0.4 m (rms inf) on some draws, because the robust weight of a
    residual over 1e154 m underflowed to 0 and such points cost nothing; the cable's points went
    unclaimed."""
    rng = np.random.default_rng(seed)
    s = np.sort(np.r_[rng.uniform(0.8, 2.5, 7), rng.uniform(6.1, 9.8, 13)])
    truth = catenary(s, 288.4, 191.0, 714.0)  # the curve the comm2_05 scene's cable lies on there
    z = truth + rng.normal(0, 0.03, len(s))
    z0, s0, c, rms = fit_catenary(s, z)
    assert rms < 0.05
    assert np.abs(catenary(s, z0, s0, c) - truth).max() < 0.06


def test_catenary_fit_of_a_straight_piece_is_no_worse_than_its_line():
    """23 points of a wire at an AHN4 tower (12AN2_20) that bend the wrong way: a catenary tends
    to the straight line as c grows, so its fit must be as good as the line's. Started on the
    points' slope instead of at the lowest point, the solver stalls on the flat valley towards
    c = infinity (rms 0.122 m against the line's 0.111 m), and the piece fails the span's rms
    test."""
    s = np.array([0.0, 0.37, 0.71, 0.3, 3.56, 7.09, 7.44, 7.78, 8.11, 8.44, 7.47, 7.8, 8.14, 8.52, 2.58, 3.21, 3.8,
                  7.42, 8.71, 8.41, 7.83, 8.48, 1.56])
    z = np.array([31.39, 31.46, 31.39, 31.41, 31.8, 31.79, 31.72, 31.68, 31.63, 31.48, 31.65, 31.64, 31.64, 31.55,
                  31.62, 31.71, 31.76, 31.67, 31.48, 31.57, 31.64, 31.55, 31.52])
    line = np.polyval(np.polyfit(s, z, 1), s) - z
    z0, s0, c, rms = fit_catenary(s, z)
    assert rms <= np.sqrt(np.mean(line ** 2)) + 0.005


def test_every_conductor_found_no_false_one(corridor_result):
    rep, gpkg, _, truth = corridor_result
    cond = gpd.read_file(gpkg, layer="conductors")
    matched = {}
    for i, g in enumerate(cond.geometry):
        (ax, ay), (bx, by) = g.coords[0], g.coords[-1]
        d = np.array([bx - ax, by - ay]) / g.length
        for k, t in enumerate(truth["conductor_lines_2d"]):
            a, b = np.array(t["a"]), np.array(t["b"])
            td = (b - a) / np.linalg.norm(b - a)
            off = abs((ax - a[0]) * -td[1] + (ay - a[1]) * td[0])
            if abs(d @ td) > np.cos(np.radians(0.5)) and off < 0.1:
                matched.setdefault(k, []).append(i)
    # every truth conductor (all longer than S_min) is found once; bundles 0.6 m apart are kept apart
    assert sorted(matched) == list(range(len(truth["conductor_lines_2d"])))
    assert all(len(v) == 1 for v in matched.values())
    assert len(cond) == len(truth["conductor_lines_2d"])  # nothing from trees, roofs or pylons
    assert set(cond.columns) >= {"votes", "n_points", "length_m", "rms_m", "height_min_m", "height_max_m"}


def test_pylons_on_the_synthetic_corridor(corridor, corridor_result):
    """Towers where spans end on a tall column: the lattice towers and the distribution poles of
    the scene's truth, each within 2 m, none false; their points are class 15. (Two poles of
    line B are missed: the 3D step does not split the wire there, so no span ends at them.)"""
    rep, gpkg, wires, truth = corridor_result
    py = gpd.read_file(gpkg, layer="pylons")
    assert set(py.columns) >= {"height_m", "n_spans", "line_heading_deg", "n_points"}
    assert py.geometry.has_z.all()
    found = np.column_stack([py.geometry.x, py.geometry.y])
    true_xy = np.array([[p["x"], p["y"]] for p in truth["pylons"]])
    d_false = np.min(np.hypot(*(found[:, None, :] - true_xy[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert (d_false <= 2.0).all(), d_false  # none false
    d_true = np.min(np.hypot(*(true_xy[:, None, :] - found[None, :, :]).transpose(2, 0, 1)), axis=1)
    assert (d_true <= 2.0).sum() >= 9, d_true
    for p, dd in zip(truth["pylons"], d_true):  # heights and bases where found
        if dd <= 2.0:
            k = int(np.argmin(np.hypot(found[:, 0] - p["x"], found[:, 1] - p["y"])))
            assert abs(py.height_m[k] - p["height_m"]) <= 1.0
            assert abs(py.geometry.z[k] - p["z"]) <= 0.3
    cls = np.asarray(laspy.read(wires).classification)
    assert rep["stats"]["n_tower_points"] == int((cls == 15).sum()) > 0
    true_tower = np.asarray(laspy.read(corridor).classification) == 15
    assert (true_tower & (cls == 15)).sum() / (cls == 15).sum() >= 0.9  # tower points are tower points


def test_a_short_piece_on_a_longer_line_is_merged_into_it():
    """A wire's 150 m in one piece and its next 35 m, past a 12 m gap, fitted 0.5 degrees off (a
    sparse far stretch of a mobile scan): both ends of the short piece lie within 0.25 m of the
    long line and the two refitted together stay thin, so they become one conductor. A parallel
    wire 0.6 m away, and a short piece 0.5 m off that one, stay apart."""
    rng = np.random.default_rng(0)
    t1, t2 = np.arange(0.0, 150.0, 0.3), np.arange(162.0, 197.0, 0.5)
    y2 = (t2 - 179.5) * np.tan(np.radians(0.5))  # centred on the line: its ends 0.15 m off it
    x = np.r_[t1, t2, t1, t2]
    y = np.r_[rng.normal(0, 0.03, len(t1)), y2 + rng.normal(0, 0.03, len(t2)), 0.6 + rng.normal(0, 0.03, len(t1)),
              1.1 + y2 + rng.normal(0, 0.03, len(t2))]
    n1, n2 = len(t1), len(t2)
    parts = [np.arange(n1), n1 + np.arange(n2), n1 + n2 + np.arange(n1), 2 * n1 + n2 + np.arange(n2)]
    pieces = [hough._refit(x, y, m, len(m), 2.5, 8.0) for m in parts]
    assert abs(float(pieces[1].direction @ pieces[0].direction)) > np.cos(np.radians(1.0))
    out = hough.merge_pieces_on_lines(pieces, x, y, 2.5, 8.0, merge_gap_m=100.0)
    assert len(out) == 3
    merged = [c for c in out if len(c.members) == n1 + n2 and set(c.members) == set(np.r_[parts[0], parts[1]])]
    assert len(merged) == 1 and np.ptp(merged[0].t_range) >= 195.0
    assert any(set(c.members) == set(parts[2]) for c in out) and any(set(c.members) == set(parts[3]) for c in out)


def test_crossings_average_only_where_lines_meet():
    """Three lines through one point give one crossing (the method's mean); one line across three
    parallel lines 0.6 m apart gives three (they meet it, not each other)."""
    def line(p, ang_deg):
        d = np.array([np.cos(np.radians(ang_deg)), np.sin(np.radians(ang_deg))])
        p = np.asarray(p, float)
        return (p, d), [(p - 50 * d, p + 50 * d)]

    star = [line((0, 0), a) for a in (0, 40, 100)]
    c = crossings([l for l, _ in star], [s for _, s in star])
    assert len(c) == 1 and c[0]["n_lines"] == 3 and np.hypot(c[0]["x"], c[0]["y"]) < 1e-9
    ribbon = [line((0, off), 0) for off in (-0.6, 0.0, 0.6)] + [line((0, 0), 35)]
    c = crossings([l for l, _ in ribbon], [s for _, s in ribbon])
    assert len(c) == 3 and all(x["n_lines"] == 2 for x in c)
    assert sorted(round(x["y"], 6) for x in c) == [-0.6, 0.0, 0.6]


def test_ribbons_are_wires_not_roofs():
    """Three lines 0.6 m apart (a ribbon of phases), locally flat like a roof; a cross arm joins
    them at one end. A roof strip of the same size and density is no ribbon."""
    from scipy.spatial import cKDTree
    from toolbox_plugins.powerlines.core import ribbons

    rng = np.random.default_rng(3)
    s = rng.uniform(0, 60, 3 * 200)
    off = np.repeat([-0.6, 0.0, 0.6], 200) + rng.normal(0, 0.03, 600)
    arm = np.column_stack([np.zeros(30), rng.uniform(-0.9, 0.9, 30)])
    wires = np.column_stack([np.r_[s, arm[:, 0]], np.r_[off, arm[:, 1]], 11 + rng.normal(0, 0.03, 630)])
    roof = np.column_stack([rng.uniform(0, 60, 1000), rng.uniform(-0.9, 0.9, 1000), 8 + rng.normal(0, 0.03, 1000)])
    roof[:, 1] += 30.0
    xyz = np.r_[wires, roof]
    dist, idx = cKDTree(xyz).query(xyz, k=12)
    flat = np.ones(len(xyz), bool)
    r = ribbons(xyz, idx, dist, flat, flat)
    assert r[:600].all() and not r[630:].any()


def test_a_stack_of_cables_is_a_ribbon_a_facade_and_a_terraced_roof_are_not():
    """Three cables one above another 0.3 m apart (a joint-use pole's communication cables,
    sagging together) are locally a vertical plane, but their heights fall into bands with empty
    space between them; a wall strip of the same size fills its height, and a roof of two flat
    terraces 0.5 m apart is wide in plan."""
    from scipy.spatial import cKDTree
    from toolbox_plugins.powerlines.core import ribbons

    rng = np.random.default_rng(5)
    s = rng.uniform(0, 40, 3 * 150)
    sag = 0.5 - 0.5 * ((s - 20.0) / 20.0) ** 2
    cables = np.column_stack([s, rng.normal(0, 0.03, 450), np.repeat([5.6, 5.3, 5.0], 150) - sag
                              + rng.normal(0, 0.03, 450)])
    wall = np.column_stack([rng.uniform(0, 40, 450), 20 + rng.normal(0, 0.03, 450), rng.uniform(5.0, 5.6, 450)])
    u = rng.uniform(0, 40, 900)
    terraces = np.column_stack([u, 40 + rng.uniform(0, 4, 900), np.where(rng.uniform(0, 1, 900) < 0.5, 8.0, 8.5)
                                + rng.normal(0, 0.02, 900)])
    xyz = np.r_[cables, wall, terraces]
    dist, idx = cKDTree(xyz).query(xyz, k=12)
    flat = np.ones(len(xyz), bool)
    r = ribbons(xyz, idx, dist, flat, flat)
    assert r[:450].all() and not r[450:].any()


def test_a_sparse_stack_on_a_slope_is_a_ribbon_whichever_cable_has_more_points():
    """Four cables 0.3 m one above another climbing 5 %, 15 points each over a 10 m piece (a
    5 points/m² survey), drawn anew 100 times: a least-squares trend leans towards whichever cable
    has more points at each end and smears their height bands (a ribbon 88 times in 100 with it,
    95 with the Theil-Sen trend); walls and roofs of 5 and 10 points/m² stay surfaces."""
    from toolbox_plugins.powerlines.core import _is_ribbon

    stacks = walls = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        s = rng.uniform(0, 10, (4, 15))
        pts = [np.column_stack([s[k], rng.normal(0, 0.03, 15), 0.3 * k + 0.05 * s[k] + rng.normal(0, 0.02, 15)])
               for k in range(4)]
        stacks += _is_ribbon(np.vstack(pts), 0.05, 0.4, 0.05)
        for density in (5, 10):
            n = 40 * density  # 10 m x 4 m
            roof = np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 4, n), 0.3 * rng.uniform(0, 4, n)])
            wall = np.column_stack([rng.uniform(0, 10, n), rng.normal(0, 0.03, n), rng.uniform(0, 3, n)])
            walls += _is_ribbon(roof, 0.05, 0.4, 0.05) + _is_ribbon(wall, 0.05, 0.4, 0.05)
    assert stacks >= 93 and walls == 0


def test_a_ribbon_linked_to_a_crown_is_a_ribbon_where_it_runs_alone():
    """The same ribbon with a crown grown into it at one place: the linked set is no ribbon as a
    whole, but judged piece by piece along it every piece away from the crown is."""
    from scipy.spatial import cKDTree
    from toolbox_plugins.powerlines.core import ribbons

    rng = np.random.default_rng(4)
    s = rng.uniform(0, 60, 3 * 200)
    off = np.repeat([-0.6, 0.0, 0.6], 200) + rng.normal(0, 0.03, 600)
    wires = np.column_stack([s, off, 11 + rng.normal(0, 0.03, 600)])
    crown = rng.normal([45.0, 0.0, 10.5], [1.5, 1.5, 0.8], (400, 3))
    xyz = np.r_[wires, crown]
    dist, idx = cKDTree(xyz).query(xyz, k=12)
    flat = np.ones(len(xyz), bool)
    r = ribbons(xyz, idx, dist, flat, flat)
    away = np.abs(s - 45.0) > 10.0
    assert r[:600][away].all() and not r[600:].any()


def test_ribbon_corridor_at_default_parameters(tmp_path):
    """The compact line (three phases 0.6 m apart at one height, 11 m up) crossed above by two
    conductors: every conductor found once, none false, and its wire points."""
    path = tmp_path / "ribbon.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="ribbon", seed=1)
    truth = json.loads(path.with_name("ribbon_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    found = {k for k, _ in conductor_hits(cond, truth)}
    assert len(found) == len(truth["conductor_lines_2d"]) == len(cond) == 5
    t14 = np.asarray(laspy.read(path).classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    # recall 0.972 measured (0.960 before spans grew past their ends: beside a tower the shape test
    # sees the structure in a wire point's neighbourhood)
    assert (t14 & p14).sum() / p14.sum() >= 0.99 and (t14 & p14).sum() / t14.sum() >= 0.97
    assert rep["stats"]["n_pylons"] >= 10
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 6  # line B over each phase: not averaged into one
    for c in truth["crossings"]:
        assert np.min(np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])) <= 0.05


@pytest.mark.parametrize("stem, seed, variant, n_conductors", [
    ("r03", 4, {"line_variant": "ribbon", "phase_spacing_m": 0.3}, 5),
    ("r04", 4, {"line_variant": "ribbon", "phase_spacing_m": 0.4}, 5),
    ("b3", 4, {"bundle": 3, "bundle_spacing_m": 0.4}, 10),
    ("b3", 2, {"bundle": 3, "bundle_spacing_m": 0.4}, 10),
    ("r04d5", 8, {"line_variant": "ribbon", "phase_spacing_m": 0.4, "density_ppm2": 5.0}, 5),
    ("r03", 17, {"line_variant": "ribbon", "phase_spacing_m": 0.3}, 5),
    ("r04", 16, {"line_variant": "ribbon", "phase_spacing_m": 0.4}, 5)])
def test_ribbons_and_bundles_have_every_phase(tmp_path, stem, seed, variant, n_conductors):
    """Ribbons and triangle bundles on generator seed 4 (which the variant family's seeds 1-3 do
    not cover) and bundles on seed 2: every conductor once, none false, every crossing within
    5 cm. How they failed: the 0.3 m ribbon's Hough line leant 0.02 deg across two phases (a
    trend fitted to the whole piece kept them one wire: 4 of 5, crossings 2 of 6); the 0.4 m
    ribbon's two lines lay either side of the middle phase, each band holding half of it (two
    leaning conductors along it, crossings 0.051 m off); a jumper at a tower, drifting across a
    triangle bundle, joined its sub-conductors' groups into two conductors beside the phase (9 of
    10, crossings 15 of 21); on seed 2 a 10 m stub at a tower merged as the bundle's twin turned
    its line by 0.01 deg while the stub's ends weighed as much as the line's (8 of 10); the
    0.4 m ribbon at 5 points/m² on seed 8: in a 373 m piece the phases' offsets moved together
    0.2-0.3 m along it, which no straight trend removes (4 of 5, R 0.888, crossings 4 of 6).
    Seeds 17 and 16, first run after those fixes (held out: 6 of 20 scenes of the 0.3 and 0.4 m
    ribbons on seeds 15-24 failed so): one Hough line over all three 0.3 m phases (3 of 5,
    crossings 2 of 6), and the 0.4 m ribbon's lines leaning across the phases (4 of 5, R 0.879);
    ``ribbon_lines`` now redraws such lines one per wire."""
    path = tmp_path / f"{stem}.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=seed, **variant)
    truth = json.loads(path.with_name(f"{stem}_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert len({k for k, _ in hits}) == len(truth["conductor_lines_2d"]) == n_conductors
    assert len({i for _, i in hits}) == len(cond)  # none false
    # none along another (two conductors on one phase, each leaning with its band's edge)
    inner = [[g.interpolate(f, normalized=True) for f in (0.25, 0.5, 0.75)] for g in cond.geometry]
    assert not any(i != j and max(h.distance(q) for q in inner[i]) < 0.1
                   for i in range(len(cond)) for j, h in enumerate(cond.geometry))
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert max(crossing_errors(xy, truth)) <= 0.05 and false_crossings(xy, truth) == 0


def test_distribution_corridor_at_default_parameters(tmp_path):
    """Three wires on 9 m poles (1.2 m apart, the middle one 1 m higher) with trees under and
    beside them, crossed by a two-wire line: every conductor once, none false, every crossing
    within 5 cm. (Pairwise merging of tile pieces once chained two of its wires into one line
    between them.)"""
    path = tmp_path / "dist.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", seed=1)
    truth = json.loads(path.with_name("dist_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(5)) and len(cond) == len(hits) == 5
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 6
    for c in truth["crossings"]:
        assert np.min(np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])) <= 0.05
    t14 = np.asarray(laspy.read(path).classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    # 0.995 / 0.979 measured (recall 0.960 before spans grew past their ends: on the hill line B's
    # wires hang under the 3.5 m window)
    assert (t14 & p14).sum() / p14.sum() >= 0.99 and (t14 & p14).sum() / t14.sum() >= 0.97
    # a wire grown up to its pole stays wire there (a lattice tower's arms take the wire across
    # them, the AHN4 producer's convention; a pole's do not): measured 1.00 (0.93 before)
    src = laspy.read(path)
    poles = np.array([(q["x"], q["y"]) for q in truth["pylons"] if q["model"] == "pole"])
    near = np.min(np.hypot(np.asarray(src.x)[:, None] - poles[:, 0], np.asarray(src.y)[:, None] - poles[:, 1]),
                  axis=1) <= 1.5
    assert (t14 & near).sum() >= 50 and (t14 & near & p14).sum() / (t14 & near).sum() >= 0.98


@pytest.mark.parametrize("cables, density", [(3, None), (4, 5.0)])
def test_joint_use_corridor_at_default_parameters(tmp_path, cables, density):
    """The distribution corridor with three communication cables 0.3 m apart one above another on
    line B's poles (a vertical ribbon, as on the Oakland scans' poles), and four at 5 points/m²
    (a few points per metre of each cable): every conductor once, none false, every crossing within
    5 cm, wire-point precision and recall of at least the issue's 0.97, and most of the cables'
    points. Measured on seed 1: recall 0.983 and 0.976 (0.981 and 0.972 while a pole's footprint took
    the wire grown up to it), the cables' own 0.930 and 0.927."""
    path = tmp_path / "comm.laz"
    extra = {} if density is None else {"density_ppm2": density}
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", comm_cables=cables,
                seed=1, **extra)
    truth = json.loads(path.with_name("comm_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    n = len(truth["conductor_lines_2d"])
    assert n == 6 and sorted({k for k, _ in hits}) == list(range(n)) and len(cond) == len(hits) == n
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 9
    for c in truth["crossings"]:
        assert np.min(np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])) <= 0.05
    src = laspy.read(path)
    t14 = np.asarray(src.classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    assert (t14 & p14).sum() / p14.sum() >= 0.97 and (t14 & p14).sum() / t14.sum() >= 0.97
    comm = np.isin(np.asarray(src.object_id), [w["id"] for w in truth["wires"] if w["kind"] == "communication"]) & t14
    assert (comm & p14).sum() / comm.sum() >= 0.90


def test_wire_point_spacing_is_the_median_gap_along_fitted_spans():
    """The median gap between consecutive points of each fitted wire, leaving out gaps between
    its pieces (over max_gap_m), spans that do not fit and points of other wires."""
    from toolbox_plugins.powerlines.core import Span, wire_point_spacing

    rng = np.random.default_rng(3)
    anchor, direction = np.array([10.0, 20.0]), np.array([0.8, 0.6])
    s = np.sort(rng.uniform(0.0, 100.0, 400))
    s = s[(s < 40.0) | (s > 55.0)]  # a 15 m gap between two pieces of the wire
    xy = anchor + s[:, None] * direction
    spans = [Span(0, 0, 0, 50.0, 500.0, 12.0, 0.0, 100.0, 0.03, len(s), 0.4),
             Span(0, 1, 0, 50.0, 500.0, 12.0, 0.0, 100.0, 0.5, 50, 0.4)]  # a piece that does not fit
    line_of, wire_of = np.zeros(len(s), np.int64), np.zeros(len(s), np.int64)
    wire_of[::7] = 1
    lines = [(anchor, direction, 0.0, 100.0)]
    got = wire_point_spacing(spans, lines, xy[:, 0], xy[:, 1], line_of, wire_of, 0.2, max_gap_m=5.0)
    g = np.diff(s[wire_of == 0])
    assert got == pytest.approx(np.median(g[g <= 5.0]))
    assert wire_point_spacing(spans[1:], lines, xy[:, 0], xy[:, 1], line_of, wire_of, 0.2, 5.0) is None


def test_a_sparse_survey_gets_a_gap_scaled_to_its_wire_spacing(tmp_path):
    """A distribution corridor at 5 pts/m2 (wire points 0.4 m apart along the wire, twice the
    method's data's spacing per its V_max): at the method's V_max = 2.5 m a gap cuts a run every
    few spans (recall 0.942 measured on seed 2 without the searches that recover cut runs); the
    automatic V_max, 10 median spacings (about 4 m), finds every conductor, none false, crossings
    within 5 cm and the wire points (0.994 / 0.998 measured; recall 0.993 at V_max 2.5 m with the
    searches). Seed 1's cut runs were mostly in a span the generator strung a few metres over an
    escarpment's brow, below the height window; a pole stands there now.
    An explicit V_max is used as given."""
    path = tmp_path / "sparse.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", density_ppm2=5.0,
                seed=2)
    truth = json.loads(path.with_name("sparse_truth.json").read_text())
    t14 = np.asarray(laspy.read(path).classification) == 14

    def run(tag, **kw):
        rep = toolbox.run("powerlines", path, tmp_path / f"{tag}.gpkg",
                          outputs={"classified": str(tmp_path / f"{tag}.laz")}, **kw)
        p14 = np.asarray(laspy.read(tmp_path / f"{tag}.laz").classification) == 14
        return rep["stats"], (t14 & p14).sum() / p14.sum(), (t14 & p14).sum() / t14.sum()

    st, precision, recall = run("auto")
    assert 0.35 <= st["wire_spacing_m"] <= 0.45 and st["v_max_m_used"] == pytest.approx(10 * st["wire_spacing_m"],
                                                                                         abs=0.01)
    cond = gpd.read_file(tmp_path / "auto.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"]))) and len(cond) == len(hits)
    cr = gpd.read_file(tmp_path / "auto.gpkg", layer="crossings")
    assert max(crossing_errors(np.column_stack([cr.geometry.x, cr.geometry.y]), truth)) <= 0.05
    assert precision >= 0.99 and recall >= 0.97, (precision, recall)
    st_m, _, recall_m = run("method", v_max_m=2.5, sibling_wires=False, next_spans=False)
    assert st_m["v_max_m_used"] == 2.5 and recall_m < recall - 0.05, (recall_m, recall)
    # the searches beside fitted spans and on from their ends (into the holes the cuts left) find
    # most of the cut runs again, not all
    assert run("method_siblings", v_max_m=2.5)[2] < recall, recall


def test_corridor_variants_have_their_geometry():
    """Stacked circuits hang three phases one above another at each plan offset; a hillside
    corridor's ground rises by its slope; a 400 m span is strung so its sag keeps half the
    attachment height clear."""
    from toolbox_plugins.synthetic_scene.generator.scene import make_scene

    st = make_scene("corridor", 1, density_ppm2=1.0, line_variant="stacked")
    a = [w for w in st.truth["wires"] if w["line"] == "A" and w["kind"] == "phase"]
    per_offset = {}
    for w in a:
        per_offset.setdefault(round(w["offset_m"], 3), []).append(w)
    assert len({round(w["offset_m"], 3) for w in a}) == 4  # two circuits x two sub-conductors across
    assert all(len(v) == 3 for v in per_offset.values())
    hill = make_scene("corridor", 1, density_ppm2=1.0, slope_pct=25.0)
    flat = make_scene("corridor", 1, density_ppm2=1.0)
    rise = (hill.dtm - flat.dtm)[:, -1].mean() - (hill.dtm - flat.dtm)[:, 0].mean()
    assert rise == pytest.approx(0.25 * (hill.dtm.shape[1] - 1) * hill.dtm_resolution_m, rel=1e-3)
    long_ = make_scene("corridor", 1, density_ppm2=1.0, span_m=400.0, width_m=1000.0)
    spans = [s for s in long_.truth["spans"] if s["line"] == "A"]
    assert max(s["length_m"] for s in spans) > 390
    ox, oy = long_.origin
    for s in spans:  # the lower arms' wires hang 17.5 m up: at least half that over the ground
        c = np.array(s["curve"])
        assert np.min(c[:, 2] - long_.terrain.height(c[:, 0] - ox, c[:, 1] - oy)) >= 0.5 * 17.5 - 0.2


def test_mobile_scanner_scene_thins_with_range():
    """scanner=mobile: a track 2 m over the ground beside line A; points kept with probability
    min(1, (10 m / range)^2): the density within 10 m of the scanner is the one asked for, at
    30 m a ninth of it, and the wires overhead keep their points near the track."""
    from toolbox_plugins.synthetic_scene.generator.scene import make_scene

    sc = make_scene("corridor", 2, density_ppm2=100.0, width_m=200.0, height_m=120.0, line_variant="distribution",
                    scanner="mobile")
    (x0, y0), (x1, y1) = sc.truth["scanner"]["track"]
    d = np.array([x1 - x0, y1 - y0]) / np.hypot(x1 - x0, y1 - y0)
    lateral = np.abs((sc.x - x0) * -d[1] + (sc.y - y0) * d[0])
    first = sc.fields["return_number"] == 1  # one per pulse

    def density(lo, hi):  # pulses per m² in a band beside the track, its middle 80 % along the scene
        along = (sc.x - x0) * d[0] + (sc.y - y0) * d[1]
        m = first & (lateral >= lo) & (lateral < hi)
        a = along[m]
        return np.sum((a > np.percentile(a, 10)) & (a < np.percentile(a, 90))) / (0.8 * np.ptp(a) * 2 * (hi - lo))
    near, far = density(0.0, 5.0), density(29.0, 31.0)
    assert near == pytest.approx(100.0, rel=0.15)
    assert far == pytest.approx(100.0 * (10.0 / np.hypot(30.0, 2.0)) ** 2, rel=0.25)
    spans = [s for s in sc.truth["spans"] if s["line"] == "A"]
    assert all(s["n_points"] > 0 for s in spans)
    with pytest.raises(ValueError, match="mobile"):
        make_scene("terrain", 1, scanner="mobile")


@pytest.mark.parametrize("variant, extra, min_recall", [
    ("stacked", {}, 0.99),  # three phases 5 m above one another on each side (0.997 measured)
    ("distribution", {"slope_pct": 25.0}, 0.9),  # a 25 % hillside, trees under and beside the wires
    # phases in triangle and square bundles (0.989 and 0.982 measured; 0.43 and 0.29 before the
    # wire-like tubes and the split in height): in plan one conductor per phase where the
    # sub-conductors are closer than the Hough's band (the triangle's 0.2 m), in 3D one wire each
    ("double-circuit", {"bundle": 3, "bundle_spacing_m": 0.4}, 0.97),
    ("double-circuit", {"bundle": 4, "bundle_spacing_m": 0.6}, 0.97),
    # a ribbon's phases 0.3 m apart, closer than the Hough's band: one plan line holds them, each
    # a conductor of its own once the 3D step tells them apart (R 0.953, under the issue's 0.97;
    # 0.275 before, every conductor but one lost). At 0.4 m a 9.5 m stub line is still false.
    ("ribbon", {"phase_spacing_m": 0.3}, 0.95),
])
def test_corridor_variants_at_default_parameters(variant, extra, min_recall, tmp_path):
    path = tmp_path / "v.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant=variant, seed=1, **extra)
    truth = json.loads(path.with_name("v_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len({i for _, i in hits})  # no false conductor
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert max(crossing_errors(cr_xy, truth)) <= 0.05 and false_crossings(cr_xy, truth) == 0
    t14 = np.asarray(laspy.read(path).classification) == 14
    p14 = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    assert (t14 & p14).sum() / p14.sum() >= 0.99 and (t14 & p14).sum() / t14.sum() >= min_recall


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_crossings_are_computed_over_the_conductors_of_every_pass(seed, tmp_path):
    """A distribution line seen by a mobile scanner 12 m aside: one wire of the line across it is
    found only by a later pass (seed 3: the second pass, 12 m of it in plan; seeds 1 and 2: the
    search beside the other wire's span, 20-40 points over 13-18 m, 4 of 5 conductors without it);
    its crossings with the three phases are crossings too."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", seed=seed,
                scanner="mobile", density_ppm2=100.0, width_m=300.0, height_m=120.0, track_offset_m=12.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len({i for _, i in hits})
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    assert len(cr) == len(truth["crossings"]) == 6 == rep["stats"]["n_crossings"]
    assert max(crossing_errors(np.column_stack([cr.geometry.x, cr.geometry.y]), truth)) <= 0.05


def test_a_short_line_leant_by_the_line_it_crosses_settles_on_its_wires_trend(tmp_path):
    """The same street scan, seed 7: line B's wire is seen over 26 m only, and line A's three
    phases crossing it at 69 degrees put their points in its band near the crossings, leaning
    its plan line 0.13 degrees (7 cm at its end: crossings 3 of 6 within 5 cm, up to 8.7 cm).
    The 3D step told them apart by height; the line's output settles on its spans' own trend.
    (Its false lines on a sparse gable roof at the scene's edge are an open failure.)"""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", line_variant="distribution", seed=7,
                scanner="mobile", density_ppm2=100.0, width_m=300.0, height_m=120.0, track_offset_m=12.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    assert sorted({k for k, _ in conductor_hits(cond, truth)}) == list(range(len(truth["conductor_lines_2d"])))
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 6 and false_crossings(xy, truth) == 0
    assert max(crossing_errors(xy, truth)) <= 0.05


def test_a_lattice_member_is_no_pole_and_no_crash(tmp_path):
    """60 m spans (seed 1): a slanted lattice member seen by ALS has thin points spread wider than
    a pole's column around their middle, which holds none of the highest (the pole search raised
    an IndexError there once). Towers as before, none false; no pole among them."""
    path = tmp_path / "s.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=1, span_m=60.0)
    truth = json.loads(path.with_name("s_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    assert rep["stats"]["n_poles"] == 0
    d = [np.hypot(py.geometry.x - q["x"], py.geometry.y - q["y"]).min() for q in truth["pylons"]]
    assert sum(x <= 2.0 for x in d) >= 12
    assert all(min(np.hypot(x - q["x"], y - q["y"]) for q in truth["pylons"]) <= 2.0
               for x, y in zip(py.geometry.x, py.geometry.y))


def test_towers_the_wires_run_through_keep_their_arms(tmp_path):
    """60 m spans (seed 3): at three towers the 3D step does not cut the wires, so more spans run
    past than end there, as past a tree. Where one of them has a line that never leaves it, that
    line is its arm and it is a tower (the false conductor and its 5 false crossings before); a
    tower whose arms were taken in the first search stays one without their span ends, and one
    with neither is found from its own points (find_towers_passed_through): all 16 towers standing
    in the scene (15 before that search; the 17th stands past its east edge, unsurveyed)."""
    path = tmp_path / "s.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=3, span_m=60.0)
    truth = json.loads(path.with_name("s_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"]))) and len(cond) == len(hits)
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert max(crossing_errors(cr_xy, truth)) <= 0.05 and false_crossings(cr_xy, truth) == 0
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    d = [np.hypot(py.geometry.x - q["x"], py.geometry.y - q["y"]).min() for q in truth["pylons"] if q["in_scene"]]
    assert len(d) == 16 and sum(x <= 2.0 for x in d) == 16
    assert all(min(np.hypot(x - q["x"], y - q["y"]) for q in truth["pylons"]) <= 2.0
               for x, y in zip(py.geometry.x, py.geometry.y))


def test_a_suspension_tower_the_wires_run_through_is_found_from_its_own_points():
    """A lattice tower (legs from a 6 m square to 1.5 m at 26 m, arms at 20 m reaching 5.5 m
    across the line, peak at 28 m with the earth wire) that three conductors and the earth wire
    run through with no span ending there: one tower, at its body's centre, as high as its peak
    (a stray point 37 m over it is not its top). A crown under the
    line trimmed 7 m under the wires, and a tall crown beside it reaching over the outer
    conductor (its points through the wire's height), are not towers; nor is the tower again
    where it is known already."""
    from toolbox_plugins.powerlines.core import Pylon, find_towers_passed_through

    rng = np.random.default_rng(7)

    def segment(a, b, step=0.3):
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = max(2, int(np.linalg.norm(b - a) / step))
        return a + np.linspace(0, 1, n)[:, None] * (b - a)

    parts = []
    for sx, sy in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
        parts.append(segment([3.0 * sx, 3.0 * sy, 0.5], [0.75 * sx, 0.75 * sy, 26.0]))
    for h in np.arange(2.0, 26.0, 3.0):  # bracing rings
        w = 3.0 - 2.25 * (h - 0.5) / 25.5
        for a, b in (((-w, -w), (w, -w)), ((w, -w), (w, w)), ((w, w), (-w, w)), ((-w, w), (-w, -w))):
            parts.append(segment([*a, h], [*b, h]))
    for side in (-1, 1):
        parts.append(segment([-0.75, 0.0, 20.0], [-0.75, side * 5.5, 20.0]))
        parts.append(segment([0.75, 0.0, 20.0], [0.75, side * 5.5, 20.0]))
    parts.append(segment([0.0, 0.0, 26.0], [0.0, 0.0, 28.0]))
    tower = np.vstack(parts)
    tower = tower[rng.uniform(0, 1, len(tower)) < 0.55]
    tower += rng.normal(0, 0.03, tower.shape)
    s = np.arange(-60.0, 60.0, 0.5)
    wires, lines_xy = [], []
    for y_w, h_w in ((-5.0, 18.5), (0.0, 18.5), (5.0, 18.5), (0.0, 27.8)):  # a gentle sag either side
        wires.append(np.column_stack([s, np.full(len(s), y_w), h_w + 0.0004 * s ** 2]))
        lines_xy.append((np.array([-60.0, y_w]), np.array([60.0, y_w])))
    w = np.vstack(wires)
    under = rng.normal([30.0, 0.0, 9.0], [1.5, 1.5, 1.5], (3000, 3))
    under = under[(under[:, 2] > 1.0) & (under[:, 2] < 11.5)]
    beside = rng.normal([-30.0, 8.0, 17.0], [2.0, 2.0, 3.0], (4000, 3))
    beside = beside[beside[:, 2] > 1.0]
    headings = [0.0] * 4
    stray = np.array([[0.4, 1.6, 65.0]])  # noise over the tower the ground filter left: not its height
    pts = np.vstack([tower, under, beside, stray])
    found = find_towers_passed_through(pts[:, 0], pts[:, 1], pts[:, 2], w[:, 0], w[:, 1], w[:, 2], headings, lines_xy)
    assert len(found) == 1 and np.hypot(found[0].x, found[0].y) <= 1.0, [(p.x, p.y) for p in found]
    assert found[0].n_spans == 8 and 27.0 <= found[0].height_m <= 28.5
    trees = np.vstack([under, beside])
    assert find_towers_passed_through(trees[:, 0], trees[:, 1], trees[:, 2], w[:, 0], w[:, 1], w[:, 2], headings,
                                      lines_xy) == []
    known = [Pylon(0.2, -0.3, 28.0, 4, 0.0, np.zeros(0, np.int64), (0.0, 0.0, 1.0, 1, 1))]
    assert find_towers_passed_through(pts[:, 0], pts[:, 1], pts[:, 2], w[:, 0], w[:, 1], w[:, 2], headings, lines_xy,
                                      known=known) == []


def test_a_sparse_pole_whose_top_wire_runs_over_it_is_passed_through():
    """An 11 m wood pole the wires run across (no span ends there: one catenary fits each wire
    over it), sampled as the generator's towers are (21 of its points, the top 0.4 m unhit): its
    top wire, on the insulator 0.1 m over the pole, runs 0.5 m over its highest point, so no wire
    runs through a cell under its top. Within 1 m over it counts (an insulator holds it there;
    corridor seed 7's pole, missed on every variant of that seed). (A crown trimmed 2-3 m under a
    low line's wires is kept out before that: a cell is tall only at 0.8 of the wire's height.)"""
    from toolbox_plugins.powerlines.core import find_towers_passed_through

    rng = np.random.default_rng(2)
    h = np.sort(rng.uniform(0.3, 10.6, 16))
    pole = np.column_stack([rng.normal(0.3, 0.03, len(h)), rng.normal(0.3, 0.03, len(h)), h])
    arm = np.column_stack([np.linspace(-1.1, 1.7, 5), np.full(5, 0.3), np.full(5, 10.0)])
    s = np.arange(-60.0, 60.0, 0.4)
    wires, lines_xy = [], []
    for x_w, h_w in ((-0.9, 10.1), (0.3, 11.1), (1.5, 10.1)):  # across the line: L, C (on top), R
        wires.append(np.column_stack([np.full(len(s), x_w), s, h_w + 0.0005 * s ** 2]))
        lines_xy.append((np.array([x_w, -60.0]), np.array([x_w, 60.0])))
    w = np.vstack(wires)
    headings = [90.0] * 3
    pts = np.vstack([pole, arm])
    found = find_towers_passed_through(pts[:, 0], pts[:, 1], pts[:, 2], w[:, 0], w[:, 1], w[:, 2], headings, lines_xy)
    assert len(found) == 1 and np.hypot(found[0].x - 0.3, found[0].y - 0.3) <= 1.0, [(p.x, p.y) for p in found]


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


def test_a_crown_cap_the_wires_run_through_is_no_tower_a_pole_reaching_down_is():
    """A low line's two conductors (5.6 m up, no span ending there) running either side of a
    crown's cap that stands 0.8 m over them: the cap is tall, a column (3 of the layers down to
    3 m), slender enough and not rugged enough at 5 pts/m2 to tell, but a support stands on the
    ground and the scan sees its body under its head, where the crown's foliage hides its trunk
    (its lowest point is 3.9 m up, over half its height: dist_d5 seed 5's false tower). A sparse
    pole in its place, with points down its height, is found."""
    from toolbox_plugins.powerlines.core import find_towers_passed_through

    o = np.array([512284.5, 5403070.5])  # where it stood (the 1 m search grid lies on whole metres)
    u = np.array([-0.3265, -0.9452])  # the line's direction
    t = np.arange(-60.0, 60.0, 0.4)
    wires, lines_xy = [], []
    for at in ((1.22, -0.42), (-1.05, 0.36)):
        xy = o + at + t[:, None] * u
        wires.append(np.column_stack([xy, 5.64 - 0.005 * t + 1.5e-4 * t ** 2]))
        lines_xy.append((xy[0], xy[-1]))
    w = np.vstack(wires)
    cap = np.array(CROWN_CAP) + [*o, 0.0]
    found = find_towers_passed_through(cap[:, 0], cap[:, 1], cap[:, 2], w[:, 0], w[:, 1], w[:, 2], [70.9] * 2,
                                       lines_xy)
    assert found == [], [(p.x, p.y, p.height_m) for p in found]
    rng = np.random.default_rng(4)
    h = np.sort(rng.uniform(0.3, 6.2, 14))
    pole = np.column_stack([rng.normal(0.0, 0.03, (len(h), 2)), h])
    arm = np.column_stack([np.linspace(-1.3, 1.3, 7)[:, None] * np.array([0.9452, -0.3265]), np.full(7, 5.5)])
    pts = np.vstack([pole, arm]) + [*o, 0.0]
    found = find_towers_passed_through(pts[:, 0], pts[:, 1], pts[:, 2], w[:, 0], w[:, 1], w[:, 2], [70.9] * 2,
                                       lines_xy)
    assert len(found) == 1 and np.hypot(found[0].x - o[0], found[0].y - o[1]) <= 1.0, [(p.x, p.y) for p in found]


def test_a_conifer_the_wires_run_through_is_no_tower_it_is_wider_than_a_pole_and_stands_off_the_ground():
    """bundle3_d30 seed 9's false tower: a conifer 10.7 m tall that a triangle bundle's wires run
    through (its points within 5 m and the wires' within 12 m, metres about it, heights above
    ground; tests/data). Its points hang together down to 4.4 m, under half its height, so the
    rule for poles passes it; but it is wider than a pole (over 4 m² of cells), and a support that
    wide stands on the ground as at span ends (find_pylons: 0.35 of its height)."""
    from toolbox_plugins.powerlines.core import find_towers_passed_through

    d = np.load(Path(__file__).parent / "data" / "conifer_under_a_bundle.npz")
    p, w = d["points_cm"] / 100.0, d["wires_cm"] / 100.0
    lines_xy = [(ln[:2], ln[2:]) for ln in d["lines_m"]]
    headings = list(d["headings_deg"])
    assert find_towers_passed_through(*p.T, *w.T, headings, lines_xy) == []
    found = find_towers_passed_through(*p.T, *w.T, headings, lines_xy, wide_reach_down_share=0.5)
    assert len(found) == 1 and 0.4 < p[:, 2].min() / found[0].height_m < 0.5  # only this rule tells it


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


def test_crowns_standing_over_the_wires_off_the_ground_are_no_tower():
    """ribbon seed 17's false tower: three broadleaf crowns (up to 21 m) by a junction where two
    ribbon spans end, 46 m2 of cells, 19.6 m tall against wires 14.2 m up, their lowest points
    0.28 of that up (a lattice under 0.05). A tower that much higher than the wires beside it
    holds an earth wire not found and stands on its legs (mobile_stacked's towers: 1.25-1.32 of
    the wires, reaching down to 0.04). The two poles in the same inputs stay."""
    _, found = _find_pylons_on("crowns_taller_than_the_wires.npz")
    assert all(np.hypot(q.x, q.y) > 5.0 for q in found), [(q.x, q.y) for q in found]
    assert len(found) == 2 and all(len(q.cells) <= 5 for q in found)  # the two poles
    p, found = _find_pylons_on("crowns_taller_than_the_wires.npz", over_wires_share=100.0)
    crown = [q for q in found if np.hypot(q.x, q.y) <= 1.0]
    assert len(crown) == 1 and crown[0].height_m > 1.3 * 14.2 and len(found) == 3  # only this rule tells it


def test_a_crown_where_spans_end_is_no_pole_its_points_spread_off_one_axis():
    """slope25 seed 12's false tower: a conifer under line B's lowest wire, where the wire's
    pieces lost in it end, 5 m2 of cells (a pole's with its arms). Of its points under its head
    within 2 m, under a quarter stand on one 0.5 m vertical (the family's poles: 0.33 at least,
    most 1.0); the pole 11 m away stays."""
    from toolbox_plugins.powerlines.core import _axis_share

    _, found = _find_pylons_on("crown_where_spans_end.npz")
    assert len(found) == 1 and np.hypot(found[0].x - 9.3, found[0].y - 7.0) < 0.5
    p, found = _find_pylons_on("crown_where_spans_end.npz", min_axis_share=0.0)
    crown = [q for q in found if np.hypot(q.x, q.y) <= 1.5]
    assert len(crown) == 1 and len(found) == 2  # only this rule tells it
    share, n = _axis_share(*p.T, crown[0].x, crown[0].y, crown[0].height_m)
    assert share < 0.25 and n >= 50
    pole = [q for q in found if q is not crown[0]][0]
    assert _axis_share(*p.T, pole.x, pole.y, pole.height_m)[0] >= 0.5


def test_two_poles_side_by_side_are_two_pylons():
    """mobile_comm3 seed 15: line B ends at its joint-use pole 3.5 m from line A's pole, their
    arms joining their cells into one candidate; its base, the middle, stood 2.1 m from both.
    Each pole stands on its own thin vertical holding its own span ends: two pylons, each within
    0.3 m of its pole (B's 8 m, A's 9 m)."""
    _, found = _find_pylons_on("two_poles_side_by_side.npz", top_share=0.8)
    truth = {"A": (-1.69, 0.07), "B": (1.41, 2.30)}
    assert len(found) == 2
    for name, (tx, ty) in truth.items():
        near = [q for q in found if np.hypot(q.x - tx, q.y - ty) <= 0.3]
        assert len(near) == 1, (name, [(q.x, q.y) for q in found])
    a = min(found, key=lambda q: np.hypot(q.x - truth["A"][0], q.y - truth["A"][1]))
    b = next(q for q in found if q is not a)
    assert a.height_m > b.height_m and a.n_spans >= 2 and b.n_spans >= 2


def test_a_pole_with_a_column_beside_it_is_one_pylon():
    """The second vertical must hold span ends of its own: a pole with a trunk or a lamp post 2 m
    beside it, where no wire ends, stays one pole; with two of the ends there, two poles."""
    from toolbox_plugins.powerlines.core import _pole_pair

    rng = np.random.default_rng(5)
    z = rng.uniform(0.5, 9.0, 150)
    pole = np.column_stack([rng.normal(0, 0.05, 150), rng.normal(0, 0.05, 150), z])
    trunk = np.column_stack([2.0 + rng.normal(0, 0.1, 100), rng.normal(0, 0.1, 100), rng.uniform(0.5, 8.0, 100)])
    pts = np.vstack([pole, trunk])
    flat = np.where(pts[:, 0] > 1.0, 1, 0)
    centres = np.array([[0.5, 0.5], [2.5, 0.5]])
    ends = np.array([[0.0, 1.2], [0.0, -1.2], [0.1, 1.2], [0.1, -1.2]])
    assert _pole_pair(*pts.T, flat, np.array([0, 1]), 9.0, ends, np.full(4, 8.5), centres, 2, 0.25, 1.5) is None
    # the same with two of the ends at the second column: two poles
    ends2 = np.array([[0.0, 1.2], [0.0, -1.2], [2.0, 1.0], [2.0, -1.0]])
    pair = _pole_pair(*pts.T, flat, np.array([0, 1]), 9.0, ends2, np.full(4, 8.5), centres, 2, 0.25, 1.5)
    assert pair is not None and sorted(round(p[0][0]) for p in pair) == [0, 2]


def test_a_lattice_merged_with_a_crown_has_its_base_under_its_peak():
    """span60 seed 15: a 31 m lattice with a 21 m conifer touching it, one candidate of 149 m2 of
    cells (the largest true tower body: 73 in the family, AHN4 76); the median of its points
    stood 9 m off, in the crown. Its base is taken under its peak, within 0.5 m of the tower, and
    its points (class 15) from the cells one tower could cover about it, not the crown's."""
    tx, ty = 1.45, -2.13
    _, found = _find_pylons_on("lattice_with_a_crown_touching_it.npz", top_share=0.8)
    assert len(found) == 1 and np.hypot(found[0].x - tx, found[0].y - ty) <= 0.5
    _, whole = _find_pylons_on("lattice_with_a_crown_touching_it.npz", top_share=0.8, one_tower_m2=1e9)
    assert np.hypot(whole[0].x - tx, whole[0].y - ty) > 5.0  # the rule is what places it
    # its cells within the half-diagonal of a square of 100 m2 (extent_m adds a cell)
    assert found[0].extent_m() <= np.sqrt(50.0) + 1.0 < whole[0].extent_m()
    assert len(whole[0].cells) > 100 and len(found[0].cells) < 0.5 * len(whole[0].cells)


def test_axis_share_of_a_pole_and_of_a_cone():
    """A pole's points under its head lie on one thin vertical; a conifer's crown spreads."""
    from toolbox_plugins.powerlines.core import _axis_share

    rng = np.random.default_rng(3)
    z = rng.uniform(1, 11, 200)
    pole = np.column_stack([rng.normal(0, 0.08, 200), rng.normal(0, 0.08, 200), z])
    share, n = _axis_share(*pole.T, 0.1, -0.1, 11.0)
    assert share == 1.0 and n == int(((z >= 3) & (z <= 9.5)).sum())
    r = 2.5 * (11 - z) / 8 * rng.uniform(0.8, 1.0, 200)  # a crown's surface, 2.5 m out at 3 m up
    a = rng.uniform(0, 2 * np.pi, 200)
    cone = np.column_stack([r * np.cos(a), r * np.sin(a), z])
    assert _axis_share(*cone.T, 0.0, 0.0, 11.0)[0] < 0.35
    assert _axis_share(*pole[:2].T, 0.0, 0.0, 11.0)[0] is None  # too few to tell


def test_mobile_double_circuit_crossings_stop_at_the_last_pole(tmp_path):
    """A double circuit seen by a mobile scanner, line B ending at a pole just short of line A's
    far circuit: B crosses the three conductors of the near one only (9 of 9 true; 11 reported
    while the 5 m extension carried B past its last pole). Line A's lattice towers are found:
    with its earth wire (31 m up) in the height window, the earth wire's span ends over their
    peaks set how tall their cells must be (the nearest end), and their hollow bodies held no
    column that high (2 of 5 supports). No line on the sparse hip roof at the scene's far edge:
    the second pass's runs at a line's own spacing reached 8 m in its rows (a line validated so
    must stand clear: no other point within 0.5 m of its points, on average)."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=1, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len(truth["conductor_lines_2d"])  # none false
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 9 and false_crossings(cr_xy, truth) == 0
    assert max(crossing_errors(cr_xy, truth)) <= 0.05
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    lattice = [q for q in truth["pylons"] if q["model"] == "lattice" and q["in_scene"]]
    assert len(lattice) == 2
    for q in lattice:
        assert np.hypot(py.geometry.x - q["x"], py.geometry.y - q["y"]).min() <= 2.0
    for p in py.geometry:  # none false
        assert min(np.hypot(p.x - q["x"], p.y - q["y"]) for q in truth["pylons"]) <= 2.0


def test_a_sparse_earth_wire_over_a_stack_seen_from_the_street_is_found(tmp_path):
    """A stacked double circuit seen by a mobile scanner (seed 8): its earth wire hangs 35-38 m
    up with 185 points over 185 m. The automatic height window (the 99.95th percentile) stopped
    at 34.2 m, and once inside, the method's 2.5 m V_max validated it in 10-11 m stretches, too
    few points for the 3D step: 7 of 8 conductors, 12 of 15 crossings."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=8, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0, line_variant="stacked")
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    assert rep["stats"]["height_max_m_used"] >= 38.0
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert len({k for k, _ in hits}) == len(truth["conductor_lines_2d"]) == 8 and len(cond) == 8
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 15 and false_crossings(xy, truth) == 0
    assert max(crossing_errors(xy, truth)) <= 0.05


def test_two_crowns_tops_lined_up_are_no_conductor(tmp_path):
    """A mobile double circuit (seed 7): the tops of two dome crowns beside the road lie on one
    10 m line that fits a catenary and has nothing above it (one false conductor, P 0.996). Its
    points lie in the crowns' surface: the line is dropped, and the eight conductors stay."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=7, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": tmp_path / "c.laz"})
    assert rep["stats"]["n_surface_lines"] >= 1
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert len({k for k, _ in hits}) == len(truth["conductor_lines_2d"]) == 8 and len(cond) == 8
    t = np.asarray(laspy.read(path).classification) == 14
    p = np.asarray(laspy.read(tmp_path / "c.laz").classification) == 14
    assert (t & p).sum() / p.sum() >= 0.998 and (t & p).sum() / t.sum() >= 0.99


def test_a_wire_seen_from_one_side_gets_its_own_heading(tmp_path):
    """A mobile double circuit (seed 4): the Hough's line through the far wire of line B leaned
    0.4 degrees off it (0.23 m across at one end, its band took 48 points of the next wire), one
    false conductor for a missed one and 12 of 15 crossings; turned onto its spans' trend, every
    conductor is found, none false, and all 15 crossings lie within 5 cm."""
    path = tmp_path / "m.laz"
    toolbox.run("synthetic-scene", output=path, kind="corridor", seed=4, scanner="mobile", density_ppm2=200.0,
                width_m=300.0, height_m=120.0)
    truth = json.loads(path.with_name("m_truth.json").read_text())
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg")
    assert rep["stats"]["n_lines_realigned"] >= 1
    cond = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors")
    hits = conductor_hits(cond, truth)
    assert sorted({k for k, _ in hits}) == list(range(len(truth["conductor_lines_2d"])))
    assert len(cond) == len({i for _, i in hits})
    cr = gpd.read_file(tmp_path / "pl.gpkg", layer="crossings")
    cr_xy = np.column_stack([cr.geometry.x, cr.geometry.y])
    assert len(cr) == len(truth["crossings"]) == 15 and false_crossings(cr_xy, truth) == 0
    assert max(crossing_errors(cr_xy, truth)) <= 0.05


def test_a_line_ending_at_a_support_crosses_nothing_past_it():
    """The method's 5 m extension carries a line that ends at its last pole on to the line beside
    the pole (the synthetic mobile double circuit's 2 false crossings); with the supports found,
    a line ending at one crosses nothing more than a metre past that end, unless still short of
    the support by more than a strain insulator, and nothing more than a strain insulator past the
    support where its wire is seen up to it. A line that runs on through the other, or ends
    within a metre of it, still crosses it."""
    a = (np.array([0.0, 0.0]), np.array([1.0, 0.0]))
    b = (np.array([50.0, -50.0]), np.array([0.0, 1.0]))
    seg_a = [(np.array([0.0, 0.0]), np.array([100.0, 0.0]))]
    pole = [(50.0, -2.5, 3.0)]
    for b_end, supports, n in ((-2.0, None, 1), (-2.0, pole, 0), (-0.8, pole, 1), (20.0, pole, 1)):
        seg_b = [(np.array([50.0, -50.0]), np.array([50.0, b_end]))]
        got = crossings_at_supports([a, b], [seg_a, seg_b], supports=supports)
        assert len(got) == n, (b_end, supports, got)
    # a support that is not at the line's end (30 m along it) changes nothing
    seg_b = [(np.array([50.0, -50.0]), np.array([50.0, -2.0]))]
    assert len(crossings_at_supports([a, b], [seg_a, seg_b], supports=[(50.0, -30.0, 3.0)])) == 1
    # b's wire seen up to 3 m short of its pole (next to the structure): a line passing 1 m before
    # the pole crosses it; one passing within the strain insulator's 0.5 m of the pole does not
    assert len(crossings_at_supports([a, b], [seg_a, seg_b], supports=[(50.0, 1.0, 3.5)])) == 1
    assert len(crossings_at_supports([a, b], [seg_a, seg_b], supports=[(50.0, 0.3, 3.5)])) == 0
    # b's wire seen up to its pole (0.4 m past the pole's centre as found): it ends there, and a
    # line 0.9 m past that end, 1.3 m past the pole, does not cross it (the synthetic mobile
    # stacked circuits, seed 3); one 0.3 m past the pole does
    seg_b = [(np.array([50.0, -50.0]), np.array([50.0, -0.9]))]
    assert len(crossings_at_supports([a, b], [seg_a, seg_b], supports=[(50.0, -1.3, 3.0)])) == 0
    assert len(crossings_at_supports([a, b], [seg_a, seg_b], supports=[(50.0, -0.3, 3.0)])) == 1


def test_lines_that_both_end_at_a_support_do_not_cross_there():
    """At an angle tower a line's spans turn by 11 deg (AHN4 12AN2_20): the plan lines of the span
    ending at it and the one leaving it meet within its footprint, half a metre past the seen end
    of each, which is no crossing; the same lines with no support there, or ending at different
    supports, cross."""
    d1 = np.array([np.sin(np.radians(21.0)), np.cos(np.radians(21.0))])
    d2 = np.array([np.sin(np.radians(10.0)), np.cos(np.radians(10.0))])
    meet = np.array([0.0, 0.0])
    seg1 = [(meet - 100 * d1, meet - 0.5 * d1)]
    seg2 = [(meet + 0.5 * d2, meet + 100 * d2)]
    lines = [(meet - 100 * d1, d1), (meet + 0.5 * d2, d2)]
    tower = (2.5, 0.0, 6.0)  # its centre 2.5 m beside where they meet, reaching 6 m
    assert len(crossings(lines, [seg1, seg2])) == 1
    assert len(crossings_at_supports(lines, [seg1, seg2], supports=[tower])) == 0
    # each ending at a support of its own (two poles 9 m apart, either side of where they meet)
    assert len(crossings_at_supports(lines, [seg1, seg2], supports=[(-3.0, -4.0, 4.6), (3.0, 4.0, 4.6)])) == 1


def test_a_circuit_ends_where_its_conductors_end_together_and_reaches_as_far_as_its_longest():
    """Line B's three wires end together 1 m from line A's far conductor, at a pole a street scan
    saw too little of to find (mobile_stacked seed 5: 3 false crossings 1.3-3.7 m past B's end):
    their common end is a support, and no B wire crosses A past it; the same ends at the data's
    edge are not (the lines run on out of the survey). A wire of B seen 3.8 m short of its
    sibling's end, beside line A's pole (mobile_dist seed 5: 2 crossings missed), reaches on as
    far as its sibling."""
    from toolbox_plugins.powerlines.stages.layers import circuit_ends, circuit_reach

    u = np.array([0.0, 1.0])
    b_lines = [(np.array([x, 0.0]), u) for x in (48.0, 50.0, 52.0)]
    b_checks = [[(np.array([x, -8.0]), np.array([x, 60.0 + dy]))] for x, dy in ((48.0, 0.3), (50.0, 0.0), (52.0, -0.4))]
    a_far = (np.array([0.0, 62.0]), np.array([1.0, 0.0]))  # 2 m past B's ends
    a_seg = [[(np.array([0.0, 62.0]), np.array([100.0, 62.0]))]]
    bounds = (0.0, -10.0, 100.0, 100.0)  # B enters the survey at its edge
    ends = circuit_ends(b_lines + [a_far], b_checks + a_seg, bounds)
    assert len(ends) == 1 and abs(ends[0][0] - 50.0) < 1e-9 and abs(ends[0][1] - 60.0) < 0.5
    assert len(crossings(b_lines + [a_far], b_checks + a_seg)) == 3  # the 5 m extension
    assert len(crossings_at_supports(b_lines + [a_far], b_checks + a_seg, supports=ends)) == 0
    # at the data's edge (y = 63) their ends are where the survey stops, not a support
    assert circuit_ends(b_lines + [a_far], b_checks + a_seg, (0.0, -10.0, 100.0, 63.0)) == []
    # one wire alone ending there is no circuit's end
    assert circuit_ends(b_lines[:1] + [a_far], b_checks[:1] + a_seg, bounds) == []

    # B's wire at x = 50 seen to y = 56.2, its sibling 2.4 m beside it to y = 60; line A's pole
    # at (49.6, 58.2) beside its end: A's wire at y = 58.6 crosses it 2.4 m past its seen end
    short = [[(np.array([50.0, 0.0]), np.array([50.0, 56.2]))], [(np.array([52.4, 0.0]), np.array([52.4, 60.0]))]]
    pair = [(np.array([50.0, 0.0]), u), (np.array([52.4, 0.0]), u)]
    a_wire = (np.array([0.0, 58.6]), np.array([1.0, 0.0]))
    a_chk = [[(np.array([0.0, 58.6]), np.array([100.0, 58.6]))]]
    pole = [(49.6, 58.2, 3.0)]
    assert len(crossings_at_supports(pair + [a_wire], short + a_chk, supports=pole)) == 1  # the sibling's only
    reach = circuit_reach(pair + [a_wire], short + a_chk)
    assert len(crossings_at_supports(pair + [a_wire], reach, supports=pole)) == 2
    # a sibling ending over max_m farther, or over across_m beside it, carries nothing
    far = [short[0], [(np.array([52.4, 0.0]), np.array([52.4, 62.0]))]]
    assert circuit_reach(pair, far)[0] == far[0]
    wide = [(np.array([50.0, 0.0]), u), (np.array([53.5, 0.0]), u)]
    apart = [short[0], [(np.array([53.5, 0.0]), np.array([53.5, 60.0]))]]
    assert circuit_reach(wide, apart)[0] == apart[0]


def test_false_crossings_are_those_far_from_every_true_one():
    truth = {"conductor_lines_2d": [{"a": [0, 0], "b": [10, 0], "offset_m": 0.0},
                                    {"a": [5, -5], "b": [5, 5], "offset_m": 0.0},
                                    {"a": [0, 3], "b": [10, 3], "offset_m": 0.0, "bundle_offset_m": 0.2}],
             "crossings": [{"x": 5.0, "y": 0.0, "lines": [0, 1]}, {"x": 5.0, "y": 3.0, "lines": [2, 1]}]}
    # at a crossing, at the bundle centre line's crossing (5, 3.2), 2 m off, none near at all
    found = np.array([[5.02, 0.0], [5.0, 3.2], [7.0, 0.0], [40.0, 40.0]])
    assert false_crossings(found, truth) == 2
    assert false_crossings(found[:2], truth) == 0 and false_crossings(np.zeros((0, 2)), truth) == 0


def test_crossings_within_5_cm_of_truth(corridor_result):
    _, gpkg, _, truth = corridor_result
    cr = gpd.read_file(gpkg, layer="crossings")
    assert len(cr) == len(truth["crossings"])
    for c in truth["crossings"]:
        d = np.hypot(cr.geometry.x - c["x"], cr.geometry.y - c["y"])
        assert d.min() <= 0.05, (c, d.min())
        k = int(np.argmin(d))
        assert cr.angle_deg[k] == pytest.approx(c["angle_deg"], abs=0.5)


def test_stacked_conductors_are_separated_in_3d(corridor_result):
    _, gpkg, _, truth = corridor_result
    cond = gpd.read_file(gpkg, layer="conductors")
    c3 = gpd.read_file(gpkg, layer="conductors_3d")
    assert c3.geometry.has_z.all()
    a_phase = [i for i, g in enumerate(cond.geometry) if cond.height_max_m[i] > 15 and cond.n_wires[i] >= 2]
    assert len(a_phase) == 4  # the four plan lines of line A's phases each hold two stacked wires
    for i in a_phase:
        wires = c3[c3.conductor == i]
        heights = sorted(np.mean([p[2] for p in g.coords]) for g in wires.geometry)
        assert heights[-1] - heights[0] > 4.0  # arms 6 m apart
    # every wire is one wire across its poles and pylons: as many as in the truth
    assert c3.groupby(["conductor", "wire"]).ngroups == len(truth["wires"])
    # sags: catenaries of line A hang 2-4 m over 185 m spans, as the truth
    long_spans = c3[(c3.length_m > 150) & (c3.rms_m < 0.1)]
    assert len(long_spans) >= 8
    truth_sags = [s["sag_m"] for s in truth["spans"] if s["line"] == "A" and s["length_m"] > 150]
    assert long_spans.sag_m.between(min(truth_sags) - 0.5, max(truth_sags) + 0.5).mean() > 0.8
    assert long_spans.catenary_c_m.between(1200, 1700).mean() > 0.8


def test_wire_points_on_synthetic_truth(corridor_result, corridor):
    _, _, wires, _ = corridor_result
    t = laspy.read(corridor).classification == 14
    p = laspy.read(wires).classification == 14
    precision, recall = (t & p).sum() / p.sum(), (t & p).sum() / t.sum()
    assert precision >= 0.98 and recall >= 0.99  # 0.999 / 0.995 measured


def _ahn4_real(name, tmp_path):
    """An AHN4 corridor tile with the repo author's synthetic classes 5 and 26 dropped."""
    las = laspy.read(shared_file(f"ahn4_corridor/{name}.laz"))
    sub = laspy.LasData(las.header)
    sub.points = las.points[np.isin(las.classification, [1, 2, 9, 14, 15])]
    sub.write(tmp_path / f"{name}.laz")
    return tmp_path / f"{name}.laz", sub


@pytest.mark.parametrize("name, min_precision, min_recall", [("07CZ2_14", 0.99, 0.99), ("12AN2_20", 0.98, 0.985)])
def test_ahn4_corridors_at_default_parameters(name, min_precision, min_recall, tmp_path):
    """Both real AHN4 tiles, no setting: wire points against the producer's class 14 (measured
    0.994 / 0.998 and 0.987 / 0.991; 12AN2_20's sparse earth wires are seen in stretches up to
    26 m apart; the producer counts the wire across a tower's footprint as tower, and so do we),
    V_max chosen from the wires' point spacing (about 0.33 m on both: 3.2-3.3 m), and the tile's one tower
    (the producer's class 15) found within 2 m, nothing else taken for one."""
    path, sub = _ahn4_real(name, tmp_path)
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", crs="EPSG:28992",
                      outputs={"classified": str(tmp_path / "w.laz")})
    assert rep["stats"]["cell_size_m_used"] == pytest.approx(0.133)  # reported
    # sparser than the method's 10 points per 2.5 m of wire: V_max scaled to the spacing
    assert rep["stats"]["v_max_m_used"] == pytest.approx(10 * rep["stats"]["wire_spacing_m"], abs=0.01)
    assert rep["stats"]["v_max_m_used"] > 2.5
    truth = np.asarray(sub.classification) == 14
    out = laspy.read(tmp_path / "w.laz").classification
    pred = out == 14
    precision, recall = (truth & pred).sum() / pred.sum(), (truth & pred).sum() / truth.sum()
    assert precision >= min_precision and recall >= min_recall, (precision, recall)
    tower = np.asarray(sub.classification) == 15
    tx, ty = np.asarray(sub.x)[tower], np.asarray(sub.y)[tower]
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    assert len(py) == 1
    # (the issue asks 2 m; measured 0.05 and 0.25 m, 0.75 and 1.0 m while a tower's base was the
    # middle of its column cells)
    assert np.hypot(py.geometry.x[0] - 0.5 * (tx.min() + tx.max()), py.geometry.y[0] - 0.5 * (ty.min() + ty.max())) <= 0.5
    t15 = out == 15
    assert (tower & t15).sum() / t15.sum() >= 0.8 and (tower & t15).sum() / tower.sum() >= 0.7


@pytest.mark.parametrize("name, min_precision, min_recall", [("part3_an", 0.92, 0.90), ("part3_ak", 0.97, 0.9),
                                                              ("part2_ai", 0.90, 0.90)])
def test_mobile_scans_at_default_parameters(name, min_precision, min_recall, tmp_path):
    """Oakland mobile scans (a car-mounted scanner under distribution wires), no setting: wire
    points against the CMU wire labels (class 14), the issue's 0.90 on each. part3_an: wires
    0.3-1 m above one another, a service drop, wires leaving the tile a few metres past a pole;
    part3_ak: wires seen for 5-8 m between crowns (and a truck's top edge under them); part2_ai:
    a sparse upper wire past the last pole, the lower one through crowns."""
    path = shared_file(f"oakland_mls/oakland_{name}.laz")
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")})
    truth = np.asarray(laspy.read(path).classification) == 14
    pred = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14
    precision, recall = (truth & pred).sum() / pred.sum(), (truth & pred).sum() / truth.sum()
    assert precision >= min_precision and recall >= min_recall, (precision, recall)
    # every drawn span is a wire's: its catenary fits (part2_ai's pieces through crowns do not)
    c3 = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors_3d")
    assert len(c3) and (c3.rms_m <= 0.2).all(), c3.rms_m.max()
    # the poles that carry the wires, against the CMU utility-pole label: every pole found stands
    # on one (within 0.5 m of its points' middle); part3_ak's, away from the wires scanned, are
    # not found
    src = laspy.read(path)
    labelled = np.column_stack([src.x, src.y])[np.asarray(src.cmu_label) == 1103]
    py = gpd.read_file(tmp_path / "pl.gpkg", layer="pylons")
    poles = py[py["kind"] == "pole"]
    assert len(poles) >= {"part3_an": 3, "part3_ak": 0, "part2_ai": 3}[name]
    # no tower on a street scan where the poles carry the wires (part2_ai: a crown where a next
    # span stopped at the scan's edge was one while that end counted as a span end)
    assert name == "part3_ak" or (py["kind"] == "tower").sum() == 0
    for g in poles.geometry:
        near = labelled[np.hypot(labelled[:, 0] - g.x, labelled[:, 1] - g.y) <= 1.0]
        assert len(near) >= 20 and np.hypot(*(near.mean(axis=0) - [g.x, g.y])) <= 0.5, (g.x, g.y)
    if len(poles):  # tower points: the poles' columns and heads, not the crowns beside them (P 0.06 before)
        out = np.asarray(laspy.read(tmp_path / "w.laz").classification) == 15
        labelled_15 = np.asarray(src.classification) == 15
        assert (out & labelled_15).sum() >= 0.6 * out.sum() and (out & labelled_15).sum() >= 0.5 * labelled_15.sum()
    # a cable's end clamped to a pole's side, 4-8 m under its top, is the pole's (CMU: pole), not
    # a wire's: no wire point inside a found pole's column under its head (part2_ai had 5, part3_an 12)
    cls = np.asarray(laspy.read(tmp_path / "w.laz").classification)
    x, y, z = np.asarray(src.x), np.asarray(src.y), np.asarray(src.z)
    for g, height in zip(poles.geometry, poles["height_m"] if len(poles) else []):
        column = (np.hypot(x - g.x, y - g.y) <= 0.3) & (z < g.z + height - 1.0)
        assert not (column & (cls == 14)).any(), (g.x, g.y, int((column & (cls == 14)).sum()))


def test_in_pole_columns_takes_what_is_clamped_to_a_pole_not_its_head():
    """A pole 10 m high at (0, 0): a cable's end at its side 5 m up is in its column, the top
    wire on its head (9.5 m), a cross arm's wire 0.8 m off its axis and a point 0.4 m off it are not."""
    from toolbox_plugins.powerlines.core import in_pole_columns

    x = np.array([0.1, 0.0, 0.8, 0.4, 0.05])
    y = np.array([0.1, 0.0, 0.0, 0.0, 0.0])
    hag = np.array([5.0, 9.5, 9.2, 5.0, 8.9])
    assert in_pole_columns([(0.0, 0.0, 10.0)], x, y, hag).tolist() == [True, False, False, False, True]
    assert not in_pole_columns(np.zeros((0, 3)), x, y, hag).any()


@pytest.mark.parametrize("rel, crs", [("ahn3_amsterdam/ahn_2386_9702.laz", "EPSG:7415"),
                                      ("pdal_autzen/autzen_trim.las", None), ("lidR/Topography.laz", None)])
def test_no_power_line_is_found_on_real_surveys_without_one(rel, crs, tmp_path):
    """Real surveys with no power line in them (AHN3 Amsterdam: streets, roofs and trees; Autzen:
    a suburb in US feet; lidR's Topography: forest on a hillside), at the defaults: no conductor,
    no crossing, no pylon, and no point classified as wire."""
    path = shared_file(rel)
    kw = {"crs": crs} if crs else {}
    toolbox.run("powerlines", path, tmp_path / "pl.gpkg", outputs={"classified": str(tmp_path / "w.laz")}, **kw)
    for layer in ("conductors", "crossings", "pylons"):
        assert len(gpd.read_file(tmp_path / "pl.gpkg", layer=layer)) == 0, layer
    assert not (np.asarray(laspy.read(tmp_path / "w.laz").classification) == 14).any()


def test_ahn4_corridor_wire_points_and_lines(tmp_path):
    path, sub = _ahn4_real("07CZ2_14", tmp_path)
    rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", crs="EPSG:28992",
                      outputs={"classified": str(tmp_path / "w.laz")})
    truth = np.asarray(sub.classification) == 14
    # the 3D conductor lines lie on the producer's class-14 points
    from scipy.spatial import cKDTree

    wires = np.column_stack([sub.x, sub.y, sub.z])[truth]
    c3 = gpd.read_file(tmp_path / "pl.gpkg", layer="conductors_3d")
    import shapely

    samples = np.concatenate([shapely.get_coordinates(g.interpolate(np.arange(0, g.length, 0.05)), include_z=True)
                              for g in c3.geometry])
    # every producer wire point lies close to a fitted conductor (the model's residual)...
    d, _ = cKDTree(samples).query(wires)
    assert np.median(d) <= 0.1, np.median(d)
    # ...and the conductors run along the points (bounded below by the along-wire point spacing)
    d_back, _ = cKDTree(wires).query(samples)
    assert np.median(d_back) <= 0.2, np.median(d_back)
    assert rep["stats"]["n_wires_3d"] >= 8  # four conductor levels on each of the two circuits


def test_accumulator_too_big_is_a_clear_error(corridor, tmp_path, cli):
    r = cli("run", "hough-lines", corridor, "-o", tmp_path / "h.gpkg", "--set", "rho_step_m=0.001",
            "--set", "theta_step_deg=0.001", "--set", "tile_size_m=0")
    assert r.returncode == 2
    assert "accumulator needs" in r.stderr and "GiB" in r.stderr and "rho_step_m" in r.stderr
    assert not (tmp_path / "h.gpkg").exists()
    r = cli("run", "hough-lines", corridor, "-o", tmp_path / "h.gpkg", "--set", "overlap_m=200")
    assert r.returncode == 2 and "overlap_m" in r.stderr


def test_tophat_and_hough_through_the_cli(corridor, tmp_path, cli):
    r = cli("run", "tophat", corridor, "-o", tmp_path / "t.laz", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert 0 < rep["stats"]["n_out"] < rep["stats"]["n_in"]
    r = cli("run", "hough-lines", tmp_path / "t.laz", "-o", tmp_path / "h.gpkg")
    assert r.returncode == 0, r.stderr
    import sqlite3

    con = sqlite3.connect(tmp_path / "h.gpkg")
    styled = {row[0] for row in con.execute("SELECT f_table_name FROM layer_styles WHERE useAsDefault = 1")}
    assert styled == {"conductors", "conductor_segments", "crossings"}


def test_hough_lines_on_a_binary_raster_finds_the_edges_of_a_building(tmp_path):
    """The roof method's edge image: a rotated rectangle's mask minus its erosion; its four sides."""
    from affine import Affine
    from scipy import ndimage

    from toolbox.io.points import parse_crs
    from toolbox.io.rasters import Raster, write_raster

    yy, xx = np.mgrid[0:200, 0:200] * 0.25
    a = np.radians(20.0)
    u = (xx - 25) * np.cos(a) + (yy - 25) * np.sin(a)
    v = -(xx - 25) * np.sin(a) + (yy - 25) * np.cos(a)
    mask = (np.abs(u) <= 15) & (np.abs(v) <= 9)
    edges = mask & ~ndimage.binary_erosion(mask)
    write_raster(Raster(edges.astype(np.uint8), Affine(0.25, 0, 500000, 0, -0.25, 5400050), crs=parse_crs("EPSG:25832"),
                        nodata=None), tmp_path / "edges.tif")
    rep = toolbox.run("hough-lines-raster", tmp_path / "edges.tif", tmp_path / "e.gpkg", rho_step_m=0.25, band_m=0.5,
                      v_max_m=1.0, tile_size_m=0)
    lines = gpd.read_file(tmp_path / "e.gpkg", layer="conductors")
    assert len(lines) == 4, rep["stats"]
    az = sorted(lines.azimuth_deg.round() % 90)
    # rotated by 20 degrees in image rows (y down), i.e. -20 degrees from east in the world:
    # azimuths 110 and 20, both 20 modulo 90
    assert np.allclose(az, [20, 20, 20, 20], atol=1.0)
    # extents: a side found later loses the corner cells its neighbour's band took
    lengths = sorted(lines.length_m)
    assert 15.5 <= lengths[0] <= 18.5 and 28.0 <= lengths[-1] <= 30.5
    # the corners are the crossings of the sides; the edge cells lie just inside the outline
    corners = gpd.read_file(tmp_path / "e.gpkg", layer="crossings")
    assert len(corners) == 4
    cu, cv = np.array([-15, 15, 15, -15]), np.array([-9, -9, 9, 9])
    # image (col, row) -> world: x = 500000 + col*0.25, y = 5400050 - row*0.25, and u, v were in index metres
    ix = 25 + cu * np.cos(a) - cv * np.sin(a)
    iy = 25 + cu * np.sin(a) + cv * np.cos(a)
    true = np.column_stack([500000 + ix + 0.125, 5400050 - iy - 0.125])
    for p in true:
        d = np.hypot(corners.geometry.x - p[0], corners.geometry.y - p[1]).min()
        assert d < 0.5, (p, d)


def test_the_methods_cell_on_side_by_side_conductors_says_what_to_do(tmp_path, caplog):
    """The method's 0.5 m top-hat cell, asked for explicitly, loses AHN4's side-by-side conductors
    (the top-hat keeps few of their points); the run says so and names the parameter instead of
    returning an empty or thin file silently."""
    import logging

    path, las = _ahn4_real("07CZ2_14", tmp_path)
    with caplog.at_level(logging.WARNING):
        rep = toolbox.run("powerlines", path, tmp_path / "pl.gpkg", crs="EPSG:28992", cell_size_m=0.5)
    assert rep["stats"]["n_wire_points"] < 0.3 * int(np.sum(las.classification == 14))
    assert any("leave cell_size_m automatic" in r.getMessage() for r in caplog.records)


def test_closed_form_eigen_matches_numpy():
    from toolbox.neighbourhoods import principal_axes, symmetric3_eigenvalues

    rng = np.random.default_rng(5)
    pts = rng.normal(size=(2000, 12, 3)) * rng.uniform(0.01, 3, size=(2000, 1, 3))
    pts[:10, :, 1:] = 0.0  # points on a line: two zero eigenvalues
    pts[10:20] = pts[10:20, :1]  # one point repeated: all zero
    c = pts - pts.mean(axis=1, keepdims=True)
    cov = np.matmul(c.transpose(0, 2, 1), c) / 12
    ev, vec = np.linalg.eigh(cov)
    mine = symmetric3_eigenvalues(cov)
    # the cubic's acos loses digits where two eigenvalues meet: 1e-8 of the largest, against
    # shape thresholds of a few per cent
    np.testing.assert_allclose(mine, ev, atol=1e-8 * max(1.0, float(ev.max())))
    axes = principal_axes(cov, mine[:, 2])
    np.testing.assert_allclose(np.linalg.norm(axes, axis=1), 1.0)
    separated = ev[:, 2] - ev[:, 1] > 1e-6 * ev[:, 2]
    assert np.abs(np.sum(axes * vec[:, :, 2], axis=1))[separated].min() > 1 - 1e-9
    assert np.allclose(np.abs(axes[:10, 0]), 1.0)  # the line's own direction


def test_neighbourhood_covariances_equal_centred_products():
    """The gathered-offsets covariance against the textbook centred product, on a cloud 300 m
    from its origin (offsets from each point keep E[ab] - E[a]E[b] exact)."""
    from scipy.spatial import cKDTree

    from toolbox.neighbourhoods import neighbourhood_covariances

    rng = np.random.default_rng(9)
    xyz = rng.uniform(0, 40, (3000, 3)) * [1, 1, 0.3] + 300.0
    xyz[:50] = [320.0, 320.0, 310.0] + np.outer(np.linspace(0, 10, 50), [1, 0.2, 0])  # a line
    _, idx = cKDTree(xyz).query(xyz, k=12)
    nb = xyz[idx]
    c = nb - nb.mean(axis=1, keepdims=True)
    ref = np.matmul(c.transpose(0, 2, 1), c) / 12
    got = neighbourhood_covariances(xyz, idx)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    assert np.array_equal(got, got.transpose(0, 2, 1))
    assert np.array_equal(neighbourhood_covariances(xyz, idx, chunk=700), got)  # chunks are exact


@pytest.mark.parametrize("density", [2.0, 30.0])  # 4 and 48 points needed within 1 m: k=12 answers, or not
def test_surface_density_rule_counts_the_points_within_one_metre(density):
    """Planar and rugged neighbourhoods must hold half the survey's density within radius 1 (a
    count of the ball, its definition); shape_classes decides it from nearest-neighbour distances."""
    from scipy.spatial import cKDTree
    from toolbox_plugins.powerlines.core import shape_classes

    rng = np.random.default_rng(4)
    roof = np.column_stack([rng.uniform(0, 20, 6000), rng.uniform(0, 20, 6000), np.zeros(6000)])
    roof[:, 2] = 0.3 * roof[:, 0] + rng.normal(0, 0.02, 6000)
    crown = rng.normal([40, 10, 5], 1.5, (1500, 3))
    sparse_roof = np.column_stack([rng.uniform(60, 80, 300), rng.uniform(0, 20, 300), rng.normal(0, 0.02, 300)])
    t = np.linspace(0, 30, 200)
    wire = np.column_stack([t, 25 + 0 * t, 8 + 0.001 * (t - 15) ** 2])
    xyz = np.vstack([roof, crown, sparse_roof, wire])
    _, plain_planar, plain_rugged, _ = shape_classes(xyz)
    _, planar, rugged, _ = shape_classes(xyz, surface_density=density)
    counts = cKDTree(xyz).query_ball_point(xyz, 1.0, return_length=True)
    dense = counts >= 0.5 * np.pi * density
    assert np.array_equal(planar, plain_planar & dense) and np.array_equal(rugged, plain_rugged & dense)
    assert planar.any() and (plain_planar & ~dense).any()  # both outcomes occur


@pytest.mark.parametrize("seed", range(5))
def test_two_means_split_is_the_best_cut(seed):
    """The bundle splitter's 1D two-means: the cut of least within-group sum of squares among
    all cuts leaving min_size values on each side (checked by trying every cut)."""
    rng = np.random.default_rng(seed)
    r = np.r_[rng.normal(0, 0.05, 40 + 10 * seed), rng.normal(0.3 + 0.1 * seed, 0.05, 60)]
    rng.shuffle(r)
    upper, c0, c1, sd = _two_means_1d(r, 20)
    v = np.sort(r)
    costs = [((v[:k] - v[:k].mean()) ** 2).sum() + ((v[k:] - v[k:].mean()) ** 2).sum() for k in range(20, len(v) - 19)]
    k = 20 + int(np.argmin(costs))
    assert upper.sum() == len(v) - k and r[upper].min() >= r[~upper].max()
    assert c0 == pytest.approx(v[:k].mean()) and c1 == pytest.approx(v[k:].mean())
    assert sd == pytest.approx(np.sqrt(min(costs) / len(v)))
    assert _two_means_1d(r[:39], 20) is None  # too few for two groups of 20


def test_an_accumulator_whose_rho_range_leaves_out_zero_counts_as_numpy():
    """A ρ range that starts past the origin (points 50-60 m out, θ 0-90°): every count and peak
    as numpy's."""
    rng = np.random.default_rng(12)
    x, y = rng.uniform(50, 60, 2000), rng.uniform(50, 60, 2000)
    t = np.radians(np.arange(0, 90, 0.5))
    a = reference.NumpyAccumulator(np.cos(t), np.sin(t), 400, 10.0, 500)
    assert reference.bin_index(x[:, None], y[:, None], a.cs[None, :], a.ss[None, :], a.off).min() >= 0
    with hough_kernels.TaichiAccumulator(kernels.taichi(), np.cos(t), np.sin(t), 400, 10.0, 500) as b:
        a.vote(x, y, 1)
        b.vote(x, y, 1)
        assert np.array_equal(a.to_numpy(), b.to_numpy()) and a.peak() == b.peak()
        a.vote(x[:700], y[:700], -1)
        b.vote(x[:700], y[:700], -1)
        assert np.array_equal(a.to_numpy(), b.to_numpy()) and a.peak() == b.peak()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_closed_form_line_and_parabola_equal_polyfit(seed):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-150, 150, 300)  # metres along a wire, centred
    y = 310 + 0.02 * x + 4e-4 * x * x + rng.normal(0, 0.05, len(x))
    np.testing.assert_allclose(line_fit(x + 1e5, y), np.polyfit(x + 1e5, y, 1), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(parabola_fit(x, y), np.polyfit(x, y, 2), rtol=1e-9, atol=1e-12)
    assert line_fit(np.full(5, 3.0), np.arange(5.0)) == (0.0, 2.0)  # all x equal: flat, through the mean
    assert parabola_fit(np.array([1.0, 1.0, 2.0]), np.array([1.0, 3.0, 4.0])) == pytest.approx((0.0, 2.0, 0.0))



@pytest.mark.parametrize("seed", [0, 1, 2])
def test_median_line_fit_holds_a_wire_trend_under_a_clump_that_tilts_least_squares(seed):
    """A wire's plan trend (20 points over 8 m, 2 cm scatter) with a crown's clump 2-3 m past its
    end (16 points, 0.2-0.8 m beside it: 44 % of all): the least-median line stays within 2 cm of
    the wire over its points where the least-squares line is pulled off by more than 5 cm; on a
    clean wire of 5000 points over 300 m (256 pairs drawn, residuals on 512 of the points) it stays
    within the points' scatter (3 cm) of the truth: a start that the callers refit by least squares."""
    from toolbox_plugins.powerlines.core import median_line_fit

    rng = np.random.default_rng(seed)
    s = rng.uniform(0.0, 8.0, 20)
    off = 0.1 - 0.012 * s + rng.normal(0, 0.02, len(s))
    x, y = np.r_[s, rng.uniform(-3.0, -2.0, 16)], np.r_[off, -rng.uniform(0.2, 0.8, 16)]
    m1, m0 = median_line_fit(x, y)
    l1, l0 = line_fit(x, y)
    assert np.abs(m1 * s + m0 - (0.1 - 0.012 * s)).max() <= 0.02
    assert np.abs(l1 * s + l0 - (0.1 - 0.012 * s)).max() > 0.05
    s = rng.uniform(0.0, 300.0, 5000)
    off = 0.3 + 0.004 * s + rng.normal(0, 0.03, len(s))
    m1, m0 = median_line_fit(s, off)
    assert np.abs((m1 - 0.004) * s + m0 - 0.3).max() <= 0.03
    assert median_line_fit(np.array([0.0, 1.0]), np.array([1.0, 2.0])) == pytest.approx((1.0, 1.0))

def test_local_surface_density_counts_points_per_occupied_cell_in_its_window_in_any_piece():
    """Against a count by hand: points (first returns) over distinct occupied 1 m cells in the
    5 m blocks within the radius; and the same value for a point in any piece holding its window."""
    rng = np.random.default_rng(4)
    x = 512000 + rng.uniform(0, 300.0, 30000)
    y = 5403000 + rng.uniform(0, 120.0, 30000)
    x[:5000] = 512100 + rng.uniform(0, 20.0, 5000)  # a denser patch
    first = rng.random(len(x)) < 0.8
    d = local_surface_density(x, y, first, radius_m=20.0)
    bx, by = np.floor(np.floor(x) / 5), np.floor(np.floor(y) / 5)
    for i in rng.choice(len(x), 25, replace=False):
        win = (np.abs(bx - bx[i]) <= 4) & (np.abs(by - by[i]) <= 4)
        cells = len({(int(a), int(b)) for a, b in zip(np.floor(x[win]), np.floor(y[win]))})
        assert d[i] == pytest.approx(first[win].sum() / cells, rel=1e-12)
    piece = (x >= 512050) & (x < 512250)  # holds the windows of the points in its middle
    mid = np.flatnonzero(piece & (x >= 512080) & (x < 512220))
    d_piece = local_surface_density(x[piece], y[piece], first[piece], radius_m=20.0)
    np.testing.assert_array_equal(d_piece[np.searchsorted(np.flatnonzero(piece), mid)], d[mid])


def test_a_new_accumulator_reads_zero_whatever_the_last_one_left():
    # the kernels clear a θ row when they first touch it, not in a pass of their own:
    # the counts a previous tile left behind must never show
    rng = np.random.default_rng(7)
    x, y = rng.uniform(0, 110, 4000), rng.uniform(0, 110, 4000)
    thetas, k_min, rows = hough.accumulator_shape(x, y, 0.1, 0.1)
    c, s = np.cos(thetas), np.sin(thetas)
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows) as old:
        old.vote(x, y, 1)
    a = reference.NumpyAccumulator(c, s, k_min, 10.0, rows)
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows) as b:
        assert not b.to_numpy().any() and b.peak()[2] == 0
        a.clear_cell(40, 700)
        b.clear_cell(40, 700)  # a cell of a row no vote has touched yet
        assert not b.to_numpy().any()
        x2, y2 = x[:500], y[:500]
        a.vote(x2, y2, 1)
        b.vote(x2, y2, 1)
        assert np.array_equal(a.to_numpy(), b.to_numpy()) and a.peak() == b.peak()


@pytest.mark.parametrize("x0, y0, w, h", [(0, 0, 110, 110), (0, 0, 110, 12), (37, 0, 20, 110), (-55, -55, 110, 110)])
def test_an_accumulator_given_its_extent_counts_and_peaks_as_numpy(x0, y0, w, h):
    """With the points' bounding box, the kernel clears and scans each θ row only over the ρ bins
    the box reaches; the rest must read as zeros, whatever a previous accumulator left there,
    and every count and peak equals numpy's."""
    rng = np.random.default_rng(11)
    x, y = x0 + rng.uniform(0, w, 3000), y0 + rng.uniform(0, h, 3000)
    t = rng.uniform(0, 1, 400)  # a line across the box, so that peaks are well above the scatter
    x, y = np.r_[x, x0 + w * t], np.r_[y, y0 + h * (0.2 + 0.6 * t)]
    thetas, k_min, rows = hough.accumulator_shape(x, y, 0.1, 0.1)
    c, s = np.cos(thetas), np.sin(thetas)
    # a previous accumulator of the same shape fills whole rows with counts
    extent = (float(x.min()), float(x.max()), float(y.min()), float(y.max()))
    lo, hi = hough_kernels.reach(*reference.bin_scales(c, s, k_min, 10.0), rows, extent)
    cols = np.arange(rows)[None, :]
    outside = (cols < lo[:len(thetas), None]) | (cols > hi[:len(thetas), None])
    # (points within the disc every θ row holds: any ρ in [-radius, radius])
    radius = min(-k_min, k_min + rows - 1) * 0.1 - 0.5
    ang, rad = rng.uniform(-np.pi, np.pi, 20000), radius * np.sqrt(rng.uniform(0, 1, 20000))
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows) as old:
        old.vote(rad * np.cos(ang), rad * np.sin(ang), 1)
        assert (old.to_numpy()[outside] > 0).sum() > 1000  # left where the next one won't clear
    a = reference.NumpyAccumulator(c, s, k_min, 10.0, rows, extent=extent)
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows, extent=extent) as b:
        assert not b.to_numpy().any() and b.peak()[2] == 0
        a.vote(x, y, 1)
        b.vote(x, y, 1)
        ref = a.to_numpy()
        assert np.array_equal(ref, b.to_numpy()) and a.peak() == b.peak()
        assert not ref[outside].any()  # every vote lies within its row's reach
        left = np.arange(len(x))
        for _ in range(4):  # the detection loop
            cc, r, _ = a.peak()
            near = left[np.abs(reference.bin_index(x[left], y[left], a.cs[cc], a.ss[cc], a.off) - r) <= 4]
            a.vote(x[near], y[near], -1)
            b.vote(x[near], y[near], -1)
            left = np.setdiff1d(left, near)
            assert a.peak() == b.peak()
        with pytest.raises(ValueError, match="outside the accumulator's extent"):
            b.vote(np.array([extent[1] + 1.0]), np.array([extent[2]]), 1)


def test_an_accumulator_larger_than_the_standard_kit_counts_the_same():
    # more cells than the standard kit holds: a kit of its own is built for it
    rng = np.random.default_rng(8)
    x, y = rng.uniform(0, 300, 600), rng.uniform(0, 300, 600)
    thetas, k_min, rows = hough.accumulator_shape(x, y, 0.1, 0.1)
    assert len(thetas) * rows > hough_kernels.CELLS
    c, s = np.cos(thetas), np.sin(thetas)
    a = reference.NumpyAccumulator(c, s, k_min, 10.0, rows)
    with hough_kernels.TaichiAccumulator(kernels.taichi(), c, s, k_min, 10.0, rows) as b:
        a.vote(x, y, 1)
        b.vote(x, y, 1)
        assert np.array_equal(a.to_numpy(), b.to_numpy()) and a.peak() == b.peak()
        a.vote(x[:200], y[:200], -1)
        b.vote(x[:200], y[:200], -1)
        assert a.peak() == b.peak()


def _bridge_scene(rng, kink=False):
    """A wire 80 m along x (points every ~0.3 m) whose candidates stop 7 m either side of a crown
    at s = 40, a second wire 0.3 m beside it (a ribbon's phase) and the crown's foliage; with
    ``kink`` the two pieces hang in catenaries of their own, meeting at a support at s = 40."""
    from toolbox_plugins.powerlines.core import _span, fit_catenary

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
        spans.append(_span(0, i, 0, w[m, 0], w[m, 1], fit_catenary(w[m, 0], w[m, 2]), z=w[m, 2]))
    free = np.r_[(w[:, 0] > 33.0) & (w[:, 0] < 47.0), np.ones(len(beside) + len(crown), bool)]
    line = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 80.0)
    return spans, line, pts, free, is_gap


@pytest.mark.parametrize("seed", [0, 1])
def test_a_wire_through_a_crown_is_bridged_between_its_pieces(seed):
    """A wire's two fitted pieces either side of a crown it runs through, on one catenary: the
    gap's wire points are taken (not its neighbour's 0.3 m beside; of a crown filled with 26 points
    per cubic metre, what lies within the wire's tolerance, under a fifth of those taken); two pieces
    that hang in catenaries of their own (a support between them) are not bridged."""
    from toolbox_plugins.powerlines.core import bridge_gaps

    spans, line, p, free, is_gap = _bridge_scene(np.random.default_rng(seed))
    found = bridge_gaps(spans, [line], p[:, 0], p[:, 1], p[:, 2], free, 0.2, max_gap_m=16.0)
    assert len(found) == 1
    li, wire, k, *_ = found[0]
    assert (li, wire) == (0, 0)
    assert is_gap[k].sum() >= 0.9 * is_gap.sum() and is_gap[k].mean() >= 0.8
    assert not np.any(np.abs(p[k, 1] - 0.3) < 0.1)
    spans, line, p, free, is_gap = _bridge_scene(np.random.default_rng(seed), kink=True)
    assert bridge_gaps(spans, [line], p[:, 0], p[:, 1], p[:, 2], free, 0.2, max_gap_m=16.0) == []
    # a gap wider than max_gap_m is left alone
    spans, line, p, free, is_gap = _bridge_scene(np.random.default_rng(seed))
    assert bridge_gaps(spans, [line], p[:, 0], p[:, 1], p[:, 2], free, 0.2, max_gap_m=12.0) == []


@pytest.mark.parametrize("seed", [0, 1])
def test_a_wire_askew_to_its_line_is_bridged_past_a_crown_clump_on_a_short_piece(seed):
    """The case of Oakland part2_ai's lower wire: the wire runs 0.6 degrees askew to its 2D line
    (0.14 m across over the 14 m gap), and its piece past the crown is short (8 m) with 4 of the
    crown's points at its gap end linked to it (on its catenary, 0.4 m beside the wire). The two
    pieces' trends meet mid-gap, robustly fitted, and the gap's wire points are taken; a second
    wire askew the other way past the crown (0.3 m off mid-gap) is not joined to the first."""
    from toolbox_plugins.powerlines.core import _span, bridge_gaps, fit_catenary

    rng = np.random.default_rng(seed)
    askew = 0.01

    def wire(s, slope, at=0.0):
        return np.column_stack([s, at + slope * s + rng.normal(0, 0.02, len(s)),
                                catenary(s, 20.0, 40.0, 900.0) + rng.normal(0, 0.03, len(s))])

    def scene(b_slope, b_at=0.0):
        a = wire(np.sort(rng.uniform(0.0, 33.0, 110)), askew)
        gap = wire(np.sort(rng.uniform(33.5, 46.5, 40)), askew)
        b = wire(np.sort(rng.uniform(47.0, 55.0, 27)), b_slope, b_at)
        clump = np.column_stack([rng.uniform(47.0, 47.6, 4), b_at + b_slope * 47.3 - 0.4 + rng.normal(0, 0.05, 4),
                                 catenary(rng.uniform(47.0, 47.6, 4), 20.0, 40.0, 900.0)])
        b = np.vstack([clump, b])
        d = rng.normal(size=(3000, 3))
        crown = np.array([40.0, 0.4, 19.5]) + 3.0 * d / np.linalg.norm(d, axis=1)[:, None] * \
            rng.uniform(0, 1, (3000, 1)) ** (1 / 3)
        pts = np.vstack([a, b, gap, crown])
        spans = [_span(0, 0, i, q[:, 0], q[:, 1], fit_catenary(q[:, 0], q[:, 2]), z=q[:, 2]) for i, q in enumerate((a, b))]
        wire_of = np.r_[np.zeros(len(a) + len(b), int), np.full(len(gap) + len(crown), -1)]
        is_gap = np.r_[np.zeros(len(a) + len(b), bool), np.ones(len(gap), bool), np.zeros(len(crown), bool)]
        return spans, pts, wire_of, is_gap

    line = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 60.0)
    spans, p, wire_of, is_gap = scene(askew)
    line_of = np.where(wire_of >= 0, 0, -1)
    found = bridge_gaps(spans, [line], p[:, 0], p[:, 1], p[:, 2], wire_of < 0, 0.2, max_gap_m=16.0,
                        line_of=line_of, wire_of=wire_of)
    assert len(found) == 1
    k = found[0][2]
    assert is_gap[k].sum() >= 0.9 * is_gap.sum() and is_gap[k].mean() >= 0.8
    spans, p, wire_of, is_gap = scene(-askew, b_at=1.1)
    assert bridge_gaps(spans, [line], p[:, 0], p[:, 1], p[:, 2], wire_of < 0, 0.2, max_gap_m=16.0,
                       line_of=line_of, wire_of=wire_of) == []


def test_a_short_stub_runs_along_a_line_its_ends_lie_on():
    """A 9.5 m stub the Hough leant 1.4 deg off its wire runs along the long line both its ends
    lie within band_m of (its angle is loose over that length); a 30 m line at that angle, its
    ends as close, crosses it."""
    from toolbox_plugins.powerlines.wire_sets import runs_along

    h = (np.array([-100.0, 0.0]), np.array([1.0, 0.0]), 0.0, 600.0)
    d = np.array([np.cos(np.radians(1.4)), np.sin(np.radians(1.4))])
    assert runs_along((np.array([0.0, -0.1]), d, 0.0, 9.5), h, 0.4)
    assert not runs_along((np.array([0.0, -0.36]), d, 0.0, 30.0), h, 0.4)
    assert not runs_along((np.array([0.0, 0.3]), d, 0.0, 9.5), h, 0.4)  # its far end 0.53 m off


def test_a_wire_running_into_a_crown_is_thin_across_and_a_crowns_edge_is_not():
    """A wire whose piece a crown is linked to (mobile_dist_far seed 10: line B's wire into a
    conifer by its pole) scatters across its line by the crown's points (plain lateral rms over
    WIRE_LATERAL_RMS_M), but the points on its catenary are thin in robust sigma: a conductor. A
    crown's edge lined up along a street, at a catenary's heights, is wide either way."""
    from toolbox_plugins.powerlines.core import WIRE_LATERAL_RMS_M, thin_across

    rng = np.random.default_rng(10)
    L, z0, c = 20.0, 20.0, 900.0
    sw = np.sort(rng.uniform(0, L, 60))
    wire = np.column_stack([sw, rng.normal(0, 0.02, 60), catenary(sw, z0, 30.0, c) + rng.normal(0, 0.02, 60)])
    sc = rng.uniform(12.0, 16.0, 50)
    crown = np.column_stack([sc, rng.uniform(-0.9, 0.9, 50), catenary(sc, z0, 30.0, c) + rng.uniform(-1.0, 0.3, 50)])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, L)]

    def spans_of(pts):
        return conductors_3d(geo, pts[:, 0], pts[:, 1], pts[:, 2], band=1.0, z_link=1.0, s_link=5.0, min_span=8.0,
                             max_rms=0.2)[0]

    spans = [sp for sp in spans_of(np.vstack([wire, crown])) if sp.rms <= 0.2 and sp.s_to - sp.s_from >= 8.0]
    assert spans and max(sp.offset_rms for sp in spans) > WIRE_LATERAL_RMS_M  # the crown's scatter
    assert all(thin_across(sp) for sp in spans)
    se = rng.uniform(0, L, 150)
    edge = np.column_stack([se, rng.uniform(-0.5, 0.5, 150), catenary(se, z0, 30.0, c) + rng.normal(0, 0.05, 150)])
    assert not any(thin_across(sp) for sp in spans_of(edge))


def test_a_line_between_a_ribbons_phases_settles_on_its_own_wire():
    """A Hough line drawn between a 0.4 m ribbon's phases (ribbon04 seed 10) drifts 0.25 m off its
    wire over 500 m (under band_m) and holds pieces of the next phase: the spans of its main wire
    settle it at a quarter band_m; the other phase's pieces, trending the other way, do not."""
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.plan_geometry import main_wire_spans, realign

    slope = -0.0005  # the main wire's offset, 0.1 m at s = 0, across the line along it
    main = [Span(0, 0, k, s0 + 50.0, 900.0, 10.0, s0, s0 + 100.0, 0.03, 200, 1.4, 0.1, slope, 0.03)
            for k, s0 in enumerate(range(0, 500, 100))]
    other = [Span(0, 1, k, s0 + 50.0, 900.0, 10.0, s0, s0 + 60.0, 0.03, 60, 0.5, 0.4, 0.001, 0.03)
             for k, s0 in enumerate((0, 200))]
    assert main_wire_spans(main + other, 0.2) == main
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 500.0)]
    lines = {"conductors": gpd.GeoDataFrame({"conductor": [0], "azimuth_deg": [90.0]},
                                            geometry=[LineString([(0, 0), (500, 0)])]),
             "conductor_segments": gpd.GeoDataFrame({"conductor": [0]}, geometry=[LineString([(0, 0), (500, 0)])])}
    params = {"max_rms_3d_m": 0.2, "s_min_m": 8.0, "band_m": 0.4}
    assert realign(lines, geo, main, params, 1.0)[2] == 0  # within band_m: the band holds its wire
    lines2, geo2, n = realign(lines, geo, main_wire_spans(main + other, 0.2), params, 1.0, min_drift_m=0.1)
    assert n == 1
    for (x, y) in lines2["conductors"].geometry[0].coords:  # on the main wire at both ends
        assert abs(y - (0.1 + slope * x)) < 0.01


def test_a_line_crosses_where_its_wire_points_reach_past_its_hough_extent():
    """Line B's Hough segment stops 7 m short of line A (mobile_dist_far seed 10: its wire seen
    again near its pole, taken by the growth); its wire points reach over A: the crossing is
    there. Without them it is not."""
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.stages.layers import crossings_layer

    cond = gpd.GeoDataFrame({"conductor": [0, 1]}, geometry=[LineString([(0, 0), (100, 0)]),
                                                             LineString([(50, -40), (50, -7)])])
    segs = gpd.GeoDataFrame({"conductor": np.array([], np.int64)}, geometry=gpd.GeoSeries([]))
    assert len(crossings_layer(cond, segs, "extent", 1.0)) == 0
    reach = [None, (np.array([50.0, -40.0]), np.array([50.0, 3.0]))]
    got = crossings_layer(cond, segs, "extent", 1.0, wire_reach=reach)
    assert len(got) == 1 and got.geometry[0].distance(gpd.points_from_xy([50.0], [0.0])[0]) < 1e-6


def test_wire_points_on_a_found_support_carry_a_line_to_it_not_past_it():
    """Line B ends at a pole found 0.35 m short of line A, its wire points reaching over the pole's
    top (mobile_stacked seed 1): A passes beside the pole, no crossing. With the pole 0.33 m past
    A (mobile_stacked seed 9) B's wire runs over A to it: a crossing."""
    from shapely.geometry import LineString
    from toolbox_plugins.powerlines.core import Pylon
    from toolbox_plugins.powerlines.stages.layers import crossings_layer

    def pole(x, y):
        return Pylon(x, y, 11.0, 3, 90.0, np.array([0]), (x - 0.5, y - 0.5, 1.0, 1, 1), kind="pole")

    cond = gpd.GeoDataFrame({"conductor": [0, 1]}, geometry=[LineString([(0, 0), (100, 0)]),
                                                             LineString([(50, -40), (50, -3)])])
    segs = gpd.GeoDataFrame({"conductor": np.array([], np.int64)}, geometry=gpd.GeoSeries([]))
    past = [None, (np.array([50.0, -40.0]), np.array([50.0, 0.05]))]
    assert len(crossings_layer(cond, segs, "extent", 1.0, found=[pole(50.0, -0.35)], wire_reach=past)) == 0
    over = [None, (np.array([50.0, -40.0]), np.array([50.0, 0.4]))]
    got = crossings_layer(cond, segs, "extent", 1.0, found=[pole(50.0, 0.33)], wire_reach=over)
    assert len(got) == 1 and got.geometry[0].distance(gpd.points_from_xy([50.0], [0.0])[0]) < 1e-6


def test_a_crown_wider_than_a_pole_over_a_bare_gap_is_no_pylon_a_lattice_or_a_sparse_pole_is():
    """Two wires of a line 7.5 m up end at the edge of a crown as tall (comm4_d5 seed 9: their
    pieces lost in it): under its line, as high as its wires, a column where spans end; only its
    points, none below 3.5 m of its 8 over a body wider than a pole, tell it from a support. A
    lattice on the same spot reaches the ground, and a pole's few points may leave its foot bare."""
    from toolbox_plugins.powerlines.core import find_pylons

    rng = np.random.default_rng(5)
    r, a = 1.3 * np.sqrt(rng.uniform(0, 1, 3000)), rng.uniform(0, 2 * np.pi, 3000)
    crown = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(3.5, 8.0, 3000)])
    t = np.linspace(0.0, 1.0, 160)
    legs = [np.column_stack([sx * (1.95 - 0.4 * t), sy * (1.95 - 0.4 * t), 8.0 * t]) for sx in (-1, 1) for sy in (-1, 1)]
    u = np.linspace(-1.5, 1.5, 60)
    braces = [np.column_stack([u, np.full(60, v), np.full(60, 8.0)]) for v in (-1.5, 1.5)] + \
        [np.column_stack([np.full(60, v), u, np.full(60, 8.0)]) for v in (-1.5, 1.5)]
    lattice = np.vstack(legs + braces)
    pole = np.column_stack([rng.normal(0, 0.05, 10), rng.normal(0, 0.05, 10), np.linspace(4.2, 8.0, 10)])
    ends, span_lines = [], []
    for sign in (-1.0, 1.0):
        e0, e1 = np.array([sign * 1.8, 0.0]), np.array([sign * 60.0, 0.0])
        ends += [e0, e1]
        span_lines.append((e0, e1))
    ends, end_hag = np.array(ends), np.full(len(ends), 7.5)
    lines_xy = [(np.array([-60.0, 0.0]), np.array([60.0, 0.0]))]
    s = np.r_[np.arange(-60.0, -1.8, 0.3), np.arange(1.8, 60.0, 0.3)]
    args = dict(span_lines=span_lines, max_rugged=1.0, wire_xyh=(s, np.zeros(len(s)), np.full(len(s), 7.5)))

    def found(p, **kw):
        return find_pylons(p[:, 0], p[:, 1], p[:, 2], ends, end_hag, [0.0], lines_xy, **{**args, **kw})

    assert found(crown) == []
    assert len(found(crown, reach_down_share=1.0, min_axis_share=0.0)) == 1
    assert found(crown, reach_down_share=1.0) == []  # its points spread off one axis, too
    got = found(lattice)
    assert len(got) == 1 and np.hypot(got[0].x, got[0].y) <= 1.0 and len(got[0].cells) > 4
    got = found(pole)
    assert len(got) == 1 and np.hypot(got[0].x, got[0].y) <= 1.0


def test_a_bush_under_a_ribbon_with_wire_points_left_over_it_is_no_tower_passed_through():
    """A bush 2.3-5.2 m tall under a ribbon 10 m up, 18 of the wires' points over it left on no
    wire (ribbon04 seed 9): tall, a column, reaching down, under its lines; only the 4.8 m gap
    between the bush and the points over it says no body holds the wires. A sparse pole's few
    points leave such gaps (distribution seed 4: 3.2 m): under its gap stands no more than a pole."""
    from toolbox_plugins.powerlines.core import find_towers_passed_through

    rng = np.random.default_rng(9)
    r, a = 1.5 * np.sqrt(rng.uniform(0, 1, 400)), rng.uniform(0, 2 * np.pi, 400)
    bush = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(2.3, 5.2, 400)])
    left = np.column_stack([np.tile(np.linspace(-1.5, 1.5, 6), 3), np.repeat([-0.4, 0.0, 0.4], 6),
                            rng.uniform(10.0, 10.1, 18)])
    pts = np.vstack([bush, left])
    s = np.r_[np.arange(-60.0, -1.8, 0.3), np.arange(1.8, 60.0, 0.3)]
    wx, wy = np.tile(s, 3), np.repeat([-0.4, 0.0, 0.4], len(s))
    wh = np.full(len(wx), 10.05)
    lines_xy = [(np.array([-60.0, o]), np.array([60.0, o])) for o in (-0.4, 0.0, 0.4)]

    def found(**kw):
        return find_towers_passed_through(pts[:, 0], pts[:, 1], pts[:, 2], wx, wy, wh, [0.0] * 3, lines_xy,
                                          max_rugged=1.0, **kw)

    assert found() == []
    got = found(max_gap_m=10.0)
    assert len(got) == 1 and len(got[0].cells) > 4
    pole = np.column_stack([rng.normal(0, 0.05, 11), rng.normal(0, 0.05, 11),
                            [1.4, 2.2, 2.6, 5.8, 6.1, 6.3, 7.1, 7.4, 8.0, 8.0, 8.4]])
    pts = np.vstack([pole, np.column_stack([left[:, :2], np.full(18, 8.0)])])  # its arm's points
    wh = np.full(len(wx), 8.0)
    got = found()
    assert len(got) == 1 and np.hypot(got[0].x, got[0].y) <= 1.0

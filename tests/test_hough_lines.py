"""hough-lines: the taichi accumulator against its numpy reference (vote for vote), peaks, validation, merging, the raster route and the CLI."""
import json

import geopandas as gpd
import numpy as np
import pytest
from pl_helpers import corridor  # noqa: F401 (fixtures)
from toolbox_plugins.hough_lines import core as hough
from toolbox_plugins.hough_lines import kernels as hough_kernels
from toolbox_plugins.hough_lines import reference

import toolbox
from toolbox import kernels


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



@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
def test_accumulator_too_big_is_a_clear_error(corridor, tmp_path, cli):
    r = cli("run", "hough-lines", corridor, "-o", tmp_path / "h.gpkg", "--set", "rho_step_m=0.001",
            "--set", "theta_step_deg=0.001", "--set", "tile_size_m=0")
    assert r.returncode == 2
    assert "accumulator needs" in r.stderr and "GiB" in r.stderr and "rho_step_m" in r.stderr
    assert not (tmp_path / "h.gpkg").exists()
    r = cli("run", "hough-lines", corridor, "-o", tmp_path / "h.gpkg", "--set", "overlap_m=200")
    assert r.returncode == 2 and "overlap_m" in r.stderr



@pytest.mark.xdist_group("corridor")  # one worker makes the session's corridor and its run
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

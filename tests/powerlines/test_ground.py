"""Stage 1 of the power-line chain, ground and candidates: the height window, the surface density, the eigenvalue shape test (linear, planar, rugged, steep), ribbons and tubes."""



import numpy as np
import pytest
from pl_helpers import _bundle
from toolbox_plugins.powerlines.core import (
    local_surface_density,
    shape_classes,
)


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
    top = height_window_top(xyz[:, 2], xyz, link_m=2.5)  # the method's V_max
    assert 38.0 <= top <= 39.5
    assert np.percentile(xyz[:, 2], 99.95) + 1 < 37.0  # what the percentile alone kept
    assert height_window_top(np.r_[low, bird][:, 2], np.r_[low, bird], link_m=2.5) < 30.0



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
    from toolbox_plugins.powerlines.core import is_ribbon

    stacks = walls = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        s = rng.uniform(0, 10, (4, 15))
        pts = [np.column_stack([s[k], rng.normal(0, 0.03, 15), 0.3 * k + 0.05 * s[k] + rng.normal(0, 0.02, 15)])
               for k in range(4)]
        stacks += is_ribbon(np.vstack(pts), 0.05, 0.4, 0.05)
        for density in (5, 10):
            n = 40 * density  # 10 m x 4 m
            roof = np.column_stack([rng.uniform(0, 10, n), rng.uniform(0, 4, n), 0.3 * rng.uniform(0, 4, n)])
            wall = np.column_stack([rng.uniform(0, 10, n), rng.normal(0, 0.03, n), rng.uniform(0, 3, n)])
            walls += is_ribbon(roof, 0.05, 0.4, 0.05) + is_ribbon(wall, 0.05, 0.4, 0.05)
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

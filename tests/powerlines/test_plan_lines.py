"""Stage 2, plan lines and the 3D step: catenary fits, spans split and cut, wires peeled, bundles and ribbons split, twin lines."""



import numpy as np
import pytest
from pl_helpers import _bundle, _earth_wire_scene, _line_between, _ribbon_points
from toolbox_plugins.powerlines.core import (
    catenary,
    conductors_3d,
    fit_catenary,
    kink_cut,
    line_fit,
    parabola_fit,
    peel_catenaries,
    split_bundles,
    split_spans,
    twin_lines,
    two_means_1d,
)


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



@pytest.mark.parametrize("shape", ["triangle", "square"])
def test_bundle_split_separates_sub_conductors_across_and_in_height(shape):
    """A triangle (0.4 m) and a square (0.6 m) bundle, one connected piece each: split across the
    line and in height (about a running mean: the span sags 0.5 m) into one piece per
    sub-conductor; without heights only the side-by-side cut is possible."""
    rng = np.random.default_rng(5)
    offsets = {"triangle": [(-0.2, 0.0), (0.2, 0.0), (0.0, 0.35)],
               "square": [(-0.3, 0.0), (0.3, 0.0), (-0.3, 0.6), (0.3, 0.6)]}[shape]
    s, off, z, label = _bundle(rng, offsets)
    lab = split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z)
    assert len(np.unique(lab)) == len(offsets)
    for k in np.unique(lab):  # each piece one sub-conductor's points, all of them
        assert len(np.unique(label[lab == k])) == 1
    assert len(np.unique(split_bundles(s, off, np.zeros(len(s), np.int64), 20))) < len(offsets)



@pytest.mark.parametrize("n_wires, spacing", [(3, 0.3), (4, 0.3), (3, 0.4)])
def test_bundle_split_separates_a_ribbon_of_three_or_four_wires(n_wires, spacing):
    """A ribbon's phases side by side at one height, one connected piece: no cut in two is clean
    (one side holds two wires, as wide as a crown's layer), a cut into one group per wire is."""
    rng = np.random.default_rng(2)
    offsets = [((k - (n_wires - 1) / 2) * spacing, 0.0) for k in range(n_wires)]
    s, off, z, label = _bundle(rng, offsets)
    lab = split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z)
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
    lab = split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z)
    for k in (0, 1):  # each of the two long phases nearly whole in a piece of its own
        mine = lab[label == k]
        main = np.bincount(mine).argmax()
        assert np.mean(mine == main) >= 0.97 and np.mean(label[lab == main] == k) >= 0.97



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
    from toolbox_plugins.powerlines.core import windowed_groups

    rng = np.random.default_rng(5)
    s, off, label = [], [], []
    for k, (o, hi) in enumerate([(0.0, 300.0), (0.4, 300.0), (-0.4, 80.0)]):
        sk = rng.uniform(0.0, hi, int(2.0 * hi))
        s.append(sk), off.append(o + 0.3 * np.sin(sk / 300.0 * 2 * np.pi) + rng.normal(0, 0.04, len(sk)))
        label.append(np.full(len(sk), k))
    s, off, label = np.concatenate(s), np.concatenate(off), np.concatenate(label)
    g = windowed_groups(s, off, 20, 0.25, 0.15, 50.0)
    assert g is not None
    for k in range(3):
        main = np.bincount(g[label == k]).argmax()
        assert np.mean(g[label == k] == main) >= 0.97 and np.mean(label[g == main] == k) >= 0.97
    crown = rng.uniform([120.0, -1.0], [160.0, 1.0], (400, 2))
    assert windowed_groups(np.r_[s, crown[:, 0]], np.r_[off, crown[:, 1]], 20, 0.25, 0.15, 50.0) is None



def test_bundle_split_leaves_a_wire_with_a_crown_under_it():
    """A wire with a crown's scatter linked to it from below: bimodal in height, but the crown's
    layer is wider than a wire (pooled spread over WIRE_LATERAL_RMS_M): not cut."""
    rng = np.random.default_rng(2)
    s, off, z, _ = _bundle(rng, [(0.0, 0.0)])
    crown = rng.uniform([10, -1, 0], [40, 1, 1], (300, 3))
    s = np.r_[s, crown[:, 0]]
    off = np.r_[off, crown[:, 1]]
    z = np.r_[z, catenary(crown[:, 0], 20.0, 30.0, 900.0) - 1.0 - crown[:, 2]]
    assert len(np.unique(split_bundles(s, off, np.zeros(len(s), np.int64), 20, z=z))) == 1



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



def test_a_span_records_how_thin_its_points_are_across_the_line():
    """A wire's lateral scatter about its straight plan trend is what the 3D validation tests
    (WIRE_LATERAL_RMS_M): a drifting but thin wire passes, a crown edge's spread does not."""
    from toolbox_plugins.powerlines.core import WIRE_LATERAL_RMS_M, make_span

    rng = np.random.default_rng(3)
    s = np.sort(rng.uniform(0, 30, 200))
    fit = (10.0, 15.0, 300.0, 0.03)
    thin = make_span(0, 0, 0, s, 0.2 + 0.01 * s + rng.normal(0, 0.04, len(s)), fit)  # drifts 0.3 m, 4 cm scatter
    assert thin.offset_slope == pytest.approx(0.01, abs=0.002) and thin.offset_rms == pytest.approx(0.04, abs=0.008)
    assert thin.offset_rms <= WIRE_LATERAL_RMS_M
    wide = make_span(0, 0, 0, s, rng.uniform(-0.6, 0.6, len(s)), fit)  # spread over 1.2 m: rms 0.35
    assert wide.offset_rms > WIRE_LATERAL_RMS_M



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



@pytest.mark.parametrize("seed", range(5))
def test_two_means_split_is_the_best_cut(seed):
    """The bundle splitter's 1D two-means: the cut of least within-group sum of squares among
    all cuts leaving min_size values on each side (checked by trying every cut)."""
    rng = np.random.default_rng(seed)
    r = np.r_[rng.normal(0, 0.05, 40 + 10 * seed), rng.normal(0.3 + 0.1 * seed, 0.05, 60)]
    rng.shuffle(r)
    upper, c0, c1, sd = two_means_1d(r, 20)
    v = np.sort(r)
    costs = [((v[:k] - v[:k].mean()) ** 2).sum() + ((v[k:] - v[k:].mean()) ** 2).sum() for k in range(20, len(v) - 19)]
    k = 20 + int(np.argmin(costs))
    assert upper.sum() == len(v) - k and r[upper].min() >= r[~upper].max()
    assert c0 == pytest.approx(v[:k].mean()) and c1 == pytest.approx(v[k:].mean())
    assert sd == pytest.approx(np.sqrt(min(costs) / len(v)))
    assert two_means_1d(r[:39], 20) is None  # too few for two groups of 20



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

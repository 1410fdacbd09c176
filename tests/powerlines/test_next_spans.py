"""Stage 5, next spans: a wire's next catenary past its last support, gaps bridged."""



import numpy as np
import pytest
from pl_helpers import _bridge_scene, _next_span_scene
from toolbox_plugins.powerlines.core import (
    catenary,
    fit_catenary,
)


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
    from toolbox_plugins.powerlines.core import bridge_gaps, make_span

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
        spans = [make_span(0, 0, i, q[:, 0], q[:, 1], fit_catenary(q[:, 0], q[:, 2]), z=q[:, 2]) for i, q in enumerate((a, b))]
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

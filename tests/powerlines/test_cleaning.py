"""Stage 8, cleaning: foliage around a wire's curve, points off a span's trend, lines in or along a surface."""



import numpy as np
import pytest
from toolbox_plugins.powerlines.core import (
    catenary,
    fit_catenary,
)


def test_foliage_on_a_wires_catenary_is_not_wire_its_own_scatter_is():
    """A wire through a crown: the crown's points within the catenary's height tolerance are
    linked to its piece. The span's plan trend and lateral tolerance come from the points on the
    catenary, robustly (the foliage neither pulls nor widens them), and a point farther across
    than that with other points off the ground around it is foliage; a wire point as far off with
    nothing around it (a swinging span's tail) stays wire."""
    from toolbox_plugins.powerlines.core import WIRE_LATERAL_FLOOR_M, make_span, off_their_spans

    rng = np.random.default_rng(7)
    s_w = np.sort(rng.uniform(0, 60, 600))
    off_w = 0.1 + rng.normal(0, 0.02, len(s_w))
    z_w = catenary(s_w, 10.0, 30.0, 600.0) + rng.normal(0, 0.02, len(s_w))
    # a crown's branch over 10-13 m along the line: 1.2 m across, 0.6 m in height about the wire
    crown = rng.uniform([10.0, -0.5, -0.3], [13.0, 0.7, 0.3], (300, 3))
    crown[:, 2] += catenary(crown[:, 0], 10.0, 30.0, 600.0)
    s, off, z = np.r_[s_w, crown[:, 0]], np.r_[off_w, crown[:, 1]], np.r_[z_w, crown[:, 2]]
    sp = make_span(0, 0, 0, s, off, fit_catenary(s, z), z=z)
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
    from toolbox_plugins.powerlines.core import in_foliage, make_span

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
    sp = make_span(0, 0, 0, pts[:, 0], pts[:, 1], fit_catenary(pts[:, 0], pts[:, 2]), z=pts[:, 2])
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
    from toolbox_plugins.powerlines.core import SURFACE_CONTRAST, WIRE_ID_BASE, in_a_surface, make_span

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
        spans.append(make_span(li, k, 0, w[:, 0], w[:, 1], fit_catenary(w[:, 0], w[:, 2]), z=w[:, 2]))
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
    from toolbox_plugins.powerlines.core import WIRE_ID_BASE, along_a_surface, make_span

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
        spans.append(make_span(li, 0, 0, w[:, 0], w[:, 1], fit_catenary(w[:, 0], w[:, 2]), z=w[:, 2]))
    pts = np.vstack(wires)
    line_of = np.concatenate([np.full(len(w), li) for li, w in enumerate(wires)])
    wire_of = np.zeros(len(pts), np.int64)
    around = np.vstack([pts] + clutter)
    around_wire = np.r_[line_of * WIRE_ID_BASE, np.full(len(around) - len(pts), -1)]
    got = along_a_surface(spans, lines, pts[:, 0], pts[:, 1], pts[:, 2], line_of, wire_of, 0.2, around, around_wire)
    assert got == {0, 1}, got

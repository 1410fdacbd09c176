"""The wire-set operations the stages share: a further pass's lines folded into the first's, stubs folded, lines along one another."""



import geopandas as gpd
import numpy as np
import pytest
from toolbox_plugins.powerlines.core import (
    catenary,
)


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



def test_a_second_pass_line_along_a_found_one_is_not_another_conductor():
    from toolbox_plugins.powerlines.wire_sets import runs_along

    h = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, 100.0)
    d = np.array([np.cos(np.radians(0.3)), np.sin(np.radians(0.3))])
    assert runs_along((np.array([20.0, 0.1]), d, 0.0, 30.0), h, 0.4)  # the rest of its points
    assert not runs_along((np.array([20.0, 0.6]), d, 0.0, 30.0), h, 0.4)  # a conductor beside it
    bend = np.array([np.cos(np.radians(4.0)), np.sin(np.radians(4.0))])
    assert not runs_along((np.array([100.0, 0.0]), bend, 0.0, 40.0), h, 0.4)  # past a bend



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

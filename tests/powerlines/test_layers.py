"""Stage 10, layers: the crossings (the host's, with the power lines' rule at supports), circuit ends and reach, crossing scores."""



import geopandas as gpd
import numpy as np
from pl_helpers import crossings_at_supports
from toolbox_plugins.powerlines.evaluation import false_crossings

from toolbox.crossings import crossings


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

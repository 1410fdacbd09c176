"""The thresholds of the power-line chain's decisions, one record per decision (``Rules`` holds one
of each for a run: ``settings.Rules``). Each record's function documents what every field does;
where the values came from is in docs/powerlines.md (the section ``Rules`` names beside each).
Plain records with no numeric library, so the plugin's declaration reads its defaults from here
without importing the chain."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# a wire is thin across its line: its points' lateral rms about a straight plan trend (ALS and
# mobile scans alike: 0.04-0.1 m; a crown's edge lined up along a street is wider)
WIRE_LATERAL_RMS_M = 0.15

# the least distance across the line at which the 3D step tells side-by-side wires apart (a
# triangle bundle's 0.2 m stays one piece, a ribbon's 0.3 m does not)
SIDE_BY_SIDE_MIN_GAP_M = 0.25

# below this core-to-ring contrast (1.5 times a surface's 7) a line's points are a surface's
SURFACE_CONTRAST = 10.5

# the method's V_max, and how many median point spacings along a wire a gap may span before it
# ends a run: 2.5 m is about 10 spacings on 10 pts/m2 ALS (and 36 on the method's 228 pts/m2), so
# surveys as dense or denser keep the method's value and sparser ones scale it
V_MAX_METHOD_M = 2.5
GAP_SPACINGS = 10.0
STANDS_CLEAR_MAX = 0.5  # other points within 0.5 m of a sparse second-pass wire's points, on average
STANDS_CLEAR_RADIUS_M = 0.5
SETTLE_DRIFT_M = 0.02  # a plan line's drift off its wires' trend that its output is turned for
# a tower found this close to a pole is the pole's (its span ends and a crown beside it)
POLE_TAKES_M = 6.0
# how far a pole's footprint reaches from its base at most (its cross arms, on the 1 m search
# grid); a lattice tower's reaches 4-8 m
POLE_FOOTPRINT_M = 3.0
# a pole's column: within this of its base in plan (its radius and a street scan's lean of the
# base towards the scanner) and more than POLE_HEAD_M under its top (its arms and top insulator)
POLE_CORE_M = 0.3
POLE_HEAD_M = 1.0
# how far from a wire's points a point alone in the air is still taken for its: the closest two
# wires of a line hang on their supports (a ribbon's or a joint-use pole's cables, 0.3-0.5 m)
ALONE_REACH_M = 0.5
# at most this many others within ALONE_AROUND_M of a point alone in the air: a dense scan's
# crown points near a wire hold more (Oakland: most 20 or more)
ALONE_AROUND_M = 1.0
ALONE_MAX_AROUND = 8
# tan 1 deg: a span runs along its line within 1 deg of it (as runs_along's lines)
ALONG_SLOPE_MAX = 0.01746
MIN_CANDIDATES = 10  # fewer candidates than this: no wire can be there (a field, a road)
MIN_SECOND_PASS = 100  # wire-like points left on no wire that make a second pass worth its time
GROW_FROM_M = 1.0  # spans grow into, and the cleaning looks at, points this far off the ground
# the layers stage warns that the top-hat threw the wires away (the AHN4 case: conductors side by
# side closer than the mask cell) when it kept under 15 % of 200 or more linear candidates
TOPHAT_WARN_MIN_LINEAR = 200
TOPHAT_WARN_SHARE = 0.15
# the towers' share of the height where the spans ending at them are attached (the user's
# pylon_top_share): a tower reaches its lowest attachment's height, its peak holds the earth wire
PYLON_TOP_SHARE = 0.8
# a wire in its cross-section: its core within 0.1 m, the ring around it 0.2-0.5 m out (its
# sub-conductors and the next phase sit at a few places there; a crown or a wall fills it)
CORE_M = 0.1
RING_FROM_M = 0.2
RING_TO_M = 0.5
# a wire is a concentration of points: at least 4 times denser within 0.1 m than 0.2-0.5 m around
# (a crown's points that happen to line up are not; a next span's points are)
WIRE_CONTRAST = 4.0
# a point alone in the air beside a wire: at most 2 others within 0.4 m, taken over 3 rounds
ALONE_NEAR_M = 0.4
ALONE_MAX_NEAR = 2
ALONE_ROUNDS = 3


@dataclass(frozen=True)
class CandidateRules:
    """The ground stage's candidates: the top of the height window (``height_window_top``), the
    surface density around them (``local_surface_density``) and the eigenvalue shape test
    (``shape_classes``, with ``ribbons`` and ``tubes``); their docstrings say what each does. The
    four the user may set are the plugin's parameters' defaults (neighbours, rugged_share,
    planar_share, density_radius_m)."""

    # the eigenvalue shares that stand in for the method's planar/rugged pre-classification
    # (METHODS.md §1; the user's neighbours, rugged_share and planar_share)
    neighbours: int = 12
    rugged_share: float = 0.04
    planar_share: float = 0.2
    # a linear neighbourhood whose axis rises over 0.7 (35 degrees) is a pole's or a leg's
    max_axis_slope: float = 0.7
    # the window's top: above the 99.95th percentile only points with 2 others within V_max count
    # (an earth wire over a stack, a tower top; a bird or a lone return has none)
    window_quantile: float = 99.95
    window_min_links: int = 2
    # the survey's surface density within 200 m of a point (strips, overlaps and a mobile scan's
    # falling range count where they are), on 1 m cells
    density_radius_m: float = 200.0
    density_cell_m: float = 1.0
    # a ribbon (phases side by side): bands of 0.05 m bins, each at most 0.4 m wide, bins under 5 %
    # of the fullest empty (a cross arm joins them at a pole); sets of 20 points or more, judged in
    # 10 m pieces where linked to a crown
    ribbon_bin_m: float = 0.05
    ribbon_max_band_m: float = 0.4
    ribbon_floor_share: float = 0.05
    min_set_points: int = 20
    piece_m: float = 10.0
    # a bundle (sub-conductors 0.4-0.6 m apart): within 1 m across and in height over 5 m
    tube_max_width_m: float = 1.0
    tube_min_length_m: float = 5.0


CANDIDATES = CandidateRules()


@dataclass(frozen=True)
class SpanCutRules:
    """Where a wire is cut into spans (``split_spans``, ``kink_cut``; their docstrings say how)."""

    # slopes from least-squares lines over 10 m each side; a drop in slope of 0.02 is an
    # attachment, 0.005 when one catenary does not fit the piece (looked at again, more sensitively)
    window_m: float = 10.0
    min_drop: float = 0.02
    fine_min_drop: float = 0.005
    # a rise in slope beyond what the slackest wire gives (catenary parameter 100 m) is a kink too:
    # a span climbing an embankment from a pole at its foot
    min_c_m: float = 100.0
    # two parabolas a cut apart (cuts 1 m apart) must fit 1.5 times better than one
    kink_step_m: float = 1.0
    kink_min_gain: float = 1.5


SPAN_CUTS = SpanCutRules()


@dataclass(frozen=True)
class SurfaceRowRules:
    """A span in a surface (``span_on_surface``, ``pieces_on_surfaces``): a roof's scan row or an
    eave, seen by a mobile scanner as a thin straight line (docs/powerlines.md, "Not wires:
    surfaces, crowns lined up")."""

    # the cross-section within 2 m of the span; a surface's line: points within 0.1 m of it fill
    # every 0.25 m bin out to 1.5 m on one side (four wires 0.4 m apart span 1.2 m with gaps),
    # each along 0.3 of the span (a pole or a cross arm holds a few metres of it, not a third)
    reach_m: float = 2.0
    line_m: float = 0.1
    bin_m: float = 0.25
    min_run_m: float = 1.5
    min_cover: float = 0.3
    # directions up to 70 degrees off level either way (90: a wall's side whose top edge is the span)
    max_tilt_deg: float = 70.0
    # a span's own points (within 0.15 m across: a wire's lateral rms) in pieces cut at 2 m gaps,
    # each in a surface of its own (a short wire along the top edges of two roofs a street apart)
    piece_gap_m: float = 2.0
    piece_lateral_m: float = 0.15
    # a wall seen from the side under the span (its top edge): 70-90 degrees down, dense down its
    # scan lines, every 0.1 m filled for a metre (wires stacked 0.3 m apart leave gaps)
    wall_min_tilt_deg: float = 70.0
    wall_max_tilt_deg: float = 90.0
    wall_bin_m: float = 0.1
    wall_run_m: float = 1.0


SURFACE_ROWS = SurfaceRowRules()


@dataclass(frozen=True)
class StraightRunRules:
    """Straight 3D runs (``straight_wires``): wires seen over a few metres, whose sag there is
    millimetres; and those leading from a found pole (``wires_from_poles``), docs/powerlines.md
    "Wires too short for the Hough: short wires, pole wires"."""

    # points within 8 cm of the line, 12 or more, rising at most 0.5 (steeper is a pole); 300
    # RANSAC draws per set
    tol_m: float = 0.08
    min_points: int = 12
    max_slope: float = 0.5
    n_samples: int = 300
    # from a pole: the nearer end within 5 m of its axis in plan, continued toward it passing within
    # 1.8 m of the axis (a cross arm's reach); on average at most 0.5 other points around its points
    pole_reach_m: float = 5.0
    pole_head_m: float = 1.8
    pole_max_around: float = 0.5
    # the runs beside a found one (a stack's other wires) need 8 points, half its length
    stack_min_points: int = 8


STRAIGHT_RUNS = StraightRunRules()


@dataclass(frozen=True)
class TowerShapeRules:
    """A tower's body (``axis_share``, ``_base_cells``, ``pylon_points``) and its arms
    (``arm_lines``), docs/powerlines.md "Towers and poles"."""

    # a pole is one thin column: the share of the points within 2 m in plan, from 3 m over the
    # ground to 1.5 m under its top (under the arms), within 0.5 m of one vertical
    axis_radius_m: float = 2.0
    axis_m: float = 0.5
    axis_low_m: float = 3.0
    axis_head_m: float = 1.5
    # the base leaves out the cells without structure more than 2.5 m from the column along the
    # line (within 30 degrees of it): a stack of wires running off a pole's top
    base_reach_m: float = 2.5
    base_along_deg: float = 30.0
    # a tower's points hang together from its top down: below a gap of 2 m stand fences and bushes
    max_gap_m: float = 2.0
    # a pole's points: its column and its head, within its head reach of the axis from 1 m under its
    # top (cross arms, insulators) to 0.3 m over it
    head_depth_m: float = 1.0
    head_over_m: float = 0.3
    # a tower's points and its search: from 1 m over the ground (foundations and what the ground
    # filter leaves under a tower are not the tower)
    from_ground_m: float = 1.0
    # a cell's top is its highest point with another within 5 m under it (a far pole's few points lie
    # 2-3 m apart), not a stray point over it (a bird, noise the ground filter left)
    top_held_m: float = 5.0
    # a pole's arm is a cross arm of a metre or two (the wires leaving it across the street are
    # wires); an arm's both ends lie within the support's reach and a metre
    pole_arm_m: float = 1.5
    arm_margin_m: float = 1.0
    # a short line crossing a longer one at a tower at 45 degrees or more is its arm
    arm_min_angle_deg: float = 45.0


TOWER_SHAPE = TowerShapeRules()


@dataclass(frozen=True)
class SpanPointRules:
    """Which points are a fitted span's (``points_on_spans``, the 3D step's ``_pick_up``,
    ``off_their_spans``, ``bridge_gaps``) and the stack and clump tests of the span searches
    (``_stacked_at``, ``_clumped``), docs/powerlines.md "Each wire's points: grown, foliage taken
    off" and "Phases too sparse to find alone, stacks, next spans, gaps"."""

    # a point is on a span within 0.25 m of its plan position (the shape test's leftovers next to a
    # pole top) and within 0.5 m inside the 3D step's own band (a sub-conductor seen a few times)
    on_span_m: float = 0.25
    pick_up_m: float = 0.5
    # a flat or rough candidate is a span's point right on it only: within 0.1 m (a ribbon's phases
    # or a crown shared its neighbourhood)
    on_span_flat_m: float = 0.1
    # a wire point off its trend is foliage where another point off the ground is within 0.3 m
    # (the span at its position taken within 0.5 m of the span's extent)
    clutter_m: float = 0.3
    clutter_margin_m: float = 0.5
    # another wire within 0.5 m in plan hangs over or under a span's end: a stack
    stack_across_m: float = 0.5
    # more than half a piece's points within one window: a pole's or a crown's blob
    clump_share: float = 0.5
    # one catenary over a gap is compared with the pieces' own every 0.5 m
    gap_sample_m: float = 0.5


SPAN_POINTS = SpanPointRules()


@dataclass(frozen=True)
class FitSearchRules:
    """The 3D step's searches inside a line's band (``conductors_3d``'s helpers, ``twin_lines``,
    ``split_bundles``), docs/powerlines.md "A conductor is a wire in 3D" and "Bundles and ribbons"."""

    # a sparse wire is its longest run with the band's points on its catenary where it hangs gently
    # (slope at most 0.5), and the wires 90 % of whose points lie on it
    sparse_max_slope: float = 0.5
    sparse_wire_share: float = 0.9
    # catenary hypotheses along the line: 8 draws per first point, the middle one within 0.3 m of
    # the chord (a sparse wire over a tree is a few percent of its band)
    triple_draws: int = 8
    triple_chord_m: float = 0.3
    # lines within 0.5 degrees of each other whose bands share a wire are twins (a ribbon's lines
    # drawn between its phases)
    twin_max_angle_deg: float = 0.5
    # a bundle's split repeated 3 times at most, heights about a running mean over
    # 5 m (a span's sag is smooth at that scale); wire trends refitted over 4 rounds, up to 4 groups
    bundle_depth: int = 3
    bundle_window_m: float = 5.0
    bundle_rounds: int = 4
    bundle_max_groups: int = 4
    # pieces chained across a gap by their end slopes over 10 m (a wire rises to a pole, falls after),
    # their ends' heights apart by the link tolerance and 2 cm per metre of gap
    chain_slope_window_m: float = 10.0
    chain_rise_per_m: float = 0.02
    # the catenary fit's robust (soft L1) scale: residuals beyond 0.1 m weigh less (a wire's points
    # fit within a few centimetres; a crown's point on its curve does not)
    fit_robust_scale_m: float = 0.1


FIT_SEARCH = FitSearchRules()


@dataclass(frozen=True)
class RobustFitRules:
    """Sample sizes of the robust line fits (``median_line_fit``: least median of squares,
    Rousseeuw 1984; the shape test's Theil-Sen slope): all pairs up to these, else that many drawn
    (seeded): sample sizes, trading time against the chance of drawing a good pair."""

    lms_max_pairs: int = 256
    lms_max_points: int = 512
    theil_sen_max_pairs: int = 4000


ROBUST_FIT = RobustFitRules()


@dataclass(frozen=True)
class CircuitRules:
    """Supports where circuits end unseen (the layers stage's ``circuit_ends`` and
    ``circuit_reach``), docs/powerlines.md "Crossings"."""

    # parallel conductors within 1 degree and 5 m across whose far ends lie within 1 m of one another
    # along them, over 5 m inside the data: the circuit ends at a pole the scan saw too little of
    max_angle_deg: float = 1.0
    ends_across_m: float = 5.0
    ends_along_m: float = 1.0
    edge_m: float = 5.0
    # a wire seen short of its sibling's end (within 3 m across) runs on to it, 1 to 5 m farther
    # (mobile_dist seed 5: 2 m short of the other line's pole)
    reach_across_m: float = 3.0
    reach_min_m: float = 1.0
    reach_max_m: float = 5.0


CIRCUITS = CircuitRules()


@dataclass(frozen=True)
class WireRules:
    """The thresholds of ``conductors_3d`` (its docstring says what each does; the stage gives
    ``max_rms`` from its parameters)."""

    min_points: int = 20
    max_rms: float = math.inf
    off_link: float = 0.25
    reach: float | None = None
    peel: bool = True
    min_piece: float | None = None


@dataclass(frozen=True)
class RibbonRules:
    """The thresholds of ``ribbon_lines`` (its docstring says what each does)."""

    min_gap_m: float = SIDE_BY_SIDE_MIN_GAP_M
    max_angle_deg: float = 0.5
    search_deg: float = 0.2
    step_deg: float = 0.005
    bin_m: float = 0.02
    peak_m: float = 0.06
    min_points: int = 20
    match_m: float = 0.05
    min_wires: int = 3
    min_share: float = 0.75


@dataclass(frozen=True)
class PeelRules:
    """The thresholds of ``peel_catenaries`` (its docstring says what each does)."""

    tol_m: float = 0.1
    lateral_tol_m: float = WIRE_LATERAL_RMS_M
    max_slope: float = 0.5
    n_samples: int = 2000
    max_tries: int = 32
    seed: int = 0


@dataclass(frozen=True)
class ShortWireRules:
    """The thresholds of ``short_wires`` (its docstring says what each does)."""

    max_around: float = 0.5
    reach_m: float = 5.0
    structure_m: float = 1.5
    stack_m: float = 1.5
    max_stack_deg: float = 10.0
    tol_m: float = 0.08


@dataclass(frozen=True)
class SiblingRules:
    """The thresholds of ``sibling_wires`` (its docstring says what each does)."""

    max_sep_m: float = 4.0
    max_dz_m: float = 3.0
    bin_m: float = 0.1
    tol_m: float = 0.15
    min_points: int = 12
    min_cover: float = 0.5
    cover_bin_m: float = 2.0
    max_rounds: int = 6
    max_around: float = 0.5
    plane_m: float = 0.16


@dataclass(frozen=True)
class GrowRules:
    """The thresholds of ``grow_span_ends`` (its docstring says what each does)."""

    lateral_m: float = 0.25
    column_m: float = 0.3
    column_dz_m: float = 1.0
    own_m: float = 4.0
    support_m: float = 2.0
    margin_m: float = 0.5
    stack_m: float = 1.5


@dataclass(frozen=True)
class NextSpanRules:
    """The thresholds of ``next_spans`` (its docstring says what each does; the stage gives
    ``reach_m`` from S_min)."""

    reach_m: float = 60.0
    min_points: int = 12
    lateral_m: float = 0.3
    max_step_m: float = 0.5
    max_rise_m: float = 3.0
    min_contrast: float = WIRE_CONTRAST
    max_rounds: int = 4


@dataclass(frozen=True)
class TowerRules:
    """The thresholds of ``find_pylons`` (its docstring says what each does; the values were set
    on the synthetic variant family and the AHN4 / Oakland files, docs/powerlines.md, "Tower rules and the scenes that set them")."""

    cell_m: float = 1.0
    reach_m: float = 12.0
    column_share: float = 0.5
    end_radius_m: float = 10.0
    max_side_m: float = 40.0
    min_ends: int = 2
    max_rugged: float = 0.7
    min_slenderness: float = 2.0
    under_line_m: float = 2.0
    max_side_ratio: float = 2.0
    along_deg: float = 10.0
    max_height_share: float = 1.5
    arm_m: float = 6.0
    reach_down_share: float = 0.35
    pole_area_m2: float = 4.0
    over_wires_share: float = 1.2
    over_wires_reach_down_share: float = 0.15
    min_axis_share: float = 0.25
    axis_area_m2: float = 12.0
    pair_apart_m: float = 1.5
    one_tower_m2: float = 100.0
    peak_reach_m: float = 5.0


TOWERS = TowerRules()


@dataclass(frozen=True)
class PairRules:
    """The thresholds of ``pole_pair`` (its docstring says what each does; ``find_pylons`` gives
    ``min_share`` and ``apart_m`` from its own ``min_axis_share`` and ``pair_apart_m``)."""

    min_share: float = 0.25
    apart_m: float = 1.5
    axis_m: float = 0.5
    low_m: float = 3.0
    head_m: float = 1.5
    second_share: float = 0.5
    min_points: int = 5
    min_rise_share: float = 0.5


@dataclass(frozen=True)
class PassedThroughRules:
    """The thresholds of ``find_towers_passed_through`` (its docstring says what each does; the values were set
    on the synthetic variant family and the AHN4 / Oakland files, docs/powerlines.md, "Tower rules and the scenes that set them")."""

    cell_m: float = 1.0
    reach_m: float = 12.0
    column_share: float = 0.5
    arm_m: float = 6.0
    max_above_m: float = 2.0
    max_side_m: float = 40.0
    max_rugged: float = 0.7
    min_slenderness: float = 2.0
    known_m: float = 10.0
    under_line_m: float = 2.0
    margin_m: float = 10.0
    max_side_ratio: float = 2.0
    insulator_m: float = 1.0
    reach_down_share: float = 0.5
    pole_area_m2: float = 4.0
    max_gap_m: float = 2.0
    wide_reach_down_share: float = 0.35


@dataclass(frozen=True)
class PoleRules:
    """The thresholds of ``find_poles`` (its docstring says what each does; the values were set
    on the synthetic variant family and the AHN4 / Oakland files, docs/powerlines.md, "Tower rules and the scenes that set them")."""

    radius_m: float = 0.25
    ring_m: float = 0.75
    window_m: float = 2.0
    min_thin_m: float = 2.5
    min_fill: float = 0.6
    wire_reach_m: float = 2.0
    end_radius_m: float = 10.0
    column_m: float = 0.45
    voxel_m: float = 0.05
    head_m: float = 1.8
    max_ring_share: float = 0.6
    # (named in passing in its docstring) a thin point's cylinder holds 6 voxels or more, and thin
    # points count from 1 m over the ground (the ground filter's leftovers and a pole's foot aside);
    # thin points within 0.3 m in plan are one column; the column's fill counted in 0.5 m layers;
    # its top where the points above its thin part first break by 1.5 m; its footprint on 0.1 m cells
    min_thin_voxels: int = 6
    from_ground_m: float = 1.0
    link_m: float = 0.3
    layer_m: float = 0.5
    top_break_m: float = 1.5
    footprint_cell_m: float = 0.1


@dataclass(frozen=True)
class FoliageRules:
    """The thresholds of ``in_foliage`` (its docstring says what each does)."""

    window_m: float = 1.0
    min_contrast: float = WIRE_CONTRAST
    min_sides: int = 5
    margin_m: float = 0.5


@dataclass(frozen=True)
class SurfaceRules:
    """The thresholds of ``in_a_surface`` (its docstring says what each does)."""

    min_contrast: float = SURFACE_CONTRAST
    reach_m: float = 1.5
    margin_m: float = 0.5


@dataclass(frozen=True)
class AlongSurfaceRules:
    """The thresholds of ``along_a_surface`` (its docstring says what each does)."""

    reach_m: float = 3.0
    inner_m: float = 0.5
    tol_m: float = 0.1
    slab_m: float = 0.5
    max_slope_deg: float = 60.0
    min_share: float = 0.7
    bin_m: float = 0.25
    min_fill: float = 0.7
    min_cover: float = 0.5
    min_points: int = 10
    margin_m: float = 0.5


@dataclass(frozen=True)
class Rules:
    """The thresholds of each decision of the chain, by stage. Each record's function documents
    what every field does; where the values came from is said beside each record. A stage passes
    its record to the core function, with the values it derives from the run given by name.
    (``PairRules`` is taken from ``towers`` by ``find_pylons``; ``PeelRules`` is the 3D fit's own.)"""

    # each record's values were set on the synthetic variant family, AHN4 and the Oakland scans; the
    # section of docs/powerlines.md named beside it says which scene set which value, and why

    # plan_lines, "A conductor is a wire in 3D" (the stage gives max_rms from max_rms_3d_m)
    wires: WireRules = field(default_factory=WireRules)
    # plan_lines, "Bundles and ribbons"
    ribbons: RibbonRules = field(default_factory=RibbonRules)
    # more_wires, "Wires too short for the Hough: short wires, pole wires"
    short_wires: ShortWireRules = field(default_factory=ShortWireRules)
    # more_wires and cleaning, "Phases too sparse to find alone, stacks, next spans, gaps"
    siblings: SiblingRules = field(default_factory=SiblingRules)
    # more_wires and supports, "Each wire's points: grown, foliage taken off"
    grow: GrowRules = field(default_factory=GrowRules)
    # next_spans, "Phases too sparse to find alone, stacks, next spans, gaps" (the stage gives reach_m
    # from s_min_m)
    next_spans: NextSpanRules = field(default_factory=NextSpanRules)
    # supports, "Towers and poles" and "Tower rules and the scenes that set them" (pylon_top_share
    # is the user's)
    towers: TowerRules = field(default_factory=TowerRules)
    passed_through: PassedThroughRules = field(default_factory=PassedThroughRules)
    poles: PoleRules = field(default_factory=PoleRules)
    # cleaning, "Each wire's points: grown, foliage taken off" and "Lines in a surface"
    foliage: FoliageRules = field(default_factory=FoliageRules)
    surface: SurfaceRules = field(default_factory=SurfaceRules)
    along_surface: AlongSurfaceRules = field(default_factory=AlongSurfaceRules)

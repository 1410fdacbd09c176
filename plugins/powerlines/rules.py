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
    min_contrast: float = 4.0
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


@dataclass(frozen=True)
class FoliageRules:
    """The thresholds of ``in_foliage`` (its docstring says what each does)."""

    window_m: float = 1.0
    min_contrast: float = 4.0
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

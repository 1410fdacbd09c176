"""Power-line pre-classification and the 3D conductor step (pure numpy/scipy).

* ``shape_classes``: eigenvalue shape of each candidate's neighbourhood: linear (wires),
  planar (roofs: a flat 2D patch) or rugged (vegetation: volumetric scatter). It stands in for the
  planar/rugged pre-classification the method ran in LAStools.
* ``conductors_3d``: beyond the method's 2D limit — the 3D points near a 2D line are split by
  height and continuity (so wires stacked in plan come apart), each wire into spans at its
  attachment points (the highest points between sags), and a catenary
  z = z0 + c·(cosh((s - s0)/c) - 1) is fitted per span in its vertical plane; where one does
  not fit (wires stacked closer than the height link, clutter linked to a wire),
  ``peel_catenaries`` takes them out one at a time.
* ``short_wires``: wires seen over a few metres only (a mobile scan's wires across the street),
  straight 3D runs that leave the wires found at a support.
"""

# the topics (each module's own docstring says what it holds); every name is re-exported here,
# so the stages read ``from ..core import X`` whatever module X lives in
from .bundles import (  # noqa: F401
    WINDOWED_SPLIT_M,
    split_bundles,
    two_means_1d,
    windowed_groups,
)
from .candidates import (  # noqa: F401
    DENSITY_BLOCK_M,
    MAX_DENSITY_NEIGHBOURS,
    height_window_top,
    is_ribbon,
    local_surface_density,
    ribbons,
    shape_classes,
    tubes,
)
from .catenaries import (  # noqa: F401
    FIT_TOLERANCE_FLOOR_M,
    ISOLATION_M,
    MAX_NEIGHBOUR_PAIRS,
    N_BEST_LINES,
    SIDE_BY_SIDE_MIN_GAP_M,
    SURFACE_CONTRAST,
    WIDE_GAP_LINKS,
    WIRE_HEIGHT_RMS_M,
    WIRE_ID_BASE,
    WIRE_LATERAL_FLOOR_M,
    WIRE_LATERAL_RMS_M,
    Span,
    catenary,
    fit_catenary,
    fit_tolerance_m,
    kink_cut,
    line_fit,
    median_line_fit,
    parabola_fit,
    split_spans,
)
from .clutter import (  # noqa: F401
    FLANK_EDGE_M,
    FLANK_MIN_ROWS,
    FLANK_ROW_GAP_M,
    AlongSurfaceRules,
    FoliageRules,
    SurfaceRules,
    along_a_surface,
    core_and_ring,
    core_and_ring_masks,
    core_ring_contrast,
    flank_rows,
    in_a_surface,
    in_foliage,
    off_their_spans,
)
from .missed_wires import (  # noqa: F401
    SetNeighbours,
    ShortWireRules,
    SiblingRules,
    ball_pairs,
    short_wires,
    sibling_wires,
    straight_wires,
    wires_from_poles,
)
from .spans import (  # noqa: F401
    GrowRules,
    NextSpanRules,
    bridge_gaps,
    grow_span_ends,
    next_spans,
    pieces_on_surfaces,
    points_on_spans,
    span_on_surface,
    wire_point_spacing,
)
from .support_ends import (  # noqa: F401
    STRAIN_INSULATOR_M,
    ends_at_supports,
)
from .supports import (  # noqa: F401
    PairRules,
    PassedThroughRules,
    PoleRules,
    Pylon,
    TowerRules,
    _tower_shaped,
    axis_share,
    find_poles,
    find_pylons,
    find_towers_passed_through,
    in_pole_columns,
    pole_pair,
    pylon_points,
    under_its_lines,
)
from .wires_3d import (  # noqa: F401
    PeelRules,
    RibbonRules,
    WireRules,
    _ribbon_group,
    alone_beside_wires,
    band_owner,
    conductors_3d,
    make_span,
    peel_catenaries,
    ribbon_lines,
    span_in_frame,
    stands_clear,
    thin_across,
    twin_lines,
)

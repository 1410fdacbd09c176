"""Stage 4, rejection: lines that are rows of a surface or a crown, crowded spans."""



import numpy as np
from toolbox_plugins.powerlines.core import (
    catenary,
)


def test_points_of_a_crown_that_line_up_are_no_conductor():
    """A wire stands out in its cross-section (far denser within 0.1 m than 0.2-0.5 m around);
    a catenary through points of a crown that happen to line up does not: the crown's line is
    dropped, the wire kept, even with a crown touching it along a third of its span."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.stages.rejection import lines_not_wires

    rng = np.random.default_rng(4)
    L, z0, c = 40.0, 20.0, 900.0
    sw = rng.uniform(0, L, 200)
    wire = np.column_stack([sw, rng.normal(0, 0.03, 200), catenary(sw, z0, L / 2, c) + rng.normal(0, 0.03, 200)])
    touching = rng.uniform([0, -1.5, z0 - 1.5], [L / 3, 1.5, z0 + 1.0], (600, 3))
    crown = rng.uniform([0, 8.5, z0 - 1.5], [L, 11.5, z0 + 1.5], (4000, 3))  # a row of crowns at y = 10
    pts = np.vstack([wire, touching, crown])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, L), (np.array([0.0, 10.0]), np.array([1.0, 0.0]), 0.0, L)]
    spans = [Span(0, 0, 0, L / 2, c, z0, 0.0, L, 0.03, 200, 0.2), Span(1, 0, 0, L / 2, c, z0, 0.0, L, 0.1, 25, 0.2)]
    assert lines_not_wires(spans, geo, pts[:, 0], pts[:, 1], pts[:, 2], max_rms=0.2) == {1}



def test_the_top_edge_of_a_wall_is_no_conductor():
    """A straight, level line 3.5 m over the ground seen from the street, the top edge of a truck's
    side (Oakland part3_ak): the side is below the height window, so only every point off the
    ground shows it in a surface; wires stacked 0.3 m apart over one another are not a wall."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.stages.rejection import lines_not_wires

    rng = np.random.default_rng(5)
    L, z0 = 10.0, 9.7
    top = np.column_stack([np.arange(0, L, 0.15), rng.normal(0, 0.01, 67), np.full(67, z0)])
    # the side: vertical scan lines every 0.15 m along, a point every 2 cm down to 1.5 m
    sl, zz = np.meshgrid(np.arange(0, L, 0.15), np.arange(z0 - 1.5, z0, 0.02))
    side = np.column_stack([sl.ravel(), rng.normal(0, 0.01, sl.size), zz.ravel()])
    stacked = np.vstack([top + [0, 5.0, -dz] for dz in (0.0, 0.3, 0.6, 0.9)])  # four wires 5 m aside
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, L), (np.array([0.0, 5.0]), np.array([1.0, 0.0]), 0.0, L)]
    spans = [Span(0, 0, 0, L / 2, 1e6, z0, 0.0, L, 0.01, 67, 0.0), Span(1, 0, 0, L / 2, 1e6, z0, 0.0, L, 0.01, 67, 0.0)]
    cand = np.vstack([top, stacked])  # what the height window keeps
    off_ground = np.vstack([top, side, stacked])
    assert lines_not_wires(spans, geo, *cand.T, max_rms=0.2) == set()  # the window alone cannot tell
    assert lines_not_wires(spans, geo, *cand.T, max_rms=0.2, below=tuple(off_ground.T)) == {0}



def test_a_span_through_a_crown_on_a_line_with_wires_is_crowded():
    """On a line that holds a wire, a second catenary through points of a crown that line up is,
    on its own, no denser within 0.1 m than around it: it is listed as crowded and the line,
    whose wire stands out, is kept."""
    from toolbox_plugins.powerlines.core import Span
    from toolbox_plugins.powerlines.stages.rejection import lines_not_wires

    rng = np.random.default_rng(6)
    L, z0, c = 40.0, 20.0, 900.0
    sw = rng.uniform(0, L, 300)
    wire = np.column_stack([sw, rng.normal(0, 0.03, 300), catenary(sw, z0, L / 2, c) + rng.normal(0, 0.03, 300)])
    crown = rng.uniform([0, -1.5, z0 - 4.0], [L, 1.5, z0 - 1.0], (3000, 3))  # under the wire
    pts = np.vstack([wire, crown])
    geo = [(np.array([0.0, 0.0]), np.array([1.0, 0.0]), 0.0, L)]
    spans = [Span(0, 0, 0, L / 2, c, z0, 0.0, L, 0.03, 300, 0.2), Span(0, 1, 0, L / 2, c, z0 - 2.0, 0.0, L, 0.05, 40, 0.2)]
    crowded = []
    assert lines_not_wires(spans, geo, *pts.T, max_rms=0.2, crowded=crowded) == set()
    assert crowded == [1]

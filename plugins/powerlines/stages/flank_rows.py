"""Stage 10, flank rows (#77, trees are not wires): a mobile scanner passing a crown's or a
hedge's flank side-on leaves a row of points at every step of its scan angle, one above the
other, all ending at the flank's edges; the 3D step fits each as a wire level of one plan line.
Levels stacked deeper than a span carries, each close above the next and ending with it
(``flank_rows``), are dropped with their points, and a conductor left without a span goes. Last
in the chain: run earlier, the cleaning's stacks and the lone points took the rows' points back."""

from __future__ import annotations

from ..core import flank_rows
from ..state import PointLabels, State, Wires
from ..wire_sets import drop_spans, keep_conductors, renumbering


def stage(scene, st: State, settings, ctx) -> State:
    pc, hu = scene.pc, scene.hu
    lines, geo, spans = st.wires.as_tuple()
    gone = flank_rows(spans)
    n_lines = 0
    if gone:
        conductor_of, wire_of_input = st.labels.conductor.copy(), st.labels.wire.copy()
        spans, conductor_of, wire_of_input = drop_spans([spans[k] for k in gone], spans, geo, pc.x * hu, pc.y * hu,
                                                        conductor_of, wire_of_input)
        held = sorted({sp.conductor for sp in spans})
        n_lines = len(geo) - len(held)
        if n_lines:
            if st.fitted_of is not None:  # the same renumbering: layers reads the wires' reach from it
                st.fitted_of = renumbering(held, len(geo))[st.fitted_of]
            lines, geo, spans, conductor_of, wire_of_input = keep_conductors(held, lines, geo, spans, conductor_of,
                                                                             wire_of_input)
        st.wires, st.labels = Wires(lines, geo, spans), PointLabels(conductor_of, wire_of_input)
    st.counts.update(n_flank_row_spans=len(gone), n_flank_row_lines=n_lines)
    return st

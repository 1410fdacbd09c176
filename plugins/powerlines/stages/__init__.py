"""The power-line chain, one module per stage, in the order they run (``CHAIN``).

Each stage is ``stage(scene, state, settings, ctx) -> state``: ``scene`` (``state.Scene``) is
what the ground stage measured of the input and stays fixed; ``state`` (``state.State``) carries
the wires found so far and their labels, per candidate until the cleaning stage switches them to
per input point; ``settings`` (``settings.Settings``) the run's parameters and derived values.

1. ``ground``: ground, height above it, candidates and their shapes (builds the scene)
2. ``plan_lines``: top-hat, tiled Hough, the 3D step (catenary spans); V_max from the spacing
3. ``more_wires``: second pass, short wires, sibling phases, points on spans, spans grown
4. ``rejection``: lines that are rows of a surface or crown, crowded spans
5. ``next_spans``: a wire's next catenary past its last support, gaps bridged
6. ``supports``: pylons and poles, their arms, wires grown up to them
7. ``pole_wires``: short wires leading from a found pole
8. ``cleaning``: (labels per input point from here) foliage and off-trend points, lines in surfaces, stacks
9. ``plan_split``: side-by-side wires split in plan, lone points beside wires, pole columns, realignment
10. ``layers``: the GeoPackage layers, the classified cloud, the stats
"""

from __future__ import annotations

from . import cleaning, more_wires, next_spans, plan_lines, plan_split, pole_wires, rejection, supports

CHAIN = (("plan_lines", plan_lines.stage), ("more_wires", more_wires.stage), ("rejection", rejection.stage),
         ("next_spans", next_spans.stage), ("supports", supports.stage), ("pole_wires", pole_wires.stage),
         ("cleaning", cleaning.stage), ("plan_split", plan_split.stage))

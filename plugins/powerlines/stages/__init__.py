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
10. ``flank_rows``: wire levels stacked deeper than a span carries, ending together: a crown's flank
11. ``layers``: the GeoPackage layers, the classified cloud, the stats
"""

from __future__ import annotations

import time

from . import (cleaning, flank_rows, ground, more_wires, next_spans, plan_lines, plan_split, pole_wires, rejection,
               supports)

CHAIN = (("plan_lines", plan_lines.stage), ("more_wires", more_wires.stage), ("rejection", rejection.stage),
         ("next_spans", next_spans.stage), ("supports", supports.stage), ("pole_wires", pole_wires.stage),
         ("cleaning", cleaning.stage), ("plan_split", plan_split.stage), ("flank_rows", flank_rows.stage))


def run_chain(pc, settings, ctx, until: str | None = None):
    """The scene and the state after the stages up to and including ``until`` (a name of CHAIN;
    None: all of them), each stage's seconds in ``state.timings["stage_<name>_s"]``. Only the
    ground stage runs when the input holds too few candidates for a wire (``no_wire_possible``)."""
    from ..state import State

    st = State()
    t = time.perf_counter()
    scene = ground.stage(pc, settings, ctx, st.timings)
    st.timings["stage_ground_s"] = time.perf_counter() - t
    if until == "ground" or no_wire_possible(scene):
        return scene, st
    return scene, run_stages(scene, st, settings, ctx, last=until)


def run_stages(scene, st, settings, ctx, first: str | None = None, last: str | None = None):
    """The stages of CHAIN from ``first`` through ``last`` (None: from the first, to the last) on
    a scene and the state the stages before ``first`` left."""
    names = [name for name, _ in CHAIN]
    for name in (first, last):
        if name is not None and name not in names:
            raise ValueError(f"no stage {name!r}; the stages after ground: {', '.join(names)}")
    lo = names.index(first) if first else 0
    hi = names.index(last) if last else len(names) - 1
    # a bar over the stages, naming the one running (several take seconds on a dense tile)
    with ctx.progress(total=hi - lo + 1, desc="powerlines", unit="stage") as bar:
        for name, stage in CHAIN[lo:hi + 1]:
            bar.set_postfix_str(name, refresh=True)
            t = time.perf_counter()
            st = stage(scene, st, settings, ctx)
            st.timings[f"stage_{name}_s"] = time.perf_counter() - t
            ctx.log.debug("powerlines: %s: stage %s took %.2f s", scene.pc.source, name,
                          st.timings[f"stage_{name}_s"])
            bar.update(1)
    return st


def no_wire_possible(scene) -> bool:
    """Fewer candidates than a wire needs stand in the height window (a field, a road)."""
    from ..rules import MIN_CANDIDATES

    return len(scene.candidates) < MIN_CANDIDATES

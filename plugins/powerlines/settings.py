"""The power-line chain's settings: the run's parameters with the values derived from them, the
plugin's fixed values, each with where it came from, and the run's ``rules`` (``rules.Rules``: the
thresholds of every core decision the stages take, one record per decision). (Not there yet,
#76: the numeric defaults of the smaller core helpers, and the literals inside function bodies.)"""

from __future__ import annotations

from dataclasses import dataclass, field

from .rules import Rules

# the method's V_max, and how many median point spacings along a wire a gap may span before it
# ends a run: 2.5 m is about 10 spacings on 10 pts/m2 ALS (and 36 on the method's 228 pts/m2), so
# surveys as dense or denser keep the method's value and sparser ones scale it
V_MAX_METHOD_M = 2.5
GAP_SPACINGS = 10.0
STANDS_CLEAR_MAX = 0.5  # other points within 0.5 m of a sparse second-pass wire's points, on average
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


@dataclass
class Settings:
    """The run's parameters (``params``: the user's, validated) with the derived values and the
    rules of every decision."""

    params: dict  # with v_max_m resolved (the method's, or the plan-line stage's from the spacing)
    cell_m: float  # the top-hat's mask cell: the user's, or a third of band_m
    v_max_auto: bool  # whether v_max_m is the run's to derive
    rules: Rules = field(default_factory=Rules)

    @classmethod
    def of(cls, params: dict) -> "Settings":
        auto = params["v_max_m"] is None
        # the mask cell must keep conductors band_m apart (the closest the Hough tells apart) in
        # separate cells with an empty one between them, or the opening keeps their band and the
        # top-hat throws the wires away (AHN4's side-by-side conductors at the method's 0.5 m)
        cell = params["cell_size_m"] if params["cell_size_m"] is not None else round(params["band_m"] / 3, 3)
        return cls(dict(params, v_max_m=V_MAX_METHOD_M if auto else params["v_max_m"], v_max_auto=auto), cell, auto)

    def derive_v_max(self, wire_spacing_m: float | None) -> bool:
        """A sparser survey than the method's samples its wires with gaps over V_max every few
        spans, and each such gap cuts a run: the gap allowed scales with the measured spacing.
        True when v_max_m changed (the plan lines are then searched again)."""
        if self.v_max_auto and wire_spacing_m is not None and GAP_SPACINGS * wire_spacing_m > self.params["v_max_m"]:
            self.params["v_max_m"] = round(GAP_SPACINGS * wire_spacing_m, 2)
            return True
        return False


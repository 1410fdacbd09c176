"""The power-line chain's settings: the run's parameters with the values derived from them, the
run's ``rules`` (``rules.Rules``: the thresholds of every core decision the stages take, one
record per decision). The plugin's fixed values, each with where it came from, are in
``rules.py``; every default of a core signature reads one of its names."""

from __future__ import annotations

from dataclasses import dataclass, field

from .rules import GAP_SPACINGS, V_MAX_METHOD_M, Rules


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


"""The products the power-line chain's stages pass on (see ``stages/__init__.py`` for the chain).

- ``Scene``: what the ground and candidate stages measured of the input; fixed after them.
- ``Wires``: the conductors found so far: plan layers, each line's frame, the catenary spans.
- ``CandidateLabels``: which wire each labelled point is on, indexed by the *list* of points
  labelled (``points``: indices into the cloud). The stages up to the supports grow that list.
- ``PointLabels``: the same labels indexed by *input point* (-1: on no wire). The chain switches
  from candidate to point labels once, at the start of the cleaning stage (``to_points``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Scene:
    pc: Any  # the input PointCloud
    dtm: Any  # the ground step's DTM raster
    ground_cls: np.ndarray  # per point: the ground step's classes (2 ground, 7 noise, 1 other)
    hag: np.ndarray  # per point: height above ground (m; -inf on ground and noise)
    off: np.ndarray  # indices of the points off the ground and not noise
    low: np.ndarray  # indices of ``off`` at least 1 m up: what spans grow and continue into
    candidates: np.ndarray  # indices of the candidates (the height window, first returns)
    linear: np.ndarray  # per candidate: wire-like by the shape test
    steep: np.ndarray  # per candidate: a structure's (a pole's, a ribbon on end)
    surface_density: np.ndarray  # per candidate: first returns per occupied m² around it
    h_max: float  # the height window's top used (m)

    @property
    def hu(self) -> float:
        return self.pc.horizontal_unit_m

    @property
    def vu(self) -> float:
        return self.pc.vertical_unit_m


@dataclass
class Wires:
    lines: dict  # plan layers: "conductors" and "conductor_segments" (GeoDataFrames)
    geo: list  # per conductor: (origin, direction, t0, t1) of its plan line, metres
    spans: list  # core.Span per fitted catenary span

    def as_tuple(self):
        return self.lines, self.geo, self.spans


@dataclass
class CandidateLabels:
    points: np.ndarray  # indices into the cloud of the points labelled
    line: np.ndarray  # per labelled point: its conductor (-1: none)
    wire: np.ndarray  # per labelled point: its wire within the conductor

    def as_tuple(self):
        return self.points, self.line, self.wire

    def to_points(self, conductor_of: np.ndarray) -> "PointLabels":
        """The index switch: ``conductor_of`` (per input point, kept in step with ``line`` by the
        supports stage, which also takes tower points off it) with each point's wire."""
        wire_of_input = np.full(len(conductor_of), -1)
        wire_of_input[self.points] = self.wire
        return PointLabels(conductor_of, wire_of_input)


@dataclass
class PointLabels:
    conductor: np.ndarray  # per input point: its conductor (-1: on no wire)
    wire: np.ndarray  # per input point: its wire within the conductor


@dataclass
class Supports:
    layer: Any  # the ``pylons`` GeoDataFrame
    tower_pt: np.ndarray  # per input point: a tower's or pole's
    found: list  # core.Pylon per support


@dataclass
class State:
    """What the stages hand on; each stage fills in its part."""

    wires: Wires | None = None
    labels: CandidateLabels | PointLabels | None = None
    n_tophat: int = 0  # points the top-hat kept
    wire_spacing_m: float | None = None
    grown: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # points the spans grew into
    conductor_of: np.ndarray | None = None  # the supports stage's per-point conductors
    supports: Supports | None = None
    off_trend: np.ndarray | None = None  # points the cleaning took off their wire
    foliage: np.ndarray | None = None
    around: np.ndarray | None = None  # indices of the points at least 1 m up, and their tree
    around_xyz: np.ndarray | None = None
    around_tree: Any = None
    fitted_of: np.ndarray | None = None  # per point: conductors before the lone points were taken
    counts: dict = field(default_factory=dict)  # the stats each stage reports (n_*)
    timings: dict = field(default_factory=dict)  # seconds per step (*_s)

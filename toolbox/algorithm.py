"""Descriptions of algorithms, their parameters, inputs and outputs, and parameter validation.

A plugin describes each algorithm it provides with an :class:`Algorithm`; the host validates
parameters against those descriptions before any work starts, reads the inputs, calls
``Algorithm.run`` and writes the outputs. Nothing here knows any particular algorithm.
"""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

from .errors import UsageError

#: Kinds of data the host knows how to read and write.
INPUT_KINDS = ("points", "raster", "vector", "photos", "file")  # file: any file or folder the algorithm reads itself
OUTPUT_KINDS = ("points", "raster", "vector", "json", "image", "folder")
#: File extension of each output kind (the first is the default).
OUTPUT_EXTENSIONS = {
    "points": (".laz", ".las"),
    "raster": (".tif", ".tiff"),
    "vector": (".gpkg",),
    "json": (".json",),
    "image": (".png",),
    "folder": ("",),  # files under a folder: the output folder itself (see runner.write_output)
}
PARAM_TYPES = (float, int, bool, str)
_ID_RE = re.compile(r"^[a-z][a-z0-9]*(-[a-z0-9]+)*$")
_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")


@dataclass(frozen=True)
class Parameter:
    """One typed parameter of an algorithm.

    ``type`` is one of float, int, bool, str. ``unit`` is a short unit string ("m", "deg",
    "points") shown in help. ``minimum``/``maximum`` bound numbers (inclusive unless
    ``exclusive_minimum``); ``choices`` restricts strings. ``allow_auto`` lets the user pass
    ``auto``, which reaches the algorithm as ``None`` (an automatic choice it documents).
    """

    name: str
    type: type
    default: Any
    description: str
    unit: str | None = None
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    choices: Sequence[str] | None = None
    allow_auto: bool = False

    def __post_init__(self):
        if not _NAME_RE.match(self.name):
            raise ValueError(f"parameter name {self.name!r} must be snake_case")
        if self.type not in PARAM_TYPES:
            raise ValueError(f"parameter {self.name!r}: type must be one of float, int, bool, str")
        if self.default is not None or not self.allow_auto:
            self.validate(self.default)

    # -- help text -----------------------------------------------------------------
    def allowed(self) -> str:
        parts = []
        if self.choices:
            parts.append("one of " + ", ".join(map(str, self.choices)))
        if self.minimum is not None or self.maximum is not None:
            lo = "(" if self.exclusive_minimum else "["
            a = "-inf" if self.minimum is None else _fmt(self.minimum)
            b = "inf" if self.maximum is None else _fmt(self.maximum)
            parts.append(f"{lo}{a}, {b}]")
        if self.type is bool:
            parts.append("true or false")
        if self.allow_auto:
            parts.append("or auto")
        return " ".join(parts) if parts else "any " + self.type.__name__

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "type": self.type.__name__,
            "default": self.default,
            "unit": self.unit,
            "minimum": self.minimum,
            "maximum": self.maximum,
            "choices": list(self.choices) if self.choices else None,
            "allow_auto": self.allow_auto,
            "description": self.description,
        }

    # -- validation ----------------------------------------------------------------
    def parse(self, value: Any) -> Any:
        """Coerce a value (a string from the command line, or a Python value) and validate it."""
        if isinstance(value, str):
            text = value.strip()
            if self.allow_auto and text.lower() == "auto":
                return None
            if self.type is bool:
                low = text.lower()
                if low in ("1", "true", "yes", "on"):
                    value = True
                elif low in ("0", "false", "no", "off"):
                    value = False
                else:
                    raise UsageError(f"parameter {self.name}: {value!r} is not true or false")
            elif self.type is int:
                try:
                    value = int(text)
                except ValueError:
                    raise UsageError(f"parameter {self.name}: {value!r} is not an integer; allowed {self.allowed()}") from None
            elif self.type is float:
                try:
                    value = float(text)
                except ValueError:
                    raise UsageError(f"parameter {self.name}: {value!r} is not a number; allowed {self.allowed()}") from None
        elif value is None and self.allow_auto:
            return None
        elif self.type is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        self.validate(value)
        return value

    def validate(self, value: Any) -> None:
        if self.allow_auto and value is None:
            return
        if self.type is bool:
            ok = isinstance(value, bool)
        elif self.type is int:
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif self.type is float:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        else:
            ok = isinstance(value, str)
        if not ok:
            raise UsageError(f"parameter {self.name}: {value!r} is not of type {self.type.__name__}; allowed {self.allowed()}")
        if self.type in (int, float):
            if isinstance(value, float) and not math.isfinite(value):
                raise UsageError(f"parameter {self.name}: {value!r} is not a finite number; allowed {self.allowed()}")
            if self.minimum is not None and (value < self.minimum or (self.exclusive_minimum and value == self.minimum)):
                raise UsageError(f"parameter {self.name}: {value} is out of range; allowed {self.allowed()}")
            if self.maximum is not None and value > self.maximum:
                raise UsageError(f"parameter {self.name}: {value} is out of range; allowed {self.allowed()}")
        if self.choices and value not in self.choices:
            hint = difflib.get_close_matches(str(value), list(self.choices), n=1)
            extra = f" (did you mean {hint[0]!r}?)" if hint else ""
            raise UsageError(f"parameter {self.name}: {value!r} is not allowed{extra}; allowed {self.allowed()}")


@dataclass(frozen=True)
class Input:
    """One input of an algorithm. ``kind`` is one of INPUT_KINDS.

    ``multiple`` inputs take one or more files at once (a photo set, tiles to merge). A
    single input given several files runs the algorithm as a batch, one file at a time.

    ``dims`` (points inputs): the per-point dimensions the algorithm reads besides x, y, z, e.g.
    ``("classification", "return_number")``. When given and the run writes no point cloud, LAZ
    files are decompressed for those dimensions only; reading any other one still works (the
    host then reads the whole file again), it is just slower.
    """

    name: str
    kind: str
    description: str
    multiple: bool = False
    optional: bool = False
    dims: tuple | None = None

    def __post_init__(self):
        if self.kind not in INPUT_KINDS:
            raise ValueError(f"input {self.name!r}: kind must be one of {', '.join(INPUT_KINDS)}")


@dataclass(frozen=True)
class LayerMerge:
    """How one vector layer's features from the tiles of a survey run (``--tile-size-m``) become
    one layer. Whatever the rule, a feature is kept by the tile whose core holds it, never by the
    tiles whose buffer it reaches: a point where it lies, a polygon by its representative point,
    a line clipped to the core.

    ``join``: line pieces that meet at a tile border (cut ends within ``join_tolerance_m`` of each
    other, in the layer's units) become one feature. ``id_field`` is renumbered 0..n-1 over the
    survey; ``refs`` maps a field of this layer to the layer whose ``id_field`` it holds (an
    integer, or integers joined by commas), so references follow the renumbering. ``combine``
    says how a joined feature's field comes from its pieces: ``min``, ``max``, ``sum``, ``length``
    (the joined line's length) or ``area_m2`` (the dissolved polygon's area in m²); any other field
    is the longest (largest) piece's.

    ``dissolve`` (polygons, for objects that may be wider than the tile's buffer, so that a tile
    sees only part of one): a polygon that crosses the tile's core border is clipped to the core,
    and pieces of neighbouring tiles that meet at a border (within ``join_tolerance_m``) become
    one feature, their union.
    """

    join: bool = True
    join_tolerance_m: float = 0.15
    id_field: str | None = None
    refs: Mapping[str, str] = field(default_factory=dict)
    combine: Mapping[str, str] = field(default_factory=dict)
    dissolve: bool = False

    def __post_init__(self):
        bad = {k: v for k, v in self.combine.items() if v not in ("min", "max", "sum", "length", "area_m2")}
        if bad:
            raise ValueError(f"LayerMerge.combine: {bad} (allowed: min, max, sum, length, area_m2)")


@dataclass(frozen=True)
class Output:
    """One output of an algorithm. ``kind`` is one of OUTPUT_KINDS.

    The first output is the primary one: it is written to the path given with ``-o``. The
    others are written beside it as ``<stem>_<name><ext>`` unless given their own path.
    ``style`` names the QGIS style (a ``.qml`` in a style directory) for rasters; vector
    layers are styled by their layer name.
    """

    name: str
    kind: str
    description: str
    style: str | None = None
    optional: bool = False
    #: file name suffix for a secondary output (default ``_<name>``)
    suffix: str | None = None
    #: vector outputs in a survey run: ``{layer name: LayerMerge}``; a layer not named merges by
    #: the default rule of its geometry (see :class:`LayerMerge`: lines clipped, joined, no ids)
    merge: Mapping[str, LayerMerge] | None = None

    def __post_init__(self):
        if self.kind not in OUTPUT_KINDS:
            raise ValueError(f"output {self.name!r}: kind must be one of {', '.join(OUTPUT_KINDS)}")

    @property
    def extension(self) -> str:
        return OUTPUT_EXTENSIONS[self.kind][0]


@dataclass
class Result:
    """What an algorithm's run function returns: data per output name, and free-form stats."""

    outputs: dict[str, Any]
    stats: dict[str, Any] = field(default_factory=dict)


@dataclass
class Algorithm:
    """An algorithm as a plugin declares it.

    ``run(inputs, params, ctx)`` receives the inputs already read (``{name: data}``: a
    :class:`toolbox.io.points.PointCloud`, :class:`toolbox.io.rasters.Raster`, a dict of
    GeoDataFrames for vectors, or a list of these for ``multiple`` inputs), the validated
    parameters (``{name: value}``, defaults filled in) and a :class:`toolbox.runner.Context`.
    It returns a :class:`Result` (or a plain dict of outputs) without touching files: the host
    writes the outputs.
    """

    id: str
    title: str
    description: str
    run: Callable[..., Any]
    parameters: Sequence[Parameter] = ()
    inputs: Sequence[Input] = ()
    outputs: Sequence[Output] = ()
    reference: str = ""
    #: Survey runs (``--tile-size-m``): how far around each tile (metres) the algorithm must see
    #: points for its result inside the tile to be the one it gives on the whole survey: a number,
    #: or a function of the validated parameters. None: no declared need (the user gives
    #: ``--buffer-m``; 0 otherwise).
    tile_buffer_m: float | Callable[[Mapping[str, Any]], float] | None = None
    #: Survey runs: values an algorithm takes from its whole input (a point spacing, a density),
    #: computed once for the survey so that every tile runs with the value one run over the whole
    #: would take. ``survey_summary(points, core_box, values) -> dict`` gives one tile's share
    #: (counts of its core, from its points and buffer: x, y, z and the dimensions the input
    #: declares); the host sums them over the tiles, and
    #: ``survey_values(sums, values, horizontal_unit_m) -> dict`` turns the sums into parameter
    #: values that every tile gets (the report's ``survey_values``).
    survey_summary: Callable[..., Mapping[str, Any]] | None = None
    survey_values: Callable[..., Mapping[str, Any]] | None = None
    #: The same sums without reading the tiles again, where per-cell statistics of the points
    #: suffice: ``survey_cells(values, horizontal_unit_m) -> cell`` (CRS units; None: no values
    #: to find) asks the host for a ``CellStats`` (count, lowest and highest z per cell) gathered
    #: while it splits the files, and ``survey_cell_summary(cell_stats, values) -> dict`` gives
    #: the sums that ``survey_summary`` summed over all tiles gives. Used when every input is a
    #: plain LAS/LAZ file; otherwise the tiles' ``survey_summary`` runs.
    survey_cells: Callable[..., float | None] | None = None
    survey_cell_summary: Callable[..., Mapping[str, Any]] | None = None
    #: Peak memory of a run per input point (bytes), to refuse before reading a file this machine
    #: cannot hold (``toolbox.memory.check_fits``). None: the host's default.
    bytes_per_point: int | None = None
    #: Filled in by the registry: the plugin (entry-point name), distribution and version.
    plugin: str = ""
    distribution: str = ""
    version: str = ""

    def __post_init__(self):
        if not isinstance(self.id, str) or not _ID_RE.match(self.id):
            raise ValueError(f"algorithm id {self.id!r} must be lower-case words joined by '-'")
        if not callable(self.run):
            raise ValueError(f"algorithm {self.id}: run must be callable")
        if not self.outputs:
            raise ValueError(f"algorithm {self.id}: declares no output")
        for group, what in ((self.parameters, "parameter"), (self.inputs, "input"), (self.outputs, "output")):
            names = [x.name for x in group]
            dup = {n for n in names if names.count(n) > 1}
            if dup:
                raise ValueError(f"algorithm {self.id}: {what} {', '.join(sorted(dup))} declared twice")

    def buffer_m(self, values: Mapping[str, Any]) -> float | None:
        """The buffer this algorithm declares for the given (validated) parameters, in metres."""
        need = self.tile_buffer_m
        return float(need(values)) if callable(need) else (None if need is None else float(need))

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)

    def validate_params(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """Return every parameter's value (defaults filled in), or raise UsageError."""
        known = {p.name: p for p in self.parameters}
        for name in given:
            if name not in known:
                hint = difflib.get_close_matches(name, list(known), n=1)
                extra = f" (did you mean {hint[0]!r}?)" if hint else ""
                valid = ", ".join(known) or "none"
                raise UsageError(f"{self.id}: unknown parameter {name!r}{extra}; valid parameters: {valid}")
        values = {}
        for name, p in known.items():
            values[name] = p.parse(given[name]) if name in given else p.default
        return values

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "title": self.title,
            "description": self.description,
            "reference": self.reference,
            "plugin": self.plugin,
            "distribution": self.distribution,
            "version": self.version,
            "parameters": [p.to_dict() for p in self.parameters],
            "inputs": [{"name": i.name, "kind": i.kind, "multiple": i.multiple, "optional": i.optional,
                        "description": i.description} for i in self.inputs],
            "outputs": [{"name": o.name, "kind": o.kind, "extension": o.extension, "optional": o.optional,
                         "description": o.description} for o in self.outputs],
        }


def _fmt(x: float) -> str:
    return f"{x:g}"

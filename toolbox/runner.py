"""Running an algorithm: plan outputs, read inputs, validate, call the plugin, write atomically,
report. Also batch runs (one file at a time, in parallel processes)."""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from . import kernels, progress
from .algorithm import OUTPUT_EXTENSIONS, Algorithm, Result
from .errors import DataError, ToolboxError, UsageError
from .registry import Registry, registry

log = logging.getLogger(__name__)

# What each input kind accepts, by file extension
INPUT_EXTENSIONS = {
    "points": (".las", ".laz", ".txt", ".xyz", ".csv", ".asc", ".pts"),
    "raster": (".tif", ".tiff"),
    "vector": (".gpkg", ".shp", ".geojson", ".json", ".fgb"),
    "photos": (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".json"),
}
KIND_WORDS = {"points": "a point cloud", "raster": "a raster", "vector": "a vector file", "photos": "a photo set",
              "file": "a file or folder"}


@dataclass
class Context:
    """What a running algorithm may use from the host."""

    registry: Registry
    algorithm_id: str = ""
    quiet: bool = False
    stats: dict[str, Any] = field(default_factory=dict)
    requested: frozenset = frozenset()
    _writer: Any = None  # the run's _OutputWriter (file runs only)
    #: the algorithm the user ran, when this one runs inside it (``ctx.call``); "" at the top. An
    #: error should then name what the user can change (its parameters, or tiling), not this one's
    caller: str = ""

    def wants(self, output_name: str) -> bool:
        """Whether an optional output was asked for (required outputs are always wanted)."""
        alg = self.registry.algorithms.get(self.algorithm_id)
        if alg is not None:
            for o in alg.outputs:
                if o.name == output_name and not o.optional:
                    return True
        return output_name in self.requested

    @property
    def log(self) -> logging.Logger:
        return logging.getLogger(f"toolbox.alg.{self.algorithm_id}")

    def progress(self, iterable=None, total=None, desc: str = "", unit: str = "it"):
        return progress.bar(iterable, total=total, desc=desc or self.algorithm_id, unit=unit)

    def taichi(self):
        """The taichi module, initialised once (CUDA when present, else CPU, or as --arch says)."""
        return kernels.taichi()

    def taichi_started(self) -> bool:
        """Whether taichi already runs in this process. Starting it costs about 0.5 s, and each
        kernel's first call in a process another 0.05-0.2 s (taichi's Python front end runs even
        when its offline cache holds the machine code): a plugin may prefer numpy for work that
        small in a fresh process."""
        return kernels.started()

    def taichi_requested(self) -> bool:
        """Whether the user asked for an accelerator by name (``--arch cuda``, ``TOOLBOX_ARCH``)."""
        return kernels.requested_arch() in ("cuda", "vulkan")

    def emit(self, output_name: str, value: Any) -> None:
        """Hand over a finished output early. A raster, image or vector is then written in the
        background, beside the remaining computation (GDAL releases the GIL); a point cloud is
        queued and written when the run ends (lazrs holds the GIL while it compresses, so it
        would only take turns with the computation; see ``_OutputWriter``). The value must still
        be returned in the Result, and must not be changed afterwards. Outside a file run
        (``ctx.call``) this does nothing."""
        if self._writer is not None:
            self._writer.submit(output_name, value)

    def call(self, algorithm_id: str, inputs: Mapping[str, Any], **params) -> Result:
        """Run another algorithm in memory on data (not files); returns its Result."""
        alg = self.registry.get(algorithm_id)
        values = alg.validate_params(params)
        sub = Context(self.registry, algorithm_id, self.quiet, caller=self.caller or self.algorithm_id)
        return _as_result(alg.run(dict(inputs), values, sub), alg)


# --------------------------------------------------------------------------------------------
# Planning
# --------------------------------------------------------------------------------------------

def input_kind_of(path: str | os.PathLike) -> str | None:
    p = Path(path)
    if p.is_dir():
        return "photos"
    ext = p.suffix.lower()
    for kind in ("points", "raster", "vector"):
        if ext in INPUT_EXTENSIONS[kind]:
            return kind
    if ext in INPUT_EXTENSIONS["photos"]:
        return "photos"
    return None


def assign_inputs(alg: Algorithm, files: Sequence[str], named: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Map files onto the algorithm's declared inputs, checking their kinds: ``named`` ({input
    name: path}, the CLI's --input NAME=PATH) first, the positional files to the others in order."""
    named = dict(named or {})
    every = {s.name for s in alg.inputs}
    for n in named:
        if n not in every:
            raise UsageError(f"{alg.id} has no input {n!r}; its inputs: {', '.join(s.name for s in alg.inputs) or 'none'}")
    specs = [s for s in alg.inputs if s.name not in named]
    files = [str(f) for f in files]
    if not specs:
        if files:
            raise UsageError(f"{alg.id} takes no further input file, but {len(files)} were given")
        return _checked_kinds(alg, {n: ([v] if s.multiple else v) for s in alg.inputs for n, v in named.items() if n == s.name})
    assigned: dict[str, Any] = {s.name: ([named[s.name]] if s.multiple else named[s.name]) for s in alg.inputs
                                if s.name in named}
    rest = list(files)
    for i, spec in enumerate(specs):
        last = i == len(specs) - 1
        if spec.multiple:
            n_after = sum(1 for s in specs[i + 1:] if not s.optional)
            take = rest[: max(len(rest) - n_after, 0)] if not last else rest
            rest = rest[len(take):]
            if not take and not spec.optional:
                raise UsageError(f"{alg.id} needs {KIND_WORDS[spec.kind]} for its input {spec.name!r}")
            if take:
                assigned[spec.name] = take
        else:
            if not rest:
                if spec.optional:
                    continue
                raise UsageError(f"{alg.id} needs {KIND_WORDS[spec.kind]} for its input {spec.name!r}; see 'toolbox help {alg.id}'")
            assigned[spec.name] = rest.pop(0)
    if rest:
        raise UsageError(f"{alg.id} takes {len(specs)} input(s) but {len(files)} files were given: {', '.join(rest)} left over")
    return _checked_kinds(alg, assigned)


def _checked_kinds(alg: Algorithm, assigned: dict) -> dict:
    for spec in alg.inputs:
        if spec.name not in assigned:
            continue
        vals = assigned[spec.name] if isinstance(assigned[spec.name], list) else [assigned[spec.name]]
        for f in vals:
            if spec.kind in ("photos", "file"):
                continue
            kind = input_kind_of(f)
            if kind != spec.kind:
                what = KIND_WORDS.get(kind, "not a supported file type") if kind else "not a supported file type"
                exts = ", ".join(INPUT_EXTENSIONS[spec.kind])
                raise UsageError(
                    f"input {f!r} is {what}, but {alg.id} expects {KIND_WORDS[spec.kind]} for {spec.name!r} ({exts})"
                )
    return assigned


def plan_outputs(alg: Algorithm, output: str | os.PathLike, named: Mapping[str, str] | None = None,
                 stem: str | None = None) -> dict[str, Path]:
    """Paths of every output: the primary at ``output`` (or ``output/<stem><ext>`` for a folder),
    the others at ``<stem>_<name><ext>`` beside it, unless ``named`` gives a path for them."""
    from .io.atomic import check_name_length

    named = dict(named or {})
    known = {o.name for o in alg.outputs}
    for n in named:
        if n not in known:
            raise UsageError(f"{alg.id} has no output {n!r}; its outputs: {', '.join(sorted(known))}")
    for p in (output, *named.values()):
        check_name_length(Path(p))  # (before anything asks the file system about it)
    out = Path(output)
    primary = alg.outputs[0]
    is_dir = out.is_dir() or str(output).endswith(os.sep) or not out.suffix
    if is_dir:  # a missing folder is made by the run (see check_outputs)
        base = out / (stem or primary.name)
        primary_path = base.with_name(base.name + primary.extension)
    else:
        if out.suffix.lower() not in OUTPUT_EXTENSIONS[primary.kind]:
            exts = ", ".join(OUTPUT_EXTENSIONS[primary.kind])
            raise UsageError(f"output {str(out)!r}: {alg.id} writes {primary.kind} here, so use {exts}")
        base = out.with_suffix("")
        primary_path = out
    paths = {primary.name: Path(named.get(primary.name, primary_path))}
    for o in alg.outputs[1:]:
        if o.kind == "folder":  # its files go into the output folder (beside the primary)
            paths[o.name] = Path(named[o.name]) if o.name in named else base.parent
            continue
        p = Path(named[o.name]) if o.name in named else base.with_name(f"{base.name}{o.suffix or '_' + o.name}{o.extension}")
        if p.suffix.lower() not in OUTPUT_EXTENSIONS[o.kind]:
            raise UsageError(f"output {str(p)!r}: {alg.id}'s output {o.name!r} is {o.kind}; use {', '.join(OUTPUT_EXTENSIONS[o.kind])}")
        paths[o.name] = p
    return paths


def sidecars_of(output, path: Path, style_dirs) -> list[Path]:
    """The files written beside an output: a raster's QGIS style, a picture's world file and GDAL
    metadata. They are outputs too: never replaced without --overwrite."""
    from .io.styles import find_style

    if output.kind == "raster" and output.style and find_style(output.style, style_dirs) is not None:
        return [path.with_suffix(".qml")]
    if output.kind == "image":
        return [path.with_suffix(".wld"), path.with_name(path.name + ".aux.xml")]
    return []


def files_of(alg: Algorithm, paths: Mapping[str, Path], style_dirs) -> list[Path]:
    """Every file the outputs at ``paths`` write: each output's and its sidecars (folder outputs,
    whose files are their own, left out)."""
    by_name = {o.name: o for o in alg.outputs}
    files = []
    for name, p in paths.items():
        if by_name[name].kind != "folder":
            files += [Path(p), *sidecars_of(by_name[name], Path(p), style_dirs)]
    return files


def check_outputs(alg: Algorithm, paths: Mapping[str, Path], input_files, overwrite: bool, style_dirs,
                  staging) -> None:
    """Before any work: no file of the outputs is an input, each may be written (``--overwrite``
    for one that exists), and the folders they go into exist (made when missing)."""
    from .io.atomic import check_folder, check_writable

    files = files_of(alg, paths, style_dirs)
    check_not_inputs(files, input_files)
    kinds = {o.name: o.kind for o in alg.outputs}
    for name, p in paths.items():
        staging.make_dirs(p if kinds[name] == "folder" else Path(p).parent)  # removed again if the run fails
        if kinds[name] == "folder":
            check_folder(p)
    for p in files:
        check_writable(p, overwrite)


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def check_not_inputs(paths: Sequence[Path], input_files: Sequence[str]) -> None:
    """Refuse any output (or sidecar) that is one of the inputs, whatever --overwrite says."""
    for p in paths:
        for f in input_files:
            if _same_file(Path(p), Path(f)):
                raise UsageError(f"output {str(p)!r} is the input {str(f)!r}; the toolbox never replaces an input: "
                                 "give the output another name or folder")


def _input_files(assigned: Mapping[str, Any]) -> list[str]:
    files = []
    for v in assigned.values():
        files.extend(str(x) for x in (v if isinstance(v, list) else [v]) if isinstance(x, (str, os.PathLike)))
    return files


def parameters_used(alg: Algorithm, values: Mapping[str, Any], stats: Mapping[str, Any]) -> tuple[dict, list]:
    """Every parameter's value as the run used it: an ``auto`` one (None) takes the value the
    algorithm reported as ``<name>_used``. Returns (values, names that were auto)."""
    used, auto = dict(values), []
    for p in alg.parameters:
        if p.allow_auto and values.get(p.name) is None:
            auto.append(p.name)
            used[p.name] = stats.get(f"{p.name}_used")
    return used, auto


def _crs_label(crs) -> str | None:
    if crs is None:
        return None
    ident = crs.to_json_dict().get("id") or {}
    if ident.get("authority") and ident.get("code"):
        return f"{ident['authority']}:{ident['code']}"
    return crs.name


# --------------------------------------------------------------------------------------------
# Reading and writing
# --------------------------------------------------------------------------------------------

def _check_inputs_fit(alg, assigned, specs) -> None:
    """Every LAS/LAZ input's point count (from its header) against the memory free for the run."""
    import laspy

    from .io.points import LAS_EXTENSIONS
    from .memory import check_fits

    for name, val in assigned.items():
        for path in (val if isinstance(val, list) else [val]):
            if specs[name].kind != "points" or not isinstance(path, (str, os.PathLike)) or \
                    Path(path).suffix.lower() not in LAS_EXTENSIONS:
                continue
            try:
                with laspy.open(path) as reader:
                    n = int(reader.header.point_count)
            except Exception:  # unreadable: read_points says why, in its own words
                continue
            check_fits(alg, path, n)


def read_input(kind: str, path: str, crs=None, dims=None):
    if kind == "points":
        from .io.points import read_points

        return read_points(path, crs=crs, dims=dims)
    if kind == "raster":
        from .io.rasters import read_raster

        return read_raster(path)
    if kind == "vector":
        from .io.vectors import read_vectors

        return read_vectors(path)
    if kind in ("photos", "file"):
        p = Path(path)
        if not p.exists():
            raise DataError(f"input {path!r} does not exist; check the path")
        return p
    raise UsageError(f"unknown input kind {kind!r}")


def write_output(kind: str, data: Any, path: Path, style_dirs, overwrite: bool) -> dict:
    """Write one output atomically; return a summary (counts) for the report."""
    from .io.atomic import atomic_path

    if kind == "points":
        from .io.points import PointCloud, write_points

        if not isinstance(data, PointCloud):
            raise TypeError(f"points output must be a PointCloud, got {type(data).__name__}")
        write_points(data, path, overwrite=overwrite)
        summary = {"n_points": len(data)}
        cls = data.classification
        if cls is not None and len(cls):
            counts = np.bincount(cls) if cls.dtype.kind in "ub" else None
            if counts is not None:  # classes are small integers: a count per value, no sort
                summary["classes"] = {int(k): int(v) for k, v in enumerate(counts) if v}
            else:
                u, c = np.unique(cls, return_counts=True)
                summary["classes"] = {int(k): int(v) for k, v in zip(u, c)}
        return summary
    if kind == "raster":
        from .io.rasters import Raster, write_raster

        if not isinstance(data, Raster):
            raise TypeError(f"raster output must be a Raster, got {type(data).__name__}")
        write_raster(data, path, style_dirs=style_dirs, overwrite=overwrite)
        rows, cols = data.shape
        from .io.styles import find_style

        styled = bool(data.style) and find_style(data.style, style_dirs) is not None  # (staged: not there yet)
        return {"width": int(cols), "height": int(rows), "cell_size": data.cell_size,
                "style": str(path.with_suffix(".qml")) if styled else None}
    if kind == "vector":
        from .io.vectors import write_vectors

        write_vectors(data, path, style_dirs=style_dirs, overwrite=overwrite)
        return {"layers": {name: int(len(gdf)) for name, gdf in data.items()}}
    if kind == "json":
        with atomic_path(path, overwrite) as tmp:
            tmp.write_text(json.dumps(data, indent=2, default=_json_default), encoding="utf-8")
        return {"keys": sorted(data)[:20] if isinstance(data, dict) else None}
    if kind == "folder":
        from .io.atomic import write_folder

        entries = write_folder(data, path, overwrite)
        return {"entries": entries, "n_files": len(data)}
    if kind == "image":
        from .io.rasters import Raster, write_image

        write_image(data, path, overwrite)
        rows, cols = data.shape if isinstance(data, Raster) else np.asarray(data).shape[:2]
        return {"height": int(rows), "width": int(cols), "georeferenced": isinstance(data, Raster)}
    raise UsageError(f"unknown output kind {kind!r}")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    return str(o)


class _OutputWriter:
    """Writes a run's outputs and collects their summaries. An output emitted early by the
    algorithm is written in a background thread beside the remaining computation when its writer
    releases the GIL (GDAL: rasters, images, vectors). lazrs does not (0.8: its compressor holds
    the GIL, also ``compress_points``; measured, a Python thread beside it ran at a fifth of its
    speed): a point output is queued and written by ``finish``. ``finish`` writes what is left in
    the calling thread, one after the other: a GeoTIFF thread beside a LAZ written here took turns
    at the GIL with it and both got slower (AHN3's 43 k points: LAZ 17 ms + DTM 8 ms one after the
    other, 34 ms side by side). With more than one chunk the LAZ compression runs on all cores."""

    GIL_BOUND = ("points",)

    def __init__(self, kinds: dict, paths: dict, style_dirs, overwrite: bool):
        self.kinds, self.paths, self.style_dirs, self.overwrite = kinds, paths, style_dirs, overwrite
        self.futures: dict[str, Any] = {}
        self.held: dict[str, Any] = {}  # GIL-bound outputs, written by finish
        self._pool = None

    def submit(self, name: str, value: Any, early: bool = True) -> None:
        """Start writing an output emitted early, or queue it for ``finish`` (a GIL-bound one, or
        one handed over when the computation has ended: ``early=False``)."""
        if value is None or name not in self.paths or name in self.futures or name in self.held:
            return
        if not early or self.kinds[name] in self.GIL_BOUND:
            self.held[name] = value
            return
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="toolbox-write")
        import contextvars

        # the write runs in the run's context: its files are staged with the others
        self.futures[name] = self._pool.submit(contextvars.copy_context().run, write_output, self.kinds[name], value,
                                               self.paths[name], self.style_dirs, self.overwrite)

    def finish(self) -> dict:
        """Write the queued outputs here, wait for those in flight; the summaries, or the first
        error (after all have ended)."""
        from concurrent.futures import Future

        for name, value in self.held.items():
            fut = Future()
            try:
                fut.set_result(write_output(self.kinds[name], value, self.paths[name], self.style_dirs,
                                            self.overwrite))
            except Exception as exc:  # noqa: BLE001 - reported below with the others (Ctrl-C stops at once)
                fut.set_exception(exc)
            self.futures[name] = fut
        self.held.clear()
        written, error = {}, None
        for name, fut in self.futures.items():
            try:
                written[name] = {"path": str(self.paths[name]), "kind": self.kinds[name], **fut.result()}
            except BaseException as exc:  # noqa: BLE001 - re-raised below, after the others end
                error = error or exc
        self._close()
        if error is not None:
            raise error
        return written

    def discard(self) -> None:
        """Wait for writes in flight (their files are staged: the run's rollback removes them, and
        a file of the same name from before stays as it was)."""
        for fut in self.futures.values():
            try:
                fut.result()
            except BaseException:  # noqa: BLE001 - the run is failing anyway
                pass
        self._close()

    def _close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


def _as_result(value, alg: Algorithm) -> Result:
    if isinstance(value, Result):
        res = value
    elif isinstance(value, Mapping):
        res = Result(outputs=dict(value))
    else:
        raise TypeError(f"{alg.id}: run returned {type(value).__name__}, not a Result or dict of outputs")
    known = {o.name for o in alg.outputs}
    for name in res.outputs:
        if name not in known:
            raise TypeError(f"{alg.id}: run returned an undeclared output {name!r}")
    for o in alg.outputs:
        if o.name not in res.outputs and not o.optional:
            raise TypeError(f"{alg.id}: run did not return its output {o.name!r}")
    return res


# --------------------------------------------------------------------------------------------
# One run
# --------------------------------------------------------------------------------------------

def run_algorithm(
    algorithm_id: str,
    inputs: Sequence[str] | Mapping[str, Any] = (),
    output: str | os.PathLike | None = None,
    params: Mapping[str, Any] | None = None,
    *,
    outputs: Mapping[str, str] | None = None,
    overwrite: bool = False,
    crs: str | None = None,
    reg: Registry | None = None,
) -> dict:
    """Run one algorithm on files and write its outputs; return the run report (a dict).

    ``inputs`` is a list of paths (assigned to the declared inputs in order) or a mapping
    ``{input name: path or list of paths}``. Everything is validated before any work starts.
    """
    t0 = time.perf_counter()
    from .io.atomic import staged_outputs

    with staged_outputs() as staging:
        rep = _run_staged(algorithm_id, inputs, output, params, outputs, overwrite, crs, reg, staging, t0)
        staging.commit()
    return rep


def _run_staged(algorithm_id, inputs, output, params, outputs, overwrite, crs, reg, staging, t0) -> dict:
    from .memory import tune_allocator

    tune_allocator()  # arrays reuse freed memory instead of faulting fresh pages in (see memory.py)
    reg = reg or registry()
    alg = reg.get(algorithm_id)
    values = alg.validate_params(params or {})
    crs_given = crs
    if crs is not None:
        from .io.points import parse_crs

        crs = parse_crs(crs)
    assigned = dict(inputs) if isinstance(inputs, Mapping) else assign_inputs(alg, inputs)
    if output is None:
        raise UsageError(f"{alg.id} writes files; give an output with -o")
    stem = None
    first = next(iter(assigned.values()), None)
    if first is not None:
        stem = Path(first[0] if isinstance(first, list) else first).stem
    paths = plan_outputs(alg, output, outputs, stem)
    optional = {o.name for o in alg.outputs if o.optional}
    requested = frozenset(n for n in (outputs or {}) if n in optional)
    paths = {n: p for n, p in paths.items() if n not in optional or n in requested}
    check_outputs(alg, paths, _input_files(assigned), overwrite, reg.style_dirs, staging)

    specs = {s.name: s for s in alg.inputs}
    _check_inputs_fit(alg, assigned, specs)
    # a run that writes points writes every dimension: read them all; otherwise only the declared
    writes_points = any(o.kind == "points" and o.name in paths for o in alg.outputs)
    data = {}
    for name, val in assigned.items():
        kind = specs[name].kind
        dims = None if writes_points else specs[name].dims
        if isinstance(val, list):
            data[name] = [read_input(kind, v, crs, dims) for v in val]
        else:
            data[name] = read_input(kind, val, crs, dims)
    t_read = time.perf_counter()

    writer = _OutputWriter({o.name: o.kind for o in alg.outputs}, paths, reg.style_dirs, overwrite)
    ctx = Context(reg, alg.id, requested=requested, _writer=writer)
    try:
        try:
            result = _as_result(alg.run(data, values, ctx), alg)
        except MemoryError:
            raise DataError(f"{alg.id} ran out of memory on {stem or 'its input'}; use a coarser resolution or tile "
                            "the input") from None
        t_compute = time.perf_counter()
        for name, value in result.outputs.items():
            writer.submit(name, value, early=False)  # those not emitted early
        written = writer.finish()
    except BaseException:
        # a failed run or write leaves no file of this run behind, also none already written
        writer.discard()
        raise
    t_write = time.perf_counter()
    stats = dict(ctx.stats)
    stats.update(result.stats)
    used, auto = parameters_used(alg, values, stats)
    return {
        "algorithm": alg.id,
        "plugin": alg.plugin,
        "distribution": alg.distribution,
        "version": alg.version,
        "inputs": {k: v for k, v in assigned.items()},
        "parameters": used,
        "parameters_auto": auto,
        "crs": {"given": crs_given if crs_given is None or isinstance(crs_given, str) else _crs_label(crs_given),
                "inputs": _input_crs(data)},
        "dropped_points": _dropped(data),
        "outputs": written,
        "stats": stats,
        "taichi_arch": kernels.arch_used(),
        "timings_s": {
            "read": round(t_read - t0, 4),
            "compute": round(t_compute - t_read, 4),
            "write": round(t_write - t_compute, 4),
            "total": round(t_write - t0, 4),
        },
    }


def _clouds(data: Mapping[str, Any]):
    from .io.points import PointCloud

    for name, value in data.items():
        for v in (value if isinstance(value, list) else [value]):
            if isinstance(v, PointCloud):
                yield name, v


def _input_crs(data: Mapping[str, Any]) -> dict:
    """The CRS each point input was read in (the file's, or --crs)."""
    return {name: _crs_label(pc.crs) for name, pc in _clouds(data)}


def _dropped(data: Mapping[str, Any]) -> dict:
    """Points left out when the inputs were read (NaN or infinite coordinates), by input."""
    out = {}
    for name, pc in _clouds(data):
        n = pc.meta.get("n_dropped_non_finite", 0)
        if n:
            out[name] = out.get(name, 0) + int(n)
    return out


# --------------------------------------------------------------------------------------------
# Batch
# --------------------------------------------------------------------------------------------

def expand_inputs(files: Sequence[str], kind: str) -> list[str]:
    """Folders stand for the files of ``kind`` in them (sorted)."""
    out = []
    for f in files:
        p = Path(f)
        if p.is_dir() and kind != "photos":
            found = sorted(str(q) for q in p.iterdir() if q.suffix.lower() in INPUT_EXTENSIONS[kind] and q.is_file())
            if not found:
                raise UsageError(f"folder {f!r} holds no {KIND_WORDS[kind].removeprefix('a ')} files ({', '.join(INPUT_EXTENSIONS[kind])})")
            out.extend(found)
        else:
            out.append(str(f))
    return out


def is_batch(alg: Algorithm, files: Sequence[str]) -> bool:
    if len(alg.inputs) != 1 or alg.inputs[0].multiple:
        return False
    return len(files) > 1 or any(Path(f).is_dir() and alg.inputs[0].kind not in ("photos", "file") for f in files)


def _batch_one(args) -> tuple[str, dict | None, str | None]:
    algorithm_id, path, outdir, params, overwrite, crs, quiet, arch = args
    progress.set_quiet(True)
    kernels.set_arch(arch)
    try:
        rep = run_algorithm(algorithm_id, [path], outdir, params, overwrite=overwrite, crs=crs)
        return path, rep, None
    except ToolboxError as exc:
        return path, None, str(exc)
    except BaseException as exc:  # a bug on one file (even sys.exit) must not stop the others
        from . import signals

        if signals.received() or isinstance(exc, signals.Terminated):
            raise  # Ctrl-C or SIGTERM: the batch stops (this run left nothing)
        return path, None, f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"


def run_batch(algorithm_id: str, files: Sequence[str], outdir: str, params: Mapping[str, Any] | None = None,
              *, overwrite: bool = False, crs: str | None = None, jobs: int | None = None,
              reg: Registry | None = None) -> dict:
    """Run a single-input algorithm on many files in parallel processes; failures are collected,
    never fatal to the others. Returns {"runs": [...], "failed": [{"input", "error"}], ...}."""
    import concurrent.futures as cf
    import multiprocessing as mp

    reg = reg or registry()
    alg = reg.get(algorithm_id)
    alg.validate_params(params or {})
    if jobs is not None and jobs < 1:
        raise UsageError(f"-j {jobs}: give 1 or more worker processes (or leave -j out for one per core)")
    files = expand_inputs(files, alg.inputs[0].kind)
    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise UsageError(f"a batch of {len(files)} files writes into a folder; {outdir!r} is a file")
    _check_batch_outputs(alg, files, out, reg)
    from .io.atomic import make_folder

    created = make_folder(out)
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(files)))
    arch = kernels.requested_arch()
    tasks = [(algorithm_id, f, str(out), dict(params or {}), overwrite, crs, True, arch) for f in files]
    runs, failed = [], []
    t0 = time.perf_counter()
    bar = progress.bar(total=len(files), desc=f"{algorithm_id} batch", unit="file", leave=True)
    running = set()
    # fork keeps start-up cheap; taichi is never initialised in the parent, so children are clean
    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
        futures = {}
        for t in tasks:
            futures[pool.submit(_batch_one, t)] = t[1]
            running.add(t[1])
        try:
            _collect_batch(cf, futures, running, runs, failed, bar)
        except BaseException:
            stop_workers(pool, futures)
            for d in reversed(created):  # the folders made for it, if the stopped batch left them empty
                if d.is_dir() and not any(d.iterdir()):
                    d.rmdir()
            raise
    bar.close()
    return {
        "algorithm": alg.id, "plugin": alg.plugin, "version": alg.version,
        "parameters": {k: ("auto" if v is None and alg.parameter(k).allow_auto else v)
                       for k, v in alg.validate_params(params or {}).items()},
        "crs": {"given": crs},
        "n_files": len(files), "n_done": len(runs), "n_failed": len(failed),
        "runs": sorted(runs, key=lambda r: str(r["inputs"])), "failed": failed,
        "timings_s": {"total": round(time.perf_counter() - t0, 3)}, "jobs": jobs,
    }


def stop_workers(pool, futures) -> None:
    """Ctrl-C or SIGTERM during a pool run: cancel what has not started, end the workers (each
    removes what its run had staged), wait for them."""
    for f in futures:
        f.cancel()
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        if proc.is_alive():
            proc.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


def _check_batch_outputs(alg: Algorithm, files: Sequence[str], out: Path, reg: Registry) -> None:
    """Before any file runs: no output is an input, and no two inputs write the same output."""
    owner: dict[str, str] = {}
    optional = {o.name for o in alg.outputs if o.optional}
    for f in files:
        paths = {n: p for n, p in plan_outputs(alg, out, None, Path(f).stem).items() if n not in optional}
        every = files_of(alg, paths, reg.style_dirs)
        check_not_inputs(every, files)
        for p in every:
            key = os.path.realpath(p)
            if key in owner and owner[key] != f:
                raise UsageError(f"inputs {owner[key]!r} and {f!r} would both write {str(p)!r} (same file name); "
                                 "rename one or run them into different folders")
            owner[key] = f


def _collect_batch(cf, futures, running, runs, failed, bar) -> None:
    for fut in cf.as_completed(futures):
        path = futures[fut]
        running.discard(path)
        try:
            path, rep, err = fut.result()
        except Exception as exc:  # the worker died (out of memory, killed)
            rep, err = None, f"worker died: {type(exc).__name__}: {exc}"
        if err is None:
            runs.append(rep)
        else:
            failed.append({"input": path, "error": err})
            log.error("%s: %s", path, err)
        bar.set_postfix_str(f"in progress {len(running)}, done {len(runs)}, failed {len(failed)}")
        bar.update(1)

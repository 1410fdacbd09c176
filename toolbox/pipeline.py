"""Pipeline files (YAML or JSON): algorithms chained, the output of one stage feeding the next.

A pipeline file is data only. It is read with ``yaml.safe_load`` (no tags, no objects) and every
key is checked against the schema below; nothing in it is ever evaluated::

    pipeline:
      - algorithm: synthetic-scene      # required: an algorithm id
        name: scene                     # optional: how later stages refer to this one
        output: work/scene.laz          # optional: a temporary file when left out
        params: {kind: corridor, seed: 1}
      - algorithm: dtm
        inputs: ["@scene"]              # default: the previous stage's primary output
        output: work/dtm.tif
        outputs: {classified: work/classified.laz}
        params: {resolution_m: 1.0}

``@name`` is a stage's primary output and ``@name.output`` one of its named outputs. Relative
paths are relative to the current directory, as on the command line.
"""

from __future__ import annotations

import json
import re
import tempfile
from pathlib import Path
from typing import Any

from .errors import DataError, UsageError

STAGE_KEYS = {"algorithm", "name", "inputs", "output", "outputs", "params"}
_REF = re.compile(r"^@([A-Za-z0-9_-]+)(?:\.([a-z0-9_]+))?$")


def load(path: str | Path) -> list[dict]:
    path = Path(path)
    if not path.exists():
        raise DataError(f"pipeline {str(path)!r} does not exist; check the path")
    text = path.read_text(encoding="utf-8")
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(text)
        else:
            import yaml

            doc = yaml.safe_load(text)
    except Exception as exc:
        raise UsageError(f"pipeline {str(path)!r} is not valid YAML/JSON: {' '.join(str(exc).split())[:200]}") from None
    return validate(doc, str(path))


def validate(doc: Any, where: str = "pipeline") -> list[dict]:
    stages = doc.get("pipeline") if isinstance(doc, dict) else doc
    if isinstance(doc, dict) and set(doc) - {"pipeline"}:
        raise UsageError(f"{where}: unknown top-level key(s) {sorted(set(doc) - {'pipeline'})}; only 'pipeline' is allowed")
    if not isinstance(stages, list) or not stages:
        raise UsageError(f"{where}: expected a non-empty list of stages under 'pipeline'")
    names = set()
    for i, st in enumerate(stages, 1):
        if not isinstance(st, dict):
            raise UsageError(f"{where}: stage {i} is not a mapping")
        extra = set(st) - STAGE_KEYS
        if extra:
            raise UsageError(f"{where}: stage {i} has unknown key(s) {sorted(extra)}; allowed: {sorted(STAGE_KEYS)}")
        if not isinstance(st.get("algorithm"), str):
            raise UsageError(f"{where}: stage {i} needs 'algorithm: <id>'")
        if "inputs" in st and not (isinstance(st["inputs"], list) and all(isinstance(x, str) for x in st["inputs"])):
            raise UsageError(f"{where}: stage {i}: 'inputs' must be a list of paths or @references")
        for key in ("output",):
            if key in st and not isinstance(st[key], str):
                raise UsageError(f"{where}: stage {i}: '{key}' must be a path")
        for key in ("outputs", "params"):
            if key in st and not isinstance(st[key], dict):
                raise UsageError(f"{where}: stage {i}: '{key}' must be a mapping")
        for k, v in (st.get("params") or {}).items():
            if not isinstance(v, (str, int, float, bool)) and v is not None:
                raise UsageError(f"{where}: stage {i}: parameter {k!r} must be a scalar")
        name = st.get("name", f"stage{i}")
        if name in names:
            raise UsageError(f"{where}: two stages are named {name!r}")
        names.add(name)
    return stages


def run(stages: list[dict], *, overwrite: bool = False, crs: str | None = None, reg=None) -> dict:
    """Run validated stages in order; returns {"stages": [report, ...]}."""
    from .registry import registry
    from .runner import run_algorithm

    reg = reg or registry()
    check_plan(stages, reg)
    done: dict[str, dict] = {}
    reports = []
    prev = None
    with tempfile.TemporaryDirectory(prefix="toolbox-pipeline-") as tmp:
        for i, st in enumerate(stages, 1):
            name = st.get("name", f"stage{i}")
            alg = reg.get(st["algorithm"])
            if "inputs" in st:
                inputs = [_resolve(x, done, i) for x in st["inputs"]]
            elif prev is not None and alg.inputs:
                inputs = [_primary(prev)]
            else:
                inputs = []
            output = st.get("output") or str(Path(tmp) / f"{name}{alg.outputs[0].extension}")
            # a pipeline is a job description: the folders it names are made for it
            Path(output).parent.mkdir(parents=True, exist_ok=True)
            try:
                rep = run_algorithm(alg.id, inputs, output, st.get("params") or {},
                                    outputs=st.get("outputs"), overwrite=overwrite, crs=crs, reg=reg)
            except UsageError as exc:
                raise UsageError(f"pipeline stage {i} ({alg.id}): {exc}") from None
            except DataError as exc:
                raise DataError(f"pipeline stage {i} ({alg.id}): {exc}") from None
            rep["stage"] = name
            done[name] = rep
            reports.append(rep)
            prev = rep
        # temporary outputs vanish with the folder; say so in the report
        for rep in reports:
            for info in rep["outputs"].values():
                if info["path"].startswith(tmp):
                    info["path"] = None
    return {"stages": reports}


def check_plan(stages: list[dict], reg) -> None:
    """Everything that can be checked before the first stage runs: algorithms and parameters, each
    reference (to an earlier stage, to an output it writes), the kind of file each input gets, and
    that no two stages write one file."""
    import os

    from .algorithm import OUTPUT_EXTENSIONS
    from .runner import assign_inputs, plan_outputs

    declared: dict[str, tuple] = {}  # stage name -> (algorithm, outputs it writes)
    writers: dict[str, int] = {}
    prev = None
    for i, st in enumerate(stages, 1):
        name = st.get("name", f"stage{i}")
        try:
            alg = reg.get(st["algorithm"])
            alg.validate_params(st.get("params") or {})
        except UsageError as exc:
            raise UsageError(f"pipeline stage {i}: {exc}") from None
        asked = set(st.get("outputs") or {})
        writes = {o.name: o for o in alg.outputs if not o.optional or o.name in asked}
        stand_ins = []  # each input as a file name of its kind (references: the output they name)
        refs = st["inputs"] if "inputs" in st else ([f"@{prev}"] if prev is not None and alg.inputs else [])
        for item in refs:
            m = _REF.match(item)
            if not m:
                if item.startswith("@"):
                    raise UsageError(f"pipeline stage {i}: bad reference {item!r}; use @stage or @stage.output")
                stand_ins.append(item)
                continue
            ref_stage, ref_out = m.groups()
            if ref_stage not in declared:
                raise UsageError(f"pipeline stage {i}: {item!r} refers to a stage that does not run before it")
            ref_alg, ref_writes = declared[ref_stage]
            out = ref_writes.get(ref_out or ref_alg.outputs[0].name)
            if out is None:
                raise UsageError(f"pipeline stage {i}: stage {ref_stage!r} ({ref_alg.id}) writes no output {ref_out!r}; "
                                 f"it writes {sorted(ref_writes)} (an optional one only when asked in its 'outputs')")
            stand_ins.append(f"{ref_stage}.{out.name}{OUTPUT_EXTENSIONS[out.kind][0]}")
        try:
            assign_inputs(alg, stand_ins)
            if st.get("output"):
                stem = Path(stand_ins[0]).stem if stand_ins else None
                paths = plan_outputs(alg, st["output"], st.get("outputs"), stem)
                for out_name, p in paths.items():
                    if out_name not in writes or writes[out_name].kind == "folder":
                        continue
                    key = os.path.realpath(p)
                    if key in writers:
                        raise UsageError(f"stages {writers[key]} and {i} both write {str(p)!r}; give one of them "
                                         "another output")
                    writers[key] = i
        except UsageError as exc:
            raise UsageError(f"pipeline stage {i} ({alg.id}): {exc}") from None
        declared[name] = (alg, writes)
        prev = name


def _primary(rep: dict) -> str:
    first = next(iter(rep["outputs"].values()), None)
    if first is None:
        raise DataError(f"stage {rep.get('stage')} wrote no output to feed the next stage")
    return first["path"]


def _resolve(item: str, done: dict, i: int) -> str:
    m = _REF.match(item)
    if not m:
        if item.startswith("@"):
            raise UsageError(f"pipeline stage {i}: bad reference {item!r}; use @stage or @stage.output")
        return item
    stage, out = m.groups()
    if stage not in done:
        raise UsageError(f"pipeline stage {i}: {item!r} refers to a stage that has not run before it")
    rep = done[stage]
    if out is None:
        return _primary(rep)
    if out not in rep["outputs"]:
        raise UsageError(f"pipeline stage {i}: stage {stage!r} has no output {out!r}; it wrote {sorted(rep['outputs'])}")
    return rep["outputs"][out]["path"]

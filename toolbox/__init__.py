"""lidar-toolbox: a plugin-based GIS processing toolbox for laser-scanning and photogrammetry data.

Python API (mirrors the command line)::

    import toolbox
    toolbox.algorithms()                        # {id: Algorithm}
    toolbox.run("synthetic-scene", [], "scene.laz", kind="corridor", seed=1)
"""

from __future__ import annotations

from .algorithm import Algorithm, Input, LayerMerge, Output, Parameter, Result
from .errors import DataError, NothingFound, PluginError, ToolboxError, UsageError
from .hookspecs import hookimpl

__version__ = "0.1.0"
__all__ = [
    "Algorithm", "Input", "LayerMerge", "Output", "Parameter", "Result", "hookimpl",
    "DataError", "NothingFound", "PluginError", "ToolboxError", "UsageError",
    "algorithms", "broken_plugins", "run", "run_pipeline",
]


def algorithms() -> dict:
    """Every available algorithm by id (plugins discovered through entry points)."""
    from .registry import registry

    return dict(sorted(registry().algorithms.items()))


def broken_plugins() -> list:
    from .registry import registry

    return list(registry().broken)


def run(algorithm_id: str, inputs=(), output=None, *, outputs=None, overwrite: bool = False,
        crs: str | None = None, **params) -> dict:
    """Run an algorithm on files, write its outputs, return the run report (as ``--json`` prints).

    ``inputs``: a path, a list of paths or ``{input name: path}``; ``output``: the primary output
    path (or a folder); ``outputs``: ``{output name: path}`` for the others; ``params``: the
    algorithm's parameters (validated; defaults fill the rest).
    """
    from .runner import run_algorithm

    if isinstance(inputs, (str, bytes)) or hasattr(inputs, "__fspath__"):
        inputs = [inputs]
    return run_algorithm(algorithm_id, inputs, output, params, outputs=outputs, overwrite=overwrite, crs=crs)


def run_pipeline(path, *, overwrite: bool = False) -> dict:
    """Run a pipeline file (YAML or JSON); returns {"stages": [report, ...]}."""
    from . import pipeline

    return pipeline.run(pipeline.load(path), overwrite=overwrite)

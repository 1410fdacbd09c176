"""Plugins for registry tests: good ones, broken ones, clashing ones (loaded by entry point)."""

import numpy as np

import toolbox
from toolbox import Algorithm, Input, Output, Parameter


def _echo(inputs, params, ctx):
    pc = inputs["points"]
    pc.require_points("echo")
    cls = np.full(len(pc), params["value"], np.uint8)
    return {"points": pc.with_fields(classification=cls)}


def _fail_midway(inputs, params, ctx):
    raise RuntimeError("boom in the middle")


def _emit_then_fail(inputs, params, ctx):
    """Hands its output over early (written in the background), then fails."""
    import time

    pc = inputs["points"]
    ctx.emit("points", pc.with_fields(classification=np.full(len(pc), 3, np.uint8)))
    time.sleep(0.5)  # the background write completes meanwhile
    raise RuntimeError("boom after emitting")


def _emit_then_finish(inputs, params, ctx):
    pc = inputs["points"]
    out = pc.with_fields(classification=np.full(len(pc), params["value"], np.uint8))
    ctx.emit("points", out)
    _ = pc.fields["intensity"]  # reading the source while its record is being written
    return {"points": out}


def _raster_of(pc):
    from affine import Affine

    from toolbox.io.rasters import Raster

    w, s, e, n = pc.bounds()
    return Raster(np.ones((8, 8), np.float32), Affine((e - w) / 8, 0, w, 0, -(n - s) / 8, n), crs=pc.crs)


def _emit_raster(inputs, params, ctx):
    """Hands a raster over early (GDAL writes it in a background thread), then fails or finishes."""
    import time

    pc = inputs["points"]
    ctx.emit("grid", _raster_of(pc))
    time.sleep(0.5)  # the background write completes meanwhile
    if params["mode"] == "exact":
        raise RuntimeError("boom after emitting a raster")
    return {"grid": _raster_of(pc), "points": pc.with_fields(classification=np.full(len(pc), 4, np.uint8))}


def _alg(id_, run=_echo):
    return Algorithm(
        id=id_, title="test " + id_, description="test algorithm", run=run,
        parameters=[Parameter("value", int, 1, "class to set", minimum=0, maximum=255),
                    Parameter("cell_size_m", float, 0.5, "cell", unit="m", minimum=0.0, exclusive_minimum=True,
                              maximum=100.0),
                    Parameter("mode", str, "fast", "mode", choices=("fast", "exact"))],
        inputs=[Input("points", "points", "a cloud")],
        outputs=[Output("points", "points", "the cloud, classified")],
    )


class Good:
    @toolbox.hookimpl
    def toolbox_algorithms(self):
        return [_alg("echo-class"), _alg("fail-midway", _fail_midway)]


class Emitting:
    @toolbox.hookimpl
    def toolbox_algorithms(self):
        with_raster = _alg("emit-raster", _emit_raster)
        with_raster.outputs = [*with_raster.outputs, Output("grid", "raster", "a grid", suffix="_grid")]
        return [_alg("emit-then-fail", _emit_then_fail), _alg("emit-then-finish", _emit_then_finish), with_raster]


class Clash:
    @toolbox.hookimpl
    def toolbox_algorithms(self):
        return [_alg("echo-class")]


class Raises:
    @toolbox.hookimpl
    def toolbox_algorithms(self):
        raise ValueError("this plugin is broken on purpose")


class WrongType:
    @toolbox.hookimpl
    def toolbox_algorithms(self):
        return ["not an algorithm"]


class ExitsInHook:
    @toolbox.hookimpl
    def toolbox_algorithms(self):
        import sys

        sys.exit(4)


good = Good()
exits_in_hook = ExitsInHook()
emitting = Emitting()
clash = Clash()
raises = Raises()
wrong_type = WrongType()

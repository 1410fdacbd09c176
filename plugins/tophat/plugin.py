"""Adapter of the top-hat plugin: ``tophat`` (the method's point filter) and ``tophat-raster``."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, DataError, Input, Output, Parameter

REFERENCE = ("Grigillo, Ozvaldič, Vrečko, Kosmatin Fras (2015), Extraction of power lines from airborne and "
             "terrestrial laser scanning data using the Hough transform, Geodetski vestnik 59(2) 246-261 (§2 of "
             "METHODS.md §1)")


def _run_points(inputs, params, ctx):
    import numpy as np

    from toolbox.io.points import PointCloud

    from .core import structure, tophat_points

    pc = inputs["points"]
    pc.require_points("tophat")
    cell = params["cell_size_m"] / pc.horizontal_unit_m
    w, s, e, n = pc.bounds()
    if (e - w) / cell * (n - s) / cell > 2**62:  # flat cell indices are int64
        raise toolbox.UsageError(f"cell_size_m: a {params['cell_size_m']} m mask over {pc.source!r} is too big; "
                                 "tile the input or use a larger cell")
    # the centroid's height: mean of the cell's points (kept for the 3D steps downstream)
    cx, cy, cz, counts, _ = tophat_points(pc.x, pc.y, cell, params["max_points_per_cell"],
                                          structure(params["structure"], params["size_cells"]), z=pc.z)
    out = PointCloud(cx, cy, cz, fields={"point_count": counts.astype(np.uint16)}, crs=pc.crs,
                     source=f"tophat({pc.source})", horizontal_unit_m=pc.horizontal_unit_m,
                     vertical_unit_m=pc.vertical_unit_m)
    return toolbox.Result({"points": out}, stats={"n_in": len(pc), "n_out": len(out), "cells_kept": len(out)})


def _run_raster(inputs, params, ctx):
    from toolbox.io.rasters import Raster

    from .core import structure, tophat_raster

    r = inputs["image"]
    band = r.bands()[0]
    if band.size == 0:
        raise DataError(f"input {r.source!r} is empty")
    res = tophat_raster(band, params["mode"], structure(params["structure"], params["size_cells"]), params["threshold"])
    style = "mask" if params["mode"] == "binary" else "height"
    return {"tophat": Raster(res, r.transform, crs=r.crs, nodata=None, style=style, description="white top-hat")}


SHAPE = Parameter("structure", str, "cross", "structuring element (the method: 3x3 cross)",
                  choices=("cross", "square", "disk"))
SIZE = Parameter("size_cells", int, 3, "structuring element size", unit="cells", minimum=3, maximum=101)


@toolbox.hookimpl
def toolbox_algorithms():
    return [
        Algorithm(
            id="tophat", title="Top-hat point filter (thin structures)", run=_run_points,
            # survey runs: the opening's reach on the mask (its cells are on a fixed lattice)
            tile_buffer_m=lambda p: p["size_cells"] * p["cell_size_m"],
            description=("Binary raster of occupied cells, opening with the structuring element, top-hat = mask - "
                         "opening; in each top-hat cell fewer than max_points_per_cell points are replaced by their "
                         "centroid, denser cells (vegetation) are dropped. Leaves about 2 points per metre of wire."),
            reference=REFERENCE,
            parameters=[
                Parameter("cell_size_m", float, 0.5, "cell of the binary mask", unit="m", minimum=0.01, maximum=100.0),
                Parameter("max_points_per_cell", int, 45, "cells with this many points or more are dropped",
                          unit="points", minimum=1),
                SHAPE, SIZE,
            ],
            inputs=[Input("points", "points", "candidate points (e.g. unclassified, first returns, height window)")],
            outputs=[Output("points", "points", "one centroid per kept cell; point_count = points it replaces")],
        ),
        Algorithm(
            id="tophat-raster", title="Top-hat of a raster (binary or grey)", run=_run_raster,
            description="White top-hat of a GeoTIFF: image - opening (grey), or mask - opening of image > threshold.",
            reference="Serra (1982), Image analysis and mathematical morphology; " + REFERENCE,
            parameters=[
                Parameter("mode", str, "grey", "grey-level or binary top-hat", choices=("grey", "binary")),
                Parameter("threshold", float, 0.0, "binary mode: cells above this value are 1"),
                SHAPE, SIZE,
            ],
            inputs=[Input("image", "raster", "a GeoTIFF")],
            outputs=[Output("tophat", "raster", "the top-hat", style="height")],
        ),
    ]

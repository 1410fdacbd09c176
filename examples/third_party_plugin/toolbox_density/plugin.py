"""Hooks of the example plugin: one algorithm and a style directory."""

from __future__ import annotations

from pathlib import Path

import toolbox
from toolbox import Algorithm, DataError, Input, Output, Parameter


def _run(inputs, params, ctx):
    from affine import Affine

    from toolbox.io.rasters import Raster

    from .core import density_grid

    pc = inputs["points"]
    pc.require_points("point-density")
    keep = slice(None)
    if params["returns"] != "all":
        rn = pc.fields.get("return_number")
        nr = pc.fields.get("number_of_returns")
        if rn is None or nr is None or not rn.any():
            raise DataError(f"input {pc.source!r} has no return numbers; use returns=all")
        keep = rn == 1 if params["returns"] == "first" else rn == nr
    cell = pc.to_units(params["cell_size_m"])
    dens, (west, north) = density_grid(pc.x[keep], pc.y[keep], cell)
    dens_m2 = dens / (pc.horizontal_unit_m ** 2)
    ctx.stats["mean_density_ppm2"] = float(dens_m2[dens_m2 > 0].mean()) if (dens_m2 > 0).any() else 0.0
    return {"density": Raster(dens_m2, Affine(cell, 0, west, 0, -cell, north), crs=pc.crs, nodata=None,
                              style="point_density")}


@toolbox.hookimpl
def toolbox_algorithms():
    return [Algorithm(
        id="point-density",
        title="Point density raster",
        run=_run,
        description="Counts points per cell and writes the density in points per square metre.",
        reference="(example plugin) density as in lidR::grid_density and PDAL filters.hexbin",
        parameters=[
            Parameter("cell_size_m", float, 1.0, "cell size", unit="m", minimum=0.05, maximum=1000.0),
            Parameter("returns", str, "all", "which returns to count", choices=("all", "first", "last")),
        ],
        inputs=[Input("points", "points", "LAS/LAZ point cloud")],
        outputs=[Output("density", "raster", "points per square metre", style="point_density")],
    )]


@toolbox.hookimpl
def toolbox_style_dirs():
    return [Path(__file__).parent / "styles"]

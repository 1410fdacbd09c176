"""Adapter of the roofs plugin: ``roof-planes`` (3D Hough with a ball accumulator). The computing
lives in ``core`` (pure functions), the voting in ``kernels`` (taichi) and ``reference`` (numpy)."""

from __future__ import annotations

import toolbox
from toolbox import Algorithm, DataError, NothingFound, Input, LayerMerge, Output, Parameter, UsageError

REFERENCE = ("Borowiec, Hough transform as a tool supporting building roof detection (METHODS.md §3); "
             "Borrmann, Elseberg, Lingemann, Nüchter (2011), The 3D Hough Transform for plane detection in "
             "point clouds: a review and a new accumulator design, 3D Research 2(2)")
BUILDING_CELL_M = 1.0  # buildings are the 8-connected groups of 1 m cells holding roof points
RAM_SHARE = 0.25  # default accumulator budget: this share of the machine's memory


def _buildings(x, y, cell):
    """Building number per point (1..n): 8-connected groups of occupied ``cell`` cells, numbered
    as a raster scan labels them. Only the occupied cells are held (no grid over the extent: one
    point kilometres away costs nothing)."""
    import numpy as np
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    c = ((x - x.min()) / cell).astype(np.int64)
    r = ((y - y.min()) / cell).astype(np.int64)
    width = int(c.max()) + 2  # a column of slack: no neighbour key wraps into the next row
    keys, cell_of = np.unique(r * width + c, return_inverse=True)
    a, b = [], []
    for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):  # each pair of 8-neighbours once
        want = keys + dr * width + dc
        at = np.minimum(np.searchsorted(keys, want), len(keys) - 1)
        hit = keys[at] == want
        a.append(np.flatnonzero(hit))
        b.append(at[hit])
    a, b = np.concatenate(a), np.concatenate(b)
    graph = coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(len(keys), len(keys)))
    # components numbered from the lowest key up: the order of a raster scan's first cells
    n, comp = connected_components(graph, directed=False)
    return comp[cell_of.ravel()] + 1, n


def _roof_points(pc, params, ctx):
    """(mask of roof points, where they came from)."""
    import numpy as np

    source = params["source"]
    cls = pc.classification
    if source == "auto":
        source = "classified" if cls is not None and np.any(cls == 6) else "detect"
    if source == "all":
        return np.ones(len(pc), bool), "all"
    if source == "classified":
        if cls is None or not np.any(cls == 6):
            raise NothingFound(f"input {pc.source!r} has no building class (6); use source=detect or source=all")
        return cls == 6, "classified"
    res = ctx.call("classify", {"points": pc})
    return np.asarray(res.outputs["classified"].classification) == 6, "detect"


def _run(inputs, params, ctx):
    import time

    import geopandas as gpd
    import numpy as np

    from . import core, reference

    pc = inputs["points"]
    pc.require_points("roof-planes", 3)
    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    t0 = time.perf_counter()
    roof, source = _roof_points(pc, params, ctx)
    idx = np.flatnonzero(roof)
    # isotropic coordinates in the horizontal unit (a survey in feet: z may be in other units)
    xyz = np.column_stack([pc.x[idx], pc.y[idx], pc.z[idx] * vu / hu])
    if len(idx):
        bid, n_b = _buildings(xyz[:, 0], xyz[:, 1], BUILDING_CELL_M / hu)
    else:
        bid, n_b = np.zeros(0, np.int64), 0
    angle = params["angle_step_deg"]
    rho = params["rho_step_m"] / hu
    min_points = params["min_points"]
    order = np.argsort(bid, kind="stable")
    bounds = np.searchsorted(bid[order], np.arange(1, n_b + 2))
    groups = [order[bounds[b]:bounds[b + 1]] for b in range(n_b)]
    groups = [(b + 1, g) for b, g in enumerate(groups) if len(g) >= min_points]
    # the accumulator of the largest building, before anything is allocated
    from toolbox.memory import total_ram_bytes

    budget = (params["max_accumulator_mb"] * 2**20 if params["max_accumulator_mb"] is not None
              else RAM_SHARE * total_ram_bytes())
    _check_accumulators(pc, xyz, groups, angle, rho, budget)
    spacing = core.mean_spacing_xy(xyz[:, :2]) if len(xyz) >= 2 else float("nan")
    link = params["link_m"] / hu if params["link_m"] is not None else max(1.0 / hu, 4 * spacing)
    voter = reference.vote
    if groups:
        from .kernels import TaichiVoter

        voter = TaichiVoter(ctx.taichi())
    plane_id = np.zeros(len(pc), np.int32)
    rows, geoms = [], []
    line_rows, line_geoms = [], []
    next_id = 1
    reg_counts: dict = {}
    for b, g in ctx.progress(groups, desc="roof-planes", unit="building"):
        planes = core.detect_planes(xyz[g], angle, rho, params["max_distance_m"] / hu, min_points, link, voter,
                                    normal_tol_deg=params["normal_tol_deg"] or None, min_width=link)
        planes, reg = core.regularise_planes(xyz[g], planes, params["regularise_sigma"])
        for k, v in reg.items():
            reg_counts[k] = reg_counts.get(k, 0) + v
        n = _building_layers(xyz[g], planes, int(b), next_id, params, (spacing, link, hu, vu),
                             (rows, geoms, line_rows, line_geoms))
        for k, pl in enumerate(planes):
            plane_id[idx[g[pl.indices]]] = next_id + k
        next_id += n
    if rows:
        gdf = gpd.GeoDataFrame(rows, geometry=geoms, crs=pc.crs)
    else:
        gdf = gpd.GeoDataFrame({"plane_id": np.array([], np.int64)}, geometry=gpd.GeoSeries([], crs=pc.crs), crs=pc.crs)
    gdf.attrs["geometry_type"] = "Polygon Z"
    if line_rows:
        lines = gpd.GeoDataFrame(line_rows, geometry=line_geoms, crs=pc.crs)
    else:
        lines = gpd.GeoDataFrame({"kind": np.array([], str)}, geometry=gpd.GeoSeries([], crs=pc.crs), crs=pc.crs)
    lines.attrs["geometry_type"] = "LineString Z"
    on_plane = int((plane_id > 0).sum())
    stats = {"source": source, "n_roof_points": int(len(idx)), "n_buildings": len(groups), "n_planes": next_id - 1,
             "points_on_planes": on_plane, "share_on_planes": round(on_plane / max(len(idx), 1), 4),
             "point_spacing_m": round(spacing * hu, 3) if np.isfinite(spacing) else None,
             "link_m_used": round(link * hu, 3), "max_accumulator_mb_used": round(budget / 2**20, 1), "regularised": reg_counts, "accumulator_cells": len(reference.ball_cells(angle)),
             "seconds": round(time.perf_counter() - t0, 3)}
    stats["n_roof_lines"] = {k: sum(r["kind"] == k for r in line_rows) for k in ("ridge", "hip", "valley", "break", "step")}
    return toolbox.Result({"planes": {"roof_planes": gdf, "roof_lines": lines}, "classified": pc.with_fields(plane_id=plane_id)},
                          stats=stats)


def _check_accumulators(pc, xyz, groups, angle, rho, budget) -> None:
    """Refuse a building whose ball accumulator would pass ``budget`` bytes, before any is made."""
    import numpy as np

    from . import core

    hu = pc.horizontal_unit_m
    for b, g in groups:
        p = xyz[g] - xyz[g].mean(axis=0)
        radius = float(np.sqrt((p * p).sum(axis=1).max()))
        need = core.accumulator_bytes(angle, radius, rho)
        if need > budget:
            raise UsageError(
                f"roof-planes: the ball accumulator of building {b} in {pc.source!r} ({radius * hu:.0f} m across "
                f"from its centre) would take {need / 2**20:.0f} MiB, over the budget of {budget / 2**20:.0f} MiB; "
                f"raise angle_step_deg or rho_step_m (or max_accumulator_mb)")


def _building_layers(pts_b, planes, b: int, first_id: int, params, scale, out) -> int:
    """One building's planes (outlines: concave hulls lifted onto each plane) and roof lines
    (ridges, hips, valleys, breaks, steps) appended to ``out`` (plane rows, plane geometries, line
    rows, line geometries), the planes numbered from ``first_id``. Returns the number of planes."""
    import numpy as np
    import shapely
    from shapely.geometry import LineString, MultiPoint, Polygon

    from . import core

    spacing, link, hu, vu = scale
    rows, geoms, line_rows, line_geoms = out
    hulls = []
    for pl in planes:
        pts = pts_b[pl.indices]
        hull = shapely.concave_hull(MultiPoint(pts[:, :2]), ratio=params["hull_ratio"])
        if not isinstance(hull, Polygon) or hull.is_empty:
            hull = MultiPoint(pts[:, :2]).convex_hull
            if not isinstance(hull, Polygon):
                hull = hull.buffer(0.5 * spacing)
        hulls.append(hull)
    pairs = core.adjacent_pairs(pts_b, planes, link)
    meets = core.roof_lines(pts_b, planes, link, pairs=pairs)
    steps = core.step_edges(pts_b, planes, hulls, link, 2 * params["max_distance_m"] / hu, pairs=pairs,
                            skip_pairs={(ln.plane_a, ln.plane_b) for ln in meets})
    for ln in meets + steps:
        line_geoms.append(LineString([(*ln.start[:2], ln.start[2] * hu / vu), (*ln.end[:2], ln.end[2] * hu / vu)]))
        line_rows.append({"kind": ln.kind, "building_id": b, "plane_a": first_id + ln.plane_a,
                          "plane_b": first_id + ln.plane_b,
                          "length_m": round(float(np.linalg.norm(ln.end - ln.start)) * hu, 3)})
    for k, (pl, hull) in enumerate(zip(planes, hulls)):
        pts = pts_b[pl.indices]
        n = pl.normal
        ring = np.asarray(hull.exterior.coords)
        zr = (pl.d - ring[:, 0] * n[0] - ring[:, 1] * n[1]) / n[2] if n[2] > 0.05 else np.full(len(ring), pts[:, 2].mean())
        geoms.append(Polygon(np.column_stack([ring, zr * hu / vu])))
        slope, aspect = core.plane_attributes(n)
        rows.append({"plane_id": first_id + k, "building_id": b, "normal_x": float(n[0]), "normal_y": float(n[1]),
                     "normal_z": float(n[2]), "d": float(pl.d * hu), "slope_deg": round(slope, 3),
                     "aspect_deg": round(aspect, 3), "n_points": int(len(pl.indices)),
                     "rms_m": round(pl.rms * hu, 4), "area_m2": round(hull.area * hu * hu / max(n[2], 1e-6), 2)})
    return len(planes)


MASK_BYTES_PER_CELL = 16  # the building mask, its labels and the morphology's temporaries


def _check_mask_grid(pc, rows: int, cols: int, cell_size_m: float) -> None:
    """Refuse a building mask too large for memory before it is allocated."""
    from toolbox.memory import total_ram_bytes

    budget = RAM_SHARE * total_ram_bytes()
    need = float(rows) * float(cols) * MASK_BYTES_PER_CELL
    if need > budget:
        raise UsageError(f"building-edges: the {cell_size_m:g} m mask over the building points of {pc.source!r} "
                         f"({cols * cell_size_m:.0f} x {rows * cell_size_m:.0f} m) would take {need / 2**30:.1f} GiB, "
                         f"over {budget / 2**30:.1f} GiB; use a larger cell_size_m or run it in tiles (--tile-size-m)")


def _run_edges(inputs, params, ctx):
    import time

    import geopandas as gpd
    import numpy as np
    from affine import Affine
    from scipy import ndimage

    from . import edges

    pc = inputs["points"]
    pc.require_points("building-edges", 3)
    hu = pc.horizontal_unit_m
    t0 = time.perf_counter()
    cell = params["cell_size_m"] / hu
    roof, height, source = _edge_roof_points(pc, params, ctx)
    idx = np.flatnonzero(roof)
    if len(idx) < 3:
        raise NothingFound(f"input {pc.source!r}: no building points found (source={source}); check min_height_m or "
                        "the classes")
    x, y = pc.x[idx], pc.y[idx]
    west, north, rows, cols = edges.mask_grid(x, y, cell)
    _check_mask_grid(pc, rows, cols, params["cell_size_m"])
    mask = edges.clean_mask(edges.rasterise(x, y, west, north, rows, cols, cell))
    if source == "height" and params["erosions"] > 0:
        # the method's erosions take off what is narrower than a building (crowns, hedges); the same
        # number of dilations gives the buildings their size back
        k = params["erosions"]
        mask = ndimage.binary_dilation(ndimage.binary_erosion(mask, iterations=k), iterations=k) & mask
    lab, n_lab = ndimage.label(mask, structure=np.ones((3, 3), bool))
    c = np.clip(((x - west) / cell).astype(np.int64), 0, cols - 1)
    r = np.clip(((north - y) / cell).astype(np.int64), 0, rows - 1)
    pt_lab = lab[r, c]
    transform = Affine(cell, 0, west, 0, -cell, north)
    min_area = params["min_area_m2"] / (hu * hu)
    out_rows, out_geoms, e_rows, e_geoms = [], [], [], []
    bid = 0
    sizes = np.bincount(lab.ravel(), minlength=n_lab + 1)
    boxes = ndimage.find_objects(lab)
    order = np.argsort(pt_lab, kind="stable")
    first = np.searchsorted(pt_lab[order], np.arange(n_lab + 2))
    for b in ctx.progress(range(1, n_lab + 1), desc="building-edges", unit="building"):
        if sizes[b] * cell * cell < min_area:
            continue
        members = order[first[b]:first[b + 1]]
        if len(members) < 3:
            continue
        rs, cs = boxes[b - 1]
        r0, r1, c0, c1 = max(rs.start - 2, 0), rs.stop + 2, max(cs.start - 2, 0), cs.stop + 2
        edge = edges.edge_pixels(lab[r0:r1, c0:c1] == b)
        lines, my_edges = _outline_edges(ctx, pc, edge, transform @ Affine.translation(c0, r0), params["cell_size_m"])
        direction = edges.refine_direction(x[members], y[members], edges.dominant_direction(lines))
        poly = edges.regular_outline(x[members], y[members], direction, cell, min_area=min_area)
        if poly is None:
            continue
        bid += 1
        for line, votes, length in my_edges:  # only a building with an outline keeps its edges
            e_geoms.append(line)
            e_rows.append({"building_id": bid, "votes": votes, "length_m": length})
        out_geoms.append(poly)
        hb = float(np.percentile(height[idx[members]], 95)) * hu if height is not None else None
        out_rows.append({"building_id": bid, "area_m2": round(float(poly.area) * hu * hu, 2),
                         "height_m": round(hb, 2) if hb is not None else None, "n_points": int(len(members)),
                         "direction_deg": round(float(np.degrees(direction)), 2), "n_edges": len(lines)})
    def frame(rows_, geoms_, kind):
        if rows_:
            f = gpd.GeoDataFrame(rows_, geometry=geoms_, crs=pc.crs)
        else:
            f = gpd.GeoDataFrame({"building_id": np.array([], np.int64)}, geometry=gpd.GeoSeries([], crs=pc.crs),
                                 crs=pc.crs)
        f.attrs["geometry_type"] = kind
        return f

    layers = {"building_outlines": frame(out_rows, out_geoms, "Polygon"), "roof_edges": frame(e_rows, e_geoms, "LineString")}
    # a building outline may come out in parts (a MultiPolygon): GeoPackage layers hold one type
    layers["building_outlines"] = layers["building_outlines"].explode(index_parts=False).reset_index(drop=True)
    layers["building_outlines"].attrs["geometry_type"] = "Polygon"
    return toolbox.Result({"outlines": layers}, stats={"source": source, "n_buildings": bid, "n_edges": len(e_rows),
                                                     "seconds": round(time.perf_counter() - t0, 3)})


def _edge_roof_points(pc, params, ctx):
    """(mask of the building points, their heights above the terrain or None, the source used)
    for building-edges."""
    import numpy as np

    hu, vu = pc.horizontal_unit_m, pc.vertical_unit_m
    cls = pc.classification
    source = params["source"]
    height = None
    if source != "all":
        # heights above the terrain: the file's ground when it has one, else the ground filter's
        has_ground = cls is not None and np.any(cls == 2)
        dtm = ctx.call("dtm", {"points": pc}, ground="file" if has_ground else "filter", resolution_m=1.0).outputs["dtm"]
        height = (pc.z - dtm.sample(pc.x, pc.y)) * vu / hu
    if source == "auto":
        source = "classified" if cls is not None and np.any(cls == 6) else "height"
    if source == "all":
        return np.ones(len(pc), bool), height, source
    if source == "classified":
        if cls is None or not np.any(cls == 6):
            raise NothingFound(f"input {pc.source!r} has no building class (6); use source=height or source=detect")
        return cls == 6, height, source
    if source == "detect":
        return np.asarray(ctx.call("classify", {"points": pc}).outputs["classified"].classification) == 6, height, source
    # the method: last returns above a height threshold
    last = np.ones(len(pc), bool)
    if "return_number" in pc.fields and "number_of_returns" in pc.fields:
        last = np.asarray(pc.fields["return_number"]) == np.asarray(pc.fields["number_of_returns"])
    return last & (height >= params["min_height_m"] / hu), height, source


def _outline_edges(ctx, pc, edge, transform, cell_size_m: float):
    """The straight edges of one building's outline pixels (``edge``, placed by ``transform``)
    through hough-lines-raster: ([(direction rad, votes)], [(LineString, votes, length m)])."""
    import numpy as np
    from shapely.geometry import LineString

    from toolbox.io.rasters import Raster

    lines, my_edges = [], []
    if edge.sum() < 4:
        return lines, my_edges
    img = Raster(edge.astype(np.uint8), transform, crs=pc.crs)
    try:
        res = ctx.call("hough-lines-raster", {"image": img}, theta_step_deg=0.5, rho_step_m=cell_size_m,
                       band_m=cell_size_m, min_votes=max(4, int(round(2.0 / cell_size_m))),
                       s_min_m=2.0, v_max_m=2 * cell_size_m, tile_size_m=0.0)
        found = res.outputs["lines"]["conductors"]
    except DataError:
        found = []
    for row in (found.itertuples() if len(found) else []):
        xy = np.asarray(row.geometry.coords)
        lines.append((float(np.arctan2(xy[-1, 1] - xy[0, 1], xy[-1, 0] - xy[0, 0])), float(row.votes)))
        my_edges.append((LineString(xy), int(row.votes), round(float(row.geometry.length) * pc.horizontal_unit_m, 3)))
    return lines, my_edges


# survey runs: the classify step's ground (the DTM's 60 m) and a building reaching that far beyond
# the tile's border, whole in the tile that keeps it (an outline or plane by its representative point)
SURVEY_BUFFER_M = 60.0


@toolbox.hookimpl
def toolbox_algorithms():
    return [Algorithm(
        id="building-edges", title="Building outlines (raster edges, 2D Hough, regularised)", run=_run_edges,
        description=(
            "The method's raster route: building cells on a grid (the file's class 6, buildings found by classify, "
            "or, as the method, last returns above min_height_m with erosions taking off what is narrower than a "
            "building), the edge pixels (the mask minus its erosion) of each building into the 2D Hough "
            "(hough-lines-raster, through the host), and an outline regularised to the building's dominant "
            "direction (the vote-weighted direction of its Hough lines, walls at right angles are one direction): "
            "the building's points rasterised again in a frame turned to it, so walls come out straight and "
            "corners square. Layers building_outlines (Polygon: area, height above the terrain, points, "
            "direction) and roof_edges (the Hough lines)."),
        reference=REFERENCE,
        tile_buffer_m=SURVEY_BUFFER_M,
        parameters=[
            Parameter("source", str, "auto", "building cells from the file's class 6 (classified), from classify "
                      "(detect), from last-return heights (height, the method), or every point (all: a roof-only "
                      "cut-out; no height above the terrain then); auto: classified when the file has class 6, else "
                      "height", choices=("auto", "classified", "detect", "height", "all")),
            Parameter("cell_size_m", float, 0.5, "cell of the building mask", unit="m", minimum=0.05, maximum=10.0),
            Parameter("min_height_m", float, 2.5, "source=height: lowest building cell above the terrain", unit="m",
                      minimum=0.0, maximum=500.0),
            Parameter("erosions", int, 2, "source=height: erosions (then as many dilations) that take off "
                      "vegetation", unit="cells", minimum=0, maximum=50),
            Parameter("min_area_m2", float, 10.0, "smallest building", unit="m2", minimum=0.0, maximum=1e7),
        ],
        inputs=[Input("points", "points", "LAS/LAZ point cloud")],
        outputs=[Output("outlines", "vector", "layers building_outlines and roof_edges", style="building_outlines",
                        # a building wider than the buffer is seen in parts: each tile's part, clipped to
                        # its core, joins its neighbours'
                        merge={"building_outlines": LayerMerge(id_field="building_id", dissolve=True, join_tolerance_m=1.0,
                                                               combine={"area_m2": "area_m2", "height_m": "max"}),
                               "roof_edges": LayerMerge(refs={"building_id": "building_outlines"})})],
    ), Algorithm(
        id="roof-planes", title="Roof planes (3D Hough, ball accumulator)", run=_run,
        description=(
            "Every roof point votes for the planes through it, ρ = x·cosθ·cosφ + y·sinθ·cosφ + z·sinφ, in a ball "
            "accumulator (cells of nearly equal area on the sphere, Borrmann et al. 2011) per building; the "
            "fullest cell is refitted by least squares, grown to the points within max_distance_m, split into "
            "connected patches (link_m), and each patch of min_points or more is a plane whose votes are taken "
            "back; repeated while a cell holds min_points votes. Points then go to the nearest plane they touch, "
            "near-duplicate planes merge; a plane narrower than link_m (a strip along a ridge) is dropped; faces are "
            "regularised within their own fit's uncertainty (levelled, aspects on the building's axes, equal "
            "slopes shared; regularise_sigma). Roof points: the file's class 6 (source=classified), buildings found by "
            "classify (detect), or every point of the input (all); auto takes class 6 when the file has it. "
            "Where two adjacent faces meet, their intersection clipped to both is a roof line (ridge, hip, valley, "
            "break); where a face stands over an adjacent lower one without meeting it, the part of its outline "
            "along the lower one is a step line. Writes the planes as PolygonZ (normal, d, slope, aspect, rms, building) and the input with a "
            "plane_id dimension (0: on no plane)."),
        reference=REFERENCE,
        tile_buffer_m=SURVEY_BUFFER_M,
        parameters=[
            Parameter("source", str, "auto", "where the roof points come from", choices=("auto", "classified",
                                                                                         "detect", "all")),
            Parameter("angle_step_deg", float, 2.0, "angular size of an accumulator cell (the refit, not the "
                      "cell, sets the normal's accuracy)", unit="deg", minimum=0.1, maximum=30.0),
            Parameter("rho_step_m", float, 0.2, "ρ bin of the accumulator", unit="m", minimum=0.005, maximum=10.0),
            Parameter("max_distance_m", float, 0.15, "largest distance of a point from its plane", unit="m",
                      minimum=0.001, maximum=10.0),
            Parameter("min_points", int, 15, "smallest plane", unit="points", minimum=3),
            Parameter("normal_tol_deg", float, 10.0, "a point joins a plane only when the plane through its 10 "
                      "nearest points is this close to it (what tells a face from a slice across faces); 0: "
                      "distance alone, as the method", unit="deg", minimum=0.0, maximum=90.0),
            Parameter("link_m", float, None, "points closer than this in plan belong to one patch; coplanar "
                      "patches further apart are separate planes (auto: 4 x the point spacing, at least 1 m; "
                      "reported as link_m_used)", unit="m", minimum=0.01, maximum=100.0, allow_auto=True),
            Parameter("regularise_sigma", float, 3.0, "faces made regular where their points cannot tell "
                      "otherwise: levelled, aspects on the building's axes, equal slopes shared, each within this "
                      "many standard errors of the face's own fit (0: off)", minimum=0.0, maximum=10.0),
            Parameter("hull_ratio", float, 0.3, "concave hull of a face's points (0 most concave, 1 convex)",
                      minimum=0.0, maximum=1.0),
            Parameter("max_accumulator_mb", float, None, "memory an accumulator may take (auto: a quarter of "
                      "this machine's RAM); above it the run stops and says which resolution to lower",
                      unit="MiB", minimum=1.0, maximum=1e7, allow_auto=True),
        ],
        inputs=[Input("points", "points", "LAS/LAZ or ASCII point cloud (buildings as class 6, or one roof)")],
        outputs=[
            Output("planes", "vector", "layers roof_planes (one PolygonZ per face) and roof_lines (LineStringZ "
                   "where adjacent faces meet: ridge, hip, valley or break; step where a face stands over a "
                   "lower one it does not meet)", style="roof_planes"),
            Output("classified", "points", "the input with plane_id (int32, 0 = on no plane)", suffix="_classified"),
        ],
    )]

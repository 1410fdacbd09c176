"""Synthetic ALS survey scenes with exact truth.

``make_scene(kind, seed, ...)`` returns a :class:`Scene`: points (x, y, z and LAS fields, the
classification being the truth), the true DTM grid, and truth records for every object
(buildings and their roof planes, trees, pylons, wires and their catenaries, conductor 2D
lines and their crossings, water). Deterministic: the same arguments give the same arrays.

The sensor model is a nadir ALS: pulses fall uniformly over the area; each pulse gives one
return on open ground, roofs, water (rarely) or the bridge deck, and up to four returns in tree
crowns (first on the crown surface, then inside, the last one on the ground when it gets
through). Wires and pylons are hit along their length (footprint scatter across them), and the
pulse goes on to the ground, as a real sensor records it. A few low outliers sit under ground.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .objects import (
    Building,
    Trees,
    catenary_sag,
    catenary_z,
    compound_building,
    lattice_tower,
    sample_segments,
    vegetation_class,
    wood_pole,
)
from .terrain import Terrain, _line_frame

KINDS = ("corridor", "terrain", "roofs")
ROOF_SETS = ("basic", "all")  # all (kind=roofs): also pyramid, shed, mansard, gambrel, L, T and cross-shaped
# buildings, and trees whose crowns reach over some eaves
DEFAULT_SPAN_M = 185.0  # the distance between towers of the double-circuit and stacked lines
DEFAULT_EXTENT = {"corridor": (600.0, 250.0), "terrain": (400.0, 300.0), "roofs": (160.0, 120.0)}

# ASPRS classes used here
GROUND, LOW_VEG, MED_VEG, HIGH_VEG, BUILDING, NOISE, WATER, WIRE, TOWER, BRIDGE = 2, 3, 4, 5, 6, 7, 9, 14, 15, 17


@dataclass
class Scene:
    kind: str
    seed: int
    origin: tuple[float, float]
    extent: tuple[float, float]
    crs: str
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    fields: dict
    dtm: np.ndarray  # (rows, cols), north-up, cell centres
    dtm_resolution_m: float
    truth: dict = field(default_factory=dict)
    terrain: Terrain | None = None

    @property
    def dtm_transform(self):
        from affine import Affine

        ox, oy = self.origin
        return Affine(self.dtm_resolution_m, 0, ox, 0, -self.dtm_resolution_m, oy + self.extent[1])


class _Points:
    """Collects points of the pulses as they are generated."""

    def __init__(self):
        self.parts = []

    def add(self, u, v, z, cls, ret, nret, pulse, obj=-1, plane=-1, intensity=None):
        n = len(u)
        if n == 0:
            return
        full = lambda val, dt: np.broadcast_to(np.asarray(val, dt), (n,)).copy()  # noqa: E731
        self.parts.append(dict(
            u=np.asarray(u, float), v=np.asarray(v, float), z=np.asarray(z, float),
            cls=full(cls, np.uint8), ret=full(ret, np.uint8), nret=full(nret, np.uint8),
            pulse=full(pulse, np.float64), obj=full(obj, np.int32), plane=full(plane, np.int32),
            intensity=full(0 if intensity is None else intensity, np.uint16),
        ))

    def concat(self):
        return {k: np.concatenate([p[k] for p in self.parts]) for k in self.parts[0]}


LINE_VARIANTS = ("double-circuit", "stacked", "ribbon", "distribution")
SCANNERS = ("airborne", "mobile")


def make_scene(kind: str = "corridor", seed: int = 1, density_ppm2: float = 12.0, noise_m: float = 0.03,
               width_m: float | None = None, height_m: float | None = None, dtm_resolution_m: float = 1.0,
               origin=(512000.0, 5403000.0), crs: str = "EPSG:25832", line_variant: str = "double-circuit",
               phase_spacing_m: float = 0.6, bundle: int = 2, bundle_spacing_m: float = 0.6,
               roof_set: str = "basic", span_m: float | None = None, slope_pct: float = 0.0,
               scanner: str = "airborne", track_offset_m: float = 6.0, full_density_range_m: float = 10.0,
               comm_cables: int = 0, comm_spacing_m: float = 0.3) -> Scene:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}")
    if roof_set not in ROOF_SETS:
        raise ValueError(f"roof_set must be one of {ROOF_SETS}")
    W, H = DEFAULT_EXTENT[kind] if roof_set == "basic" or kind != "roofs" else (300.0, 220.0)
    W = float(width_m or W)
    H = float(height_m or H)
    rng = np.random.default_rng(seed)
    terrain = Terrain.random(W, H, rng, features=(kind != "roofs"), tilt=slope_pct / 100.0)
    if kind == "roofs":
        terrain.hills = [(h[0], h[1], h[2] * 0.3, h[3] * 1.5) for h in terrain.hills]
    truth: dict = {"buildings": [], "roof_planes": [], "trees": [], "pylons": [], "wires": [], "spans": [],
                   "conductor_lines_2d": [], "crossings": [], "water": None, "bridge": None}
    if line_variant not in LINE_VARIANTS:
        raise ValueError(f"line_variant must be one of {LINE_VARIANTS}")
    if scanner not in SCANNERS or (scanner == "mobile" and kind != "corridor"):
        raise ValueError(f"scanner must be one of {SCANNERS} (mobile: corridor scenes only)")
    lines = _scene_lines(kind, line_variant, W, H, rng, terrain, (phase_spacing_m, comm_cables, comm_spacing_m,
                                                                  bundle, bundle_spacing_m, span_m))
    buildings = _place_buildings(kind, W, H, rng, terrain, lines, roof_set)
    trees = _place_trees(kind, W, H, rng, terrain, buildings, lines)
    n_eave_trees = 0
    if kind == "roofs" and roof_set == "all":
        trees, n_eave_trees = _add_eave_trees(trees, buildings, terrain, rng)

    pts = _Points()
    # ---- pulses: uniform over the area ------------------------------------------------
    n_pulses = rng.poisson(density_ppm2 * W * H)
    u = rng.uniform(0, W, n_pulses)
    v = rng.uniform(0, H, n_pulses)
    pulse_id = _gps_time(u, v, H)
    zg = terrain.height(u, v)
    taken = np.zeros(n_pulses, bool)

    # buildings (single returns on the roof)
    _roof_returns(pts, buildings, trees, n_eave_trees, u, v, taken, pulse_id, rng, noise_m)

    _deck_and_water_returns(pts, terrain, u, v, taken, pulse_id, rng, noise_m)

    # vegetation: multiple returns
    if len(trees):
        _vegetation_returns(pts, trees, u, v, zg, taken, pulse_id, rng, noise_m)

    # open ground
    og = ~taken
    pts.add(u[og], v[og], zg[og] + rng.normal(0, noise_m, og.sum()), GROUND, 1, 1, pulse_id[og],
            intensity=rng.integers(300, 900, og.sum()))

    # ---- wires and pylons ---------------------------------------------------------------
    spacing = 1.2 / np.sqrt(density_ppm2)  # along-wire spacing of hits, as scan lines cross a wire
    wire_id = 0
    for line in lines:
        _add_line(line, terrain, rng, pts, truth, spacing, noise_m, wire_id, origin)
        wire_id += 100

    _outlier_returns(pts, terrain, W, H, n_pulses, rng)

    allp = pts.concat()
    if scanner == "mobile":
        allp = _mobile_thinning(allp, lines[0], terrain, rng, track_offset_m, full_density_range_m)
    # a tower outside the scene holds its wires' ends but is not surveyed: its points (and the
    # ground under them) are clipped as the wires' are (after the thinning's draws, which stay)
    inside = (allp["u"] >= 0) & (allp["u"] <= W) & (allp["v"] >= 0) & (allp["v"] <= H)
    allp = {k: val[inside] for k, val in allp.items()}
    order = np.lexsort((allp["ret"], allp["pulse"]))  # acquisition order: by pulse, then return
    allp = {k: val[order] for k, val in allp.items()}
    ox, oy = origin
    fields = _las_fields(allp)

    # ---- truth ---------------------------------------------------------------------------
    dtm = _truth_dtm(terrain, W, H, dtm_resolution_m)
    _object_truth(truth, buildings, trees, terrain, allp, origin)
    _crossings(truth)
    if scanner == "mobile":
        _mobile_truth(truth, allp, origin, _track(lines[0], track_offset_m, origin), full_density_range_m)
    u_all, v_all = allp["u"], allp["v"]
    cls_all = allp["cls"]
    vals, counts = np.unique(cls_all, return_counts=True)
    truth["class_counts"] = {int(a): int(b) for a, b in zip(vals, counts)}
    truth["n_points"] = int(len(u_all))
    truth["n_pulses"] = int(n_pulses)
    return Scene(kind, seed, (ox, oy), (W, H), crs, u_all + ox, v_all + oy, allp["z"], fields, dtm,
                 dtm_resolution_m, truth, terrain)


def _scene_lines(kind, line_variant, W, H, rng, terrain, shape) -> list:
    """The scene's power lines (none but on a corridor) with their supports placed."""
    phase_spacing_m, comm_cables, comm_spacing_m, bundle, bundle_spacing_m, span_m = shape
    if kind != "corridor":
        lines = []
    elif line_variant == "ribbon":
        lines = _ribbon_lines(W, H, rng, terrain, phase_spacing_m)
    elif line_variant == "distribution":
        lines = _distribution_lines(W, H, rng, terrain, comm_cables, comm_spacing_m)
    else:
        lines = _power_lines(kind, W, H, rng, terrain, bundle, bundle_spacing_m, span_m=span_m,
                             stacked=line_variant == "stacked")
    for line in lines:
        line["towers"] = _supports_at_brows(line, terrain, others=[o for o in lines if o is not line])
    return lines


def _deck_and_water_returns(pts, terrain, u, v, taken, pulse_id, rng, noise_m) -> None:
    """The bridge deck's returns, and the few a specular pond sends back; ``taken`` marks both."""
    if terrain.embankment is not None and terrain.embankment.bridge_at is not None:
        deck = terrain.embankment.deck_mask(u, v) & ~taken & (terrain.embankment.raise_m(u, v) < terrain.embankment.height_m - 0.05)
        pts.add(u[deck], v[deck], terrain.deck_height(u[deck], v[deck]) + rng.normal(0, noise_m, deck.sum()),
                BRIDGE, 1, 1, pulse_id[deck], obj=9000, intensity=700)
        taken |= deck
    water = terrain.water_mask(u, v) & ~taken
    back = water & (rng.uniform(0, 1, len(u)) < 0.04)
    pts.add(u[back], v[back], terrain.pond_level_m + rng.normal(0, noise_m, back.sum()) if back.any() else [],
            WATER, 1, 1, pulse_id[back], obj=9100, intensity=rng.integers(20, 80, back.sum()))
    taken |= water


def _outlier_returns(pts, terrain, W, H, n_pulses, rng) -> None:
    """Outliers below the ground (multipath) and a few birds high over it."""
    n_low = max(3, int(n_pulses * 5e-5))
    lu, lv = rng.uniform(0, W, n_low), rng.uniform(0, H, n_low)
    pts.add(lu, lv, terrain.height(lu, lv) - rng.uniform(1.0, 15.0, n_low), NOISE, 1, 1, _gps_time(lu, lv, H), intensity=30)
    n_high = max(2, n_low // 4)
    hu, hv = rng.uniform(0, W, n_high), rng.uniform(0, H, n_high)
    pts.add(hu, hv, terrain.height(hu, hv) + rng.uniform(45.0, 90.0, n_high), NOISE, 1, 1, _gps_time(hu, hv, H), intensity=30)


def _las_fields(allp) -> dict:
    """The point fields written to the LAS file."""
    return {
        "classification": allp["cls"],
        "return_number": allp["ret"],
        "number_of_returns": allp["nret"],
        "intensity": allp["intensity"],
        "gps_time": allp["pulse"],
        "point_source_id": (1 + (allp["v"] // 80.0)).astype(np.uint16),
        "object_id": allp["obj"],
        "plane_id": allp["plane"],
    }


def _truth_dtm(terrain, W, H, resolution_m) -> np.ndarray:
    """The terrain's heights at the cell centres of the truth DTM (north up)."""
    cols = int(np.ceil(W / resolution_m))
    rows = int(np.ceil(H / resolution_m))
    cu = (np.arange(cols) + 0.5) * resolution_m
    cv = H - (np.arange(rows) + 0.5) * resolution_m
    UU, VV = np.meshgrid(cu, cv)
    return terrain.height(UU, VV).astype(np.float32)


def _mobile_truth(truth, allp, origin, track, full_density_range_m) -> None:
    """What the mobile scanner's thinning left of each span, and the scanner's track."""
    for sp in truth["spans"]:
        a, b = np.asarray(sp["a"][:2]) - origin, np.asarray(sp["b"][:2]) - origin
        t = ((allp["u"] - a[0]) * (b - a)[0] + (allp["v"] - a[1]) * (b - a)[1]) / max(sp["length_m"], 1e-9) ** 2
        sp["n_points"] = int(np.sum((allp["obj"] == sp["wire_id"]) & (t >= 0) & (t < 1)))
    truth["scanner"] = {"kind": "mobile", "track": track, "height_over_ground_m": MOBILE_TRACK_HEIGHT_M,
                        "full_density_range_m": full_density_range_m}


MOBILE_TRACK_HEIGHT_M = 2.0  # a car-mounted scanner's head over the road


def _roof_returns(pts, buildings, trees, n_eave_trees: int, u, v, taken, pulse_id, rng, noise_m: float) -> None:
    """The pulses not ``taken`` that fall on a roof: one return (two under a crown over the eave,
    the last ``n_eave_trees`` trees), with the roof plane's id, added to ``pts``; each building's
    ``_plane_base`` set; ``taken`` marks them."""
    plane_base = 0
    for b in buildings:
        inside = b.contains(u, v) & ~taken
        zr, face = b.roof_height(u[inside], v[inside])
        i_in = np.flatnonzero(inside)
        roof_hit, nret = np.ones(len(zr), bool), np.ones(len(zr), np.uint8)
        if n_eave_trees:  # a crown over the eave: its top is the first return, the roof (if reached) the last
            cz, ck = _crown_top(trees, len(trees) - n_eave_trees, u[inside], v[inside])
            over = cz > zr + 0.1
            roof_hit = ~over | (rng.uniform(0, 1, len(zr)) < 0.5)
            nret = np.where(over & roof_hit, 2, 1)
            pts.add(u[i_in[over]], v[i_in[over]], cz[over] - np.abs(rng.normal(0, 0.2, over.sum())),
                    trees.asprs[ck[over]], 1, nret[over], pulse_id[i_in[over]], obj=trees.first_id + ck[over],
                    intensity=rng.integers(150, 600, over.sum()))
        h = i_in[roof_hit]
        pts.add(u[h], v[h], zr[roof_hit] + rng.normal(0, noise_m, len(h)), BUILDING, nret[roof_hit], nret[roof_hit],
                pulse_id[h], obj=b.id, plane=np.where(face[roof_hit] >= 0, plane_base + face[roof_hit], -1), intensity=rng.integers(900, 1400, len(h)))
        b._plane_base = plane_base
        plane_base += len(b.faces)
        taken |= inside


def _object_truth(truth: dict, buildings, trees, terrain, allp: dict, origin) -> None:
    """The truth records of the buildings (and their roof planes with the points on each), the
    trees, the water and the bridge, in world coordinates (``origin`` added)."""
    ox, oy = origin
    for b in buildings:
        truth["buildings"].append({
            "id": b.id, "roof": b.roof, "footprint": (b.footprint_uv() + origin).tolist(),
            "length_m": b.length_m, "width_m": b.width_m, "heading_deg": float(np.degrees(b.heading_rad)),
            "eave_z": b.base_z + b.eave_m, "pitch_deg": b.pitch_deg,
            **({"parapet_height_m": b.parapet[0], "parapet_thickness_m": b.parapet[1]} if getattr(b, "parapet", None) else {}),
            "top_z": b.roof_top(),
        })
        for j, f in enumerate(b.faces):
            n, d = b.face_plane_world(f, origin)
            poly = b.face_polygon_uv(f)
            from shapely import affinity

            poly = affinity.translate(poly, ox, oy)
            truth["roof_planes"].append({
                "plane_id": b._plane_base + j, "building_id": b.id, "face": f.name,
                "normal": n.tolist(), "offset": d, "slope_deg": float(np.degrees(np.arccos(n[2]))),
                "polygon_wkt": poly.wkt,
                "n_points": int(np.sum(allp["plane"] == b._plane_base + j)),
            })
    for k in range(len(trees)):
        truth["trees"].append({
            "id": int(trees.first_id + k), "x": float(trees.u[k] + ox), "y": float(trees.v[k] + oy),
            "ground_z": float(trees.ground[k]), "top_z": float(trees.top[k]), "radius_m": float(trees.radius[k]),
            "conifer": bool(trees.conifer[k]), "asprs_class": int(trees.asprs[k]),
        })
    if terrain.pond is not None:
        cu_, cv_, ru, rv = terrain.pond
        ang = np.linspace(0, 2 * np.pi, 65)
        truth["water"] = {"level_z": terrain.pond_level_m,
                          "ring": np.column_stack([cu_ + ox + ru * np.cos(ang), cv_ + oy + rv * np.sin(ang)]).tolist()}
    if terrain.embankment is not None:
        e = terrain.embankment
        truth["bridge"] = {"axis": [[e.p0[0] + ox, e.p0[1] + oy], [e.p1[0] + ox, e.p1[1] + oy]],
                           "opening_at_m": e.bridge_at, "height_m": e.height_m}


def _vegetation_returns(pts, trees, u, v, zg, taken, pulse_id, rng, noise_m: float) -> None:
    """The pulses (``u``, ``v``; ground ``zg``) not ``taken`` that fall in a crown: up to four
    returns through it, some reaching the ground, added to ``pts``; ``taken`` marks them."""
    from scipy.spatial import cKDTree

    tree_index = cKDTree(np.column_stack([trees.u, trees.v]))
    free = np.flatnonzero(~taken)
    k = min(4, len(trees))
    reach = float(trees.radius.max())
    # only the pulses with a crown centre in their cell or the next (cells as wide as the largest
    # crown's radius) can fall in a crown: the others are not searched (the same neighbours result)
    at = np.flatnonzero(_near_centres(u[free], v[free], trees.u, trees.v, reach))
    near = free[at]
    dist = np.full((len(free), k), np.inf)
    idx = np.full((len(free), k), len(trees))
    d_near, i_near = tree_index.query(np.column_stack([u[near], v[near]]), k=k, distance_upper_bound=reach)
    dist[at], idx[at] = d_near.reshape(len(near), k), i_near.reshape(len(near), k)
    best_top = np.full(len(free), -np.inf)
    best_k = np.full(len(free), -1)
    for j in range(k):
        ok = idx[:, j] < len(trees)
        kk = np.where(ok, idx[:, j], 0)
        inside = np.flatnonzero(ok & (dist[:, j] < trees.radius[kk]))
        ztop, _ = trees.surfaces(kk[inside], dist[inside, j])
        better = ztop > best_top[inside]
        best_top[inside[better]] = ztop[better]
        best_k[inside[better]] = kk[inside[better]]
    hit = best_k >= 0
    pi = free[hit]
    tk = best_k[hit]
    r = np.hypot(u[pi] - trees.u[tk], v[pi] - trees.v[tk])
    ztop, zbot = trees.surfaces(tk, r)
    n_ret = rng.choice([1, 2, 3, 4], size=len(pi), p=[0.25, 0.35, 0.28, 0.12])
    reaches_ground = (n_ret >= 2) & (rng.uniform(0, 1, len(pi)) < np.where(trees.conifer[tk], 0.45, 0.6))
    n_veg = n_ret - reaches_ground
    first = ztop - np.abs(rng.normal(0, 0.25, len(pi)))
    first = np.maximum(first, zbot)
    cls = trees.asprs[tk]
    for rnum in range(1, 5):
        sel = n_veg >= rnum
        if not sel.any():
            continue
        if rnum == 1:
            zz = first[sel]
        else:  # inside the crown, lower with each return
            frac = np.sort(rng.uniform(0, 1, (sel.sum(), 3)), axis=1)[:, rnum - 2]
            zz = first[sel] - frac * (first[sel] - zbot[sel])
        pts.add(u[pi[sel]], v[pi[sel]], zz + rng.normal(0, noise_m, sel.sum()), cls[sel], rnum, n_ret[sel],
                pulse_id[pi[sel]], obj=trees.first_id + tk[sel], intensity=rng.integers(150, 600, sel.sum()))
    g = reaches_ground
    pts.add(u[pi[g]], v[pi[g]], zg[pi[g]] + rng.normal(0, noise_m, g.sum()), GROUND, n_ret[g], n_ret[g],
            pulse_id[pi[g]], intensity=rng.integers(100, 400, g.sum()))
    taken[pi] = True


def _near_centres(u, v, cu, cv, reach_m: float) -> np.ndarray:
    """Mask of the points (``u``, ``v``) that may have a centre (``cu``, ``cv``) within
    ``reach_m``: on a grid of cells ``reach_m`` wide, those with a centre in their cell or one of
    the eight around it (a centre nearer than ``reach_m`` is never further away)."""
    if not len(u):
        return np.zeros(0, bool)
    x0, y0 = min(u.min(), cu.min()), min(v.min(), cv.min())
    cell = max(reach_m, 1e-6)
    # indices from 1, so that the cells around every centre's lie on the grid
    ci, cj = ((cu - x0) // cell).astype(np.int64) + 1, ((cv - y0) // cell).astype(np.int64) + 1
    pi, pj = ((u - x0) // cell).astype(np.int64) + 1, ((v - y0) // cell).astype(np.int64) + 1
    marked = np.zeros((max(ci.max(), pi.max()) + 2, max(cj.max(), pj.max()) + 2), bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            marked[ci + di, cj + dj] = True
    return marked[pi, pj]


def _track_frame(line, offset_m):
    """The scanner's track in plan: a point on it, its direction (line A's) and its left normal;
    ``offset_m`` beside line A (a road along it)."""
    d = np.asarray(line["dir"], float)
    across = np.array([-d[1], d[0]])
    return np.asarray(line["towers"][0], float) + across * offset_m, d, across


def _track(line, offset_m, origin=(0.0, 0.0)):
    """The track's ends (well past the scene) in world coordinates, for the truth."""
    t0, d, _ = _track_frame(line, offset_m)
    return [(t0 - d * 1e4 + origin).tolist(), (t0 + d * 1e4 + origin).tolist()]


def _mobile_thinning(allp, line, terrain, rng, offset_m, full_range_m):
    """A car-mounted scanner driving beside line A: each point is kept with probability
    min(1, (full_range_m / r)^2), r its range from the scanner head (2 m over the ground under the
    track), as the density of a profile scanner falls with range; so wires overhead are seen from
    below, dense near the road, and roofs and crowns further off thin out."""
    t0, d, across = _track_frame(line, offset_m)
    du, dv = allp["u"] - t0[0], allp["v"] - t0[1]
    along = du * d[0] + dv * d[1]
    lateral = du * across[0] + dv * across[1]
    foot = t0[None, :] + along[:, None] * d[None, :]
    head = terrain.height(foot[:, 0], foot[:, 1]) + MOBILE_TRACK_HEIGHT_M
    r = np.hypot(lateral, allp["z"] - head)
    keep = rng.uniform(0, 1, len(r)) < np.minimum(1.0, (full_range_m / np.maximum(r, 1e-3)) ** 2)
    return {k: v[keep] for k, v in allp.items()}


def _gps_time(u, v, H):
    """Acquisition time: 80 m wide strips flown west to east at 60 m/s, strips one after another."""
    strip = np.floor(v / 80.0)
    return 1.0e5 + strip * 40.0 + u / 60.0 + (v - strip * 80.0) * 1e-5


# ------------------------------------------------------------------------------------------
# layout
# ------------------------------------------------------------------------------------------

def bundle_offsets(n: int, spacing_m: float):
    """(across, up) offsets of the sub-conductors of a bundle of ``n``: side by side for 2, a
    triangle (two below, one above) for 3, a square for 4 (as spacers hold them)."""
    h = 0.5 * spacing_m
    return {1: [(0.0, 0.0)], 2: [(-h, 0.0), (h, 0.0)],
            3: [(-h, 0.0), (h, 0.0), (0.0, spacing_m * np.sqrt(3) / 2)],
            4: [(-h, 0.0), (h, 0.0), (-h, spacing_m), (h, spacing_m)]}[n]


def _power_lines(kind, W, H, rng, terrain, bundle: int = 2, bundle_spacing_m: float = 0.6,
                 span_m: float | None = None, stacked: bool = False):
    """Line A: a straight double-circuit transmission line across the scene (lattice towers,
    phases in bundles of ``bundle`` sub-conductors ``bundle_spacing_m`` apart, an earth wire;
    ``stacked``: each circuit's three phases one above another, 5 m apart, on one side of the
    tower), spans of ``span_m`` (default 185 m). Line B: a distribution line on wood poles
    crossing it at a sharp angle, lower."""
    lines = []
    ang_a = np.radians(rng.uniform(3, 8))
    a0 = np.array([-40.0, 0.42 * H - 0.5 * W * np.tan(ang_a)])
    dir_a = np.array([np.cos(ang_a), np.sin(ang_a)])
    span = DEFAULT_SPAN_M if span_m is None else float(span_m)
    towers = [a0 + dir_a * (60.0 + k * span) for k in range(int((W + 200.0) / span) + 2)]
    towers = [t for t in towers if -20 < t[0] < W + 20]
    model = lattice_tower(height_m=38.0, arms=((21.0, 6.0), (26.0, 6.0), (31.0, 6.0)), earth_z=38.0) \
        if stacked else lattice_tower()
    wires = []
    for arm in [a for a in model.attachments if a.startswith("arm")]:
        for dx, dz in bundle_offsets(bundle, bundle_spacing_m):
            wires.append({"attach": arm, "dx": dx, "dz": dz, "kind": "phase", "c": 1300.0})
    wires.append({"attach": "earth", "dx": 0.0, "kind": "earth", "c": 1600.0})
    lines.append({"name": "A", "model": model, "towers": towers, "dir": dir_a, "wires": wires, "voltage_kv": 110})
    # line B: crosses A at 20-30 degrees, near the middle of the scene
    ang_b = ang_a + np.radians(rng.uniform(20, 30))
    mid = a0 + dir_a * (0.5 * W / np.cos(ang_a) + 40.0)
    dir_b = np.array([np.cos(ang_b), np.sin(ang_b)])
    poles = []
    for k in range(-6, 7):
        # a pole that would stand in the ditch, the pond or on the embankment moves along the line
        for shift in (0.0, 6.0, -6.0, 12.0, -12.0, 18.0, -18.0, 24.0, -24.0):
            p = mid + dir_b * (-35.0 + 70.0 * k + shift)
            if 5 < p[0] < W - 5 and 5 < p[1] < H - 5 and not terrain.excluded(p[0], p[1], 1.0):
                poles.append(p)
                break
    lines.append({"name": "B", "model": wood_pole(), "towers": poles, "dir": dir_b,
                  "wires": [{"attach": a, "dx": 0.0, "kind": "phase", "c": 700.0} for a in ("L", "C", "R")],
                  "voltage_kv": 20})
    return lines


def _ribbon_lines(W, H, rng, terrain, spacing_m):
    """Line A: a compact three-phase line, its phases side by side ``spacing_m`` apart at one
    height about 11 m over the ground (a horizontal ribbon of wires). Line B: two conductors on
    taller poles crossing above it at 30-40 degrees."""
    from .objects import compact_pole

    ang_a = np.radians(rng.uniform(3, 8))
    a0 = np.array([-20.0, 0.45 * H - 0.5 * W * np.tan(ang_a)])
    dir_a = np.array([np.cos(ang_a), np.sin(ang_a)])
    model = compact_pole(11.0, 3, spacing_m)
    poles_a = _poles_along(a0, dir_a, 30.0, 75.0, W, H, terrain)
    wires_a = [{"attach": f"P{i}", "dx": 0.0, "kind": "phase", "c": 900.0} for i in range(3)]
    ang_b = ang_a + np.radians(rng.uniform(30, 40))
    mid = a0 + dir_a * (0.5 * W / np.cos(ang_a) + 20.0)
    dir_b = np.array([np.cos(ang_b), np.sin(ang_b)])
    start_b = mid - dir_b * 300.0
    poles_b = _poles_along(start_b, dir_b, 35.0, 80.0, W, H, terrain)
    return [{"name": "A", "model": model, "towers": poles_a, "dir": dir_a, "wires": wires_a, "voltage_kv": 20},
            {"name": "B", "model": wood_pole(16.0, 2.0), "towers": poles_b, "dir": dir_b,
             "wires": [{"attach": a, "dx": 0.0, "kind": "phase", "c": 800.0} for a in ("L", "R")], "voltage_kv": 20}]


def _distribution_lines(W, H, rng, terrain, comm_cables: int = 0, comm_spacing_m: float = 0.3):
    """Line A: a medium-voltage line, three wires on 9 m poles, spans of 40-50 m, trees trimmed
    2-3 m below its wires and a row of trees beside it. Line B: a low-voltage line, two wires on
    7 m poles, crossing it at 60-80 degrees; with ``comm_cables``, its poles are 8 m joint-use
    poles carrying that many communication cables one above another, ``comm_spacing_m`` apart,
    the highest 0.8 m under its wires."""
    from .objects import joint_use_pole

    ang_a = np.radians(rng.uniform(3, 8))
    a0 = np.array([-20.0, 0.45 * H - 0.5 * W * np.tan(ang_a)])
    dir_a = np.array([np.cos(ang_a), np.sin(ang_a)])
    poles_a = _poles_along(a0, dir_a, 25.0, rng.uniform(40.0, 50.0), W, H, terrain)
    ang_b = ang_a + np.radians(rng.uniform(60, 80))
    mid = a0 + dir_a * (0.5 * W / np.cos(ang_a) + 20.0)
    dir_b = np.array([np.cos(ang_b), np.sin(ang_b)])
    poles_b = _poles_along(mid - dir_b * 300.0, dir_b, 22.0, 40.0, W, H, terrain)
    return [{"name": "A", "model": wood_pole(9.0, 1.4), "towers": poles_a, "dir": dir_a, "voltage_kv": 10,
             "wires": [{"attach": a, "dx": 0.0, "kind": "phase", "c": 500.0} for a in ("L", "C", "R")],
             "trim_m": (5.0, 6.0), "tree_row_m": (4.0, 8.0)},
            {"name": "B", "model": joint_use_pole(8.0, 0.6, comm_cables, comm_spacing_m) if comm_cables
             else wood_pole(7.0, 0.6), "towers": poles_b, "dir": dir_b, "voltage_kv": 0.4,
             "wires": [{"attach": a, "dx": 0.0, "kind": "phase", "c": 400.0} for a in ("L", "R")]
             + [{"attach": f"T{k}", "dx": 0.0, "kind": "communication", "c": 400.0} for k in range(comm_cables)]}]


def _poles_along(start, direction, first_m, span_m, W, H, terrain):
    """Poles every ``span_m`` along a line, inside the scene, moved along it off excluded ground
    (the ditch, the pond, the embankment)."""
    poles = []
    for k in range(0, 40):
        for shift in (0.0, 6.0, -6.0, 12.0, -12.0):
            p = start + direction * (first_m + span_m * k + shift)
            if 5 < p[0] < W - 5 and 5 < p[1] < H - 5 and not terrain.excluded(p[0], p[1], 1.0):
                poles.append(p)
                break
    return poles


def _line_distance(u, v, line):
    p, d = line["towers"][0], line["dir"]
    return np.abs(_line_frame(u, v, p[0], p[1], p[0] + d[0], p[1] + d[1])[0])


def _place_buildings(kind, W, H, rng, terrain, lines, roof_set="basic"):
    specs = []
    if kind == "roofs":
        specs = [("hip_dormer", 16.0, 11.0), ("hip", 14.0, 10.0), ("gable", 12.0, 9.0), ("flat", 22.0, 14.0),
                 ("gable", 30.0, 18.0), ("hip", 11.0, 9.0), ("flat", 5.0, 4.0), ("gable", 9.0, 7.0)]
        if roof_set == "all":
            specs += [("pyramid", 10.0, 10.0), ("shed", 12.0, 8.0), ("mansard", 16.0, 12.0), ("gambrel", 14.0, 10.0),
                      ("L", 18.0, 9.0), ("T", 20.0, 10.0), ("cross", 18.0, 9.0), ("L", 15.0, 8.0), ("T", 16.0, 9.0),
                      ("flat_parapet", 20.0, 14.0), ("flat_parapet", 12.0, 9.0)]
    else:
        specs = [("hip_dormer", 16.0, 11.0), ("flat", 60.0, 40.0), ("gable", 34.0, 20.0), ("hip", 14.0, 10.0),
                 ("gable", 12.0, 9.0), ("hip", 12.0, 9.5), ("gable", 10.0, 8.0), ("flat", 18.0, 12.0),
                 ("flat", 4.0, 3.0), ("gable", 5.0, 4.0), ("flat", 3.5, 3.0), ("gable", 11.0, 8.5),
                 ("hip", 13.0, 10.0), ("flat", 25.0, 15.0)]
    placed: list[Building] = []
    want_near = bool(lines)  # one house stands next to line A
    for roof, L, Wd in specs:
        if L + 16 > min(W, H):  # does not fit, with its 8 m margins, in a small scene
            continue
        near = want_near and roof in ("gable", "hip") and L <= 14
        for _try in range(400):
            heading = np.pi / 2 if roof == "hip_dormer" else rng.uniform(0, np.pi)  # test building: faces E/W
            cu, cv = rng.uniform(L / 2 + 8, W - L / 2 - 8), rng.uniform(L / 2 + 8, H - L / 2 - 8)
            if roof in ("L", "T", "cross"):
                style = "gable" if len(placed) % 2 else "hip"
                b = compound_building(len(placed) + 1, roof, style, cu, cv, L, Wd, heading, rng)
            else:
                b = Building(len(placed) + 1, cu, cv, L, Wd, heading, 0.0, roof)
            fp = b.footprint_uv()
            ring = np.vstack([fp, fp.mean(0), (fp + fp.mean(0)) / 2])
            if terrain.excluded(ring[:, 0], ring[:, 1], 3.0).any():
                continue
            if any(o.contains(ring[:, 0], ring[:, 1], margin=6.0).any() or
                   b.contains(*o.footprint_uv().T, margin=6.0).any() for o in placed):
                continue
            ok = True
            for line in lines:
                dmin = _line_distance(ring[:, 0], ring[:, 1], line).min()
                ok &= (13.0 <= dmin <= 22.0) if (near and line["name"] == "A") else (dmin > 25.0)
                towers = np.array(line["towers"]).reshape(-1, 2)
                if len(towers) and np.min(np.hypot(towers[:, 0] - cu, towers[:, 1] - cv)) < L + 10:
                    ok = False
            if ok:
                want_near = want_near and not near
                break
        else:
            continue
        eave = {"flat": rng.uniform(3.0, 10.0) if L > 15 else rng.uniform(2.4, 3.5),
                "gable": rng.uniform(3.0, 8.0), "hip": rng.uniform(4.0, 7.0), "hip_dormer": 6.0}[roof] \
            if roof in ("flat", "gable", "hip", "hip_dormer") else float(rng.uniform(3.0, 6.0))
        if L <= 5:
            eave = rng.uniform(2.3, 3.0)
        b.eave_m = float(eave)
        if roof in ("L", "T", "cross"):
            b.pitch_deg = float(rng.uniform(25, 40))
        elif roof in ("flat", "gable", "hip", "hip_dormer"):
            b.pitch_deg = {"flat": 0.0, "gable": rng.uniform(25, 42) if L < 20 else rng.uniform(12, 20),
                           "hip": rng.uniform(28, 40), "hip_dormer": 35.0}[roof]
        elif roof == "flat_parapet":
            b.pitch_deg = 0.0
            b.parapet = (float(rng.uniform(0.4, 1.0)), float(rng.uniform(0.25, 0.4)))
        elif roof in ("pyramid", "shed"):
            b.pitch_deg = float(rng.uniform(20, 35) if roof == "pyramid" else rng.uniform(8, 18))
        else:  # mansard, gambrel: steep below the break, shallow above
            b.pitch_deg = float(rng.uniform(55, 70))
            b.upper_pitch_deg = float(rng.uniform(15, 30))
            b.break_inset_m = float(rng.uniform(1.2, 2.0))
        fpx = np.vstack([b.footprint_uv(), [[cu, cv]]])
        b.base_z = float(terrain.height(fpx[:, 0], fpx[:, 1]).max())
        if roof == "hip_dormer":
            # gable dormer on the north (in the building frame) main face, below the main ridge
            t = np.tan(np.radians(b.pitch_deg))
            b.dormer = (-0.15 * L, 2.6, Wd / 2 - 1.2, b.eave_m + t * (Wd / 2) - 0.9, 40.0)
        b.build_faces()
        placed.append(b)
    return placed


def _add_eave_trees(trees, buildings, terrain, rng):
    """Trees beside about half the buildings, crowns reaching over the eave (0.1-0.5 of the crown's
    radius inside the wall) and topping it by 1-4 m: the case that tests a roof filter's edges."""
    from shapely.geometry import Point, Polygon

    rows = []
    outlines = [Polygon(b.footprint_uv()) for b in buildings]
    for b, poly in zip(buildings, outlines):
        if rng.uniform() < 0.5:
            continue
        ring = np.asarray(poly.exterior.coords)
        k = int(rng.integers(0, len(ring) - 1))
        p0, p1 = ring[k], ring[k + 1]
        if np.hypot(*(p1 - p0)) < 4.0:
            continue
        mid = p0 + (p1 - p0) * rng.uniform(0.3, 0.7)
        nrm = np.array([p1[1] - p0[1], p0[0] - p1[0]]) / np.hypot(*(p1 - p0))
        if poly.contains(Point(*(mid + 0.1 * nrm))):
            nrm = -nrm
        radius = rng.uniform(2.5, 4.5)
        c = mid + nrm * radius * rng.uniform(0.5, 0.9)
        if any(o.distance(Point(*c)) < 0.5 for o in outlines) or terrain.excluded(c[:1], c[1:], 1.0).any():
            continue
        ground = float(terrain.height(c[:1], c[1:])[0])
        height = b.base_z + b.eave_m - ground + rng.uniform(1.0, 4.0)
        rows.append((c[0], c[1], ground, height, radius, rng.uniform() < 0.3))
    if not rows:
        return trees, 0
    u, v, g, h, r, con = (np.array(c) for c in zip(*rows))
    add = dict(u=u, v=v, ground=g, top=g + h, base=g + 0.3 * h, radius=r, conifer=con.astype(bool),
               asprs=vegetation_class(h))
    return Trees(**{k: np.r_[getattr(trees, k), add[k]] for k in add}, first_id=trees.first_id), len(rows)


def _crown_top(trees, first, u, v):
    """The highest crown top of trees[first:] over each point (-inf where none) and its tree."""
    best = np.full(len(u), -np.inf)
    which = np.zeros(len(u), int)
    for k in range(first, len(trees)):
        r = np.hypot(u - trees.u[k], v - trees.v[k])
        zt, _ = trees.surfaces(k, r)
        zt = np.where(r < trees.radius[k], zt, -np.inf)
        better = zt > best
        best, which = np.where(better, zt, best), np.where(better, k, which)
    return best, which


def _place_trees(kind, W, H, rng, terrain, buildings, lines):
    n_forest = {"corridor": 260, "terrain": 320, "roofs": 25}[kind]
    n_bush = {"corridor": 120, "terrain": 140, "roofs": 20}[kind]
    # clustered: a few stands plus scattered trees
    centres = rng.uniform([0, 0], [W, H], (5, 2))
    pick = rng.integers(0, 5, n_forest)
    pos = centres[pick] + rng.normal(0, 22, (n_forest, 2))
    scattered = rng.uniform([0, 0], [W, H], (n_forest // 3, 2))
    bushes = rng.uniform([0, 0], [W, H], (n_bush, 2))
    rows = []
    for line in lines:  # a row of trees beside a line (hedgerows along a road)
        if "tree_row_m" in line:
            t0, d = np.asarray(line["towers"][0]), np.asarray(line["dir"])
            along = np.arange(-50.0, W + 50.0, 11.0) + rng.uniform(-3, 3)
            side = rng.choice([-1.0, 1.0], len(along)) * rng.uniform(*line["tree_row_m"], len(along))
            rows.append(t0 + along[:, None] * d + side[:, None] * np.array([-d[1], d[0]]))
    pos = np.vstack([pos, scattered, *rows, bushes])
    is_bush = np.r_[np.zeros(len(pos) - n_bush, bool), np.ones(n_bush, bool)]
    u, v = pos[:, 0], pos[:, 1]
    ok = (u > 2) & (u < W - 2) & (v > 2) & (v < H - 2) & ~terrain.excluded(u, v, 1.0)
    for b in buildings:
        ok &= ~b.contains(u, v, margin=6.0)
    for line in lines:
        towers = np.array(line["towers"])
        if len(towers):
            dt = np.min(np.hypot(u[:, None] - towers[None, :, 0], v[:, None] - towers[None, :, 1]), axis=1)
            ok &= dt > 9.0
    u, v, is_bush = u[ok], v[ok], is_bush[ok]
    n = len(u)
    height = np.where(is_bush, rng.uniform(0.6, 1.8, n), rng.uniform(6.0, 24.0, n))
    small = ~is_bush & (rng.uniform(0, 1, n) < 0.15)
    height = np.where(small, rng.uniform(2.5, 4.8, n), height)
    if lines:
        # trees under line A stay below the conductors (utilities trim them)
        lo, hi = lines[0].get("trim_m", (5.0, 11.0))
        under = _line_distance(u, v, lines[0]) < (3.0 if "trim_m" in lines[0] else 12.0)
        height = np.where(under & ~is_bush, np.minimum(height, rng.uniform(lo, hi, n)), height)
    radius = np.where(is_bush, rng.uniform(0.5, 1.4, n), np.clip(height * rng.uniform(0.18, 0.3, n), 1.2, 5.5))
    conifer = ~is_bush & (rng.uniform(0, 1, n) < 0.35)
    base_rel = np.where(is_bush, 0.1, height * rng.uniform(0.25, 0.5, n))
    ground = terrain.height(u, v)
    return Trees(u, v, ground, ground + height, ground + base_rel, radius, conifer, vegetation_class(height),
                 first_id=10000)


def _ground_under(terrain, pa, pb, n: int = 41):
    """The span pa-pb's plan length, ``n`` probes along it (metres from pa) and the ground there."""
    L = float(np.hypot(*(pb - pa)))
    probe = np.linspace(0, L, n)
    return L, probe, terrain.height(pa[0] + probe * (pb - pa)[0] / L, pa[1] + probe * (pb - pa)[1] / L)


def _strung_clear(terrain, pa, pb, za, zb, low, c, tries: int = 40):
    """The catenary parameter a span pa-pb (plan) between heights za, zb is strung at: ``c``
    tightened (x1.2, up to ``tries`` times) until the wire keeps half ``low`` (the lower
    attachment's height over its support's ground) over the ground beneath it; and whether it
    does."""
    L, probe, under = _ground_under(terrain, pa, pb)
    for k in range(tries + 1):
        if low <= 0 or np.min(catenary_z(probe, L, za, zb, c) - under) >= 0.5 * low:
            return c, True
        if k < tries:
            c *= 1.2
    return c, False


def _supports_at_brows(line, terrain, others=(), min_span_m: float = 12.0, clear_of_lines_m: float = 12.0,
                       max_added: int = 3) -> list:
    """The line's supports with one added where a span cannot be strung clear of the ground
    (``_strung_clear`` fails for one of its wires: a straight, taut wire would pass a few metres
    over the brow of an escarpment), at the brow (where the chord between the attachments comes
    nearest the ground), moved along the line off water, ditch and embankment (a pole may stand on
    a slope), as a line designer would put one there; at most ``max_added`` per span, none nearer
    than ``min_span_m`` to another nor within ``clear_of_lines_m`` of the ``others`` lines' axes (no
    pole under another line's wires). Over an embankment, where none may stand, a span stays as
    tight as it gets (a few tenths of a metre short of that clearance)."""
    model, d = line["model"], line["dir"]
    across = np.array([-d[1], d[0]])
    towers = [np.asarray(t, float) for t in line["towers"]]
    out = [towers[0]] if towers else []
    for nxt in towers[1:]:
        todo, added = [(out[-1], nxt)], 0
        while todo:
            a, b = todo.pop(0)
            ga, gb = float(terrain.height(*a)), float(terrain.height(*b))
            brow = None
            for w in line["wires"]:
                dx_att, z_att = model.attachments[w["attach"]]
                off = dx_att + w["dx"]
                pa, pb = a + across * off, b + across * off
                za, zb = ga + z_att + w.get("dz", 0.0), gb + z_att + w.get("dz", 0.0)
                if _strung_clear(terrain, pa, pb, za, zb, min(za - ga, zb - gb), w["c"])[1]:
                    continue
                L, probe, under = _ground_under(terrain, pa, pb)
                brow = float(probe[np.argmin(za + (zb - za) * probe / L - under)])
                break
            if brow is None or added >= max_added:
                out.append(b)
                continue
            L = float(np.hypot(*(b - a)))
            at = None
            for shift in np.r_[0.0, np.c_[np.arange(2.0, 13.0, 2.0), -np.arange(2.0, 13.0, 2.0)].ravel()]:
                t = brow + shift
                p = a + (b - a) / L * t
                if min_span_m <= t <= L - min_span_m and not terrain.excluded(p[0], p[1], 1.0, slopes=False) \
                        and all(_line_distance(p[0], p[1], o) >= clear_of_lines_m for o in others):
                    at = p
                    break
            if at is None:
                out.append(b)
                continue
            added += 1
            todo[:0] = [(a, at), (at, b)]  # each end appended once its span clears, in order
    return out


def _add_line(line, terrain, rng, pts, truth, spacing, noise_m, wire_base, origin):
    ox, oy = origin
    model = line["model"]
    d = line["dir"]
    across = np.array([-d[1], d[0]])  # +x of the tower frame
    heading = float(np.arctan2(d[1], d[0]))
    towers = line["towers"]
    for ti, t in enumerate(towers):
        zb = float(terrain.height(t[0], t[1]))
        pid = int(2000 + wire_base + ti)
        truth["pylons"].append({"id": pid, "line": line["name"], "model": model.name, "x": float(t[0] + ox),
                                "y": float(t[1] + oy), "z": zb, "heading_deg": float(np.degrees(heading) % 360.0),
                                "roll_deg": 0.0, "pitch_deg": 0.0, "height_m": model.height_m,
                                "in_scene": bool(0 <= t[0] <= terrain.width_m and 0 <= t[1] <= terrain.height_m)})
        local = sample_segments(model.segments, 0.3, rng, keep=0.55)
        # tower frame: x across the line, y along it
        uu = t[0] + local[:, 0] * across[0] + local[:, 1] * d[0]
        vv = t[1] + local[:, 0] * across[1] + local[:, 1] * d[1]
        zz = zb + local[:, 2] + rng.normal(0, noise_m, len(local))
        tp = _gps_time(uu, vv, 1e9) + 1e-4
        pts.add(uu, vv, zz, TOWER, 1, 2, tp, obj=pid, intensity=500)
        pts.add(uu, vv, terrain.height(uu, vv) + rng.normal(0, noise_m, len(uu)), GROUND, 2, 2, tp, intensity=300)
    for wi, w in enumerate(line["wires"]):
        wid = wire_base + wi
        dx_att, z_att = model.attachments[w["attach"]]
        off = dx_att + w["dx"]
        ends = [np.asarray(t) + across * off for t in towers]
        zs = [float(terrain.height(t[0], t[1])) + z_att + w.get("dz", 0.0) for t in towers]
        truth["wires"].append({"id": wid, "line": line["name"], "kind": w["kind"], "attach": w["attach"],
                               "offset_m": float(off), "dz_m": float(w.get("dz", 0.0)), "catenary_c_m": w["c"]})
        for si in range(len(towers) - 1):
            pa, pb = ends[si], ends[si + 1]
            L = float(np.hypot(*(pb - pa)))
            za, zb_ = zs[si], zs[si + 1]
            # a long span is strung tighter: the wire keeps at least half the lower attachment's
            # height over the ground beneath it (clearance), as a line designer would keep it
            low = min(za - float(terrain.height(*towers[si])), zb_ - float(terrain.height(*towers[si + 1])))
            c, _ = _strung_clear(terrain, pa, pb, za, zb_, low, w["c"])
            n = int(L / spacing)
            s = np.sort(rng.uniform(0, L, n))
            # gaps: stretches without hits, as real scans have
            keep = np.ones(n, bool)
            for _ in range(rng.poisson(L / 45.0)):
                g0 = rng.uniform(0, L)
                keep &= ~((s > g0) & (s < g0 + rng.uniform(0.8, 4.0)))
            s = s[keep]
            t_ = (pb - pa) / L
            lat = rng.normal(0, 0.04, len(s))  # footprint scatter across the wire
            uu = pa[0] + s * t_[0] + lat * -t_[1]
            vv = pa[1] + s * t_[1] + lat * t_[0]
            zz = catenary_z(s, L, za, zb_, c) + rng.normal(0, 0.03, len(s))
            inside = (uu >= 0) & (uu <= terrain.width_m) & (vv >= 0) & (vv <= terrain.height_m)
            uu, vv, zz, s = uu[inside], vv[inside], zz[inside], s[inside]
            tp = _gps_time(uu, vv, 1e9) + 2e-4 + wid * 1e-6
            pts.add(uu, vv, zz, WIRE, 1, 2, tp, obj=wid, intensity=rng.integers(40, 160, len(uu)))
            pts.add(uu, vv, terrain.height(uu, vv) + rng.normal(0, noise_m, len(uu)), GROUND, 2, 2, tp,
                    intensity=rng.integers(200, 600, len(uu)))
            ss = np.linspace(0, L, 60)
            curve = np.column_stack([pa[0] + ss * t_[0] + ox, pa[1] + ss * t_[1] + oy, catenary_z(ss, L, za, zb_, c)])
            truth["spans"].append({"wire_id": wid, "line": line["name"], "span": si, "length_m": L,
                                   "a": [float(pa[0] + ox), float(pa[1] + oy), za], "b": [float(pb[0] + ox), float(pb[1] + oy), zb_],
                                   "catenary_c_m": c, "sag_m": catenary_sag(L, za, zb_, c),
                                   "n_points": int(len(uu)), "curve": curve.tolist()})
    # the 2D conductor lines: one per distinct plan offset (stacked wires share one)
    offsets = sorted({round(w["offset_m"], 3) for w in truth["wires"] if w["line"] == line["name"]})
    if len(towers) >= 2:
        p0, p1 = np.asarray(towers[0]), np.asarray(towers[-1])
        for off in offsets:
            ids = [w["id"] for w in truth["wires"] if w["line"] == line["name"] and round(w["offset_m"], 3) == off]
            a = p0 + across * off
            b = p1 + across * off
            # the plan centre of the bundle (phase) its wires belong to: sub-conductors closer in
            # plan than a Hough band may come out as one conductor per phase, there
            attach = next(w["attach"] for w in truth["wires"] if w["id"] == ids[0])
            centre = float(np.mean([w["offset_m"] for w in truth["wires"]
                                    if w["line"] == line["name"] and w["attach"] == attach]))
            truth["conductor_lines_2d"].append({"line": line["name"], "offset_m": off, "bundle_offset_m": round(centre, 3),
                                                "wire_ids": ids,
                                                "a": [float(a[0] + ox), float(a[1] + oy)],
                                                "b": [float(b[0] + ox), float(b[1] + oy)]})


def _crossings(truth):
    """2D crossings of every pair of conductor lines of different power lines."""
    from shapely.geometry import LineString

    L = truth["conductor_lines_2d"]
    for i in range(len(L)):
        for j in range(i + 1, len(L)):
            if L[i]["line"] == L[j]["line"]:
                continue
            a, b = LineString([L[i]["a"], L[i]["b"]]), LineString([L[j]["a"], L[j]["b"]])
            p = a.intersection(b)
            if p.is_empty or p.geom_type != "Point":
                continue
            da = np.subtract(L[i]["b"], L[i]["a"])
            db = np.subtract(L[j]["b"], L[j]["a"])
            cosang = abs(np.dot(da, db)) / (np.linalg.norm(da) * np.linalg.norm(db))
            truth["crossings"].append({"x": p.x, "y": p.y, "lines": [i, j],
                                       "angle_deg": float(np.degrees(np.arccos(np.clip(cosang, -1, 1))))})

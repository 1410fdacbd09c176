"""Scene objects with exact geometry: buildings with planar roof faces, trees, lattice pylons,
catenary conductors. Pure numpy/shapely; local metres."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ROOF_TYPES = ("flat", "flat_parapet", "gable", "hip", "hip_dormer", "pyramid", "shed", "mansard", "gambrel", "L", "T", "cross")


# ------------------------------------------------------------------------------------------
# Buildings
# ------------------------------------------------------------------------------------------

@dataclass
class RoofFace:
    """A planar roof face z = z0 + ga * a + gb * b in the building frame (a along, b across)."""

    name: str
    z0: float
    ga: float
    gb: float
    polygon_ab: object = None  # shapely Polygon in the building frame


@dataclass
class Building:
    id: int
    cu: float  # centre, local metres
    cv: float
    length_m: float  # along a (the ridge direction)
    width_m: float
    heading_rad: float  # direction of a, counter-clockwise from east
    eave_m: float  # eave height above the highest ground under the footprint
    roof: str
    pitch_deg: float = 0.0
    base_z: float = 0.0  # absolute height of the eave reference (set by the scene)
    faces: list = field(default_factory=list)
    dormer: tuple | None = None  # (a0, width, b_front, ridge_z_rel, pitch_deg)
    upper_pitch_deg: float = 0.0  # mansard and gambrel: the shallow upper faces' pitch ...
    break_inset_m: float = 0.0  # ... above a break this far in from the eaves (plan)
    parapet: tuple | None = None  # flat_parapet: (height over the roof, thickness), m

    def to_ab(self, u, v):
        c, s = np.cos(self.heading_rad), np.sin(self.heading_rad)
        du, dv = u - self.cu, v - self.cv
        return du * c + dv * s, -du * s + dv * c

    def to_uv(self, a, b):
        c, s = np.cos(self.heading_rad), np.sin(self.heading_rad)
        return self.cu + a * c - b * s, self.cv + a * s + b * c

    def contains(self, u, v, margin=0.0):
        a, b = self.to_ab(u, v)
        return (np.abs(a) <= self.length_m / 2 + margin) & (np.abs(b) <= self.width_m / 2 + margin)

    def footprint_uv(self):
        L, W = self.length_m / 2, self.width_m / 2
        a = np.array([-L, L, L, -L])
        b = np.array([-W, -W, W, W])
        return np.column_stack(self.to_uv(a, b))

    def build_faces(self) -> None:
        """Create the faces and their exact plan polygons (building frame)."""
        from shapely.geometry import box

        L, W = self.length_m / 2, self.width_m / 2
        t = np.tan(np.radians(self.pitch_deg))
        z = self.base_z + self.eave_m
        fp = box(-L, -W, L, W)
        if self.roof == "flat":
            self.faces = [RoofFace("flat", z, 0.0, 0.0, fp)]
            return
        if self.roof == "flat_parapet":
            # the roof face inside a low wall round the edge; the wall's top is no roof face
            th = self.parapet[1]
            self.faces = [RoofFace("flat", z, 0.0, 0.0, box(-L + th, -W + th, L - th, W - th))]
            return
        if self.roof == "gable":
            faces = [RoofFace("south", z + t * W, 0.0, t, None), RoofFace("north", z + t * W, 0.0, -t, None)]
        elif self.roof == "shed":  # one face rising from the b = -W eave
            faces = [RoofFace("shed", z + t * W, 0.0, t, None)]
        elif self.roof in ("mansard", "gambrel"):
            # steep lower faces up to a break, shallow upper ones above it: still the lowest of the
            # planes everywhere (a convex roof); the gambrel on the long sides only, gable ends
            t2, d = np.tan(np.radians(self.upper_pitch_deg)), self.break_inset_m
            zb = z + t * d
            faces = [RoofFace("south_lower", z + t * W, 0.0, t, None), RoofFace("north_lower", z + t * W, 0.0, -t, None),
                     RoofFace("south_upper", zb + t2 * (W - d), 0.0, t2, None),
                     RoofFace("north_upper", zb + t2 * (W - d), 0.0, -t2, None)]
            if self.roof == "mansard":
                faces += [RoofFace("west_lower", z + t * L, t, 0.0, None), RoofFace("east_lower", z + t * L, -t, 0.0, None),
                          RoofFace("west_upper", zb + t2 * (L - d), t2, 0.0, None),
                          RoofFace("east_upper", zb + t2 * (L - d), -t2, 0.0, None)]
        else:  # hip, hip_dormer and pyramid: equal pitch on all four faces
            faces = [
                RoofFace("south", z + t * W, 0.0, t, None),  # b<0 side, rises towards b=0
                RoofFace("north", z + t * W, 0.0, -t, None),
                RoofFace("west", z + t * L, t, 0.0, None),
                RoofFace("east", z + t * L, -t, 0.0, None),
            ]
        # min-type roof: a face is where its plane is the lowest of all
        for f in faces:
            poly = fp
            for g in faces:
                if g is f:
                    continue
                # keep (f - g)(a, b) <= 0
                poly = _clip(poly, f.ga - g.ga, f.gb - g.gb, g.z0 - f.z0)
            f.polygon_ab = poly
        if self.roof == "hip_dormer":
            a0, dw, b_front, ridge_rel, dpitch = self.dormer
            td = np.tan(np.radians(dpitch))
            zr = self.base_z + ridge_rel
            # dormer faces: z = zr - td * |a - a0|, over a0-dw/2 <= a <= a0+dw/2, 0 <= b <= b_front
            left = RoofFace("dormer_west", zr - td * a0, td, 0.0, None)
            right = RoofFace("dormer_east", zr + td * a0, -td, 0.0, None)
            north = faces[1]
            for f, (lo, hi) in ((left, (a0 - dw / 2, a0)), (right, (a0, a0 + dw / 2))):
                poly = box(lo, 0.0, hi, b_front)
                poly = _clip(poly, north.ga - f.ga, north.gb - f.gb, f.z0 - north.z0)  # dormer above the face
                f.polygon_ab = poly
            north.polygon_ab = north.polygon_ab.difference(left.polygon_ab).difference(right.polygon_ab)
            faces += [left, right]
        self.faces = [f for f in faces if f.polygon_ab is not None and f.polygon_ab.area > 1e-6]

    def roof_height(self, u, v):
        """Roof height and face index for points inside the footprint (-1: a parapet's top)."""
        a, b = self.to_ab(u, v)
        zs = np.stack([f.z0 + f.ga * a + f.gb * b for f in self.faces[: self._n_main()]])
        idx = np.argmin(zs, axis=0)
        z = np.take_along_axis(zs, idx[None], 0)[0]
        if self.roof == "hip_dormer":
            a0, dw, b_front, ridge_rel, dpitch = self.dormer
            left, right = self.faces[-2], self.faces[-1]
            zd = np.where(a < a0, left.z0 + left.ga * a, right.z0 + right.ga * a)
            inbox = (np.abs(a - a0) <= dw / 2) & (b >= 0) & (b <= b_front) & (zd > z)
            z = np.where(inbox, zd, z)
            idx = np.where(inbox, np.where(a < a0, len(self.faces) - 2, len(self.faces) - 1), idx)
        if self.roof == "flat_parapet":
            h, th = self.parapet
            wall = (np.abs(a) > self.length_m / 2 - th) | (np.abs(b) > self.width_m / 2 - th)
            z = np.where(wall, z + h, z)
            idx = np.where(wall, -1, idx)  # on no face
        return z, idx

    def _n_main(self) -> int:
        return len(self.faces) - (2 if self.roof == "hip_dormer" else 0)

    def plane_uv(self, f: RoofFace):
        """The face's plane as z = z0 + gu * u + gv * v in local scene coordinates."""
        c, s = np.cos(self.heading_rad), np.sin(self.heading_rad)
        # z = z0 + ga*a + gb*b, a = c*du + s*dv, b = -s*du + c*dv
        gu = f.ga * c - f.gb * s
        gv = f.ga * s + f.gb * c
        return f.z0 - gu * self.cu - gv * self.cv, gu, gv

    def roof_top(self) -> float:
        tops = []
        for f in self.faces:
            a, bb = np.asarray(f.polygon_ab.exterior.coords).T if f.polygon_ab.geom_type == "Polygon" else \
                np.concatenate([np.asarray(g.exterior.coords) for g in f.polygon_ab.geoms]).T
            tops.append(float(np.max(f.z0 + f.ga * a + f.gb * bb)))
        return max(tops) + (self.parapet[0] if self.parapet else 0.0)

    def face_plane_world(self, f: RoofFace, origin=(0.0, 0.0)):
        """Unit normal (upwards) and offset d with n . p = d, in local scene coordinates + origin."""
        return _plane_world(*self.plane_uv(f), origin)

    def face_polygon_uv(self, f: RoofFace):
        from shapely import affinity

        c, s = np.cos(self.heading_rad), np.sin(self.heading_rad)
        return affinity.affine_transform(f.polygon_ab, [c, -s, s, c, self.cu, self.cv])


@dataclass
class PlaneFace:
    """A roof face of a compound building in scene coordinates: z = z0 + gu * u + gv * v."""

    name: str
    z0: float
    gu: float
    gv: float
    polygon_uv: object


class CompoundBuilding:
    """An L-, T- or cross-shaped building: boxes (wings) with gable or hip roofs of their own; the
    roof over a point is the highest wing roof there, so valleys form where wings meet (how
    procedural LOD2 models join roof primitives). Coplanar faces of different wings that touch
    are one face; a face cut in two by a wing is two faces."""

    def __init__(self, id: int, roof: str, parts: list):
        self.id, self.roof, self.parts = id, roof, parts
        main = parts[0]
        self.cu, self.cv, self.length_m, self.width_m, self.heading_rad = main.cu, main.cv, main.length_m, \
            main.width_m, main.heading_rad
        self.eave_m, self.pitch_deg, self.base_z = 0.0, 0.0, 0.0
        self.faces: list[PlaneFace] = []

    def contains(self, u, v, margin=0.0):
        return np.logical_or.reduce([p.contains(u, v, margin) for p in self.parts])

    def outline_uv(self):
        from shapely import union_all
        from shapely.geometry import Polygon

        return union_all([Polygon(p.footprint_uv()) for p in self.parts])

    def footprint_uv(self):
        return np.asarray(self.outline_uv().exterior.coords)[:-1]

    def build_faces(self) -> None:
        from shapely import union_all
        from shapely.geometry import Polygon

        for p in self.parts:
            p.eave_m, p.pitch_deg, p.base_z = self.eave_m, self.pitch_deg, self.base_z
            p.build_faces()
        boxes = [Polygon(p.footprint_uv()) for p in self.parts]
        planes = [(i, k, *p.plane_uv(f), p.face_polygon_uv(f)) for i, p in enumerate(self.parts)
                  for k, f in enumerate(p.faces)]
        groups: dict = {}
        self._group_of = {}
        for i, k, z0, gu, gv, poly in planes:
            for j, q in enumerate(self.parts):
                if j == i:
                    continue
                higher = boxes[j]  # where wing j's roof (the lowest of its planes) rises above this plane
                for _, _, z0g, gug, gvg, _ in (e for e in planes if e[0] == j):
                    A, B, C = -(gug - gu), -(gvg - gv), z0g - z0
                    if max(abs(A), abs(B), abs(C)) < 1e-9:  # the same plane: never above it
                        higher = Polygon()
                        break
                    higher = _clip(higher, A, B, C)
                if not higher.is_empty:
                    poly = poly.difference(higher)
            key = (round(z0, 6), round(gu, 9), round(gv, 9))
            groups.setdefault(key, []).append(poly)
            self._group_of[(i, k)] = key
        self.faces, self._faces_of = [], {}
        for key, polys in groups.items():
            merged = union_all(polys)
            comps = [g for g in getattr(merged, "geoms", [merged]) if g.geom_type == "Polygon" and g.area > 1e-3]
            self._faces_of[key] = []
            for g in comps:
                self._faces_of[key].append(len(self.faces))
                self.faces.append(PlaneFace(f"face{len(self.faces)}", key[0], key[1], key[2], g))

    def roof_height(self, u, v):
        import shapely

        z = np.full(len(u), -np.inf)
        part = np.full(len(u), -1)
        kface = np.full(len(u), -1)
        for i, p in enumerate(self.parts):
            inside = np.flatnonzero(p.contains(u, v))
            zi, ki = p.roof_height(u[inside], v[inside])
            better = zi > z[inside] + 1e-9
            sel = inside[better]
            z[sel], part[sel], kface[sel] = zi[better], i, ki[better]
        idx = np.full(len(u), -1)
        for (i, k), key in self._group_of.items():
            sel = np.flatnonzero((part == i) & (kface == k))
            comps = self._faces_of[key]
            if len(comps) == 1 or not len(sel):
                idx[sel] = comps[0] if comps else -1
                continue
            # the component the point lies in (nearest, for points on a boundary)
            d = np.stack([shapely.distance(self.faces[c].polygon_uv, shapely.points(u[sel], v[sel])) for c in comps])
            idx[sel] = np.asarray(comps)[np.argmin(d, axis=0)]
        return z, idx

    def face_plane_world(self, f: PlaneFace, origin=(0.0, 0.0)):
        return _plane_world(f.z0, f.gu, f.gv, origin)

    def face_polygon_uv(self, f: PlaneFace):
        return f.polygon_uv

    def roof_top(self) -> float:
        return max(p.roof_top() for p in self.parts)  # the roof is the highest wing roof everywhere


def compound_building(id: int, shape: str, style: str, cu: float, cv: float, length_m: float, width_m: float,
                      heading_rad: float, rng) -> CompoundBuilding:
    """A main wing (length x width, ``style`` gable or hip) and wings at right angles to it: ``L``
    one at an end, ``T`` one off a side, ``cross`` one through it. A gable wing starts at the main
    ridge line (its inner gable stays under the main roof); a hip wing at the far eave (its inner
    hip face is then the main's far face)."""
    main = Building(id, cu, cv, length_m, width_m, heading_rad, 0.0, style)
    # narrower: its ridge stays below the main ridge, and a face it cuts into keeps a neck (or a
    # gap) of at least 0.1 of the width, wider than the point spacing of any survey we model
    w2 = float(width_m * rng.uniform(0.6, 0.8))
    ext = float(rng.uniform(4.0, 8.0))
    b1 = width_m / 2 + ext
    b0 = 0.0 if style == "gable" else -width_m / 2
    if shape == "L":
        a_c = length_m / 2 - w2 / 2
    elif shape == "T":
        a_c = float(rng.uniform(-0.2, 0.2) * length_m)
    else:  # cross: through the main wing, out on both sides
        a_c = float(rng.uniform(-0.15, 0.15) * length_m)
        b0 = -(width_m / 2 + float(rng.uniform(3.0, 6.0)))
    wu, wv = main.to_uv(a_c, (b0 + b1) / 2)
    wing = Building(id, float(wu), float(wv), b1 - b0, w2, heading_rad + np.pi / 2, 0.0, style)
    return CompoundBuilding(id, shape, [main, wing])


def _plane_world(z0, gu, gv, origin):
    """The plane z = z0 + gu * u + gv * v (local scene coordinates) as a unit normal (upwards) and
    offset d with n . p = d in world coordinates (u = x - origin x)."""
    z0w = z0 - gu * origin[0] - gv * origin[1]
    n = np.array([-gu, -gv, 1.0])
    norm = np.linalg.norm(n)
    return n / norm, float(z0w / norm)


def _clip(poly, A, B, C):
    """Keep the part of ``poly`` where A*a + B*b <= C."""
    from shapely.geometry import Polygon

    if abs(A) < 1e-12 and abs(B) < 1e-12:
        return poly if C >= 0 else Polygon()
    big = 1e4
    n = np.array([A, B]) / np.hypot(A, B)
    c = C / np.hypot(A, B)
    p0 = n * c  # a point on the line
    t = np.array([-n[1], n[0]])
    pts = [p0 + t * big, p0 + t * big - n * big, p0 - t * big - n * big, p0 - t * big]
    return poly.intersection(Polygon(pts))


# ------------------------------------------------------------------------------------------
# Vegetation
# ------------------------------------------------------------------------------------------

@dataclass
class Trees:
    """Crowns as arrays: centre, ground height, top height, crown base, radius, shape, class."""

    u: np.ndarray
    v: np.ndarray
    ground: np.ndarray
    top: np.ndarray
    base: np.ndarray
    radius: np.ndarray
    conifer: np.ndarray  # bool: cone, else spheroid
    asprs: np.ndarray  # 3, 4 or 5 by the plant's top height above ground
    first_id: int = 0

    def __len__(self):
        return len(self.u)

    def surfaces(self, k, r):
        """Top and bottom crown surface of tree k at horizontal distance r (arrays)."""
        top, base, R = self.top[k], self.base[k], self.radius[k]
        rr = np.clip(r / R, 0, 1)
        cone_top = top - (top - base) * rr
        zc = (top + base) / 2
        c = (top - base) / 2
        sph = np.sqrt(np.clip(1 - rr ** 2, 0, 1))
        sph_top = zc + c * sph
        sph_bot = zc - c * sph
        z_top = np.where(self.conifer[k], cone_top, sph_top)
        z_bot = np.where(self.conifer[k], base, sph_bot)
        return z_top, z_bot


def vegetation_class(height_m):
    """ASPRS class of a plant by its top height above ground: 3 low (< 2 m), 4 medium (< 5 m),
    5 high. Whole plants get one class, as the method's cluster-height rule does."""
    h = np.asarray(height_m)
    return np.where(h < 2.0, 3, np.where(h < 5.0, 4, 5)).astype(np.uint8)


# ------------------------------------------------------------------------------------------
# Power lines
# ------------------------------------------------------------------------------------------

def catenary_z(s, length, z_a, z_b, c):
    """Height along a span in its vertical plane: the catenary through (0, z_a) and (length, z_b)
    with parameter c = H / w (horizontal tension over weight per metre, in metres)."""
    s0 = length / 2 - c * np.arcsinh((z_b - z_a) / (2 * c * np.sinh(length / (2 * c))))
    return z_a + c * (np.cosh((s - s0) / c) - np.cosh(s0 / c))


def catenary_sag(length, z_a, z_b, c):
    """Largest vertical distance between the chord and the catenary (metres)."""
    s = np.linspace(0, length, 2001)
    chord = z_a + (z_b - z_a) * s / length
    return float(np.max(chord - catenary_z(s, length, z_a, z_b, c)))


@dataclass
class TowerModel:
    """A pylon as 3D line segments in its local frame (x across the line, y along it, z up)."""

    name: str
    segments: np.ndarray  # (n, 2, 3)
    attachments: dict  # name -> (x, z) offset across the line and height of each wire attachment
    height_m: float


def lattice_tower(height_m=31.0, base_w=6.0, top_w=1.6, arms=((20.0, 7.5), (26.0, 7.5)), earth_z=31.0,
                  insulator_m=2.5) -> TowerModel:
    """A lattice transmission tower: four legs, horizontal rings, X bracing, cross arms, a peak."""
    segs = []
    z_top_body = max(a[0] for a in arms) + 1.0
    levels = np.linspace(0, z_top_body, 9)

    def half(z):
        return base_w / 2 + (top_w / 2 - base_w / 2) * min(z / z_top_body, 1.0)

    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    for i in range(len(levels) - 1):
        z0, z1 = levels[i], levels[i + 1]
        h0, h1 = half(z0), half(z1)
        for k in range(4):
            sx, sy = corners[k]
            tx, ty = corners[(k + 1) % 4]
            segs.append(((sx * h0, sy * h0, z0), (sx * h1, sy * h1, z1)))  # leg
            segs.append(((sx * h1, sy * h1, z1), (tx * h1, ty * h1, z1)))  # ring
            segs.append(((sx * h0, sy * h0, z0), (tx * h1, ty * h1, z1)))  # bracing
            segs.append(((tx * h0, ty * h0, z0), (sx * h1, sy * h1, z1)))
    hw = top_w / 2
    attachments = {}
    for j, (z_arm, reach) in enumerate(arms):
        for side in (-1, 1):
            tip = (side * reach, 0.0, z_arm)
            for y in (-hw, hw):
                segs.append(((side * hw, y, z_arm), tip))  # lower chord
                segs.append(((side * hw, y, z_arm + 1.2), tip))  # upper chord
            attachments[f"arm{j}_{'L' if side < 0 else 'R'}"] = (side * (reach - 0.5), z_arm - insulator_m)
    peak = (0.0, 0.0, earth_z)
    for sx, sy in corners:
        segs.append(((sx * hw, sy * hw, z_top_body), peak))
    attachments["earth"] = (0.0, earth_z)
    return TowerModel("lattice", np.array(segs, float), attachments, earth_z)


def wood_pole(height_m=11.0, arm_half_m=1.4) -> TowerModel:
    segs = [((0, 0, 0), (0, 0, height_m)), ((-arm_half_m, 0, height_m - 1.0), (arm_half_m, 0, height_m - 1.0))]
    att = {"L": (-1.2, height_m - 0.9), "C": (0.0, height_m + 0.1), "R": (1.2, height_m - 0.9)}
    return TowerModel("pole", np.array(segs, float), att, height_m)


def joint_use_pole(height_m=8.0, arm_half_m=0.6, cables=3, spacing_m=0.3, drop_m=0.8) -> TowerModel:
    """A low-voltage pole that also carries ``cables`` communication cables one above another,
    ``spacing_m`` apart on its side, the highest ``drop_m`` under its wires (a vertical ribbon)."""
    pole = wood_pole(height_m, arm_half_m)
    att = dict(pole.attachments)
    for k in range(cables):
        att[f"T{k}"] = (0.15, height_m - 0.9 - drop_m - k * spacing_m)
    return TowerModel("joint-use pole", pole.segments, att, height_m)


def compact_pole(height_m=11.0, phases=3, spacing_m=0.6) -> TowerModel:
    """A compact line's pole: one horizontal arm carrying ``phases`` conductors ``spacing_m``
    apart at one height (a horizontal ribbon of wires)."""
    half = 0.5 * (phases - 1) * spacing_m + 0.3
    segs = [((0, 0, 0), (0, 0, height_m + 0.5)), ((-half, 0, height_m), (half, 0, height_m))]
    att = {f"P{i}": ((i - 0.5 * (phases - 1)) * spacing_m, height_m - 0.3) for i in range(phases)}
    return TowerModel("compact", np.array(segs, float), att, height_m + 0.5)


def sample_segments(segments: np.ndarray, spacing_m: float, rng, keep: float = 1.0):
    """Points along 3D segments at about ``spacing_m`` (jittered), each kept with prob. ``keep``."""
    out = []
    for p, q in segments:
        L = float(np.linalg.norm(q - p))
        n = max(int(L / spacing_m), 1)
        t = (np.arange(n) + rng.uniform(0, 1, n)) / n
        pts = p + t[:, None] * (q - p)
        out.append(pts[rng.uniform(0, 1, n) < keep])
    return np.concatenate(out) if out else np.empty((0, 3))

"""A synthetic UAV photo survey of lattice pylons with exact truth (the test data of pylon-pose,
METHODS.md §4): pylons of two types along a line with wires between them, on smooth terrain with
ground clutter (fields, roads, buildings, trees and their shadows), photographed from 100-150 m,
oblique and nadir, by a camera with Brown distortion; noise, blur and JPEG compression.

World convention (the toolbox's): x east, y north, z up in the scene's CRS; a camera maps
X_cam = R·X_world + t (COLMAP), looking along +z, x right, y down; pixel centres at integer + 0.5.
A pylon's pose is M = T·Rz(heading)·Ry(pitch)·Rx(roll) on model coordinates whose origin is the
centre of the base (model x across the line, y along it, z up)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# the pylon types are pylon_pose's model library, which these surveys are the test data of
from toolbox_plugins.pylon_pose.models import builtin_models, write_obj

from .terrain import Terrain


def rotation(heading_deg, pitch_deg, roll_deg) -> np.ndarray:
    h, p, r = np.radians([heading_deg, pitch_deg, roll_deg])
    Rz = np.array([[np.cos(h), -np.sin(h), 0], [np.sin(h), np.cos(h), 0], [0, 0, 1]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    return Rz @ Ry @ Rx


@dataclass
class Pylon:
    model: str
    x: float  # world (CRS) coordinates of the base centre
    y: float
    z: float
    heading_deg: float
    pitch_deg: float
    roll_deg: float

    def to_world(self, pts: np.ndarray) -> np.ndarray:
        return pts @ rotation(self.heading_deg, self.pitch_deg, self.roll_deg).T + [self.x, self.y, self.z]


@dataclass
class Shot:
    name: str
    R: np.ndarray
    t: np.ndarray
    target: int  # the pylon it was taken of

    @property
    def centre(self) -> np.ndarray:
        return -self.R.T @ self.t


@dataclass
class PhotoSurvey:
    seed: int
    crs: str
    origin: tuple[float, float]
    extent: tuple[float, float]
    terrain: Terrain
    models: dict
    pylons: list
    shots: list
    camera: tuple  # (width, height, (fx, fy, cx, cy, k1, k2, p1, p2)) OpenCV model
    dem: np.ndarray
    dem_resolution_m: float
    sun: np.ndarray
    clutter: dict = field(default_factory=dict)

    @property
    def dem_transform(self):
        from affine import Affine

        ox, oy = self.origin
        return Affine(self.dem_resolution_m, 0, ox, 0, -self.dem_resolution_m, oy + self.extent[1])

    def ground(self, x, y):
        return self.terrain.height(np.asarray(x) - self.origin[0], np.asarray(y) - self.origin[1])

    def K(self):
        fx, fy, cx, cy = self.camera[2][:4]
        return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])

    def distortion(self):
        k1, k2, p1, p2 = self.camera[2][4:8]
        return np.array([k1, k2, p1, p2, 0.0])

    def truth(self) -> dict:
        return {"crs": self.crs, "seed": self.seed,
                "conventions": "x east, y north, z up in the CRS; X_cam = R*X_world + t (COLMAP); pose M = "
                               "T*Rz(heading)*Ry(pitch)*Rx(roll) on model coordinates (origin: centre of the base); "
                               "angles counter-clockwise, degrees; heading 0: the model's x axis points east",
                "pylons": [{"x": p.x, "y": p.y, "z": p.z, "heading_deg": p.heading_deg, "roll_deg": p.roll_deg,
                            "pitch_deg": p.pitch_deg, "model": p.model,
                            "tilt_deg": round(tilt_of(p.heading_deg, p.pitch_deg, p.roll_deg)[0], 6),
                            "tilt_azimuth_deg": round(tilt_of(p.heading_deg, p.pitch_deg, p.roll_deg)[1], 6),
                            "symmetry_deg": self.models[p.model].symmetry_deg} for p in self.pylons],
                "photos": [{"name": s.name, "pylon": s.target} for s in self.shots],
                "camera": {"model": "OPENCV", "width": self.camera[0], "height": self.camera[1],
                           "params": list(self.camera[2])}}


def _look_at(centre, target, roll_deg=0.0, up=(0.0, 0.0, 1.0)):
    z = np.asarray(target, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.vstack([x, y, z])
    c, s = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ R
    return R, -R @ centre


def tilt_of(heading_deg, pitch_deg, roll_deg) -> tuple[float, float]:
    """(tilt, azimuth) of a pose's vertical axis: its angle from the plumb line and the compass
    direction (degrees clockwise from grid north) its top leans toward."""
    up = rotation(heading_deg, pitch_deg, roll_deg)[:, 2]
    return (float(np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0)))),
            float(np.degrees(np.arctan2(up[0], up[1])) % 360.0))


def lean_angles(heading_deg: float, tilt_deg: float, toward_deg: float) -> tuple[float, float]:
    """(pitch, roll) that tilt a pylon of ``heading_deg`` by ``tilt_deg`` with its top toward
    ``toward_deg`` (counter-clockwise from east, the toolbox's angles): the model's vertical axis
    Rz(heading)·Ry(pitch)·Rx(roll)·z made equal to that direction."""
    t, a = np.radians([tilt_deg, toward_deg])
    axis = rotation(heading_deg, 0.0, 0.0).T @ [np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)]
    # Ry(p)·Rx(r)·z = (sin p cos r, -sin r, cos p cos r)
    return float(np.degrees(np.arctan2(axis[0], axis[2]))), float(np.degrees(np.arcsin(-axis[1])))


def _lean(pylons, line_dir_deg: float, leans, seed: int):
    """Tilts the pylons that ``leans`` names ({index: (tilt_deg, along | across | random)}) by
    exactly that much, the top toward the line (along), square to it (across) or anywhere; its own
    random stream, so that a survey without leaning pylons is the one it always was."""
    rng = np.random.default_rng(seed + 104729)
    for i, (tilt, direction) in sorted(leans.items()):
        p = pylons[i]
        toward = {"along": line_dir_deg, "across": line_dir_deg + 90.0}.get(direction, rng.uniform(0, 360))
        toward += 180.0 * (rng.uniform() < 0.5)
        p.pitch_deg, p.roll_deg = (round(v, 6) for v in lean_angles(p.heading_deg, tilt, toward))


def leaning_pylons(n_pylons: int, lean_deg: float, lean_share: float, lean_direction: str, seed: int) -> dict:
    """{index: (lean_deg, lean_direction)} for ``lean_share`` of the pylons (at least one when the
    share is above 0), the middle ones first: a leaning pylon between upright neighbours, as an
    inspection meets it."""
    if lean_deg <= 0 or lean_share <= 0:
        return {}
    rng = np.random.default_rng(seed + 130363)
    n = min(n_pylons, max(1, int(round(lean_share * n_pylons))))
    order = sorted(range(n_pylons), key=lambda i: (abs(i - (n_pylons - 1) / 2), rng.uniform()))
    return {i: (lean_deg, lean_direction) for i in order[:n]}


def make_pylon_survey(seed: int = 1, n_pylons: int = 3, photos_per_pylon: int = 12, span_m: float = 150.0,
                      origin=(512000.0, 5403000.0), crs: str = "EPSG:25832", image_size=(2400, 1600),
                      distance_m=(100.0, 150.0), slope_pct: float = 0.0, leans: dict | None = None) -> PhotoSurvey:
    """A photo survey of ``n_pylons`` along a line; the pylons ``leans`` names ({index: (tilt_deg,
    along | across | random)}, e.g. from ``leaning_pylons``) lean by exactly that much, the
    others stand within 0.3° of upright."""
    rng = np.random.default_rng(seed)
    models = builtin_models()
    line_len = span_m * (n_pylons - 1)
    margin = 220.0
    W = H = float(np.ceil(line_len + 2 * margin))
    terrain = Terrain.random(W, H, rng, features=False, tilt=slope_pct / 100.0)
    terrain.hills = [(h[0], h[1], h[2] * 0.6, h[3] * 1.3) for h in terrain.hills]
    line_dir = rng.uniform(0, 180)
    d = np.array([np.cos(np.radians(line_dir)), np.sin(np.radians(line_dir))])
    centre = np.array([W / 2, H / 2])
    types = ["vl220", "u110"] * n_pylons
    start = int(rng.integers(0, 2))
    pylons = []
    for i in range(n_pylons):
        uv = centre + d * (i - (n_pylons - 1) / 2) * span_m + rng.normal(0, 2.0, 2)
        name = types[start + i]
        heading = (line_dir - 90.0 + (180.0 if rng.uniform() < 0.5 else 0.0) + rng.uniform(-4, 4)) % 360.0
        pylons.append(Pylon(name, float(origin[0] + uv[0]), float(origin[1] + uv[1]),
                            float(terrain.height(uv[0], uv[1])), round(float(heading), 3),
                            round(float(rng.uniform(-0.3, 0.3)), 3), round(float(rng.uniform(-0.3, 0.3)), 3)))
    _lean(pylons, line_dir, leans or {}, seed)
    w, h = image_size
    f = 1.02 * w  # a 53° wide lens, like a 24 mm on full frame
    camera = (w, h, (round(f, 2), round(f * 1.0004, 2), round(w / 2 + rng.uniform(-8, 8), 2),
                     round(h / 2 + rng.uniform(-8, 8), 2), -0.06, 0.012, 2e-4, -1.5e-4))
    shots = []
    for i, p in enumerate(pylons):
        height = models[p.model].height_m
        mid = np.array([p.x, p.y, p.z + 0.5 * height])
        az0 = rng.uniform(0, 360)
        for k in range(photos_per_pylon):
            nadir = k < max(1, photos_per_pylon // 6)
            elev = rng.uniform(78, 88) if nadir else rng.uniform(35, 70)
            az = az0 + 360.0 * k / photos_per_pylon + rng.uniform(-10, 10)
            dist = rng.uniform(*distance_m)
            dirv = np.array([np.cos(np.radians(elev)) * np.cos(np.radians(az)),
                             np.cos(np.radians(elev)) * np.sin(np.radians(az)), np.sin(np.radians(elev))])
            cam = mid + dist * dirv
            aim = mid + np.array([rng.uniform(-9, 9), rng.uniform(-9, 9), rng.uniform(-4, 4)])
            up = (0.0, 0.0, 1.0) if not nadir else (np.cos(np.radians(az + 90)), np.sin(np.radians(az + 90)), 0.0)
            R, t = _look_at(cam, aim, rng.uniform(-3, 3), up)
            shots.append(Shot(f"IMG_{len(shots) + 1:04d}.JPG", R, t, i))
    res = 1.0
    uu, vv = np.meshgrid(np.arange(W / res) * res + res / 2, H - (np.arange(H / res) * res + res / 2))
    dem = terrain.height(uu, vv).astype(np.float32)
    sun_az, sun_el = np.radians(rng.uniform(120, 240)), np.radians(rng.uniform(35, 55))
    sun = -np.array([np.cos(sun_el) * np.cos(sun_az), np.cos(sun_el) * np.sin(sun_az), np.sin(sun_el)])
    survey = PhotoSurvey(seed, crs, tuple(origin), (W, H), terrain, models, pylons, shots, camera, dem, res, sun)
    survey.clutter = _clutter(survey, rng)
    return survey


# ----------------------------------------------------------------------------------------------
# Rendering
# ----------------------------------------------------------------------------------------------

ORTHO_M = 0.15  # ground texture resolution


def _clutter(s: PhotoSurvey, rng) -> dict:
    """Ground features in local metres: fields (polygons), roads (bands), buildings (rectangles) and
    trees (discs), kept clear of the pylons' bases."""
    W, H = s.extent
    bases = np.array([[p.x - s.origin[0], p.y - s.origin[1]] for p in s.pylons])

    def clear(u, v, r):
        return np.min(np.hypot(bases[:, 0] - u, bases[:, 1] - v)) > r

    fields = []
    for _ in range(int(W * H / 9000)):
        c = rng.uniform(0, [W, H])
        a = rng.uniform(0, np.pi)
        L, B = rng.uniform(40, 140), rng.uniform(30, 90)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        poly = (np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [L / 2, B / 2]) @ R.T + c
        fields.append((poly, rng.integers(0, 5)))
    roads = []
    for _ in range(3):
        p = rng.uniform(0, [W, H])
        a = rng.uniform(0, np.pi)
        roads.append((p, np.array([np.cos(a), np.sin(a)]), rng.uniform(5, 8)))
    buildings = []
    while len(buildings) < int(W * H / 12000):
        c = rng.uniform(0, [W, H])
        if not clear(*c, 35.0):
            continue
        a = rng.uniform(0, np.pi)
        L, B = rng.uniform(8, 22), rng.uniform(7, 14)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        buildings.append(((np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [L / 2, B / 2]) @ R.T + c, rng.uniform(4, 9)))
    trees = []
    while len(trees) < int(W * H / 800):
        c = rng.uniform(0, [W, H])
        if clear(*c, 6.0):
            trees.append((c, rng.uniform(1.8, 4.5), rng.uniform(6, 16)))
    return {"fields": fields, "roads": roads, "buildings": buildings, "trees": trees}


def ortho_texture(s: PhotoSurvey, rng) -> np.ndarray:
    """The ground's colour seen from above (BGR uint8, north up, ``ORTHO_M`` cells); trees and
    buildings carry their shadows, cast by ``s.sun``."""
    import cv2

    W, H = s.extent
    cols, rows = int(W / ORTHO_M), int(H / ORTHO_M)
    palette = np.array([[70, 120, 90], [60, 140, 120], [80, 110, 140], [95, 150, 150], [60, 100, 80]], np.uint8)
    img = np.empty((rows, cols, 3), np.uint8)
    img[:] = (75, 125, 105)
    px = lambda uv: np.round(np.column_stack([uv[:, 0] / ORTHO_M, (H - uv[:, 1]) / ORTHO_M]) * 4).astype(np.int32)  # noqa: E731
    for poly, k in s.clutter["fields"]:
        cv2.fillPoly(img, [px(poly)], tuple(int(c) for c in palette[k]), cv2.LINE_AA, shift=2)
    small = rng.normal(0, 1, (rows // 16 + 1, cols // 16 + 1, 3)).astype(np.float32)
    big = cv2.resize(small, (cols, rows), interpolation=cv2.INTER_CUBIC)
    img = np.clip(img.astype(np.float32) + 10 * big + rng.normal(0, 6, (rows, cols, 1)).astype(np.float32), 0, 255).astype(np.uint8)
    for p, d, width in s.clutter["roads"]:
        a, b = p - d * 2 * W, p + d * 2 * W
        cv2.line(img, tuple(px(a[None])[0]), tuple(px(b[None])[0]), (105, 108, 110), int(width / ORTHO_M), cv2.LINE_AA, shift=2)
        n = np.array([-d[1], d[0]]) * (width / 2 - 0.3)
        for side in (-1, 1):
            cv2.line(img, tuple(px((a + side * n)[None])[0]), tuple(px((b + side * n)[None])[0]), (200, 200, 200), 1,
                     cv2.LINE_AA, shift=2)
    shadow = -s.sun[:2] / -s.sun[2]  # ground offset per metre of height
    for poly, h in s.clutter["buildings"]:
        cv2.fillPoly(img, [px(np.vstack([poly, poly + shadow * h]))], (40, 60, 55), cv2.LINE_AA, shift=2)
        hull = cv2.convexHull(np.vstack([poly, poly + shadow * h]).astype(np.float32))[:, 0]
        cv2.fillPoly(img, [px(hull)], (40, 60, 55), cv2.LINE_AA, shift=2)
        cv2.fillPoly(img, [px(poly)], (80, 85, 150) if h > 6 else (140, 140, 135), cv2.LINE_AA, shift=2)
        cv2.polylines(img, [px(poly)], True, (50, 50, 70), 2, cv2.LINE_AA, shift=2)
    for c, r, h in s.clutter["trees"]:
        sc = c + shadow * h * 0.4
        cv2.circle(img, tuple(px(sc[None])[0]), int(r / ORTHO_M * 4), (35, 55, 45), -1, cv2.LINE_AA, shift=2)
    for c, r, h in s.clutter["trees"]:
        q = px(c[None])[0]
        cv2.circle(img, tuple(q), int(r / ORTHO_M * 4), (40, 95, 55), -1, cv2.LINE_AA, shift=2)
        cv2.circle(img, tuple(q + (np.array([-shadow[0], shadow[1]]) * r / ORTHO_M * 1.2).astype(np.int32)),
                   int(r * 0.5 / ORTHO_M * 4), (60, 125, 80), -1, cv2.LINE_AA, shift=2)
    return img


def _ray_ground(s: PhotoSurvey, C, d, iterations=8):
    """Where rays C + t·d (d: (..., 3)) meet the terrain (x, y world), by fixed-point iteration on
    the height; rays that do not point down get NaN."""
    down = d[..., 2] < -0.02
    z = np.full(d.shape[:-1], float(np.median(s.dem)))
    for _ in range(iterations):
        t = np.where(down, (z - C[2]) / np.where(down, d[..., 2], -1.0), np.nan)
        x, y = C[0] + t * d[..., 0], C[1] + t * d[..., 1]
        z = s.ground(x, y)
    return x, y


def lens_map(s: PhotoSurvey):
    """For every photo pixel, where it lies in the ideal pinhole image (the camera's distortion
    inverted): the remap tables of ``render_photo``, the same for every photo of the survey."""
    import cv2

    w, h = s.camera[0], s.camera[1]
    K = s.K()
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float32) + 0.5, np.arange(h, dtype=np.float32) + 0.5)
    und = cv2.undistortPoints(np.stack([jj, ii], -1).reshape(-1, 1, 2), K, s.distortion(), P=K).reshape(h, w, 2)
    return und[..., 0].copy(), und[..., 1].copy()


def render_photo(s: PhotoSurvey, shot: Shot, ortho: np.ndarray, rng, jpeg_quality: int = 88, lens=None) -> bytes:
    """One JPEG photo: ground texture by ray casting on the terrain, the pylons' shadows, the wires
    and the pylons' beams drawn in an ideal pinhole image, then the lens's distortion, blur, noise
    and JPEG compression."""
    import cv2

    w, h = s.camera[0], s.camera[1]
    pad = int(0.12 * w)
    K = s.K()
    Kp = K.copy()
    Kp[0, 2] += pad
    Kp[1, 2] += pad
    W2, H2 = w + 2 * pad, h + 2 * pad
    step = 4
    gu, gv = np.meshgrid(np.arange(0, W2 + step, step) + 0.5, np.arange(0, H2 + step, step) + 0.5)
    rays = np.stack([gu, gv, np.ones_like(gu)], -1) @ np.linalg.inv(Kp).T @ shot.R  # world directions
    C = shot.centre
    x, y = _ray_ground(s, C, rays)
    ou = ((x - s.origin[0]) / ORTHO_M - 0.5).astype(np.float32)
    ov = ((s.origin[1] + s.extent[1] - y) / ORTHO_M - 0.5).astype(np.float32)
    ou = cv2.resize(np.nan_to_num(ou, nan=-1e4), (W2, H2), interpolation=cv2.INTER_LINEAR)[:H2, :W2]
    ov = cv2.resize(np.nan_to_num(ov, nan=-1e4), (W2, H2), interpolation=cv2.INTER_LINEAR)[:H2, :W2]
    img = cv2.remap(ortho, ou, ov, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(190, 175, 160))
    img = img.astype(np.float32)

    def to_px(P):
        cam = P @ shot.R.T + shot.t
        ok = cam[:, 2] > 1.0
        uv = cam[:, :2] / np.where(ok, cam[:, 2], 1.0)[:, None] * [Kp[0, 0], Kp[1, 1]] + Kp[:2, 2]
        return uv - 0.5, cam[:, 2], ok  # cv2 draws with pixel centres at integers

    def draw(alpha, colour_img, A, B, widths_px, colours, opacity):
        """Beams as anti-aliased lines into an 8-bit alpha mask and a colour layer; a beam thinner
        than a pixel is drawn 1 px wide and fainter."""
        ua, _, oka = to_px(A)
        ub, _, okb = to_px(B)
        colours = np.broadcast_to(np.asarray(colours, float), (len(A), 3))
        for p, q, wpx, col, ok in zip(ua, ub, widths_px, colours, oka & okb):
            if not ok or np.any(np.abs(np.r_[p, q]) > 1e5):
                continue
            th = max(int(round(wpx)), 1)
            p16, q16 = tuple(int(v) for v in np.round(p * 16)), tuple(int(v) for v in np.round(q * 16))
            cv2.line(alpha, p16, q16, int(255 * opacity * min(wpx, 1.0)), th, cv2.LINE_AA, shift=4)
            cv2.line(colour_img, p16, q16, tuple(float(c) for c in col), th + 2, cv2.LINE_8, shift=4)

    def compose(img, alpha, colour_img):
        a = alpha.astype(np.float32)[..., None] / 255.0
        return img * (1 - a) + colour_img.astype(np.float32) * a

    # shadows of the pylons on the ground
    alpha, colour = np.zeros((H2, W2), np.uint8), np.zeros((H2, W2, 3), np.uint8)
    for p in s.pylons:
        m = s.models[p.model]
        SA, SB = _shadow_on_ground(s, p.to_world(m.a)), _shadow_on_ground(s, p.to_world(m.b))
        depth = np.linalg.norm(0.5 * (SA + SB) - C, axis=1)
        draw(alpha, colour, SA, SB, m.width_m * Kp[0, 0] / depth, (30, 45, 40), 0.55)
    img = compose(img, alpha, colour)
    # wires (thinner than a pixel: faint), then the beams, lit by the sun or not
    alpha, colour = np.zeros((H2, W2), np.uint8), np.zeros((H2, W2, 3), np.uint8)
    sag = np.linspace(0, 1, 60)
    for pa, pb in zip(s.pylons[:-1], s.pylons[1:]):
        ta, tb = pa.to_world(s.models[pa.model].attachments), pb.to_world(s.models[pb.model].attachments)
        for j in range(min(len(ta), len(tb))):
            P = ta[j] + sag[:, None] * (tb[j] - ta[j])
            P[:, 2] -= 16.0 * sag * (1 - sag)  # 4 m of sag
            depth = np.linalg.norm(P[:-1] - C, axis=1)
            draw(alpha, colour, P[:-1], P[1:], 0.04 * Kp[0, 0] / depth, (60, 60, 60), 0.8)
    light = np.cross(-s.sun, [0.0, 0.0, 1.0])
    light /= max(np.linalg.norm(light), 1e-9)
    for p in s.pylons:
        m = s.models[p.model]
        A, B = p.to_world(m.a), p.to_world(m.b)
        depth = np.linalg.norm(0.5 * (A + B) - C, axis=1)
        dirs = (B - A) / np.linalg.norm(B - A, axis=1)[:, None]
        tone = 115.0 + 80.0 * np.abs(dirs @ light)
        draw(alpha, colour, A, B, m.width_m * Kp[0, 0] / depth, np.column_stack([tone, tone, tone - 6]), 0.95)
    img = compose(img, alpha, colour)
    # the lens: each photo pixel takes the ideal image at its undistorted position
    ux, uy = lens if lens is not None else lens_map(s)
    mx = (ux + pad - 0.5).astype(np.float32)
    my = (uy + pad - 0.5).astype(np.float32)
    photo = cv2.remap(img, mx, my, cv2.INTER_LINEAR)
    photo = cv2.GaussianBlur(photo, (0, 0), 0.7)
    photo = photo + rng.normal(0, 3.0, photo.shape[:2] + (1,)).astype(np.float32)
    ok, buf = cv2.imencode(".jpg", np.clip(photo, 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    return buf.tobytes()


def _shadow_on_ground(s: PhotoSurvey, X: np.ndarray) -> np.ndarray:
    out = X.copy()
    g = s.ground(X[:, 0], X[:, 1])
    for _ in range(5):
        t = (X[:, 2] - g) / -s.sun[2]
        out = X + t[:, None] * s.sun
        g = s.ground(out[:, 0], out[:, 1])
    return out


def survey_files(s: PhotoSurvey, progress=lambda it, **kw: it, workers: int = 2) -> dict:
    """The survey as files ({relative path: bytes or text}): photos/*.JPG, a COLMAP text model in
    colmap/ and the same as a binary model in colmap_bin/, the same cameras as a Metashape XML (cameras.xml), each pylon type as models/*.obj."""
    import tempfile
    from concurrent.futures import ThreadPoolExecutor
    from pathlib import Path

    from toolbox.io.cameras import Camera, Image, quaternion_from_matrix, write_colmap, write_metashape_xml

    rng = np.random.default_rng(s.seed + 7919)
    ortho = ortho_texture(s, rng)
    seeds = rng.integers(0, 2**31, len(s.shots))
    cam = Camera(1, "OPENCV", s.camera[0], s.camera[1], tuple(float(v) for v in s.camera[2]))
    images = {k + 1: Image(k + 1, sh.name, 1, quaternion_from_matrix(sh.R), sh.t) for k, sh in enumerate(s.shots)}
    files: dict = {}
    with ThreadPoolExecutor(max_workers=workers) as pool:  # OpenCV's remap and drawing run without the GIL
        lens = lens_map(s)
        futs = [pool.submit(render_photo, s, sh, ortho, np.random.default_rng(sd), lens=lens)
                for sh, sd in zip(s.shots, seeds)]
        for sh, fut in zip(s.shots, progress(futs, total=len(futs), desc="photos", unit="photo")):
            files[f"photos/{sh.name}"] = fut.result()
    with tempfile.TemporaryDirectory() as tmp:
        for sub, binary in (("colmap", False), ("colmap_bin", True)):  # the text model and COLMAP's default
            (Path(tmp) / sub).mkdir()
            write_colmap(Path(tmp) / sub, {1: cam}, images, binary=binary)
            for f in sorted((Path(tmp) / sub).iterdir()):
                files[f"{sub}/{f.name}"] = f.read_bytes() if binary else f.read_text(encoding="utf-8")
        write_metashape_xml(Path(tmp) / "cameras.xml", cam, images, s.crs, scale=0.8)
        files["cameras.xml"] = (Path(tmp) / "cameras.xml").read_text(encoding="utf-8")
        for name, m in s.models.items():
            write_obj(m, Path(tmp) / f"{name}.obj")
            files[f"models/{name}.obj"] = (Path(tmp) / f"{name}.obj").read_text(encoding="utf-8")
    return files


def perturb_images(images: dict, position_m: float, angle_deg: float, seed: int = 0) -> dict:
    """Copies of COLMAP images whose poses carry an alignment's error: each camera centre moved by
    ``position_m`` and its orientation turned by ``angle_deg`` about a random axis (both exactly
    those sizes, random directions), to test how a pose search copes with imperfect cameras."""
    from scipy.spatial.transform import Rotation

    from toolbox.io.cameras import Image, quaternion_from_matrix

    rng = np.random.default_rng(seed)
    out = {}
    for k, im in images.items():
        axis, shift = rng.normal(size=3), rng.normal(size=3)
        dR = Rotation.from_rotvec(np.radians(angle_deg) * axis / np.linalg.norm(axis)).as_matrix()
        R = dR @ im.R
        C = im.centre + position_m * shift / np.linalg.norm(shift)
        out[k] = Image(im.id, im.name, im.camera_id, quaternion_from_matrix(R), -R @ C, dict(im.extra))
    return out

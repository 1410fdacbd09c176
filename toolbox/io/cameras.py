"""Cameras of an aligned photo set: the COLMAP text model (cameras.txt, images.txt), read and
written here so that every photo plugin reads cameras the same way.

World convention (one for the whole toolbox): x east, y north, z up, in the CRS of the DEM the
photos come with, i.e. a georeferenced COLMAP model. A camera maps a world point to camera
coordinates by X_cam = R·X_world + t (R from the quaternion qw, qx, qy, qz as COLMAP writes it);
the camera looks along +z, x to the right of the image, y down. Pixel centres are at integer + 0.5
(COLMAP's convention). Distortion follows OpenCV's Brown model (k1, k2, p1, p2, k3)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError

# COLMAP camera models we read, with their parameter names in file order
MODELS = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}


@dataclass
class Camera:
    id: int
    model: str
    width: int
    height: int
    params: tuple[float, ...]

    def _p(self) -> dict:
        return dict(zip(MODELS[self.model], self.params))

    @property
    def K(self) -> np.ndarray:
        p = self._p()
        fx = p.get("fx", p.get("f"))
        fy = p.get("fy", p.get("f"))
        return np.array([[fx, 0.0, p["cx"]], [0.0, fy, p["cy"]], [0.0, 0.0, 1.0]])

    @property
    def distortion(self) -> np.ndarray:
        """OpenCV's coefficient vector (k1, k2, p1, p2, k3[, k4, k5, k6])."""
        p = self._p()
        base = [p.get("k1", 0.0), p.get("k2", 0.0), p.get("p1", 0.0), p.get("p2", 0.0), p.get("k3", 0.0)]
        if self.model == "FULL_OPENCV":
            base += [p["k4"], p["k5"], p["k6"]]
        return np.array(base, np.float64)

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Pixel coordinates of a distorted photo -> those of the ideal pinhole camera with the same K."""
        import cv2

        uv = np.asarray(uv, np.float64).reshape(-1, 1, 2)
        if not len(uv) or not np.any(self.distortion):
            return uv.reshape(-1, 2).copy()
        K = self.K
        return cv2.undistortPoints(uv, K, self.distortion, P=K).reshape(-1, 2)

    def project(self, xyz_cam: np.ndarray, distort: bool = True) -> np.ndarray:
        """Pixels of points in camera coordinates (distorted unless ``distort`` is False)."""
        import cv2

        xyz = np.asarray(xyz_cam, np.float64).reshape(-1, 3)
        d = self.distortion if distort else np.zeros(5)
        uv, _ = cv2.projectPoints(xyz, np.zeros(3), np.zeros(3), self.K, d)
        return uv.reshape(-1, 2)


@dataclass
class Image:
    id: int
    name: str
    camera_id: int
    qvec: np.ndarray  # qw, qx, qy, qz
    tvec: np.ndarray
    extra: dict = field(default_factory=dict)

    @property
    def R(self) -> np.ndarray:
        w, x, y, z = np.asarray(self.qvec, np.float64) / np.linalg.norm(self.qvec)
        return np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])

    @property
    def centre(self) -> np.ndarray:
        """The camera's position in world coordinates, −Rᵀ·t."""
        return -self.R.T @ np.asarray(self.tvec, np.float64)

    def world_to_camera(self, xyz: np.ndarray) -> np.ndarray:
        return np.asarray(xyz, np.float64) @ self.R.T + np.asarray(self.tvec, np.float64)


def quaternion_from_matrix(R: np.ndarray) -> np.ndarray:
    """(qw, qx, qy, qz) of a rotation matrix, qw >= 0."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return -q if w < 0 else q


def _lines(path: Path):
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataError(f"camera model {str(path.parent)!r} has no {path.name}; give the folder of a COLMAP text "
                        "model (cameras.txt, images.txt)") from None
    except UnicodeDecodeError:
        raise DataError(f"{str(path)!r} is not a text file; export the COLMAP model as text "
                        "(colmap model_converter --output_type TXT)") from None
    for no, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if s and not s.startswith("#"):
            yield no, s


def read_colmap_text(folder) -> tuple[dict[int, Camera], dict[int, Image]]:
    """Cameras and images of a COLMAP text model folder; one-line DataError naming the file and
    line for anything it cannot read."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"camera model {str(folder)!r} is not a folder; give the folder holding cameras.txt and "
                        "images.txt")
    cameras: dict[int, Camera] = {}
    for no, s in _lines(folder / "cameras.txt"):
        f = s.split()
        where = f"{folder / 'cameras.txt'}:{no}"
        if len(f) < 4:
            raise DataError(f"{where}: a camera line needs CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]")
        model = f[1].upper()
        if model not in MODELS:
            raise DataError(f"{where}: camera model {f[1]!r} is not supported; use one of {', '.join(MODELS)} "
                            "(colmap image_undistorter gives PINHOLE)")
        try:
            params = tuple(float(v) for v in f[4:])
            cam = Camera(int(f[0]), model, int(f[2]), int(f[3]), params)
        except ValueError:
            raise DataError(f"{where}: not a number in {s!r}") from None
        if len(params) != len(MODELS[model]):
            raise DataError(f"{where}: {model} takes {len(MODELS[model])} parameters "
                            f"({', '.join(MODELS[model])}), the line has {len(params)}")
        cameras[cam.id] = cam
    images: dict[int, Image] = {}
    for no, s in _lines(folder / "images.txt"):
        # images.txt alternates a pose line and a line of 2D points (X Y POINT3D_ID triples, maybe
        # empty); a points line ends in a number, a pose line in the photo's file name
        f = s.split()
        try:
            float(f[-1])
            continue
        except ValueError:
            pass
        where = f"{folder / 'images.txt'}:{no}"
        if len(f) < 10:
            raise DataError(f"{where}: an image line needs IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")
        try:
            img = Image(int(f[0]), " ".join(f[9:]), int(f[8]), np.array(f[1:5], float), np.array(f[5:8], float))
        except ValueError:
            raise DataError(f"{where}: not a number in {s!r}") from None
        if img.camera_id not in cameras:
            raise DataError(f"{where}: image {img.name!r} uses camera {img.camera_id}, which cameras.txt lacks")
        images[img.id] = img
    return cameras, images


def write_colmap_text(folder, cameras, images) -> None:
    """Write cameras.txt, images.txt and an empty points3D.txt into ``folder`` (which must exist)."""
    folder = Path(folder)
    cam_lines = ["# Camera list with one line of data per camera:",
                 "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    for c in cameras.values() if isinstance(cameras, dict) else cameras:
        cam_lines.append(" ".join([str(c.id), c.model, str(c.width), str(c.height)] + [repr(float(p)) for p in c.params]))
    img_lines = ["# Image list with two lines of data per image:",
                 "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
                 "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    for i in images.values() if isinstance(images, dict) else images:
        img_lines.append(" ".join([str(i.id)] + [repr(float(v)) for v in (*i.qvec, *i.tvec)] + [str(i.camera_id), i.name]))
        img_lines.append("")
    (folder / "cameras.txt").write_text("\n".join(cam_lines) + "\n", encoding="utf-8")
    (folder / "images.txt").write_text("\n".join(img_lines) + "\n", encoding="utf-8")
    (folder / "points3D.txt").write_text("# 3D point list (empty)\n", encoding="utf-8")

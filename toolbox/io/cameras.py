"""Cameras of an aligned photo set: a COLMAP model (binary or text, through pycolmap) or a
Metashape camera XML, read and written here so that every photo plugin reads cameras the same way.

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


# COLMAP's model folder in either of its forms (COLMAP writes binary by default), each with its two
# files that matter here; points3D is not used
COLMAP_FORMS = {"binary": ("cameras.bin", "images.bin"), "text": ("cameras.txt", "images.txt")}


def colmap_form(folder) -> str:
    """``binary`` or ``text``: the form of the COLMAP model in ``folder`` (binary where both are)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"camera model {str(folder)!r} is not a folder; give the folder of a COLMAP model "
                        "(cameras.bin, images.bin or cameras.txt, images.txt)")
    for form, names in COLMAP_FORMS.items():
        if all((folder / n).is_file() for n in names):
            return form
    have = [n for names in COLMAP_FORMS.values() for n in names if (folder / n).is_file()]
    if have:
        form = "binary" if have[0].endswith(".bin") else "text"
        missing = [n for n in COLMAP_FORMS[form] if n not in have][0]
        raise DataError(f"camera model {str(folder)!r} has {have[0]} but no {missing}; give the whole COLMAP model folder")
    raise DataError(f"camera model {str(folder)!r} has no COLMAP model (cameras.bin, images.bin or cameras.txt, "
                    "images.txt); give the folder COLMAP wrote (sparse/0)")


def _colmap_error(folder, form: str, err: Exception, read_from: str) -> DataError:
    """pycolmap's messages in the user's terms: which folder, what is wrong, what to do."""
    import re

    text = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    msg = re.sub(r"^\[[^\]]*\]\s*", "", text).replace(read_from, str(folder))
    cams, imgs = COLMAP_FORMS[form]
    m = re.search(r"Rig with ID (\d+) does not exist", msg)
    rigs = "rigs.bin" if form == "binary" else "rigs.txt"
    if m and not (Path(folder) / rigs).exists():  # a model without rigs gets one per camera, same id
        what = f"an image in {imgs} uses camera {m.group(1)}, which {cams} lacks"
    elif "VerifyParams" in msg:
        what = f"a camera in {cams} has the wrong number of parameters for its model"
    elif "Camera model does not exist" in msg:
        what = f"a camera in {cams} has a model COLMAP does not know"
    else:
        what = f"COLMAP cannot read it, it is damaged or not a COLMAP model (pycolmap: {msg})"
    return DataError(f"camera model {str(folder)!r} ({form}): {what}; export the model again from COLMAP "
                     "(colmap model_converter)")


def read_colmap(folder) -> tuple[dict[int, Camera], dict[int, Image]]:
    """Cameras and posed images of a COLMAP model folder, binary or text, read by pycolmap; one-line
    DataError naming the folder for anything it cannot read. Images without a pose (not
    registered) are left out: nothing can be measured in them."""
    import os
    import tempfile

    import pycolmap

    folder = Path(folder)
    form = colmap_form(folder)
    rec = pycolmap.Reconstruction()
    ext = ".bin" if form == "binary" else ".txt"
    with tempfile.TemporaryDirectory() as tmp:
        # the model without its 3D points, which nothing here uses (millions in a real model, and
        # often not shipped with the cameras): links to the rest beside an empty points3D
        for name in ("cameras", "images", "rigs", "frames"):
            if (folder / f"{name}{ext}").is_file():
                os.symlink((folder / f"{name}{ext}").resolve(), Path(tmp) / f"{name}{ext}")
        (Path(tmp) / f"points3D{ext}").write_bytes(bytes(8) if form == "binary" else b"")
        try:
            (rec.read_binary if form == "binary" else rec.read_text)(tmp)
        except Exception as err:  # pycolmap raises ValueError, IndexError, RuntimeError for bad files
            raise _colmap_error(folder, form, err, tmp) from None
    cameras: dict[int, Camera] = {}
    for cid, c in rec.cameras.items():
        model = c.model.name
        if model not in MODELS:
            raise DataError(f"camera model {str(folder)!r}: camera {cid} is {model}, which is not supported; use one of "
                            f"{', '.join(MODELS)} (colmap image_undistorter gives PINHOLE)")
        cameras[cid] = Camera(int(cid), model, int(c.width), int(c.height), tuple(float(v) for v in c.params))
    images: dict[int, Image] = {}
    for iid, im in rec.images.items():
        if not im.has_pose:
            continue
        pose = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world  # a method since 3.12
        x, y, z, w = np.asarray(pose.rotation.quat, np.float64)
        images[int(iid)] = Image(int(iid), im.name, int(im.camera_id), np.array([w, x, y, z]),
                                 np.asarray(pose.translation, np.float64).copy())
    if not images:
        raise DataError(f"camera model {str(folder)!r} has no posed image; give a model COLMAP has aligned")
    return cameras, images


def write_colmap(folder, cameras, images, binary: bool = False) -> None:
    """Write a COLMAP model (binary: *.bin, COLMAP's default; else text) into ``folder`` (which
    must exist), through pycolmap."""
    import pycolmap

    rec = pycolmap.Reconstruction()
    for c in cameras.values() if isinstance(cameras, dict) else cameras:
        rec.add_camera_with_trivial_rig(pycolmap.Camera(camera_id=c.id, model=c.model, width=c.width, height=c.height,
                                                        params=[float(p) for p in c.params]))
    for i in images.values() if isinstance(images, dict) else images:
        w, x, y, z = np.asarray(i.qvec, np.float64) / np.linalg.norm(i.qvec)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(np.array([x, y, z, w])), np.asarray(i.tvec, np.float64))
        rec.add_image_with_trivial_frame(pycolmap.Image(name=i.name, camera_id=i.camera_id, image_id=i.id), pose)
    (rec.write_binary if binary else rec.write_text)(str(folder))


# ----------------------------------------------------------------------------------------------
# Agisoft Metashape camera XML (File > Export > Export Cameras > Agisoft XML)
# ----------------------------------------------------------------------------------------------
# Metashape stores each camera as a 4 x 4 camera-to-chunk transform (camera axes as OpenCV's: x
# right, y down, z forward) in the chunk's internal frame, and the chunk's <transform> (rotation,
# translation, scale) maps that frame to geocentric (ECEF) coordinates when the chunk has a
# geographic or projected CRS (its <reference>); for a local CRS, straight to it. Its calibration
# gives f and the principal point as an offset from the image centre, with b1 (affinity: fx = f +
# b1) and its tangential terms swapped relative to OpenCV (Metashape p1 = OpenCV p2).


def _chunk_to_world(crs_wkt: str | None, target_crs):
    """A function mapping geocentric or local coordinates (N, 3) to the target CRS's (E, N, h),
    and whether the chunk is geocentric."""
    from pyproj import CRS, Transformer

    if not crs_wkt or crs_wkt.strip().upper().startswith("LOCAL_CS") or target_crs is None:
        return (lambda p: np.asarray(p, float)), False
    tgt = CRS.from_user_input(target_crs)
    tr = Transformer.from_crs(CRS.from_epsg(4978), tgt.to_3d(), always_xy=True)

    def f(p):
        p = np.asarray(p, float).reshape(-1, 3)
        return np.column_stack(tr.transform(p[:, 0], p[:, 1], p[:, 2]))

    return f, True


def _orthonormal(M: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(M)
    R = u @ vt
    return R if np.linalg.det(R) > 0 else -R


def read_metashape_xml(path, crs=None) -> tuple[dict[int, Camera], dict[int, Image]]:
    """Cameras and images of a Metashape camera XML in the toolbox's world convention. ``crs`` is
    the CRS of the world coordinates wanted (the DEM's); needed when the chunk is georeferenced.
    Cameras without a transform (not aligned) are left out."""
    import xml.etree.ElementTree as ET

    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise DataError(f"camera file {str(path)!r} does not exist; check the path") from None
    except ET.ParseError as exc:
        raise DataError(f"{str(path)!r} is not a readable Metashape camera XML ({exc}); export it again "
                        "(File > Export > Export Cameras > Agisoft XML)") from None
    chunk = root.find("chunk") if root.tag != "chunk" else root
    if chunk is None or chunk.find("sensors") is None or chunk.find("cameras") is None:
        raise DataError(f"{str(path)!r} has no <chunk> with <sensors> and <cameras>; give a Metashape camera XML")

    def num(el, tag, default=0.0):
        e = el.find(tag)
        return float(e.text) if e is not None and e.text is not None else default

    cameras: dict[int, Camera] = {}
    for s in chunk.find("sensors"):
        cal = s.find("calibration")
        res = s.find("resolution") if cal is None or cal.find("resolution") is None else cal.find("resolution")
        if cal is None or res is None:
            raise DataError(f"{str(path)!r}: sensor {s.get('id')} has no calibration; calibrate the cameras in "
                            "Metashape first (Align Photos)")
        w, h = int(res.get("width")), int(res.get("height"))
        f = num(cal, "f")
        if cal.get("type", "frame") != "frame" or f <= 0:
            raise DataError(f"{str(path)!r}: sensor {s.get('id')} is not a calibrated frame camera (type "
                            f"{cal.get('type')!r}); only frame cameras are supported")
        if num(cal, "b2") != 0.0 or num(cal, "k4") != 0.0:
            raise DataError(f"{str(path)!r}: sensor {s.get('id')} uses b2 or k4, which the OpenCV model lacks; fix "
                            "them to 0 in Metashape's camera calibration and re-optimise")
        params = (f + num(cal, "b1"), f, w / 2 + num(cal, "cx"), h / 2 + num(cal, "cy"), num(cal, "k1"),
                  num(cal, "k2"), num(cal, "p2"), num(cal, "p1"), num(cal, "k3"), 0.0, 0.0, 0.0)
        cameras[int(s.get("id"))] = Camera(int(s.get("id")), "FULL_OPENCV", w, h, params)

    S, Rch, Tch = 1.0, np.eye(3), np.zeros(3)
    tr = chunk.find("transform")
    if tr is not None:
        if tr.find("rotation") is not None:
            Rch = np.array(tr.find("rotation").text.split(), float).reshape(3, 3)
        if tr.find("translation") is not None:
            Tch = np.array(tr.find("translation").text.split(), float)
        S = num(tr, "scale", 1.0)
    ref = chunk.find("reference")
    to_world, geocentric = _chunk_to_world(ref.text if ref is not None else None, crs)
    if geocentric and crs is None:
        raise DataError(f"{str(path)!r} is georeferenced; give the DEM so that its CRS is known")
    images: dict[int, Image] = {}
    for c in chunk.find("cameras").iter("camera"):
        t = c.find("transform")
        if t is None or c.get("enabled", "true") == "false":
            continue
        sid = int(c.get("sensor_id"))
        if sid not in cameras:
            raise DataError(f"{str(path)!r}: camera {c.get('label')!r} uses sensor {sid}, which <sensors> lacks")
        M = np.array(t.text.split(), float).reshape(4, 4)
        centre_c = S * Rch @ M[:3, 3] + Tch
        axes_c = Rch @ M[:3, :3]  # camera axes (columns) in the chunk's outer frame
        centre = to_world(centre_c)[0]
        if geocentric:  # camera axes through the map's local frame: one metre along each, projected
            ends = to_world(centre_c + axes_c.T)
            axes = _orthonormal((ends - centre).T)
        else:
            axes = _orthonormal(axes_c)
        R = axes.T
        label = c.get("label")
        images[int(c.get("id"))] = Image(int(c.get("id")), label, sid, quaternion_from_matrix(R), -R @ centre)
    if not images:
        raise DataError(f"{str(path)!r} holds no aligned camera; align the photos in Metashape first")
    return cameras, images


def write_metashape_xml(path, camera: Camera, images, crs: str, scale: float = 1.0) -> None:
    """A Metashape camera XML of ``images`` (one sensor, ``camera``: PINHOLE or OPENCV) in a chunk
    georeferenced to ``crs`` through a geocentric chunk transform (a local frame at the cameras'
    centre, scaled by ``scale``), as Metashape writes it."""
    from pyproj import CRS, Transformer

    fx, fy, cx, cy = (float(v) for v in (camera.K[0, 0], camera.K[1, 1], camera.K[0, 2], camera.K[1, 2]))
    k1, k2, p1, p2, k3 = (float(v) for v in camera.distortion[:5])
    tgt = CRS.from_user_input(crs)
    to_geo = Transformer.from_crs(tgt.to_3d(), CRS.from_epsg(4978), always_xy=True)
    imgs = list(images.values() if isinstance(images, dict) else images)
    centres = np.array([i.centre for i in imgs])
    mid = centres.mean(axis=0)
    T = np.array(to_geo.transform(*mid))
    east = np.array(to_geo.transform(mid[0] + 1, mid[1], mid[2])) - T
    north = np.array(to_geo.transform(mid[0], mid[1] + 1, mid[2])) - T
    Rch = _orthonormal(np.column_stack([east, north, np.cross(east, north)]))

    def to_chunk(p):
        g = np.column_stack(to_geo.transform(*np.asarray(p, float).reshape(-1, 3).T))
        return (g - T) @ Rch / scale

    cams = []
    for k, i in enumerate(imgs):
        c = to_chunk(i.centre)[0]
        ends = to_chunk(i.centre + i.R)  # rows of R: the camera axes in the world frame
        axes = _orthonormal((ends - c).T)
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = axes, c
        label = i.name
        cams.append(f'      <camera id="{k}" sensor_id="0" label="{label}">\n'
                    f'        <transform>{" ".join(repr(float(v)) for v in M.ravel())}</transform>\n      </camera>')
    xml = f'''<?xml version="1.0" encoding="UTF-8"?>
<document version="1.5.0">
  <chunk label="Chunk 1" enabled="true">
    <sensors next_id="1">
      <sensor id="0" label="synthetic ({camera.width}x{camera.height})" type="frame">
        <resolution width="{camera.width}" height="{camera.height}"/>
        <calibration type="frame" class="adjusted">
          <resolution width="{camera.width}" height="{camera.height}"/>
          <f>{fy!r}</f>
          <cx>{cx - camera.width / 2!r}</cx>
          <cy>{cy - camera.height / 2!r}</cy>
          <b1>{fx - fy!r}</b1>
          <k1>{k1!r}</k1>
          <k2>{k2!r}</k2>
          <k3>{k3!r}</k3>
          <p1>{p2!r}</p1>
          <p2>{p1!r}</p2>
        </calibration>
      </sensor>
    </sensors>
    <cameras next_id="{len(imgs)}" next_group_id="0">
{chr(10).join(cams)}
    </cameras>
    <reference>{tgt.to_wkt()}</reference>
    <transform>
      <rotation locked="false">{" ".join(repr(float(v)) for v in Rch.ravel())}</rotation>
      <translation locked="false">{" ".join(repr(float(v)) for v in T)}</translation>
      <scale locked="false">{scale!r}</scale>
    </transform>
  </chunk>
</document>
'''
    Path(path).write_text(xml, encoding="utf-8")


def read_cameras(path, crs=None) -> tuple[dict[int, Camera], dict[int, Image]]:
    """A COLMAP model folder (binary or text) or a Metashape camera XML."""
    p = Path(path)
    if p.is_dir():
        return read_colmap(p)
    if p.suffix.lower() == ".xml":
        return read_metashape_xml(p, crs)
    if not p.exists():
        raise DataError(f"cameras {str(p)!r} do not exist; give a COLMAP model folder or a Metashape camera XML")
    raise DataError(f"cameras {str(p)!r}: not a folder (COLMAP model) nor a .xml (Metashape camera XML)")

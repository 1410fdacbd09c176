"""Pylon pose from photos (Serebro 2017, METHODS.md §4): pure functions on arrays.

Conventions (the same as ``toolbox.io.cameras`` and the scene generator): world x east, y north,
z up, in the DEM's CRS; a camera maps X_cam = R·X_world + t (COLMAP); a pylon's pose is
M = T·Rz(heading)·Ry(pitch)·Rx(roll) applied to model coordinates whose origin is the centre of
the base, angles counter-clockwise in degrees (heading 0: the model's x axis points east)."""

from __future__ import annotations

import numpy as np

from . import reference


def direction_weights(sigma: float = 1.0, spread: int = 2, kappa: float = 1.0) -> np.ndarray:
    """The method's integer weights round(κ·exp((s² − δ²) / (2σ²))) for δ = −s..s."""
    delta = np.arange(-spread, spread + 1)
    return np.round(kappa * np.exp((spread ** 2 - delta ** 2) / (2.0 * sigma ** 2))).astype(np.int32)


def smooth_directions(a: np.ndarray, weights: np.ndarray, mode: str = "max") -> np.ndarray:
    """The smoothed descriptor b[cell][i] from a[cell][·] over neighbouring direction bins (the
    bins wrap: 179° neighbours 0°). ``mode`` "max" (the thesis's text: the best-weighted
    neighbour) or "sum" (its listing). int32 (rows, cols, bins)."""
    if mode not in ("max", "sum"):
        raise ValueError(f"mode must be 'max' or 'sum', got {mode!r}")
    spread = len(weights) // 2
    a = a.astype(np.int32)
    b = np.zeros_like(a)
    for k, w in zip(range(-spread, spread + 1), weights):
        shifted = np.roll(a, -k, axis=2) * int(w)  # a[..., i + k] at index i
        b = np.maximum(b, shifted) if mode == "max" else b + shifted
    return b


def photo_descriptor(segments: np.ndarray, image_size: tuple[int, int], cell_px: int = 8, bins: int = 180,
                     mode: str = "max", sigma: float = 1.0, spread: int = 2, kappa: float = 1.0):
    """(b, table): a photo's smoothed direction descriptor on k x k pixel cells from its line
    segments (S, 4: x0, y0, x1, y1 in undistorted pixels), and the bin boundary table the
    similarity needs. image_size: (width, height) in pixels."""
    table = reference.direction_table(bins)
    width, height = image_size
    shape = (int(np.ceil(height / cell_px)), int(np.ceil(width / cell_px)))
    a = reference.occupancy(segments, shape, cell_px, table)
    return smooth_directions(a, direction_weights(sigma, spread, kappa), mode), table


def rotation(heading_deg, pitch_deg, roll_deg) -> np.ndarray:
    """Rz(heading)·Ry(pitch)·Rx(roll), counter-clockwise angles in degrees; arrays broadcast to
    (..., 3, 3)."""
    h, p, r = (np.radians(np.asarray(v, np.float64)) for v in (heading_deg, pitch_deg, roll_deg))
    h, p, r = np.broadcast_arrays(h, p, r)
    ch, sh, cp, sp, cr, sr = np.cos(h), np.sin(h), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    out = np.empty(h.shape + (3, 3))
    out[..., 0, 0] = ch * cp
    out[..., 0, 1] = ch * sp * sr - sh * cr
    out[..., 0, 2] = ch * sp * cr + sh * sr
    out[..., 1, 0] = sh * cp
    out[..., 1, 1] = sh * sp * sr + ch * cr
    out[..., 1, 2] = sh * sp * cr - ch * sr
    out[..., 2, 0] = -sp
    out[..., 2, 1] = cp * sr
    out[..., 2, 2] = cp * cr
    return out


def pose_matrices(K: np.ndarray, R_cam: np.ndarray, t_cam: np.ndarray, x, y, z, heading_deg, pitch_deg=0.0,
                  roll_deg=0.0, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """P = K·[R|t]·M for each candidate pose (float64, (N, 3, 4)), M the pylon's model-to-world
    transform. ``origin`` is subtracted from world coordinates first (the camera's t must be in the
    same shifted frame), which keeps the numbers of a projected CRS small."""
    Rm = rotation(heading_deg, pitch_deg, roll_deg).reshape(-1, 3, 3)
    T = np.column_stack([np.broadcast_to(np.asarray(v, np.float64), (len(Rm),)) for v in (x, y, z)])
    T = T - np.asarray(origin, np.float64)
    A = K @ R_cam  # (3, 3)
    P = np.empty((len(Rm), 3, 4))
    P[:, :, :3] = A @ Rm
    P[:, :, 3] = (A @ T.T).T + K @ t_cam
    return P


def similarity(b: np.ndarray, table: np.ndarray, P: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray,
               cell_px: int, kernel=None) -> np.ndarray:
    """A_s for every pose in P: the taichi kernel when given, else the numpy reference."""
    if kernel is not None:
        return kernel(b, P, seg_a, seg_b, cell_px, table)
    return reference.similarity(b, P, seg_a, seg_b, cell_px, table)


def euler_from_rotation(R: np.ndarray) -> tuple[float, float, float]:
    """(heading, pitch, roll) in degrees of R = Rz(heading)·Ry(pitch)·Rx(roll), heading in [0, 360)."""
    heading = np.degrees(np.arctan2(R[1, 0], R[0, 0])) % 360.0
    pitch = np.degrees(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    roll = np.degrees(np.arctan2(R[2, 1], R[2, 2]))
    return float(heading), float(pitch), float(roll)


def canonical_pose(pose: np.ndarray, symmetry_deg: float) -> np.ndarray:
    """The same placement of a model symmetric under turns of ``symmetry_deg`` about its z axis,
    written with the heading in [0, symmetry_deg): the model turned by whole symmetry steps, so
    that pitch and roll change with it (half a turn round, a 180-degree-symmetric tower has pitch
    and roll of the opposite sign)."""
    pose = np.asarray(pose, float).copy()
    if symmetry_deg >= 360.0:
        pose[3] %= 360.0
        return pose
    k = -np.floor(pose[3] / symmetry_deg + 1e-12)
    R = rotation(pose[3], pose[4], pose[5]) @ rotation(k * symmetry_deg, 0.0, 0.0)
    h, p, r = euler_from_rotation(R)
    pose[3:] = [0.0 if h > 360.0 - 1e-9 else h, p, r]  # a hair below 0 comes back as nearly 360
    return pose

"""The pylon model library: lattice tower types as 3D beams in their model frame (origin at the
centre of the base, x across the line, y along it, z up), with each beam's width and the wires'
attachment points. ``pylon-pose`` searches for these when no model file is given; the synthetic
photo surveys render them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SYMMETRY_DEG = {"vl220": 180.0, "u110": 360.0}  # the rotation that maps each type onto itself


@dataclass
class PylonModel:
    """A pylon type as 3D beams in its model frame, with each beam's width and the wires'
    attachment points."""

    name: str
    a: np.ndarray  # (n, 3) beam ends
    b: np.ndarray
    width_m: np.ndarray  # (n,)
    attachments: np.ndarray  # (k, 3)
    symmetry_deg: float

    @property
    def height_m(self) -> float:
        return float(max(self.a[:, 2].max(), self.b[:, 2].max()))

    def base_corners(self) -> np.ndarray:
        """The four leg feet (model frame), counter-clockwise."""
        feet = np.vstack([self.a, self.b])
        feet = feet[np.abs(feet[:, 2]) < 1e-9]
        ang = np.arctan2(feet[:, 1], feet[:, 0])
        feet = feet[np.argsort(ang)]
        keep = np.ones(len(feet), bool)
        keep[1:] = np.linalg.norm(np.diff(feet, axis=0), axis=1) > 1e-6
        return feet[keep]


def lattice_model(name: str, body_m: float, base_w: float, top_w: float, arms, peak_m: float, panels: int = 8,
                  insulator_m: float = 2.5) -> PylonModel:
    """A square lattice tower: four legs, rings and X bracing on every face in ``panels`` panels up
    to ``body_m``, arms (side -1/+1 across the line, height, reach) of two chords each, and a peak.
    Legs 0.3 m wide, the rest 0.12 m."""
    a, b, w = [], [], []
    levels = np.linspace(0.0, body_m, panels + 1)
    half = np.interp(levels, [0.0, body_m], [base_w / 2, top_w / 2])
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    ring = [np.array([[sx * h, sy * h, z] for sx, sy in corners]) for z, h in zip(levels, half)]

    def beam(p, q, width):
        a.append(p)
        b.append(q)
        w.append(width)

    for lo, hi in zip(ring[:-1], ring[1:]):
        for k in range(4):
            j = (k + 1) % 4
            beam(lo[k], hi[k], 0.3)
            beam(hi[k], hi[j], 0.12)
            beam(lo[k], hi[j], 0.12)
            beam(lo[j], hi[k], 0.12)
    hw = top_w / 2
    att = []
    for side, z_arm, reach in arms:
        tip = np.array([side * (hw + reach), 0.0, z_arm])
        for y in (-hw, hw):
            beam(np.array([side * hw, y, z_arm]), tip, 0.12)  # lower chord
            beam(np.array([side * hw, y, z_arm + 1.5]), tip, 0.12)  # upper chord
        beam(np.array([side * hw, -hw, z_arm]), np.array([side * hw, hw, z_arm]), 0.12)
        att.append(tip - [side * 0.3, 0.0, insulator_m])
    apex = np.array([0.0, 0.0, peak_m])
    for k in range(4):
        beam(ring[-1][k], apex, 0.12)
    att.append(apex)
    return PylonModel(name, np.array(a, float), np.array(b, float), np.array(w, float), np.array(att, float),
                      SYMMETRY_DEG.get(name, 360.0))


def builtin_models() -> dict[str, PylonModel]:
    """The two types of the thesis's survey: VL-220 (180° symmetric: two arms on each side at the
    same heights) and U-110 (a 90° symmetric base under an asymmetric top: arms staggered, two on one
    side, one on the other)."""
    return {
        "vl220": lattice_model("vl220", 27.0, 6.0, 1.6, [(-1, 20.0, 6.5), (1, 20.0, 6.5), (-1, 25.5, 4.5), (1, 25.5, 4.5)],
                               31.0),
        "u110": lattice_model("u110", 23.0, 5.0, 1.4, [(-1, 15.5, 3.5), (1, 18.5, 3.5), (-1, 21.5, 3.5)], 26.0, panels=7),
    }


def write_obj(model: PylonModel, path) -> None:
    """Wavefront OBJ: the beam ends as ``v``, each beam an ``l`` (the model frame: origin at the
    centre of the base, x across the line, y along it, z up, metres)."""
    lines = [f"# pylon type {model.name}: {len(model.a)} beams; origin = centre of the base, z up, metres",
             f"# symmetry_deg {model.symmetry_deg:g}"]
    for p, q in zip(model.a, model.b):
        lines.append("v {:.4f} {:.4f} {:.4f}".format(*p))
        lines.append("v {:.4f} {:.4f} {:.4f}".format(*q))
    lines += [f"l {2 * i + 1} {2 * i + 2}" for i in range(len(model.a))]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")

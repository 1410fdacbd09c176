"""Analytic terrain with the features that break ground filters, evaluated exactly anywhere.

Everything is in local metres (u east, v north, from the scene's south-west corner); heights in
metres. The same function gives the ground points and the true DTM, so the truth is exact.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Embankment:
    """A road embankment along a straight axis, cut by a bridge opening."""

    p0: tuple[float, float]
    p1: tuple[float, float]
    height_m: float = 4.0
    crest_m: float = 8.0
    side_slope: float = 1.5  # horizontal per vertical (1:1.5)
    bridge_at: float | None = None  # along-axis position (m from p0) of the bridge opening's centre
    bridge_gap_m: float = 16.0

    def frame(self, u, v):
        d = np.subtract(self.p1, self.p0)
        length = float(np.hypot(*d))
        t = d / length
        du, dv = u - self.p0[0], v - self.p0[1]
        along = du * t[0] + dv * t[1]
        across = -du * t[1] + dv * t[0]
        return along, across, length

    def raise_m(self, u, v):
        along, across, length = self.frame(u, v)
        half = self.crest_m / 2
        prof = np.clip(self.height_m - (np.abs(across) - half) / self.side_slope, 0, self.height_m)
        # ends and the bridge opening fall off with the same side slope (abutments)
        end = np.minimum(along, length - along)
        lim = np.clip(self.height_m + end / self.side_slope, 0, self.height_m)
        if self.bridge_at is not None:
            g = np.abs(along - self.bridge_at) - self.bridge_gap_m / 2
            lim = np.minimum(lim, np.clip(g / self.side_slope, 0, self.height_m))
        return np.minimum(prof, lim)

    def deck_mask(self, u, v):
        """Where the bridge deck is (over the opening, crest width)."""
        if self.bridge_at is None:
            return np.zeros(np.shape(u), bool)
        along, across, _ = self.frame(u, v)
        span = self.bridge_gap_m / 2 + self.height_m * self.side_slope
        return (np.abs(along - self.bridge_at) <= span) & (np.abs(across) <= self.crest_m / 2)


@dataclass
class Terrain:
    width_m: float
    height_m: float
    base_m: float = 300.0
    hills: list = field(default_factory=list)  # (cu, cv, amplitude_m, sigma_m)
    steep: tuple | None = None  # (v_centre, rise_m, half_width_m): a tanh step across the scene
    ridge: tuple | None = None  # (u0, v0, u1, v1, height_m, half_width_m)
    ditch: tuple | None = None  # (u0, v0, u1, v1, depth_m, top_width_m, bottom_width_m)
    embankment: Embankment | None = None
    pond: tuple | None = None  # (cu, cv, ru, rv): an ellipse of still water
    pond_level_m: float | None = None
    tilt: float = 0.0  # a plane's rise per metre eastwards (a corridor on a slope)

    @classmethod
    def random(cls, width_m, height_m, rng, features=True, tilt: float = 0.0) -> "Terrain":
        W, H = width_m, height_m
        hills = []
        for _ in range(6):
            hills.append((rng.uniform(0, W), rng.uniform(0, H), rng.uniform(-6, 9), rng.uniform(35, 110)))
        t = cls(W, H, hills=hills, tilt=tilt)
        if features:
            t.steep = (0.82 * H, 14.0, 8.0)  # up to ~41 degrees
            t.ridge = (0.62 * W, 0.12 * H, 0.97 * W, 0.55 * H, 7.0, 22.0)
            t.ditch = (0.04 * W, 0.28 * H, 0.48 * W, 0.31 * H, 1.6, 4.5, 1.0)
            t.embankment = Embankment((0.56 * W, -5.0), (0.58 * W, 0.70 * H), bridge_at=0.36 * H + 5.0)
            t.pond = (0.22 * W, 0.62 * H, min(28.0, 0.08 * W), min(16.0, 0.07 * H))
            t.pond_level_m = None
            # water level: the natural height at the shore's lowest point, minus a little
            ang = np.linspace(0, 2 * np.pi, 73)
            cu, cv, ru, rv = t.pond
            shore = t._natural(cu + ru * np.cos(ang), cv + rv * np.sin(ang))
            t.pond_level_m = float(shore.min() - 0.3)
        return t

    def _natural(self, u, v):
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        z = np.full(np.broadcast(u, v).shape, self.base_m)
        z = z + 2.5 * np.sin(u / 95.0) + 1.8 * np.cos(v / 70.0) + 0.8 * np.sin((u + 2 * v) / 41.0) + self.tilt * u
        for cu, cv, a, s in self.hills:
            z = z + a * np.exp(-((u - cu) ** 2 + (v - cv) ** 2) / (2 * s * s))
        if self.steep is not None:
            vc, rise, hw = self.steep
            z = z + rise * 0.5 * (1 + np.tanh((v - vc) / hw))
        if self.ridge is not None:
            u0, v0, u1, v1, h, hw = self.ridge
            d, along, L = _line_frame(u, v, u0, v0, u1, v1)
            ends = np.clip(np.minimum(along, L - along) / 30.0, 0, 1)  # fade out over 30 m
            z = z + h * np.clip(1 - np.abs(d) / hw, 0, 1) * ends
        if self.ditch is not None:
            u0, v0, u1, v1, depth, top, bottom = self.ditch
            d, along, L = _line_frame(u, v, u0, v0, u1, v1)
            inside = (along >= 0) & (along <= L)
            side = (top - bottom) / 2
            prof = depth * np.clip((top / 2 - np.abs(d)) / side, 0, 1)
            z = z - np.where(inside, prof, 0.0)
        return z

    def height(self, u, v):
        """Bare-earth height (the truth DTM) at local coordinates."""
        z = self._natural(u, v)
        if self.embankment is not None:
            z = z + self.embankment.raise_m(u, v)
        if self.pond is not None:
            w = self.pond_weight(u, v)
            z = np.where(w > 0, (1 - w) * z + w * self.pond_level_m, z)
        return z

    def pond_weight(self, u, v):
        """1 inside the water, falling to 0 over a 4 m shore band."""
        if self.pond is None:
            return np.zeros(np.shape(u))
        cu, cv, ru, rv = self.pond
        r = np.sqrt(((u - cu) / ru) ** 2 + ((v - cv) / rv) ** 2)
        return np.clip((1.0 + 4.0 / min(ru, rv) - r) / (4.0 / min(ru, rv)), 0, 1)

    def water_mask(self, u, v):
        if self.pond is None:
            return np.zeros(np.shape(u), bool)
        cu, cv, ru, rv = self.pond
        return ((u - cu) / ru) ** 2 + ((v - cv) / rv) ** 2 <= 1.0

    def deck_height(self, u, v):
        """Bridge deck surface: the embankment crest continued over the opening."""
        e = self.embankment
        return self._natural(u, v) + e.height_m + 0.25

    def excluded(self, u, v, margin_m=0.0, slopes: bool = True):
        """Where objects (buildings, trees) must not stand: water, embankment, ditch, steep band,
        ridge crest; with ``slopes`` False, only the first three (a pole may stand on a slope)."""
        bad = np.zeros(np.shape(u), bool)
        if self.pond is not None:
            cu, cv, ru, rv = self.pond
            bad |= ((u - cu) / (ru + margin_m + 4)) ** 2 + ((v - cv) / (rv + margin_m + 4)) ** 2 <= 1
        if self.embankment is not None:
            _, across, _ = self.embankment.frame(u, v)
            reach = self.embankment.crest_m / 2 + self.embankment.height_m * self.embankment.side_slope
            bad |= np.abs(across) <= reach + margin_m + 2
        if self.ditch is not None:
            u0, v0, u1, v1, _, top, _ = self.ditch
            d, along, L = _line_frame(u, v, u0, v0, u1, v1)
            bad |= (np.abs(d) <= top / 2 + margin_m + 1.5) & (along >= -margin_m) & (along <= L + margin_m)
        if not slopes:
            return bad
        if self.steep is not None:
            vc, _, hw = self.steep
            bad |= np.abs(v - vc) <= 2.2 * hw + margin_m
        if self.ridge is not None:  # buildings stand on levelled ground, not astride a ridge crest
            u0, v0, u1, v1, _, hw = self.ridge
            d, along, L = _line_frame(u, v, u0, v0, u1, v1)
            bad |= (np.abs(d) <= hw + margin_m) & (along >= -margin_m) & (along <= L + margin_m)
        return bad


def _line_frame(u, v, u0, v0, u1, v1):
    du, dv = u1 - u0, v1 - v0
    L = float(np.hypot(du, dv))
    tu, tv = du / L, dv / L
    along = (u - u0) * tu + (v - v0) * tv
    d = -(u - u0) * tv + (v - v0) * tu
    return d, along, L

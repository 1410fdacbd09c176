"""Wire geometry: the span record, line and catenary fits, spans split where a wire's slope
jumps (a tower it runs through), the fitted spans' tolerances."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rules import FIT_SEARCH, ROBUST_FIT, SIDE_BY_SIDE_MIN_GAP_M, SPAN_CUTS, SURFACE_CONTRAST, WIRE_LATERAL_RMS_M  # noqa: F401 (re-exported)

# the least lateral tolerance of a wire's points about its trend, whatever their measured
# scatter: a few centimetres of ranging noise on either side
WIRE_LATERAL_FLOOR_M = 0.05


# the least rms about its catenary that a wire's span may have, whatever the fit of the span it
# continues (ALS and mobile scans fit 0.02-0.05 m)
WIRE_HEIGHT_RMS_M = 0.08


# a sparse wire's visible stretches may lie this many of the 3D step's links apart (AHN4's
# earth wires: hit in stretches of 10-40 m, up to 26 m apart, where links are 6.4 m)
WIDE_GAP_LINKS = 5.0


# the radius within which a sparse wire has no other point of its band (its own points aside)
ISOLATION_M = 0.5


# a wire's id over all lines: line * WIRE_ID_BASE + wire
WIRE_ID_BASE = 1 << 20


# how many of a set's best-supported lines (through distinct points) straight_wires tries before
# it leaves the set: a cross arm or a pole top's several angles come before a wire beside them
N_BEST_LINES = 5


# (pairs of points within min_length / 2 a set's neighbourhoods are kept for: 16 bytes each)
MAX_NEIGHBOUR_PAIRS = 20_000_000
# the least a point may lie off a fitted catenary (or line) and be on it: a fit's rms understates
# how far its wire's points scatter when it is thin (a few points, a short piece)
FIT_TOLERANCE_FLOOR_M = 0.15


def fit_tolerance_m(rms_m: float, floor_m: float = FIT_TOLERANCE_FLOOR_M) -> float:
    """How far from a fit a point may lie and be on it: three times the fit's rms (or MAD), at
    least ``floor_m``."""
    return max(3 * rms_m, floor_m)


@dataclass
class Span:
    conductor: int  # index of the 2D line
    wire: int  # index of the wire (height level) along that line
    span: int
    s0: float
    c: float
    z0: float
    s_from: float
    s_to: float
    rms: float
    n_points: int
    sag: float
    offset: float = 0.0  # the wire's lateral offset from the 2D line at s = 0 (side-by-side conductors)
    offset_slope: float = 0.0  # its change per unit along the line (wires not quite parallel to it)
    offset_rms: float = 0.0  # its points' lateral scatter about that straight trend (a wire is thin)
    lateral_tol: float = np.inf  # how far across from that trend a point of this wire lies (3 robust sigma)
    chained: bool = False  # found past another span's end (next_spans): it may stop where the view does


def line_fit(x, y) -> tuple[float, float]:
    """(slope, intercept) of the least-squares line y = slope·x + intercept: ``np.polyfit(x, y, 1)``
    in closed form about the mean (polyfit's general machinery cost 150 µs a call, 150 calls per
    AHN4 run). A slope of 0 when all x are equal."""
    xm, ym = float(np.mean(x)), float(np.mean(y))
    dx = x - xm
    sxx = float(dx @ dx)
    slope = float(dx @ (y - ym)) / sxx if sxx > 0 else 0.0
    return slope, ym - slope * xm


def median_line_fit(x, y, max_pairs: int = ROBUST_FIT.lms_max_pairs,
                    max_points: int = ROBUST_FIT.lms_max_points) -> tuple[float, float]:
    """(slope, intercept) of the line through two of the points that leaves the smallest median
    absolute residual (least median of squares, Rousseeuw 1984): a wire's plan trend where up to
    half of what was linked to it is a crown's scatter, which pulls a least-squares line (a clump
    at one end tilts it). Pairs at least a quarter of the points' extent apart; all of them up to
    ``max_pairs``, else that many drawn (seeded); residuals counted on at most ``max_points``."""
    n = len(x)
    if n < 3:
        return line_fit(x, y)
    order = np.argsort(x, kind="stable")
    ev = order[::-(-n // max_points)]
    rng = np.random.default_rng(0)
    i, j = np.triu_indices(n, 1) if n * (n - 1) // 2 <= 4 * max_pairs else rng.integers(0, n, (2, 4 * max_pairs))
    far = np.abs(x[j] - x[i]) >= 0.25 * float(np.ptp(x))
    i, j = i[far], j[far]
    if len(i) > max_pairs:
        pick = rng.choice(len(i), max_pairs, replace=False)
        i, j = i[pick], j[pick]
    if not len(i):
        return line_fit(x, y)
    slope = (y[j] - y[i]) / (x[j] - x[i])
    icpt = y[i] - slope * x[i]
    med = np.median(np.abs(y[ev][None, :] - slope[:, None] * x[ev][None, :] - icpt[:, None]), axis=1)
    k = int(np.argmin(med))
    return float(slope[k]), float(icpt[k])


def parabola_fit(x, y) -> tuple[float, float, float]:
    """(a2, a1, a0) of the least-squares parabola y = a2·x² + a1·x + a0 (``np.polyfit(x, y, 2)``;
    x should be centred), by the 3x3 normal equations."""
    x2 = x * x
    m = np.array([[x2 @ x2, x2 @ x, x2.sum()], [x2 @ x, x2.sum(), x.sum()], [x2.sum(), x.sum(), float(len(x))]])
    try:
        return tuple(float(v) for v in np.linalg.solve(m, np.array([x2 @ y, x @ y, y.sum()])))
    except np.linalg.LinAlgError:  # fewer than 3 distinct x: a straight line
        slope, icpt = line_fit(x, y)
        return 0.0, slope, icpt


def catenary(s, z0, s0, c):
    with np.errstate(over="ignore"):
        return z0 + c * (np.cosh((s - s0) / c) - 1.0)


def fit_catenary(s, z):
    """Least-squares catenary through (s, z); returns (z0, s0, c, rms). Started from the parabola
    through the points (a catenary's first-order form: z0 + (s - s0)^2 / 2c)."""
    from scipy.optimize import least_squares, leastsq

    span = max(float(s.max() - s.min()), 1.0)
    sm = float(s.mean())
    k, b, a = parabola_fit(s - sm, z)
    if k > 1e-7:
        c0 = 1.0 / (2.0 * k)
        s00 = sm - b / (2.0 * k)
        z00 = a - b * b / (4.0 * k)
    else:  # (nearly) straight: a very tight wire
        c0, s00, z00 = 50.0 * span, float(s[np.argmin(z)]), float(z.min())
    c0 = float(np.clip(c0, 1.0, 1e7))

    # MINPACK asks for the Jacobian at the point whose residuals it has just had, and scipy's
    # leastsq tries both functions at the start point first: the residuals, robust weights and
    # Jacobian of the last point are kept (and the Jacobian built in one preallocated array, in
    # MINPACK's column order): per evaluation a few numpy calls on a few hundred points, whose
    # overhead is most of the cost (36 AHN4 spans 51 -> 39 ms, the same curves to 1e-5 m)
    last = {}
    jac_out = np.empty((3, len(s)))
    f_m = FIT_SEARCH.fit_robust_scale_m

    # The robust soft-L1 cost sum(f² ρ((r/f)²)), ρ(t) = 2(√(1+t) − 1), f = f_m, written as plain
    # least squares of r̃ = r·w, w = √(2/(q+1)), q = √(1+(r/f)²) (Σ r̃² is exactly that cost), so that
    # MINPACK's Levenberg-Marquardt minimises it: the same curves as scipy's trust-region solver
    # with loss="soft_l1" at 60 % of its time (to 0.1 mm on 95 of 99 AHN4 and corridor spans; the
    # other 4, nearly straight pieces where both stop at the cap, within 3 mm).
    def model(p):
        key = (float(p[0]), float(p[1]), float(p[2]))
        if last.get("key") != key:
            c = np.exp(p[2])
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # c underflows on hopeless pieces
                u = (s - p[1]) / c
                ch = np.cosh(u)
                r = p[0] + c * (ch - 1.0) - z  # = catenary(s, p0, p1, c) - z, operation for operation
                q = r / f_m
                np.hypot(q, 1.0, out=q)  # sqrt(1 + q²) without overflow: a far point must not weigh 0
                w = np.sqrt(2.0 / (q + 1.0))
            last.clear()
            last.update(key=key, c=c, u=u, ch=ch, r=r, q=q, w=w)
        return last

    def res(p):  # a copy: scipy's robust-loss path scales residuals in place
        return model(p)["r"].copy()

    def jac(p):  # analytic: 3-4x fewer model evaluations than finite differences
        m = model(p)
        c, u, ch = m["c"], m["u"], m["ch"]
        with np.errstate(over="ignore", invalid="ignore"):
            sh = np.sinh(u)
            return np.column_stack([np.ones_like(s), -sh, c * (ch - 1.0 - u * sh)])

    def res_robust(p):
        m = model(p)
        r = m["r"]
        with np.errstate(invalid="ignore"):  # an overflowed trial step stays infinite: rejected
            return np.where(np.isfinite(r), r * m["w"], r)

    def jac_robust(p):  # rows: d r̃ / d(z0, s0, log c)
        m = model(p)
        if "jac" not in m:
            c, u, ch, q, w = m["c"], m["u"], m["ch"], m["q"], m["w"]
            with np.errstate(over="ignore", invalid="ignore"):
                g = w * (q + 1.0) / (2.0 * q)  # d r̃ / d r = w (1 - (q - 1) / 2q)
                sh = np.sinh(u)
                jac_out[0] = g
                np.multiply(sh, g, out=jac_out[1])
                np.negative(jac_out[1], out=jac_out[1])
                np.multiply(u, sh, out=jac_out[2])  # c (cosh u - 1) - (s - s0) sinh u = c (cosh u - 1 - u sinh u)
                np.subtract(ch - 1.0, jac_out[2], out=jac_out[2])
                jac_out[2] *= c * g
            m["jac"] = True
        return jac_out

    # 50 evaluations settle every well-posed span; short, tight pieces whose c is barely
    # determined crawl along a flat valley without converging, for an rms that changes by a
    # millimetre (a trial step to a tiny c makes cosh overflow: the solver rejects that step, and
    # must not print a warning to the user)
    with np.errstate(over="ignore", invalid="ignore"):
        x0 = np.array([z00, s00, np.log(c0)])
        if len(s) >= 3:
            # MINPACK's lmder called as least_squares(method="lm", max_nfev=50) calls it (the same
            # tolerances, factor, scaling: the same steps), through leastsq: scipy's generic
            # wrapper cost more per evaluation than the model (99 spans 140-156 -> 90 ms)
            x = leastsq(res_robust, x0, Dfun=jac_robust, col_deriv=True, full_output=True, ftol=1e-8, xtol=1e-8,
                        gtol=1e-8, maxfev=50, factor=100.0, diag=None)[0]
        else:
            x = least_squares(res, x0, jac=jac, loss="soft_l1", f_scale=f_m, max_nfev=50).x
    z0, s0, lc = x
    r = res(x)
    # RMS over the inliers: poles and insulators joined to a wire must not condemn its fit
    mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    inl = np.abs(r) <= fit_tolerance_m(mad)
    with np.errstate(over="ignore"):  # a hopeless piece's residuals may be huge: its rms is then inf
        rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else np.inf
    return float(z0), float(s0), float(np.exp(lc)), rms


def split_spans(s, z, min_span: float, window_m: float = SPAN_CUTS.window_m, min_drop: float = SPAN_CUTS.min_drop,
                min_c_m: float = SPAN_CUTS.min_c_m):
    """Cut positions along a wire at its attachment points. Along one catenary the slope only
    grows; where the slope drops (rising on the left, falling on the right) the wire passes an
    attachment point; so does a rise in slope far steeper than a catenary's (see below). Slopes
    come from least-squares lines over ``window_m`` on each side."""
    if s.max() - s.min() < 2 * min_span:
        return []
    order = np.argsort(s)
    s, z = s[order], z[order]
    step = 1.0
    # candidate positions on a grid centred on the wire: mirror-symmetric, so a line taken the
    # other way round gives the same cuts
    centre = 0.5 * (s.min() + s.max())
    half = np.floor((0.5 * (s.max() - s.min()) - min_span) / step)
    pos = centre + step * np.arange(-half, half + 1)
    lo = np.searchsorted(s, pos - window_m)
    mid = np.searchsorted(s, pos)
    hi = np.searchsorted(s, pos + window_m)
    # prefix sums for least-squares slopes over index ranges
    cs, cz = np.r_[0, np.cumsum(s)], np.r_[0, np.cumsum(z)]
    css, csz = np.r_[0, np.cumsum(s * s)], np.r_[0, np.cumsum(s * z)]

    def slope(i, j):
        n = j - i
        with np.errstate(invalid="ignore", divide="ignore"):
            sx, sz = cs[j] - cs[i], cz[j] - cz[i]
            sxx, sxz = css[j] - css[i], csz[j] - csz[i]
            return np.where(n >= 5, (n * sxz - sx * sz) / (n * sxx - sx * sx), np.nan)

    left, right = slope(lo, mid), slope(mid, hi)
    drop = left - right
    # a catenary's slope grows by window / c between the two windows; a jump far beyond what
    # the slackest wire (c >= min_c_m) gives is a kink at an attachment point too (a span
    # climbing an embankment from a pole at its foot)
    kink = np.where(drop > 0, drop, -drop - window_m / min_c_m)  # how far past each threshold
    cand = np.isfinite(drop) & ((drop > min_drop) | (-drop > window_m / min_c_m))
    cuts = []
    for i in np.flatnonzero(cand)[np.argsort(-kink[cand])]:
        if all(abs(pos[i] - c) >= min_span for c in cuts):
            cuts.append(float(pos[i]))
    return sorted(cuts)


def kink_cut(s, z, min_span: float, step_m: float = SPAN_CUTS.kink_step_m, min_gain: float = SPAN_CUTS.kink_min_gain,
             min_drop: float = SPAN_CUTS.min_drop):
    """Where along a piece of wire that one catenary fits, two fit it markedly better: an
    attachment the wire runs through that ``split_spans``' slope windows missed (a suspension
    tower hiding the wire's points; 60 m spans' small kinks). Parabolas (a catenary's first-order form) left and
    right of each cut ``step_m`` apart, at least ``min_span`` from the ends; the best cut counts
    when it lowers the rms ``min_gain`` times, the slope drops there by ``min_drop`` (rising into
    it, falling after it: a catenary's slope only grows) and both sides meet there (within 3 of
    their rms: one wire, attached). Returns the cut or None."""
    if s.max() - s.min() < 2 * min_span or len(s) < 12:
        return None
    order = np.argsort(s)
    s, z = s[order], z[order]
    centre, half = 0.5 * (s[0] + s[-1]), 0.5 * (s[-1] - s[0])
    u = (s - centre) / half  # conditioning: in [-1, 1]
    pos = centre + step_m * np.arange(-np.floor((half - min_span) / step_m), np.floor((half - min_span) / step_m) + 1)
    k = np.searchsorted(s, pos)
    pw = np.column_stack([u ** i for i in range(5)])  # u^0..u^4
    pz = np.column_stack([z * u ** i for i in range(3)])  # z u^0..u^2
    cp = np.vstack([np.zeros((1, 5)), np.cumsum(pw, axis=0)])
    cz = np.vstack([np.zeros((1, 3)), np.cumsum(pz, axis=0)])
    cz2 = np.r_[0.0, np.cumsum(z * z)]

    def fits(i, j):  # parabola coefficients and SSE over the index ranges [i, j)
        m = cp[j] - cp[i]
        A = np.stack([m[:, 0:3], m[:, 1:4], m[:, 2:5]], axis=1)
        b = cz[j] - cz[i]
        ok = (j - i) >= 6
        A[~ok] = np.eye(3)
        with np.errstate(all="ignore"):
            coef = np.linalg.solve(A, b[..., None])[..., 0]
        sse = (cz2[j] - cz2[i]) - np.einsum("ij,ij->i", coef, b)
        return coef, np.where(ok, np.maximum(sse, 0.0), np.inf)

    n = len(s)
    _, sse1 = fits(np.array([0]), np.array([n]))
    cl, sl = fits(np.zeros_like(k), k)
    cr, sr = fits(k, np.full_like(k, n))
    sse2 = sl + sr
    best = int(np.argmin(sse2))
    if not np.isfinite(sse2[best]) or sse2[best] * min_gain ** 2 > sse1[0]:
        return None
    # cuts in one gap split the points alike: the attachment is where the two sides meet
    same = np.flatnonzero(k == k[best])
    ub = (pos[same] - centre) / half
    basis = np.column_stack([np.ones_like(ub), ub, ub * ub])
    gap = np.abs(basis @ cl[best] - basis @ cr[best])
    at = int(np.argmin(gap))
    ub = ub[at]
    slope_l = (cl[best][1] + 2 * cl[best][2] * ub) / half
    slope_r = (cr[best][1] + 2 * cr[best][2] * ub) / half
    rms2 = np.sqrt(sse2[best] / n)
    if slope_l - slope_r < min_drop or gap[at] > 3 * rms2:
        return None
    return float(pos[same[at]])

"""Accuracy measures of ground filters (ISPRS filter test conventions, Sithole & Vosselman 2004)."""

from __future__ import annotations

import numpy as np


def ground_errors(truth_ground: np.ndarray, predicted_ground: np.ndarray) -> dict:
    """Type I (ground rejected), type II (objects accepted as ground), total error (%) and Cohen's kappa."""
    tg = np.asarray(truth_ground, bool)
    pg = np.asarray(predicted_ground, bool)
    a = int(np.sum(tg & pg))
    b = int(np.sum(tg & ~pg))
    c = int(np.sum(~tg & pg))
    d = int(np.sum(~tg & ~pg))
    n = a + b + c + d
    po = (a + d) / n
    pe = ((a + b) * (a + c) + (c + d) * (b + d)) / (n * n)
    return {
        "type1_pct": round(100.0 * b / max(a + b, 1), 3),
        "type2_pct": round(100.0 * c / max(c + d, 1), 3),
        "total_pct": round(100.0 * (b + c) / max(n, 1), 3),
        "kappa": round((po - pe) / (1 - pe), 4) if pe < 1 else 1.0,
    }

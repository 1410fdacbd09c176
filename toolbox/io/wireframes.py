"""Wireframe models (3D line segments) of rigid objects such as pylon types: Wavefront OBJ with
``l`` elements, or JSON ``{"name", "beams": [[x0, y0, z0, x1, y1, z1], ...]}``; a folder of them
is a library of types."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import DataError

SUFFIXES = (".obj", ".json")


def read_wireframe(path) -> tuple[str, np.ndarray, np.ndarray]:
    """(name, ends A (n, 3), ends B (n, 3)) of one model file; a polyline ``l a b c`` gives its
    consecutive pairs."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataError(f"model {str(path)!r} does not exist; check the path") from None
    except UnicodeDecodeError:
        raise DataError(f"model {str(path)!r} is not a text file; give a Wavefront OBJ with 'l' lines or a JSON model") from None
    if path.suffix.lower() == ".json":
        try:
            beams = np.asarray(json.loads(text)["beams"], float).reshape(-1, 6)
        except (ValueError, KeyError, TypeError):
            raise DataError(f"model {str(path)!r}: JSON needs \"beams\": [[x0, y0, z0, x1, y1, z1], ...]") from None
        a, b = beams[:, :3], beams[:, 3:]
    else:
        verts, pairs = [], []
        for no, line in enumerate(text.splitlines(), 1):
            f = line.split("#", 1)[0].split()
            if not f:
                continue
            try:
                if f[0] == "v":
                    verts.append([float(v) for v in f[1:4]])
                elif f[0] == "l":
                    idx = [int(t.split("/")[0]) for t in f[1:]]
                    pairs += list(zip(idx[:-1], idx[1:]))
            except ValueError:
                raise DataError(f"{path}:{no}: not a number in {line.strip()!r}") from None
        V = np.asarray(verts, float).reshape(-1, 3)
        try:
            ij = np.array([[i - 1 if i > 0 else len(V) + i for i in p] for p in pairs], int).reshape(-1, 2)
            a, b = V[ij[:, 0]], V[ij[:, 1]]
        except IndexError:
            raise DataError(f"model {str(path)!r}: an 'l' line names a vertex the file lacks") from None
    keep = np.linalg.norm(b - a, axis=1) > 1e-9
    if not keep.any():
        raise DataError(f"model {str(path)!r} has no beams; a pylon model needs 'l' lines (OBJ) or \"beams\" (JSON)")
    return path.stem, a[keep], b[keep]


def read_wireframes(path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """One model file, or every model file of a folder (a library of types): {name: (A, B)}."""
    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in SUFFIXES)
        if not files:
            raise DataError(f"model folder {str(path)!r} holds no .obj or .json model")
        return {n: (a, b) for n, a, b in (read_wireframe(f) for f in files)}
    name, a, b = read_wireframe(path)
    return {name: (a, b)}


def rotational_symmetry_deg(a: np.ndarray, b: np.ndarray, tol_m: float = 0.02) -> float:
    """The smallest turn about the vertical axis (90, 180 or 360 degrees) that maps the model onto
    itself (every beam onto a beam, either way round)."""
    from scipy.spatial import cKDTree

    seg = np.vstack([np.hstack([a, b]), np.hstack([b, a])])
    tree = cKDTree(seg)
    for turn in (90.0, 180.0):
        c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        moved = np.hstack([a @ R.T, b @ R.T])
        if np.all(tree.query(moved)[0] < tol_m):
            return turn
    return 360.0

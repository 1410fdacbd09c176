"""Operations on a set of found wires (plan lines ``lines``, their frames ``geo``, catenary spans
``spans``) and the labels of the candidates on them: keeping some conductors, appending or
folding in a further pass's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from shapely.geometry import LineString

from .core import span_in_frame


def add_pass(found2, lines, geo, spans, line_of, wire_of_pt, hu, params):
    """A further pass's result (``lines_and_wires`` on the points on no wire, or None) added to
    the first's: a line along one found already is the rest of its points (near a tower, a
    sparse stretch, past the end of its 2D extent), not another conductor, so its wires are
    folded into that line's; the others are appended as new conductors. ``line_of`` and
    ``wire_of_pt`` are updated in place. Returns (lines, geo, spans)."""
    if found2 is None:
        return lines, geo, spans
    lines2, geo2, spans2, line_of2, wire2, _ = found2
    along = {}  # pass-2 line -> the pass-1 line it runs along
    for i, g in enumerate(geo2):
        j = next((j for j, h in enumerate(geo) if runs_along(g, h, params["band_m"])), None)
        if j is not None:
            along[i] = j
    pos = np.flatnonzero(line_of < 0)  # where pass 2's points sit among pass 1's
    if along:
        spans, geo, lines = fold_into(along, geo2, spans2, line_of2, wire2, geo, spans, lines, line_of,
                                       wire_of_pt, pos, hu)
    new = [i for i in range(len(geo2)) if i not in along]
    lines2, geo2, spans2, line_of2, wire2 = keep_conductors(new, lines2, geo2, spans2, line_of2, wire2)
    if len(geo2):
        n0 = len(geo)
        for sp in spans2:
            sp.conductor += n0
        geo, spans = geo + geo2, spans + spans2
        mine = line_of2 >= 0  # the kept lines' points (the folded ones' are given out already)
        line_of[pos[mine]] = line_of2[mine] + n0
        wire_of_pt[pos[mine]] = wire2[mine]
        lines = append_conductors(lines, lines2, n0)
    return lines, geo, spans


def fold_stubs(lines, geo, spans, line_of, wire_of_pt, hu, params):
    """A line at most half as long as another that it runs along (``runs_along``) is a stretch of
    that conductor the Hough fitted on its own (a sub-conductor of a bundle near a tower, a
    stretch past a gap), not another one: folded into it as ``add_pass`` folds a further pass's
    lines. Returns (lines, geo, spans, line_of, wire_of_pt)."""
    length = [t1 - t0 for (_, _, t0, t1) in geo]
    stubs = [i for i, g in enumerate(geo)
             if any(j != i and length[j] >= 2 * length[i] and runs_along(g, h, params["band_m"]) for j, h in enumerate(geo))]
    if not stubs:
        return lines, geo, spans, line_of, wire_of_pt
    # (keep_conductors renumbers the spans in place: the stubs' selection works on copies)
    sub = keep_conductors(stubs, lines, geo, [dataclasses.replace(sp) for sp in spans], line_of, wire_of_pt)
    lines, geo, spans, line_of, wire_of_pt = keep_conductors([i for i in range(len(geo)) if i not in stubs], lines,
                                                              geo, spans, line_of, wire_of_pt)
    pos = np.flatnonzero(line_of < 0)
    lines, geo, spans = add_pass((*sub[:3], sub[3][pos], sub[4][pos], 0), lines, geo, spans, line_of, wire_of_pt,
                                  hu, params)
    return lines, geo, spans, line_of, wire_of_pt


def fold_into(along: dict, geo2, spans2, line_of2, wire2, geo, spans, lines, line_of, wire_of_pt, pos, hu):
    """Second-pass lines ``along`` first-pass ones ({pass-2 line: pass-1 line}) folded into them:
    their spans re-expressed in the pass-1 line's frame as new wires of it, their points (``pos``:
    where pass 2's per-point arrays sit in the pass-1 ones) given to it, and its 2D extent and
    plan line stretched over them. Returns (spans, geo, lines)."""
    next_wire = {j: max([sp.wire for sp in spans if sp.conductor == j], default=-1) + 1 for j in set(along.values())}
    wire_map, spans = {}, list(spans)
    for sp in spans2:
        if sp.conductor not in along:
            continue
        j = along[sp.conductor]
        if (sp.conductor, sp.wire) not in wire_map:
            wire_map[(sp.conductor, sp.wire)] = next_wire[j]
            next_wire[j] += 1
        spans.append(span_in_frame(sp, geo2[sp.conductor], geo[j], j, wire_map[(sp.conductor, sp.wire)]))
    for k in np.flatnonzero(np.isin(line_of2, list(along))):
        key = (int(line_of2[k]), int(wire2[k]))
        if key not in wire_map:
            wire_map[key] = next_wire[along[key[0]]]
            next_wire[along[key[0]]] += 1
        line_of[pos[k]], wire_of_pt[pos[k]] = along[key[0]], wire_map[key]
    geo = list(geo)
    cond = lines["conductors"].copy()
    for j in set(along.values()):
        a, d, t0, t1 = geo[j]
        t0 = min([t0] + [sp.s_from for sp in spans if sp.conductor == j])
        t1 = max([t1] + [sp.s_to for sp in spans if sp.conductor == j])
        geo[j] = (a, d, t0, t1)
        cond.loc[cond.index[j], "geometry"] = LineString([(a + t0 * d) / hu, (a + t1 * d) / hu])
        if "length_m" in cond.columns:
            cond.loc[cond.index[j], "length_m"] = t1 - t0
    return spans, geo, {**lines, "conductors": cond}


def runs_along(g, h, band_m: float, max_angle_deg: float = 1.0) -> bool:
    """Whether line ``g`` runs along line ``h`` (both (anchor, direction, t0, t1)): within
    ``max_angle_deg`` of it and both its ends within ``band_m`` of it."""
    (a, d, t0, t1), (b, e, _, _) = g, h
    # a short line's Hough angle is loose (a 10 m stub leant 1.4 deg off its wire): its ends within
    # band_m of the other line tell, up to the angle that band allows over its length
    max_angle_deg = max(max_angle_deg, float(np.degrees(np.arctan2(band_m, t1 - t0))))
    if abs(float(d @ e)) < np.cos(np.radians(max_angle_deg)):
        return False
    normal = np.array([-e[1], e[0]])
    return all(abs(float((a + t * d - b) @ normal)) <= band_m for t in (t0, t1))


def append_conductors(lines: dict, more: dict, n0: int) -> dict:
    """The layers of a second Hough pass appended to the first's, its conductors numbered from
    ``n0`` (crossings are computed once, over the final conductors)."""
    out = {}
    for name in ("conductors", "conductor_segments"):
        add = more[name].assign(conductor=more[name]["conductor"] + n0)
        g = pd.concat([lines[name], add], ignore_index=True)
        g.attrs.update(lines[name].attrs)
        out[name] = g
    return out


def keep_conductors(keep_lines, lines, geo, spans, line_of, wire_of_pt):
    """Only the given conductors (renumbered) in the layers, the geometry, the spans and the
    per-point conductor and wire of the 3D step."""
    new_id = renumbering(keep_lines, len(geo))
    line_of = new_id[line_of]
    wire_of_pt = np.where(line_of < 0, -1, wire_of_pt)
    spans = [sp for sp in spans if new_id[sp.conductor] >= 0]
    for sp in spans:
        sp.conductor = int(new_id[sp.conductor])
    return select_conductors(lines, keep_lines), [geo[i] for i in keep_lines], spans, line_of, wire_of_pt


def renumbering(keep_lines, n_lines: int) -> np.ndarray:
    """Old conductor -> new, indexed by a per-point conductor (-1: dropped; -1 stays -1)."""
    new_id = np.full(n_lines + 1, -1, np.int64)
    new_id[keep_lines] = np.arange(len(keep_lines))
    return new_id


def select_conductors(lines: dict, keep: list) -> dict:
    """Keep the given conductors (renumbered) with their segments (crossings are computed once,
    over the final conductors)."""
    cond = lines["conductors"]
    remap = {old: new for new, old in enumerate(keep)}
    new_cond = cond.iloc[keep].reset_index(drop=True).assign(conductor=list(range(len(keep))))
    seg = lines["conductor_segments"]
    seg = seg[seg["conductor"].isin(keep)].reset_index(drop=True)
    seg = seg.assign(conductor=[remap[c] for c in seg["conductor"]])
    for g, src in ((new_cond, cond), (seg, lines["conductor_segments"])):
        g.attrs.update(src.attrs)
    return {"conductors": new_cond, "conductor_segments": seg}


def drop_spans(gone, spans, geo, px, py, line_of, wire_of_pt):
    """The spans ``gone`` taken out, with their points (those of their wire within their extent,
    ``p*`` in metres) on no wire again. Returns (spans, line_of, wire_of_pt)."""
    for sp in gone:
        a, d, _, _ = geo[sp.conductor]
        mine = np.flatnonzero((line_of == sp.conductor) & (wire_of_pt == sp.wire))
        s = (px[mine] - a[0]) * d[0] + (py[mine] - a[1]) * d[1]
        out = mine[(s >= sp.s_from) & (s <= sp.s_to)]
        line_of[out], wire_of_pt[out] = -1, -1
    return [sp for sp in spans if not any(sp is q for q in gone)], line_of, wire_of_pt

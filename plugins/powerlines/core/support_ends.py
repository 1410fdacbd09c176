"""Crossings at supports: where a line ends at a found tower or pole, an intersection past that
end is no crossing (the method's crossings are not pylon positions). The rule the host's
``toolbox.crossings.crossings`` takes as its ``excluded`` predicate."""

from __future__ import annotations

import numpy as np

# how far short of its support's centre a wire ending there stops in plan (a dead-end string of
# insulators holds it off the arm)
STRAIN_INSULATOR_M = 0.5


def ends_at_supports(lines, segments, supports, beyond_m: float = 1.0):
    """The predicate ``excluded(i, j, point)`` for ``crossings``, or None without ``supports``
    [(x, y, reach_m)] (towers and poles found): an intersection more than ``beyond_m`` past the
    end of a line's segments, where that end is within a support's reach, and within
    STRAIN_INSULATOR_M of that support or past it, is not a crossing: the line ends at the support,
    and the extension would carry it on to the line beside the pole; where that end lies within
    STRAIN_INSULATOR_M of the support along the line, nothing more than STRAIN_INSULATOR_M past the
    support is; nor is one of two lines that both end at a support, within its reach."""
    if not supports:
        return None
    sup = np.asarray([s_[:2] for s_ in supports], float).reshape(-1, 2)
    sup_reach = np.asarray([s_[2] for s_ in supports], float)
    # per line, how far along it each end at a support reaches: beyond_m past its segments, or up
    # to the support less a strain insulator (the wire runs on to its arm, unseen over the last
    # metres next to the structure, and a line crossing there crosses it)
    extents = []
    for (a, d), segs in zip(lines, segments):
        a, d = np.asarray(a, float), np.asarray(d, float)
        t = np.array([(np.asarray(e, float) - a) @ d for seg in segs for e in seg]) if len(segs) else np.zeros(1)
        lim, ends_at = [], set()
        for t_end, side in ((t.min(), -1.0), (t.max(), 1.0)):
            near = np.flatnonzero(np.hypot(*(sup - (a + t_end * d)).T) <= sup_reach) if len(segs) else []
            if len(near):
                at = float(np.max(side * ((sup[near] - a) @ d)))  # the farthest support, along the line
                reach = max(side * t_end + beyond_m, at - STRAIN_INSULATOR_M)
                if abs(side * t_end - at) <= STRAIN_INSULATOR_M:
                    # its wire seen up to the support: it ends there, not a metre past it
                    reach = max(side * t_end, at + STRAIN_INSULATOR_M)
            lim.append(None if not len(near) else side * reach)
            ends_at.update(int(k) for k in near)
        extents.append((a, d, lim, ends_at))

    def ends_at_support(k, p):
        a, d, (lim0, lim1), _ = extents[k]
        t = (p - a) @ d
        return (lim0 is not None and t < lim0) or (lim1 is not None and t > lim1)

    def turns_at_support(i, j, p):
        # both end at one support and meet within its reach: one line's wires turning there (an
        # angle tower), or its arms
        return any(np.hypot(*(sup[k] - p)) <= sup_reach[k] for k in extents[i][3] & extents[j][3])

    def excluded(i, j, p):
        return ends_at_support(i, p) or ends_at_support(j, p) or turns_at_support(i, j, p)

    return excluded

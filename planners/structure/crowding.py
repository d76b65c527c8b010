"""Crowded stretches: another member's steel among a thin member's points.

On a coarse scan a small member's envelope holds some points of the
girder it crosses or frames into: that girder's own envelope, measured at
10 cm, is narrower than its section, so its flange points near the
crossing lie nearest the small member's axis.  A row of cross girders
joined across main girders (grillage seed 8 at 10 cm: 19 of its 99 points
are the main girders') is refitted through the centre of a section box
that those points stretch, and leans 1–4°: its ends leave the true line by
more than a section.  Refitted from their own points only, each of the
nine such grillage members at 10 cm is found.

Those points are found by where they are, along the member and across it.
The member is cut into stretches; in each, the extent of its points
across the member (the diagonal of their box in a plane normal to the
axis) is measured.  A member's own section gives about the same extent in
every stretch (fewer points give less, never more); a crossing girder's
flange adds to one or two stretches' extent, 2–3 times over.  A stretch
is *crowded* when its extent exceeds ``CROWDED_RATIO`` times the median
stretch's, and by ``CROWDED_MARGIN_SPACINGS`` spacings or more.  The line through the points of the
other stretches and the section they show (the 99th percentile of their
distances from it, plus ``CROWDED_PAD_SPACINGS``) then tell which points
of the crowded stretches are the member's: those within that section.
Nothing is left out when no stretch is crowded, when more than
``CROWDED_MAX_SHARE`` of them are (that is a member whose section varies,
not a crossing), or when too few points would remain.

The model measures members only on a coarse scan, where a girder's
section is a few spacings across (a finer scan resolves it, and the
girder's envelope holds its own points), and only those of at most
``CROWDED_MAX_POINTS`` points (which bounds the work).
"""

from __future__ import annotations

import numpy as np

from planners.structure.faces import cross_section
from planners.structure.lines import fit_line

#: a stretch is this many spacings long, and at least ``CROWDED_STRETCH_M``
CROWDED_STRETCH_SPACINGS = 5.0
CROWDED_STRETCH_M = 0.3
#: a stretch's extent is measured from this many points or more
CROWDED_MIN_STRETCH_POINTS = 3
#: stretches so measured a member needs
CROWDED_MIN_STRETCHES = 3
#: a crowded stretch's extent is over this many times the median's
CROWDED_RATIO = 1.5
#: and by at least this many spacings (20 grillage seeds at 10 cm: a
#: spacing left one joined row crowded by 0.31 m against 0.20 m unfound;
#: a ratio of 1.3 found one more member but cost Warren and the frame
#: precision, 0.963 → 0.954 and 0.968 → 0.964)
CROWDED_MARGIN_SPACINGS = 0.5
#: at most this share of the stretches may be crowded
CROWDED_MAX_SHARE = 0.5
#: the section the uncrowded stretches show is widened by this many spacings
CROWDED_PAD_SPACINGS = 0.5
#: members with more points than this are not measured
CROWDED_MAX_POINTS = 400
#: fewest points the uncrowded stretches must keep
CROWDED_MIN_POINTS = 8


def uncrowded_points(q: np.ndarray, spacing: float) -> np.ndarray | None:
    """Mask of a member's points ``q`` (N, 3) that are its own, the points
    another member brought into crowded stretches left out; ``None`` when no
    point is left out (see the module docstring)."""
    n = len(q)
    if n < 2 * CROWDED_MIN_POINTS or n > CROWDED_MAX_POINTS:
        return None
    c, d, _, _, _ = fit_line(q)
    cs = cross_section(q, c, d)
    t, uv = cs.t, cs.uv
    stretch = max(CROWDED_STRETCH_SPACINGS * spacing, CROWDED_STRETCH_M)
    bins = np.floor((t - t.min()) / stretch).astype(np.int64)
    ids, inv, counts = np.unique(bins, return_inverse=True, return_counts=True)
    lo = np.full((len(ids), 2), np.inf)
    hi = np.full((len(ids), 2), -np.inf)
    np.minimum.at(lo, inv, uv)
    np.maximum.at(hi, inv, uv)
    extent = np.linalg.norm(hi - lo, axis=1)
    measured = counts >= CROWDED_MIN_STRETCH_POINTS
    if int(measured.sum()) < CROWDED_MIN_STRETCHES:
        return None
    typical = float(np.median(extent[measured]))
    crowded = (
        measured
        & (extent > CROWDED_RATIO * typical)
        & (extent > typical + CROWDED_MARGIN_SPACINGS * spacing)
    )
    if not crowded.any() or crowded.sum() > CROWDED_MAX_SHARE * len(ids):
        return None
    clear = ~crowded[inv]
    if int(clear.sum()) < CROWDED_MIN_POINTS:
        return None
    c2, d2, _, _, _ = fit_line(q[clear])
    w = q - c2
    off = np.linalg.norm(w - np.outer(w @ d2, d2), axis=1)
    reach = float(np.percentile(off[clear], 99)) + CROWDED_PAD_SPACINGS * spacing
    keep = clear | (off <= reach)
    return None if keep.all() else keep

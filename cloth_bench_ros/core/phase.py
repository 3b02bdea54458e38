"""
The change of phase of a dynamic trial: the first frame in which the cloth touches the table.

The paper scores its fling only "before the change of phase", the frame at which the falling
cloth first contacts the table. A recording rarely says which frame that is, so it is found in
the data: a frame is in contact when enough of its points lie in the contact band, 1-2 cm above
the table top. The band starts where the cleaning's table-plane band ends: the cleaning removes
the cloth's lowest centimetre with the table, so that centimetre is never counted, on a real
cloud cleaned or not and on a simulated one alike. A share of the points is required, and a few
at the least, so that sensor noise and single stray points do not count; a recording whose very
first frame is already "in contact" shows something other than the falling cloth in the band
(a table higher than the scene's) and gives no answer rather than a wrong one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from cloth_bench_ros.core.scene import TABLE_PLANE_DISTANCE, TABLE_TOP_Z
import numpy as np

CONTACT_MARGIN = 0.02  # m above the table top: the band's top ...
CONTACT_FLOOR = TABLE_PLANE_DISTANCE  # ... and its bottom: what the cleaning leaves of the cloth
CONTACT_MIN_POINTS = 8  # points in the band, at the least ...
CONTACT_MIN_FRACTION = 0.004  # ... or this fraction of the frame's points, whichever is more
# Points drawn on a simulated surface for the rule: as many as the real frame has, up to the
# count whose threshold is CONTACT_MIN_POINTS (2000): the same share of points on both sides.
CONTACT_SAMPLES = round(CONTACT_MIN_POINTS / CONTACT_MIN_FRACTION)


@dataclass(frozen=True)
class ContactSearch:
    """Outcome of `first_table_contact`: the contact frame's position, or why there is none."""

    index: int | None  # position in the frames given, None if no contact was found
    reason: str  # one line: what was found


def contact_points(
    points: np.ndarray, table_z: float = TABLE_TOP_Z, margin: float = CONTACT_MARGIN
) -> int:
    """Return the points of a frame (n, 3) in the contact band: CONTACT_FLOOR to `margin` up."""
    height = np.asarray(points, dtype=np.float64).reshape(-1, 3)[:, 2] - table_z
    return int(np.count_nonzero((height > CONTACT_FLOOR) & (height <= margin)))


def contact_samples(real_points: int) -> int:
    """Return how many points to draw on a simulated surface to judge it beside a real frame."""
    return min(int(real_points), CONTACT_SAMPLES)


def in_contact(
    points: np.ndarray, table_z: float = TABLE_TOP_Z, margin: float = CONTACT_MARGIN
) -> bool:
    """Return True if enough of the frame's points lie at the table to be cloth resting on it."""
    n = len(points)
    needed = max(CONTACT_MIN_POINTS, int(np.ceil(CONTACT_MIN_FRACTION * n)))
    return n > 0 and contact_points(points, table_z, margin) >= needed


def first_table_contact(
    frames: Iterable[np.ndarray], table_z: float = TABLE_TOP_Z, margin: float = CONTACT_MARGIN
) -> ContactSearch:
    """Return the first of `frames` (world clouds in order) where the cloth touches the table."""
    return first_contact(in_contact(points, table_z, margin) for points in frames)


def first_contact(flags: Iterable[bool]) -> ContactSearch:
    """Return the first True of per-frame `in_contact` flags, unless the first frame is one."""
    seen = 0
    for i, touching in enumerate(flags):
        seen += 1
        if not touching:
            continue
        if i == 0:
            return ContactSearch(
                None,
                'points in the contact band from the first frame on (a table higher '
                "than the scene's in the clouds: clean them, or give the frame)",
            )
        return ContactSearch(i, 'first table contact')
    return ContactSearch(None, f'no table contact in {seen} frames')

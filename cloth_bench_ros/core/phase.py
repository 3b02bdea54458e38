"""
The change of phase of a dynamic trial: the first frame in which the cloth touches the table.

The paper scores its fling only "before the change of phase", the frame at which the falling
cloth first contacts the table. A recording rarely says which frame that is, so it is found in
the data: a frame is in contact when at least `min_points` of its points (after the table plane
itself has been removed, as the cleaning does) lie within `margin` above the table top. A few
points are required, not one, so that sensor noise and single stray points do not count; a
recording whose very first frame is already "in contact" shows the table itself, not the cloth,
and gives no answer rather than a wrong one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from cloth_bench_ros.core.scene import TABLE_TOP_Z
import numpy as np

CONTACT_MARGIN = 0.02  # m above the table top; more than the cleaning's 1 cm plane band
CONTACT_MIN_POINTS = 8  # points in the band, at the least ...
CONTACT_MIN_FRACTION = 0.004  # ... or this fraction of the frame's points, whichever is more


@dataclass(frozen=True)
class ContactSearch:
    """Outcome of `first_table_contact`: the contact frame's position, or why there is none."""

    index: int | None  # position in the frames given, None if no contact was found
    reason: str  # one line: what was found


def contact_points(
    points: np.ndarray, table_z: float = TABLE_TOP_Z, margin: float = CONTACT_MARGIN
) -> int:
    """Return the points of a frame (n, 3) within `margin` above the table top (or below it)."""
    z = np.asarray(points, dtype=np.float64).reshape(-1, 3)[:, 2]
    return int(np.count_nonzero(z <= table_z + margin))


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
                'points at the table top from the first frame on (the table is in '
                'the clouds: clean them, or give the frame)',
            )
        return ContactSearch(i, 'first table contact')
    return ContactSearch(None, f'no table contact in {seen} frames')

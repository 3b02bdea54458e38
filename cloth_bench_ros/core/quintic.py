"""Quintic polynomial segments and chains of them: a task's gripper motion per axis."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class QuinticSegment:
    """x(t) = a0 + a1 t + ... + a5 t^5 on [0, duration], fixed by (p, v, a) at both ends."""

    duration: float
    start: tuple[float, float, float]
    end: tuple[float, float, float]

    @property
    def coefficients(self) -> np.ndarray:
        p0, v0, a0 = self.start
        p1, v1, a1 = self.end
        T = self.duration
        # Solve for a3, a4, a5 given a0 = p0, a1 = v0, a2 = a0 / 2.
        A = np.array(
            [[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4], [6 * T, 12 * T**2, 20 * T**3]]
        )
        b = np.array(
            [
                p1 - (p0 + v0 * T + 0.5 * a0 * T**2),
                v1 - (v0 + a0 * T),
                a1 - a0,
            ]
        )
        c3, c4, c5 = np.linalg.solve(A, b)
        return np.array([p0, v0, 0.5 * a0, c3, c4, c5])

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at local times t (not clamped)."""
        c = self.coefficients
        t = np.asarray(t, dtype=float)
        pos = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
        vel = c[1] + t * (2 * c[2] + t * (3 * c[3] + t * (4 * c[4] + t * 5 * c[5])))
        acc = 2 * c[2] + t * (6 * c[3] + t * (12 * c[4] + t * 20 * c[5]))
        return pos, vel, acc


def hold(duration: float, p: float) -> QuinticSegment:
    """Return a segment that stays at p for `duration` seconds."""
    return QuinticSegment(duration, (p, 0.0, 0.0), (p, 0.0, 0.0))


@dataclass(frozen=True)
class QuinticChain:
    """Segments played one after the other; before 0 the start holds, after the end the end."""

    segments: tuple[QuinticSegment, ...]

    @property
    def duration(self) -> float:
        return float(sum(s.duration for s in self.segments))

    @property
    def breakpoints(self) -> np.ndarray:
        """Return the times at which segments end, from the start of the chain."""
        return np.cumsum([s.duration for s in self.segments])

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at chain times t."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        pos, vel, acc = np.empty_like(t), np.empty_like(t), np.empty_like(t)
        ends = self.breakpoints
        starts = ends - np.array([s.duration for s in self.segments])
        # A time on a breakpoint belongs to the segment that ends there (its end conditions hold).
        index = np.clip(np.searchsorted(ends, t - 1e-12, side='left'), 0, len(self.segments) - 1)
        for i, seg in enumerate(self.segments):
            mask = index == i
            if mask.any():
                local = np.clip(t[mask] - starts[i], 0.0, seg.duration)
                pos[mask], vel[mask], acc[mask] = seg.evaluate(local)
        outside = (t < 0.0) | (t > ends[-1])
        vel[outside] = 0.0
        acc[outside] = 0.0
        return pos, vel, acc

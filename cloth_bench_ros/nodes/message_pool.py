"""
Messages published again once nobody else holds them: the per-step messages of the node graph.

The embedded intra-process transport hands each subscriber the published object itself, so a
message refilled in place could change under a subscriber that has not run yet, or that kept it.
A pool owns a few messages and gives one back for refilling only when CPython's reference counts
say that nothing but the pool holds it and its parts (queues and subscribers hold references);
else it builds a new one in that slot. What a subscriber receives is never changed after it was
published, as with rclpy, and the steady state builds no message at all. Where publish serialises
the message (DDS, real rclpy), nothing holds it afterwards: `in_place` pools have one message,
refilled every time without a check.
"""

from __future__ import annotations

import sys
from typing import Any, Callable, Generic, TypeVar

T = TypeVar('T')


class MessagePool(Generic[T]):
    """`size` messages from `build` (one if `in_place`); `take()` returns one free to refill."""

    def __init__(
        self,
        build: Callable[[], T],
        parts: Callable[[T], tuple] = lambda m: (m,),
        size: int = 4,
        in_place: bool = False,
    ) -> None:
        self.build, self.parts, self.in_place = build, parts, in_place
        size = 1 if in_place else size
        self.slots: list[Any] = [None] * size
        self.free_refs: list[list[int]] = [[] for _ in range(size)]
        self.next = 0
        self.built = 0  # messages built so far (size at start, more while subscribers hold them)
        for i in range(size):
            self._refill_slot(i)

    def _refill_slot(self, i: int) -> None:
        self.slots[i] = self.build()
        self.built += 1
        self.free_refs[i] = self._refs(i)  # the counts of a message only the pool holds

    def _refs(self, i: int) -> list[int]:
        return [sys.getrefcount(p) for p in self.parts(self.slots[i])]

    def take(self) -> T:
        """Return the next message, to be refilled and published; built anew if still held."""
        if self.in_place:
            return self.slots[0]
        i = self.next
        self.next = (i + 1) % len(self.slots)
        if self._refs(i) != self.free_refs[i]:
            self._refill_slot(i)
        return self.slots[i]

"""The connected parts of the experience map. One session makes one part; a map kept over sessions holds one part
per session until a session relocalises in another's, and the two become one (neoslam.store). Each part is named
by its first (lowest) experience, whose pose fixes the part's frame."""

from __future__ import annotations

import numpy as np

__all__ = ["MapParts"]

INITIAL_CAPACITY = 256


class MapParts:
    """Which part each experience belongs to; parts join when a link ties them."""

    def __init__(self) -> None:
        self._part = np.zeros(INITIAL_CAPACITY, dtype=int)
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def add(self) -> int:
        """A new experience, a part of its own until linked; returns its id."""
        if self._n == len(self._part):
            self._part = np.concatenate([self._part, np.zeros_like(self._part)])
        self._part[self._n] = self._n
        self._n += 1
        return self._n - 1

    def link(self, a: int, b: int) -> None:
        """Experiences a and b are linked: their parts are one, named by the lower root."""
        part_a, part_b = self._part[a], self._part[b]
        if part_a != part_b:
            parts = self._part[: self._n]
            parts[parts == max(part_a, part_b)] = min(part_a, part_b)

    def part_of(self, experience: int) -> int:
        return int(self._part[experience])

    def labels(self) -> np.ndarray:
        """The part of every experience (a view: valid until the next experience is added)."""
        return self._part[: self._n]

    def members(self, part: int) -> np.ndarray:
        """The experiences of a part (a boolean mask over all)."""
        return self._part[: self._n] == part

    def roots(self) -> list[int]:
        """The first experience of every part: the ones that fix the parts' frames."""
        return np.unique(self._part[: self._n]).tolist()

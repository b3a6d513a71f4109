"""Bounded memory of the last samples, indexed by global sample index (for isolation)."""

from __future__ import annotations

import numpy as np


class History:
    """Ring buffers of per-sample fields; holds the last ``capacity`` samples."""

    def __init__(self, capacity: int, fields: dict[str, int]) -> None:
        """``fields`` maps a name to its width (1: a scalar per sample)."""
        self.capacity = capacity
        self.data = {name: np.full((capacity, w) if w > 1 else capacity, np.nan) for name, w in fields.items()}
        self.end = 0  # one past the newest global index written

    @property
    def start(self) -> int:
        return max(0, self.end - self.capacity)

    def write(self, first_index: int, values: dict[str, np.ndarray]) -> None:
        n = len(next(iter(values.values())))
        if n == 0:
            return
        if first_index != self.end:
            raise ValueError(f"history is written in order: expected index {self.end}, got {first_index}")
        if n > self.capacity:  # only the tail fits
            values = {k: v[-self.capacity:] for k, v in values.items()}
            first_index += n - self.capacity
            n = self.capacity
        pos = (first_index + np.arange(n)) % self.capacity
        for k, v in values.items():
            self.data[k][pos] = v
        self.end = first_index + n

    def read(self, a: int, b: int, name: str) -> np.ndarray:
        """Samples a..b-1 (global indices, clipped to what is held)."""
        a = max(a, self.start)
        b = min(b, self.end)
        if b <= a:
            return self.data[name][:0].copy()
        pos = np.arange(a, b) % self.capacity
        return self.data[name][pos].copy()

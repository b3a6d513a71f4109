"""Wording of repair notes: every note names the file, the rows (source lines) and the column."""

from __future__ import annotations

from typing import Sequence

#: how many places a note lists before it says "and N more"
LISTED = 3


def plural(where: str, n: int) -> str:
    return where if n == 1 else f"{where}s"


def span(a: int, b: int) -> str:
    return f"{a}" if a == b else f"{a}-{b}"


def places(where: str, spans: Sequence[tuple[int, int]], total: int | None = None) -> str:
    """``line 12``, ``lines 31-32, 95-96 and 4 more`` from (first, last) source lines; ``total``: how many
    places there are when ``spans`` lists only the first ones."""
    total = len(spans) if total is None else total
    shown = ", ".join(span(a, b) for a, b in spans[:LISTED])
    many = total > 1 or spans[0][0] != spans[0][1]
    more = f" and {total - LISTED} more" if total > LISTED else ""
    return f"{plural(where, 2 if many else 1)} {shown}{more}"


def counted(counts: dict[str, int]) -> str:
    """``NaN 2, inf 1`` for the non-zero counts."""
    return ", ".join(f"{k} {v}" for k, v in counts.items() if v)

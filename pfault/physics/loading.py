"""Time histories and pore-pressure sources.

A pore-pressure source gives dp (Pa, negative for drawdown) per cell at a time. Per-material
drawdown tables are one source; a groundwater-flow model can supply another with the same method.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Table:
    """Piecewise-linear function of time, constant beyond the ends."""
    times: tuple
    values: tuple

    @classmethod
    def from_pairs(cls, pairs: Sequence[Sequence[float]], scale: float = 1.0) -> Table:
        return cls(tuple(p[0] for p in pairs), tuple(scale * p[1] for p in pairs))

    def __call__(self, t: float) -> float:
        return float(np.interp(t, self.times, self.values))

    def first_difference(self, other: Table, until: float,
                         rtol: float = 1e-12) -> tuple[float, float, float] | None:
        """Where this table and ``other`` first differ on [0, until]: (t, this one's value, the other's) or
        None. Two piecewise-linear functions agree on an interval when they agree at its ends and at every
        breakpoint of either inside it; a difference within rtol of their largest magnitude there is
        round-off (the same table written another way, ``-0.1*MPa`` or ``-100*kPa``)."""
        t = np.union1d(self.times, other.times)
        t = np.union1d(t[(t > 0.0) & (t < until)], [0.0, until])
        mine, theirs = np.interp(t, self.times, self.values), np.interp(t, other.times, other.values)
        scale = max(np.max(np.abs(mine)), np.max(np.abs(theirs)))
        bad = np.nonzero(np.abs(mine - theirs) > rtol * scale)[0]
        return None if len(bad) == 0 else (float(t[bad[0]]), float(mine[bad[0]]), float(theirs[bad[0]]))


class MaterialDrawdown:
    """dp(t) uniform within each material, from per-material tables (None: no change)."""

    def __init__(self, tables: Iterable[Table | None]) -> None:
        self.tables = list(tables)  # index = material id

    @property
    def active(self) -> bool:
        return any(t is not None for t in self.tables)

    def cell_values(self, t: float, cell_material: np.ndarray, centroids: np.ndarray | None = None) -> np.ndarray:
        per_material = np.array([0.0 if tab is None else tab(t) for tab in self.tables])
        return per_material[cell_material]

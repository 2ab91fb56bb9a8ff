"""A step's record, typed: what solving it cost, what it measured, and its JSON form (summary.json's ``steps``).

The solver policy returns a ``Solve`` for each solve; the costs of solves that make one step (sub-steps of a cut
step, the Newton rounds between which faces broke) combine with ``+``. The time loop measures the converged state
(the land surface, each term, the pore-pressure source) into a ``StepRecord``, which the observers read and never
change. ``as_json`` gives the record's keys as summary.json has always had them (docs/outputs.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


def counts_text(counts: dict) -> str:
    """The counts of the terms' configurations as the progress line and the Newton monitor print them: a fault's
    faces stuck/slipping/open, a soil's cells compacting on the virgin line and the others."""
    parts = []
    if "stick" in counts:
        parts.append(f"stick/slip/open {counts['stick']}/{counts['slip']}/{counts['open']}")
    if "cells_virgin" in counts:
        parts.append(f"virgin/elastic cells {counts['cells_virgin']}/{counts['cells_elastic']}")
    return "  ".join(parts)


@dataclass(frozen=True)
class SolveCost:
    """Iterations, wall time, numeric factorisations, Jacobians and preconditioner set-ups of one solve or of several (``+``), and their
    residual histories in order (nonlinear solves)."""
    newton_its: int = 0
    ksp_its: int = 0
    wall_s: float = 0.0
    factorizations: int = 0
    jacobians: int = 0
    residual_history: tuple = ()
    pc_setups: int = 0          # preconditioner set-ups (PETSc's PCSetUp events, nested ones too; 0 unless logging)

    def __add__(self, other: SolveCost) -> SolveCost:
        return SolveCost(self.newton_its + other.newton_its, self.ksp_its + other.ksp_its,
                         self.wall_s + other.wall_s, self.factorizations + other.factorizations,
                         self.jacobians + other.jacobians, self.residual_history + other.residual_history,
                         self.pc_setups + other.pc_setups)

    @property
    def ksp_per_newton(self) -> float:
        return self.ksp_its / self.newton_its if self.newton_its else 0.0


@dataclass(frozen=True)
class Solve:
    """A solve at time ``time_s`` (or the solves of one step, combined): how it ended (SNES's ``reason``), its
    cost, and for nonlinear equations the predictor it started from, its absolute tolerance, the null pivots of a
    singular Jacobian, the sub-steps it was cut into, the rounds of its Newton solve after which faces broke and
    the faces broken (``breaking``: ``breaking_passes``, ``faces_broken_step``) and the counts of each term's
    configuration (a fault's faces stuck/slipping/open, a soil's cells compacting on the virgin line: ``counts``,
    pfault.solver.terms)."""
    time_s: float
    converged: bool
    reason: int
    cost: SolveCost
    nonlinear: bool = False
    predictor: str = ""
    atol: float = 0.0
    null_pivots: int = 0
    substeps: int = 1
    breaking: tuple[int, int] | None = None
    counts: dict = field(default_factory=dict)

    def as_json(self) -> dict:
        c = self.cost
        rec: dict[str, Any] = {"time_s": float(self.time_s), "newton_its": int(c.newton_its),
                               "ksp_its": int(c.ksp_its), "wall_s": float(c.wall_s),
                               "converged": bool(self.converged), "reason": int(self.reason)}
        if self.nonlinear:
            rec.update({"predictor": self.predictor, "factorizations": int(c.factorizations),
                        "jacobians": int(c.jacobians), "residual_history": [float(v) for v in c.residual_history],
                        "atol": float(self.atol)})
            if self.null_pivots:
                rec["null_pivots"] = int(self.null_pivots)
            rec.update(self.counts)
        rec["ksp_per_newton"] = c.ksp_per_newton
        if self.substeps > 1:
            rec["substeps"] = int(self.substeps)
        if self.breaking is not None:
            rec["breaking_passes"], rec["faces_broken_step"] = (int(v) for v in self.breaking)
        return rec


@dataclass(frozen=True)
class StepRecord:
    """A completed step: its number, its solve, and what was measured after it: the land surface's largest
    subsidence and horizontal displacement (m), the land surface's hazard maxima (``hazard``: on output steps,
    pfault.hazard), each term's measures (``terms``: one per term, each with ``as_json``: a fault term's is
    pfault.faults.measures.FaultMeasures), the pore-pressure source's figures (``source``) and, on output steps,
    the margins to failure (``margins``: pfault.margins.MarginStep, or None). ``initial``: the geostatic initial
    state (step 0)."""
    step: int
    solve: Solve
    max_subsidence_m: float | None = None
    max_horizontal_displacement_m: float | None = None
    hazard: dict = field(default_factory=dict)
    terms: tuple = ()
    source: dict = field(default_factory=dict)
    initial: bool = False
    margins: Any = None

    @property
    def converged(self) -> bool:
        return self.solve.converged

    @property
    def time_s(self) -> float:
        return self.solve.time_s

    @property
    def margins_wall_s(self) -> float:
        """The wall time of the margins' linear solve (0 without margins)."""
        return 0.0 if self.margins is None else float(self.margins.cost.wall_s)

    def as_json(self) -> dict:
        """summary.json's record of the step (docs/outputs.md)."""
        if self.initial:
            rec = {"time_s": 0.0, "newton_its": 0, "ksp_its": 0, "wall_s": float(self.solve.cost.wall_s),
                   "converged": True, "initial": True, "step": self.step, **self.solve.counts}
        else:
            rec = self.solve.as_json()
            rec.update(self.source)
            rec["step"] = self.step
        if self.max_subsidence_m is not None:
            rec["max_subsidence_m"] = float(self.max_subsidence_m)
            rec["max_horizontal_displacement_m"] = float(self.max_horizontal_displacement_m or 0.0)
        for measures in self.terms:
            rec.update(measures.as_json())
        if self.margins is not None:
            merge_json(rec, self.margins.as_json())
        rec.update(self.hazard)
        return rec


def merge_json(into: dict, other: dict) -> dict:
    """``other`` merged into ``into``, nested dicts key by key (a fault's margin beside its figures), other values
    replaced; returns ``into``."""
    for key, value in other.items():
        if isinstance(value, dict) and isinstance(into.get(key), dict):
            merge_json(into[key], value)
        else:
            into[key] = value
    return into

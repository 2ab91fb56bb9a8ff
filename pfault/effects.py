"""The effects a scene asks for, decided once from what it sets, and what each of them cost.

A scene builds only what it names: faults (each Lagrange or penalty) bring the multiplier field and the contact
code; `-pfault_flow` the flow system and its KSP; per-material pressure tables the pore-pressure load;
`-pfault_heads_file` the reading of a groundwater model's heads and the pore-pressure load; a
geostatic start the gravity solve and the initial stress; boundary tractions and prescribed displacements their
loads. Every effect's work runs inside PETSc log events named here, so its cost (set-up and per step) is read
from PETSc's log, not from timers of our own.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from mpi4py import MPI
from petsc4py import PETSc

if TYPE_CHECKING:
    from .faults.settings import FaultSettings
    from .physics.loading import MaterialDrawdown
    from .scene import Boundary, Material, Settings

# effect -> the PETSc log events its work runs in
EVENTS = {
    "faults": ("pfaultFaultSetup", "pfaultFaultResidual", "pfaultFaultJacobian"),
    "flow": ("pfaultFlowAssemble", "pfaultFlowSolve", "pfaultPorePressureLoad"),
    "pressure_tables": ("pfaultPorePressureLoad",),
    "heads": ("pfaultHeadsRead", "pfaultPorePressureLoad"),
    "geostatic": ("pfaultGeostatic",),
    "tractions": ("pfaultTractionLoad",),
    "displacements": ("pfaultDisplacementLoad",),
    "soils": ("pfaultSoilSetup", "pfaultSoilResidual", "pfaultSoilJacobian"),
}


def event(name: str) -> PETSc.Log.Event:
    return PETSc.Log.Event(name)


@contextmanager
def logged(name: str) -> Iterator[None]:
    """Run the block inside the PETSc log event ``name``."""
    ev = event(name)
    ev.begin()
    try:
        yield
    finally:
        ev.end()


@dataclass(frozen=True)
class Effects:
    faults: tuple          # ((name, method), ...)
    flow: bool
    pressure_tables: tuple  # materials with a head or pressure table
    geostatic: str         # the initial stress of a geostatic start (gravity, lithostatic), "" without one
    tractions: tuple       # surfaces with a non-zero traction
    displacements: tuple   # surfaces with prescribed displacements
    heads: str = ""        # the groundwater model's head file (-pfault_heads_file), or ""
    unchanged: tuple = ()  # materials whose pore pressure does not change (-pfault_pore_pressure_unchanged_materials)
    soils: tuple = ()      # materials with memory (pfault.soils)

    def on(self, name: str) -> bool:
        return bool(getattr(self, name))

    def detail(self, name: str) -> str:
        v = getattr(self, name)
        if name == "faults":
            return ", ".join(f"{n} ({m})" for n, m in v)
        if name == "geostatic":
            return {"gravity": "gravity solve, K0 initial stress", "lithostatic": "lithostatic initial stress "
                    "(the overburden), K0"}.get(v, "")
        if name == "flow":
            return "transient groundwater flow" + self._unchanged() if v else ""
        if name == "heads":
            return v + self._unchanged()
        if name == "pressure_tables":
            return ", ".join(v) + self._unchanged()
        return ", ".join(v)

    def _unchanged(self) -> str:
        return f" (pore pressure unchanged in {', '.join(self.unchanged)})" if self.unchanged else ""

    def line(self) -> str:
        """One line naming every effect and whether the scene asks for it."""
        label = {"faults": "faults", "flow": "groundwater flow", "pressure_tables": "pore-pressure tables",
                 "geostatic": "geostatic start", "tractions": "boundary tractions",
                 "displacements": "prescribed displacements",
                 "heads": "groundwater-model heads", "soils": "materials with memory"}
        parts = [f"{label[k]} {self.detail(k) if self.on(k) else 'off'}" for k in EVENTS]
        return "effects: " + "; ".join(parts)


def decide(settings: Settings, materials: Sequence[Material], drawdown: MaterialDrawdown, flow: bool,
           faults: Iterable[FaultSettings], boundaries: Iterable[Boundary], heads: str = "",
           unchanged: Iterable[str] = (), soils: tuple = ()) -> Effects:
    """Effects of a scene from its settings: the material names, the drawdown tables, whether the flow model is
    on, the fault settings, the boundary conditions, the head file of a groundwater model ("" without), the
    materials whose pore pressure does not change and the materials with memory."""
    tables = tuple(m.name for m, tab in zip(materials, drawdown.tables) if tab is not None)
    return Effects(faults=tuple((f.name, f.method) for f in faults), flow=bool(flow), pressure_tables=tables,
                   geostatic=settings.geostatic_stress if settings.geostatic else "",
                   tractions=tuple(b.name for b in boundaries
                                   if b.kind in ("traction", "displacement") and any(b.traction)),
                   displacements=tuple(b.name for b in boundaries
                                       if b.kind == "displacement" and any(b.displacement)),
                   heads=heads, unchanged=tuple(unchanged), soils=tuple(soils))


def event_total(name: str, key: str = "time") -> float:
    """An event's ``key`` ("time" in seconds, "count") so far on this rank, summed over every log stage
    (0 unless PETSc's logging is on)."""
    ev, total, stage = event(name), 0.0, 0
    while True:
        try:
            total += ev.getPerfInfo(stage)[key]
        except PETSc.Error:
            return total
        stage += 1


def event_times(names: Iterable[str]) -> float:
    """Seconds spent so far in the given events on this rank."""
    return sum(event_total(n) for n in names)


class EffectCosts:
    """Set-up and per-step time of each effect, from PETSc's log (max over ranks)."""

    def __init__(self, comm: PETSc.Comm) -> None:
        self.comm = comm
        PETSc.Log.begin()
        for names in EVENTS.values():
            for n in names:
                event(n)
        self.at_setup: dict[str, float] | None = None

    def mark_setup(self) -> None:
        self.at_setup = {k: event_times(v) for k, v in EVENTS.items()}

    def record(self, effects: Effects, n_steps: int) -> dict[str, dict[str, Any]]:
        mpi = self.comm.tompi4py()
        out: dict[str, dict[str, Any]] = {}
        for k, names in EVENTS.items():
            if not effects.on(k):       # (the pore-pressure load is the flow's or the tables')
                out[k] = {"on": False, "detail": "", "setup_s": 0.0, "per_step_s": 0.0}
                continue
            total = event_times(names)
            setup = (self.at_setup or {}).get(k, total)
            setup, total = mpi.allreduce(setup, op=MPI.MAX), mpi.allreduce(total, op=MPI.MAX)
            out[k] = {"on": effects.on(k), "detail": effects.detail(k), "setup_s": setup,
                      "per_step_s": (total - setup) / max(n_steps, 1)}
        return out

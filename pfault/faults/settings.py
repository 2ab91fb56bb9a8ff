"""What a scene asks of its faults: per-fault friction and enforcement, and the contact law's physical choices."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FaultSettings:
    """One fault (a physical surface of the mesh)."""
    name: str
    cohesion: float                # Pa
    friction_angle: float          # degrees
    method: str                    # lagrange | penalty
    penalty_normal: float          # Pa/m (0: automatic from the adjacent cells)
    penalty_tangential: float
    tensile_strength: float = 0.0  # Pa: of the intact surface (0: a pre-existing fault, broken from the start)
    residual_cohesion: float = 0.0  # Pa: of a broken face of a candidate surface
    tension_cutoff: str = "apex"   # apex: the law opens at c / tan(phi); zero: at t_N = 0 (no tension)

    @property
    def candidate(self) -> bool:
        """A candidate surface: intact until its strength is exceeded (pfault.faults.breaking)."""
        return self.tensile_strength > 0.0


@dataclass(frozen=True)
class ContactSettings:
    """Physical choices of the contact law shared by all faults, and the monitor switch."""
    effective_stress: bool = True  # friction and opening act on t_N + alpha p
    suction: bool = False          # geostatic scenes: keep negative pore pressure on dry faces
    monitor: bool = False          # one line per Newton iteration with the faces' states

"""The geostatic initial state a scene may start from (-pfault_geostatic true): step 0.

The vertical stress is that of an elastic gravity solve with the faults glued (every fault face stuck: no jump
while the state forms; the overburden in flat layers, the arching around stiff bodies), or with
-pfault_geostatic_stress lithostatic the weight of the column above each cell (pfault.physics.geostatic.overburden,
no solve), except in the cells of a material with memory, whose vertical stress is the weight of the column above
them either way (the K0 procedure: pfault.soils.term.SoilTerm.initial_vertical_stress); the horizontal stresses
follow the K0 rule on effective stresses, sigma'_h = K0 sigma'_v, with hydrostatic pore pressure below the water
table (K0 = -pfault_geostatic_k0, default nu/(1-nu) of each material); no initial shear. That stress is the initial
state: it loads nothing, displacements are those caused by the drawdown, and stresses and fault tractions are the
initial ones plus the changes; the terms' histories start from it (a fault face's initial traction is the
prestress projected on it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

from .errors import StepNotConverged, run_on_root
from .physics import geostatic as gs


def overburden(mpi: Any, cell_coords: np.ndarray, density: np.ndarray, gravity: float) -> np.ndarray:
    """The overburden (Pa) at the centroids of this rank's cells (``cell_coords``: n x 4 x 3): the cells of every
    rank gathered on rank 0 (their vertices found again by their coordinates: a split fault's two copies of a vertex
    are one there, the column crosses the fault as if glued), the columns followed there, the values sent back."""
    parts = mpi.gather((cell_coords, density))

    def columns():
        weight = gs.overburden(np.concatenate([c for c, _ in parts]), np.concatenate([d for _, d in parts]), gravity)
        return np.split(weight, np.cumsum([len(d) for _, d in parts])[:-1])
    return mpi.scatter(run_on_root(mpi, columns))


class GeostaticStart:
    """Computes the geostatic initial state of ``equations`` (pfault.solver.equations.Equations) into a
    state, with the linear solver ``solve_linear(A, b, x) -> KSP reason`` (the step solver's)."""

    def __init__(self, equations: Any, settings: Any) -> None:
        self.eq, self.settings = equations, settings

    def compute(self, state: Any, solve_linear: Any) -> None:
        """The initial stress (``state.sigma0``), the terms' histories from it, and u = u_ref: the initial state,
        in equilibrium with zero displacement."""
        self.start(state, self.initial_stress(state, solve_linear))

    def initial_stress(self, state: Any, solve_linear: Any) -> np.ndarray:
        """The initial stress per local cell (cells x 3 x 3, Pa): the vertical stress of the elastic gravity solve
        or the lithostatic column (-pfault_geostatic_stress), the terms' own where they give one (a material with
        memory's overburden), and the K0 rule (pfault.physics.geostatic.k0_stress)."""
        eq, asm, s = self.eq, self.eq.asm, self.settings
        if s.geostatic_stress == "lithostatic":
            sigma_v = -overburden(eq.comm.tompi4py(), eq.mesh.coords[eq.mesh.cells], asm.density, s.gravity)
        else:
            sigma_v = self.gravity_stress(state, solve_linear)[:, 2, 2].copy()
        for term in eq.terms:
            cells, vertical = term.initial_vertical_stress()    # a material with memory's: its overburden
            sigma_v[cells] = vertical
        nu = asm.lam / (2 * (asm.lam + asm.mu))
        return gs.k0_stress(sigma_v, asm.centroids[:, 2], asm.alpha, nu, s.k0, s.water_density, s.gravity,
                            s.water_table)

    def start(self, state: Any, sigma0: np.ndarray) -> None:
        """The initial state of the stress ``sigma0`` (per local cell): the terms' histories from it, and
        u = u_ref, in equilibrium with zero displacement."""
        eq = self.eq
        state.sigma0 = sigma0
        eq.loads.set(0.0)       # the terms' loads back from gravity's to those of the start
        state.u.set(0.0)
        loc = eq.local_array(state.u)
        state.histories = tuple(term.prestressed(state.sigma0, loc, load, h)
                                for term, load, h in zip(eq.terms, eq.loads.term_loads, state.histories))
        eq.to_global(loc, PETSc.InsertMode.INSERT_VALUES, out=state.u)
        state.u.copy(state.u_ref)

    def gravity_stress(self, state: Any, solve_linear: Any) -> np.ndarray:
        """The effective stress per cell of the elastic gravity state with the terms' initial operator (the faults
        glued); StepNotConverged if the solve fails."""
        eq = self.eq
        eq.loads.gravity(eq.loads.f)
        ug = state.u.duplicate()
        reason = solve_linear(eq.initial_operator(), eq.loads.f, ug)
        norm = ug.norm()
        if reason <= 0 or not np.isfinite(norm):
            # the initial stress would come from a wrong state: faults open at step 0, every step loaded by it
            ug.destroy()
            why = f"KSP reason {reason}" if reason <= 0 else "a non-finite solution"
            raise StepNotConverged(f"-pfault_geostatic: the elastic gravity solve of the initial stress failed "
                                   f"({why}); check the solver options (-pfault_solver, -ksp_*, -pc_*) or start "
                                   f"without it (-pfault_geostatic false)")
        sig = eq.effective_stress(eq.local_array(ug), state.histories)
        ug.destroy()
        return sig

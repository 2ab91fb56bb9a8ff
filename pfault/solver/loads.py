"""The load vector f(t) of the equations: the pore-pressure change of the source (Terzaghi/Biot), boundary
tractions and prescribed displacements scaled by their histories, loads that do not change in time, and the
loads of the equations' terms (pfault.solver.terms: the face bubbles' loads and the pore pressure a fault's laws
see); the gravity load of a geostatic initial state."""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

from ..effects import logged


class Loads:
    """The loads of ``equations`` (pfault.solver.equations.Equations, whose K is not yet constrained: the lifts
    of prescribed displacements are -K g). ``f`` holds the load of the time last set (``set``) and
    ``term_loads`` the terms' loads of that time (one per term, in order); ``static_local`` loads that do not
    change in time (a local array: body forces of a verification case)."""

    def __init__(self, equations: Any, boundaries: list, source: Any, settings: Any) -> None:
        eq = self.eq = equations
        self.source, self.settings = source, settings
        self.mesh, self.dofmap, self.asm = eq.mesh, eq.dofmap, eq.asm
        self.f = eq.create_vec()
        self.static_local = np.zeros(eq.dofmap.n_local)
        self._gravity_norm: float | None = None
        with logged("pfaultDisplacementLoad"):
            self.lifts = self._prescribed_displacements(boundaries)
        self.surface_loads = []         # boundary loads per surface, scaled by the surface's history
        with logged("pfaultTractionLoad"):
            for i, b in enumerate(boundaries):
                if b.kind in ("traction", "displacement") and any(b.traction):
                    loc = np.zeros(eq.dofmap.n_local)
                    tr = [bb.traction if j == i else (0.0, 0.0, 0.0) for j, bb in enumerate(boundaries)]
                    eq.asm.traction_load(tr, loc)
                    self.surface_loads.append((b, loc))
        scratch = np.zeros(eq.dofmap.n_local)
        self.term_loads = tuple(term.load(0.0, None, self.asm.alpha, scratch) for term in eq.terms)  # none yet

    def _prescribed_displacements(self, boundaries: list) -> list:
        """For each displacement boundary: (boundary, g on its constrained dofs, lift = -K g) as global Vecs."""
        out = []
        which = self.mesh.vert_displacement_bc
        mask = self.mesh.vert_data[:, 0]
        for i, b in enumerate(boundaries):
            if b.kind != "displacement" or not any(b.displacement):
                continue
            loc = np.zeros(self.dofmap.n_local)
            for side in range(self.dofmap.max_sides):
                sel = (self.dofmap.vert_sides > side) & (which == i)
                dofs = self.dofmap.vertex_dofs(side)[sel]
                bits = ((mask[sel, None] >> np.arange(3)) & 1) * ((b.components >> np.arange(3)) & 1)
                vals = np.broadcast_to(np.asarray(b.displacement), dofs.shape)
                loc[dofs[bits == 1]] = vals[bits == 1]
            g = self.eq.to_global(loc, PETSc.InsertMode.INSERT_VALUES)
            lift = g.duplicate()
            self.eq.K.mult(g, lift)
            lift.scale(-1.0)
            out.append((b, g, lift))
        return out

    def cell_dp(self, t: float) -> np.ndarray:
        """Pore-pressure change per local cell at time t (Pa; the source's, zero where it is inactive)."""
        if not self.source.active:
            return np.zeros(len(self.mesh.cells))
        return self.source.cell_dp(t)

    def set(self, t: float) -> None:
        """The load f(t) and the terms' loads at t."""
        bc = self.eq.bc_local_owned
        loc = self.static_local.copy()
        for b, fl in self.surface_loads:
            loc += b.scale(t) * fl
        dp = None
        if self.source.active:
            with logged("pfaultPorePressureLoad"):
                dp = self.source.cell_dp(t)
                self.asm.pore_pressure_load(dp, loc)
        self.term_loads = tuple(term.load(t, dp, self.asm.alpha, loc) for term in self.eq.terms)
        self.eq.to_global(loc, out=self.f)
        for b, g, lift in self.lifts:
            self.f.axpy(b.scale(t), lift)
        arr = self.f.getArray()
        arr[bc] = 0.0
        for b, g, lift in self.lifts:
            arr[bc] += b.scale(t) * g.getArray()[bc]

    def gravity(self, out: Any, with_terms: bool = True) -> None:
        """The gravity load vector (zero on constrained dofs) into ``out``; ``with_terms``: with the terms' loads of
        the initial gravity state (a fault's glued faces' bubbles: their condensed load and the right-hand side of
        their rows), which become the terms' loads."""
        grav = np.zeros(self.dofmap.n_local)
        self.asm.gravity_load(self.settings.gravity, grav)
        if with_terms:
            b = np.zeros((len(self.asm.vol), 3))
            b[:, 2] = -self.asm.density * self.settings.gravity
            self.term_loads = tuple(term.gravity_load(b, load, grav)
                                    for term, load in zip(self.eq.terms, self.term_loads))
        self.eq.to_global(grav, out=out)
        out.getArray()[self.eq.bc_local_owned] = 0.0

    def gravity_norm(self) -> float:
        """|gravity load| of a geostatic scene (0 otherwise), computed once."""
        if self._gravity_norm is None:
            self._gravity_norm = 0.0
            if self.settings.geostatic:
                g = self.eq.create_vec()
                self.gravity(g, with_terms=False)      # (a scale: the terms' loads stay the step's)
                self._gravity_norm = g.norm()
                g.destroy()
        return self._gravity_norm

    def destroy(self) -> None:
        self.f.destroy()
        for _, g, lift in self.lifts:
            g.destroy()
            lift.destroy()

"""When the iterative solver keeps its preconditioner (pfault.solver.policy.PreconditionerReuse): across Jacobians of
one configuration (every face's state, every soil cell's branch) within a step that vary only in soil moduli; set
up anew at a step's first Jacobian, at a changed configuration and where a term whose Jacobian carries constraints varies (a slipping
face). One rank, with a stand-in SNES that records what the rule sets (the PC's reuse flag, SNES's lag)."""

import numpy as np
from petsc4py import PETSc

from pfault.faults.term import FaultTerm
from pfault.soils.term import SoilTerm
from pfault.solver.policy import PreconditionerReuse
from pfault.solver.terms import TermDefaults


class FakePC:
    def __init__(self):
        self.reuse = []

    def setReusePreconditioner(self, flag):
        self.reuse.append(bool(flag))


class FakeKSP:
    def __init__(self, pc):
        self.pc = pc

    def getPC(self):
        return self.pc


class FakeSnes:
    def __init__(self):
        self.pc, self.lag = FakePC(), []

    def getKSP(self):
        return FakeKSP(self.pc)

    def setLagPreconditioner(self, lag):
        self.lag.append(lag)


class FakeEquations:
    moduli_vary_only = True     # the Jacobian last assembled varies in soil moduli only


def test_kept_while_only_moduli_vary_in_one_configuration():
    snes, eq = FakeSnes(), FakeEquations()
    keep = PreconditionerReuse(PETSc.COMM_SELF, eq)
    faces_cells = np.array([0, 0, 2, 1, 1, 1])         # faces' states, then cells' branches
    moved = faces_cells.copy()
    moved[-1] = 0                                       # one cell back on its swelling line
    for states, moduli_only in ((faces_cells, True),    # the first Jacobian: set up
                                (faces_cells, True),    # the soil's moduli moved: kept
                                (faces_cells.copy(), True),
                                (faces_cells, False),   # a face slips: its friction direction varies
                                (faces_cells, True),
                                (moved, True),          # a cell changed branch
                                (moved, True)):
        eq.moduli_vary_only = moduli_only
        keep.decide(snes, states)
    keep.begin_step()                                   # a new step: its first Jacobian sets it up
    keep.decide(snes, moved)
    keep.decide(snes, moved)
    assert snes.pc.reuse == [False, True, True, False, True, False, True, False, True]
    assert snes.lag == [-2, -1, -1, -2, -1, -2, -1, -2, -1]     # SNES rebuilds once (-2) or keeps (-1)


def test_which_terms_vary_in_moduli_only():
    """The soils' tangent varies in its cells' moduli (K = p'/kappa); a fault's slipping faces carry constraints,
    and a term says nothing of the kind by default."""
    assert SoilTerm.moduli_vary_only and not FaultTerm.moduli_vary_only and not TermDefaults.moduli_vary_only

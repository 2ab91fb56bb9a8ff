"""What the cells of the materials with memory remember and what they are loaded with, as plain frozen data.

The soil term (pfault.soils.term) is given a ``SoilMemory`` and returns the next one. Per cell of the term, in its
order: the initial effective stress (the geostatic start's, which loads nothing), the law's history at the last
converged state (pfault.physics.soil.SoilHistory: effective stress, preconsolidation p'_c, plastic strain), the P1
strain of that state (relative to the initial state: a step's strain increment is measured from it) and the branch
each cell took in its last step. Before the initial stress is known the memory is empty (``started`` False): the
cells are then elastic with their reference modulus (the geostatic gravity solve).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics import soil as sl


@dataclass(frozen=True)
class SoilMemory:
    """Per cell: initial effective stress ``stress0`` (n,3,3, Pa, tension positive), the law's history ``law``, the
    strain ``strain`` (n,3,3) of that state and the ``branch`` of its last step (ELASTIC, VIRGIN)."""
    stress0: np.ndarray | None
    law: sl.SoilHistory | None
    strain: np.ndarray | None
    branch: np.ndarray

    @property
    def started(self) -> bool:
        return self.stress0 is not None

    @staticmethod
    def empty(n: int) -> SoilMemory:
        """Before the initial stress: nothing remembered yet."""
        return SoilMemory(None, None, None, np.zeros(n, np.int64))

    def arrays(self, cells: np.ndarray, n_cells: int) -> dict:
        """The memory of the cells ``cells`` (local ids) as arrays per local cell (``n_cells``; zero elsewhere and
        before the initial stress): the initial effective stress, the law's stress, preconsolidation and plastic
        strain, the strain of that state (9 components each) and the branch of the last step."""
        def per_cell(values: np.ndarray | None, width: int) -> np.ndarray:
            out = np.zeros((n_cells, width))
            if values is not None:
                out[cells] = np.reshape(values, (len(cells), width))
            return out if width > 1 else out[:, 0]
        law = self.law if self.law is not None else sl.SoilHistory(None, None, None)
        return {"stress0": per_cell(self.stress0, 9), "stress": per_cell(law.stress, 9),
                "preconsolidation": per_cell(law.preconsolidation, 1), "plastic_strain": per_cell(law.plastic_strain, 9),
                "strain": per_cell(self.strain, 9), "branch": per_cell(self.branch.astype(float), 1)}

    @staticmethod
    def of_arrays(arrays: dict, cells: np.ndarray) -> SoilMemory:
        """The memory of the cells ``cells`` in ``arrays`` (``arrays``' per local cell)."""
        def tensor(name: str) -> np.ndarray:
            return np.array(arrays[name][cells], dtype=float).reshape(-1, 3, 3)
        law = sl.SoilHistory(tensor("stress"), np.array(arrays["preconsolidation"][cells], dtype=float),
                             tensor("plastic_strain"))
        return SoilMemory(tensor("stress0"), law, tensor("strain"), np.asarray(arrays["branch"][cells]).astype(np.int64))


@dataclass(frozen=True)
class SoilLoad:
    """What the cells see at a time: the pore-pressure change per cell (Pa; dp = rho_w g times the head change)."""
    dp: np.ndarray

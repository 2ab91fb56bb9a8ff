"""What a fault remembers and what it is loaded with, as plain frozen data (pure NumPy).

The fault term (pfault.faults.term) is given a ``FaultHistory`` and returns the next one: nothing about a face's
past lives in the term. ``FaultLoad`` is what the faces see at the time the equations were last set to: the pore
pressure of their contact laws and the load on the face bubbles. Both are per owned fault face, in the order of
pfault.faults.faces.FaultFaces.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from . import contact as ct
from .bubbles import BubbleLoad


@dataclass(frozen=True)
class StepStart:
    """The converged state a solve starts from: the jumps the laws act on (local frame), which a stuck face's slip
    increment is measured from, and each face's state there."""
    g: np.ndarray
    state: np.ndarray

    def trial(self) -> np.ndarray:
        """States of a step's elastic trial: closed faces stuck, open faces open."""
        return np.where(self.state == ct.OPEN, ct.OPEN, ct.STICK)


@dataclass(frozen=True)
class FaultHistory:
    """Each owned face's history: the initial traction ``t0`` (local frame, Pa: the prestress of a geostatic start,
    which loads nothing), the start of the current solve, whether it has slid (slipping or open at the end of a
    completed step, now or before: its tangential jump is then reported as slip), whether it is broken
    (pfault.faults.breaking; every face of a pre-existing fault from the start) and when it broke (s; NaN while
    intact and on a pre-existing fault)."""
    t0: np.ndarray
    start: StepStart
    slid: np.ndarray
    broken: np.ndarray
    break_time: np.ndarray

    @staticmethod
    def new(broken: np.ndarray) -> FaultHistory:
        """The history before any load, the faces in ``broken`` broken."""
        nf = len(broken)
        return FaultHistory(np.zeros((nf, 3)), StepStart(np.zeros((nf, 3)), np.full(nf, ct.STICK)),
                            np.zeros(nf, dtype=bool), np.asarray(broken, dtype=bool).copy(), np.full(nf, np.nan))

    def with_breaks(self, new: np.ndarray, t: float) -> FaultHistory:
        """The faces ``new`` broke at time t (for good: a broken face stays broken)."""
        new = np.asarray(new, dtype=bool) & ~self.broken
        return replace(self, broken=self.broken | new, break_time=np.where(new, float(t), self.break_time))


@dataclass(frozen=True)
class FaultLoad:
    """What the faces see at a time: alpha p at each face (``pn``, Pa, compression positive: the effective traction
    is t + (pn, 0, 0)) and the load on the face bubbles."""
    pn: np.ndarray
    bubbles: BubbleLoad

    def effective(self, t: np.ndarray) -> np.ndarray:
        """Effective tractions (Terzaghi): the multiplier is the total traction; friction and opening act on
        t_N + alpha p."""
        te = np.array(t, dtype=float, copy=True)
        te[:, 0] += self.pn
        return te


@dataclass(frozen=True)
class FacePressure:
    """The pore pressure the faces' contact laws see (``at``): with a geostatic start the hydrostatic pressure below
    the water table at the face's centroid (``static``) plus the change; clamped at zero unless suction is kept
    (``clamp``); times the Biot coefficient of the face's minus cell (``alpha``). Without effective stress
    (-pfault_contact_effective_stress false) nothing (``active`` False)."""
    active: bool
    static: np.ndarray
    alpha: np.ndarray
    cell: np.ndarray
    clamp: bool

    def at(self, t: float, cell_dp: np.ndarray | None) -> np.ndarray:
        """alpha p at the faces at time t for the pore-pressure change per local cell ``cell_dp`` (None: no
        change).

        In a geostatic scene p is the absolute pressure, and it is clamped at zero unless
        ``-pfault_contact_suction``: a fault face above the lowered water table is dry. Without the geostatic
        state p is only the change from an unknown initial pressure, and it is used as it is."""
        nf = len(self.cell)
        if not self.active or not nf:
            return np.zeros(nf)
        p = self.static.copy()
        if cell_dp is not None and t > 0:
            p += cell_dp[self.cell]
        if self.clamp:
            p = np.maximum(p, 0.0)
        return self.alpha * p


def face_pressure(contact: object, settings: object, face_z: np.ndarray, face_cell: np.ndarray,
                  alpha: np.ndarray) -> FacePressure:
    """FacePressure of faces at heights ``face_z`` (m) with minus cells ``face_cell`` (``alpha``: per local cell);
    ``contact``: pfault.faults.settings.ContactSettings; ``settings``: the scene's (geostatic start, water table,
    water density, gravity)."""
    s = settings
    static = np.zeros(len(face_z))
    if s.geostatic:
        static = static + s.water_density * s.gravity * np.maximum(s.water_table - face_z, 0.0)
    return FacePressure(bool(contact.effective_stress), static, alpha[face_cell], face_cell,
                        bool(s.geostatic and not contact.suction))

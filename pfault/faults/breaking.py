"""Candidate surfaces that break: the strength of each fault face while intact and once broken (pure NumPy).

A fault with a tensile strength T > 0 (-pfault_fault_<name>_tensile_strength) is a candidate surface: each of its
faces is intact, glued (held in the stick branch of its law, no jump), until its effective traction leaves the
intact strength surface

    t_N <= min(T, c / tan(phi))   and   |t_T| <= c - t_N tan(phi)

(Mohr-Coulomb with cohesion c and a tension cut-off at T, or at the cone's apex where that is smaller); it is then
broken for good: its law is the fault law of pfault.faults.contact with the residual cohesion c_r (open at
c_r / tan(phi), no tensile strength beyond that apex), the same friction angle. A fault without tensile strength
is a pre-existing fault: every face broken from the start, with its cohesion c (the law before candidate surfaces
existed).

A face leaves the strength surface when its excess over it is more than ``BREAK_TOLERANCE`` of the face's strength
scale (the largest of its cut-off, its cohesion and the magnitude of its traction): the tractions of a converged
step are exact to the solver's tolerance, and a face loaded exactly to its strength stays intact. Which faces
break depends on each face's own traction only, so the broken set does not depend on the partition. At a Newton
iterate whose tractions are known to within an error, a face's verdict is settled where the error cannot move its
traction across that threshold (``verdicts``): the solver breaks faces between Newton iterations only where every
verdict is settled (pfault.solver.policy.Settling).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import contact as ct

BREAK_TOLERANCE = 1e-10     # relative excess over the strength that breaks an intact face


@dataclass(frozen=True)
class FaceStrength:
    """Per face: whether it is on a candidate surface, the intact surface's cohesion and tension cut-off (Pa),
    the cohesion of its law once broken (Pa: the residual one on a candidate surface, the cohesion on a
    pre-existing fault) and tan(phi)."""
    candidate: np.ndarray
    cohesion: np.ndarray
    cutoff: np.ndarray
    broken_cohesion: np.ndarray
    tan_phi: np.ndarray

    def initially_broken(self) -> np.ndarray:
        """Faces broken before any load: those of pre-existing faults."""
        return ~self.candidate

    def law_cohesion(self, broken: np.ndarray) -> np.ndarray:
        """The cohesion of each face's contact law (an intact face's law is held stuck: its cohesion is unused)."""
        return np.where(broken, self.broken_cohesion, self.cohesion)


def face_strength(settings: list, fault: np.ndarray) -> FaceStrength:
    """FaceStrength of faces of the faults ``fault`` (index into ``settings``, pfault.faults.settings)."""
    coh = np.array([s.cohesion for s in settings], dtype=float)[fault]
    tphi = np.tan(np.radians([s.friction_angle for s in settings]))[fault]
    strength = np.array([s.tensile_strength for s in settings], dtype=float)[fault]
    residual = np.array([s.residual_cohesion for s in settings], dtype=float)[fault]
    candidate = strength > 0
    cutoff = np.minimum(strength, ct.tensile_strength(coh, tphi))
    return FaceStrength(candidate, coh, cutoff, np.where(candidate, residual, coh), tphi)


def excess(strength: FaceStrength, t_eff: np.ndarray) -> np.ndarray:
    """How far each face's effective traction (local frame, nf x 3) lies beyond its intact strength surface (Pa;
    negative inside): the larger of t_N - cut-off and |t_T| - (c - t_N tan(phi))."""
    tn = t_eff[:, 0]
    shear = np.linalg.norm(t_eff[:, 1:], axis=1) - (strength.cohesion - strength.tan_phi * tn)
    return np.maximum(tn - strength.cutoff, shear)


def margin(strength: FaceStrength, t_eff: np.ndarray) -> np.ndarray:
    """How far each face's effective traction (local frame, nf x 3) lies beyond the traction that breaks it (Pa):
    its excess over the intact strength surface less BREAK_TOLERANCE of its strength scale (the largest of its
    cut-off, its cohesion and the magnitude of its traction). An intact face breaks where this is positive."""
    scale = np.maximum.reduce([np.where(np.isfinite(strength.cutoff), strength.cutoff, 0.0), strength.cohesion,
                               np.linalg.norm(t_eff, axis=1)])
    return excess(strength, t_eff) - BREAK_TOLERANCE * scale


def margin_sensitivity(strength: FaceStrength) -> np.ndarray:
    """How much each face's ``margin`` can change (Pa) per pascal of change in each of its traction's components:
    1 through t_N - cut-off, sqrt(2) + tan(phi) through |t_T| + tan(phi) t_N, and sqrt(3) BREAK_TOLERANCE through
    the strength scale (|t|): sqrt(2) + tan(phi) + sqrt(3) BREAK_TOLERANCE."""
    return np.sqrt(2.0) + strength.tan_phi + np.sqrt(3.0) * BREAK_TOLERANCE


def verdicts(strength: FaceStrength, t_eff: np.ndarray, broken: np.ndarray, error: float = 0.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """The intact faces of candidate surfaces that break at the effective tractions t_eff (``margin`` positive),
    and those whose verdict is open: within ``error`` (Pa, a bound on the error of each traction component, as
    at a Newton iterate; 0 at a converged state) their margin could change sign. Where none is open, the faces
    that break are those that break at the exact tractions."""
    intact = ~broken & strength.candidate
    m = margin(strength, t_eff)
    reach = error * margin_sensitivity(strength)
    return intact & (m > 0), intact & (np.abs(m) <= reach) & (error > 0)


def exceeding(strength: FaceStrength, t_eff: np.ndarray, broken: np.ndarray) -> np.ndarray:
    """The intact faces whose effective traction exceeds their strength by more than BREAK_TOLERANCE of its
    scale: those that break."""
    return verdicts(strength, t_eff, broken)[0]

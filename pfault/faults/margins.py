"""Margins to failure of the fault faces: how much further uniform drawdown a stuck face takes before it slips,
opens or, on a candidate surface, breaks, from the converged state and its linear response (pure NumPy; the
response itself is solved by pfault.solver.response, the run's part is pfault.margins).

Conventions as pfault.faults.contact: local frame (n, m1, m2), traction t of the plus side on the minus side,
t_N < 0 compression; the laws act on the effective traction t + (alpha p, 0, 0). lam is the further drawdown (m of
head) of the loaded materials (pfault.sources: ``loaded_cells``). Along it a face's effective traction is

    t(lam) = t0 + lam r1                                  lam <= lam_dry
    t(lam) = t0 + lam_dry r1 + (lam - lam_dry) r2         beyond

r1 the total traction's rate (dt/dlam of the linear solve) plus the face's own alpha dp/dlam on its normal, r2 the
same without it: in a geostatic scene that clamps the faces' pore pressure at zero (-pfault_contact_suction false)
a face dries at lam_dry and its pore pressure stops falling there (lam_dry infinite elsewhere).

A stuck face fails where t(lam) leaves the surface

    |t_T| <= c - tan(phi) t_N        and        t_N <= T

of its law: on a pre-existing fault or a broken face the law's cohesion and T = c / tan(phi), the apex (slip on the
cone, open at the cut-off; the contact law holds a stuck face's jump at zero, so its law sees exactly this
traction), on an intact face of a candidate surface its intact strength (pfault.faults.breaking; both 'break'). On
a linear piece the cone's crossing is a root of the quadratic

    |t_T0 + lam r_T|^2 = (k0 - lam k1)^2,        k0 = c - tan(phi) t_N0,  k1 = tan(phi) r_N,

with k0 - lam k1 >= 0 (the other roots are the mirror cone's). g(lam) = |t_T(lam)| - (k0 - lam k1) is convex, so a
face inside its cone at lam = 0 leaves it at most once, at the largest such root; it reaches the cut-off at
(T - t_N0) / r_N when r_N > 0. The margin is the first of the two (the cut-off on a tie: a face pulled straight
open through the apex opens), infinite where the path never leaves the surface.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

from . import contact as ct
from .bubbles import BubbleLoad
from .history import FacePressure

SLIP, OPEN, BREAK, NEVER = 0, 1, 2, -1
MODE_NAMES = ("slip", "open", "break")          # margin_mode codes 0, 1, 2; -1: no failure under further drawdown
TIE = 1e-9          # relative: a cut-off reached within this share of the cone's crossing is reached first


@dataclass(frozen=True)
class FailureSurface:
    """Per face, the surface a stuck face fails on: cohesion (Pa), tan(phi), tension cut-off (Pa; inf: none) and
    the margin_mode of leaving it through the cone and through the cut-off."""
    cohesion: np.ndarray
    tan_phi: np.ndarray
    cutoff: np.ndarray
    cone_mode: np.ndarray
    cutoff_mode: np.ndarray


def failure_surface(strength: object, broken: np.ndarray) -> FailureSurface:
    """The surfaces of faces with ``strength`` (pfault.faults.breaking.FaceStrength), those ``broken`` broken: the
    law's (cohesion of a broken face, apex cut-off; slip, open), the intact strength elsewhere (break, break)."""
    coh = np.where(broken, strength.broken_cohesion, strength.cohesion)
    cutoff = np.where(broken, ct.tensile_strength(coh, strength.tan_phi), strength.cutoff)
    return FailureSurface(coh, np.asarray(strength.tan_phi, float), cutoff, np.where(broken, SLIP, BREAK),
                          np.where(broken, OPEN, BREAK))


def _cone_crossing(t0: np.ndarray, r: np.ndarray, s: FailureSurface) -> np.ndarray:
    """Smallest lam >= 0 at which t0 + lam r leaves the cone |t_T| <= c - tan(phi) t_N (0 where t0 is outside,
    inf where it never leaves)."""
    tT0, rT = t0[:, 1:], r[:, 1:]
    k0 = s.cohesion - s.tan_phi * t0[:, 0]
    k1 = s.tan_phi * r[:, 0]
    a = np.einsum("ni,ni->n", rT, rT) - k1 * k1
    b = np.einsum("ni,ni->n", tT0, rT) + k0 * k1
    c = np.einsum("ni,ni->n", tT0, tT0) - k0 * k0
    disc = b * b - a * c
    real = disc >= -1e-12 * (b * b + np.abs(a * c))         # a double root (a path through the apex) within round-off
    sq = np.sqrt(np.maximum(disc, 0.0))
    q = -(b + np.where(b >= 0, sq, -sq))
    with np.errstate(divide="ignore", invalid="ignore"):
        roots = np.stack([q / a, c / q], axis=1)               # stable: one of them is -c / 2b when a = 0
    finite = np.isfinite(roots)
    roots = np.where(finite, roots, 0.0)
    size = np.abs(roots)
    scale = (np.abs(k0) + np.linalg.norm(tT0, axis=1))[:, None] \
        + (np.abs(k1) + np.linalg.norm(rT, axis=1))[:, None] * size
    valid = real[:, None] & finite & (k0[:, None] - roots * k1[:, None] >= -1e-9 * scale)
    valid &= roots >= -1e-12 * np.maximum(size, 1.0)
    lam = np.max(np.where(valid, np.maximum(roots, 0.0), -np.inf), axis=1)
    lam = np.where(np.isfinite(lam), lam, np.inf)
    outside = np.linalg.norm(tT0, axis=1) > k0 + 1e-12 * (np.abs(k0) + np.abs(s.cohesion))
    return np.where(outside, 0.0, lam)


def _cutoff_crossing(t0: np.ndarray, r: np.ndarray, s: FailureSurface) -> np.ndarray:
    """Smallest lam >= 0 at which t0 + lam r reaches the cut-off t_N = T (inf where it never does)."""
    finite = np.isfinite(s.cutoff)
    gap = np.where(finite, s.cutoff - t0[:, 0], np.inf)
    rising = finite & (r[:, 0] > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(rising, gap / np.where(rising, r[:, 0], 1.0), np.inf)
    return np.where(finite & (gap < 0), 0.0, np.maximum(lam, 0.0))


def crossing(t0: np.ndarray, r: np.ndarray, s: FailureSurface) -> tuple[np.ndarray, np.ndarray]:
    """(lam, mode) per face: the smallest further drawdown lam >= 0 at which the effective traction t0 + lam r
    (nf x 3, local frame) leaves the surface ``s``, and through which part (its cone_mode or cutoff_mode; NEVER,
    with lam infinite, where it stays inside)."""
    cone, cut = _cone_crossing(t0, r, s), _cutoff_crossing(t0, r, s)
    first_cut = cut <= cone * (1.0 + TIE)
    lam = np.minimum(cone, cut)
    mode = np.where(first_cut, s.cutoff_mode, s.cone_mode)
    return lam, np.where(np.isfinite(lam), mode, NEVER)


def piecewise_crossing(t0: np.ndarray, r1: np.ndarray, lam_dry: np.ndarray, r2: np.ndarray, s: FailureSurface
                       ) -> tuple[np.ndarray, np.ndarray]:
    """``crossing`` along the path t0 + lam r1 up to lam_dry (per face; inf: no kink), t0 + lam_dry r1 +
    (lam - lam_dry) r2 beyond."""
    lam1, mode1 = crossing(t0, r1, s)
    kink = np.isfinite(lam_dry)
    at_kink = t0 + np.where(kink, lam_dry, 0.0)[:, None] * r1
    lam2, mode2 = crossing(at_kink, r2, s)
    beyond = kink & (lam1 > lam_dry)
    return np.where(beyond, lam_dry + lam2, lam1), np.where(beyond, mode2, mode1)


# -- the fault term's part of the linear response and its margins ---------------------------------------------
@dataclass(frozen=True)
class FaultLoadRate:
    """The rate of the faces' load per metre of further drawdown: alpha dp/dlam at each face (Pa/m, while it is
    wet), the drawdown at which each face dries (m; inf: never) and the rate of the bubbles' load."""
    pn: np.ndarray
    dry: np.ndarray
    bubbles: BubbleLoad


def pressure_rate(pressure: FacePressure, t: float, cell_dp: np.ndarray | None, cell_rate: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(alpha dp/dlam at each face, the drawdown at which it dries) for the pore-pressure change per local cell
    ``cell_dp`` at time t and its rate ``cell_rate`` (Pa per metre of drawdown), as FacePressure.at: a face whose
    pressure is clamped at zero and is dry now stays dry (rate 0); a wet one dries at p / -rate."""
    nf = len(pressure.cell)
    if not pressure.active or not nf:
        return np.zeros(nf), np.full(nf, np.inf)
    p = pressure.static.copy()
    if cell_dp is not None and t > 0:
        p += cell_dp[pressure.cell]
    r = cell_rate[pressure.cell]
    if not pressure.clamp:
        return pressure.alpha * r, np.full(nf, np.inf)
    wet = p > 0
    falling = wet & (r < 0)
    dry = np.full(nf, np.inf)
    dry[falling] = p[falling] / -r[falling]
    return np.where(wet, pressure.alpha * r, 0.0), dry


def load_rate(term: Any, t: float, cell_dp: np.ndarray | None, cell_rate: np.ndarray, alpha: np.ndarray,
              out: np.ndarray) -> FaultLoadRate:
    """The fault term's load rate (pfault.faults.term.FaultTerm.load, differentiated in the drawdown): the Biot
    load of the bubbles for the rate ``cell_rate`` per local cell, whose condensed load is added to ``out``, and
    the rate of the laws' pore pressure."""
    fb = term.bubbles.pore_pressure_load(alpha * cell_rate)
    pn, dry = pressure_rate(term.pressure, t, cell_dp, cell_rate)
    return FaultLoadRate(pn, dry, term.bubbles.load(fb, out))


def residual_rate(term: Any, x_loc: np.ndarray, load: Any, rate: FaultLoadRate, history: Any,
                  out: np.ndarray) -> None:
    """Add d(the faces' rows)/dlam at the fixed state x_loc to ``out``: through the bubbles' load in the jumps the
    laws take and through the pore pressure in their effective tractions, each face in its branch at x_loc."""
    state = term.law_terms(x_loc, load, history)[0]
    gl, t = term.law_jumps(x_loc, load, history)
    law = term.laws.of(history.broken)[0]
    _, _, dg, dt = ct.lagrange_rows(law, gl, history.start.g, load.effective(t), state)
    dgl = term.bubbles.jump_of_load(rate.bubbles) / np.maximum(term.faces.area, 1e-300)[:, None]
    r = np.einsum("nij,nj->ni", dg, dgl) + dt[:, :, 0] * rate.pn[:, None]
    out += np.bincount(term.faces.lm_dofs.ravel(), weights=r.ravel(), minlength=len(out))


def live_faces(term: Any, x_loc: np.ndarray, load: Any, history: Any) -> int:
    """How many faces, on all ranks, have a margin that the linear response decides: stuck now and not broken on a
    candidate surface (collective)."""
    states = term.configuration(x_loc, load, history, exact=False)
    live = (states == ct.STICK) & ~(history.broken & term.laws.strength.candidate)
    return int(term.faces.mpi.allreduce(int(np.count_nonzero(live)), op=MPI.SUM))


def face_margins(term: Any, x_loc: np.ndarray, dx_loc: np.ndarray, load: Any, rate: FaultLoadRate,
                 history: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(margin (m of further drawdown), margin_mode) of every owned face at the converged state x_loc with the
    state's rate dx_loc (per metre): zero on faces slipping or open now (their state's mode) and on broken faces
    of candidate surfaces (break), the first crossing of the failure surface on the others (NaN where the rate is
    unknown: its linear solve failed); and which faces have failed."""
    t_eff = load.effective(term.tractions(x_loc))
    dt = term.tractions(dx_loc)
    r1 = dt.copy()
    r1[:, 0] += rate.pn
    strength = term.laws.strength
    lam, mode = piecewise_crossing(t_eff, r1, rate.dry, dt, failure_surface(strength, history.broken))
    states = term.configuration(x_loc, load, history, exact=False)
    failed = states != ct.STICK
    broke = history.broken & strength.candidate
    unknown = ~np.isfinite(dt).all(axis=1)                  # the linear solve failed
    lam, mode = np.where(unknown, np.nan, lam), np.where(unknown, NEVER, mode)
    lam = np.where(failed | broke, 0.0, lam)
    mode = np.where(failed, np.where(states == ct.OPEN, OPEN, SLIP), mode)
    return lam, np.where(broke, BREAK, mode), failed | broke


@dataclass(frozen=True)
class FaultMargins:
    """The owned faces' margins at an output time (``drawdown_m``, m of further drawdown, inf where none;
    ``mode``, MODE_NAMES' codes, NEVER where none), the pore-pressure change a metre of it is (``rho_g``, Pa/m) and
    each fault's figures (``faults``: JSON-ready, by name; ``fault_figures``)."""
    drawdown_m: np.ndarray
    mode: np.ndarray
    rho_g: float
    faults: dict

    def fields(self) -> dict:
        """fault.h5's fields of the owned faces."""
        return {"fault": {"margin_drawdown_m": self.drawdown_m, "margin_pore_pressure_pa": self.rho_g * self.drawdown_m,
                          "margin_mode": self.mode.astype(np.int64)}}

    def as_json(self) -> dict:
        """The step record's part: each fault's ``margin``."""
        return {"faults": {name: {"margin": figures} for name, figures in self.faults.items()}}


def fault_figures(faces: Any, names: list, lam: np.ndarray, mode: np.ndarray, failed: np.ndarray,
                  centroids: np.ndarray, thresholds: tuple, rho_g: float) -> dict:
    """Per fault (by name): the smallest margin of its faces that have not failed (m of drawdown, and in Pa), on
    which face (its serial id: its row in fault.h5), where (``centroids``: the owned faces' centroids, site
    coordinates) and how it would fail (null where no such face fails under further drawdown), its faces failed now
    and their area, its area within each of ``thresholds`` (m; failed faces included) and the stuck faces that
    no further drawdown fails. The smallest is the same on any partition (ties: the lowest face id). Collective."""
    mpi, nk = faces.mpi, len(names)
    a = faces.area
    sums = np.zeros((nk, 3 + len(thresholds)))
    cols = [failed, a * failed, ~failed & np.isinf(lam)] + [a * (lam <= thr) for thr in thresholds]
    np.add.at(sums, faces.fault, np.column_stack(cols) if len(a) else np.zeros((0, sums.shape[1])))
    mpi.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    best = np.full((nk, 6), np.inf)                             # lam, face, x, y, z, mode
    open_ = ~failed & np.isfinite(lam)
    for k in range(nk):
        i = np.flatnonzero(open_ & (faces.fault == k))
        if len(i):
            j = i[np.lexsort((faces.face[i], lam[i]))[0]]
            best[k] = [lam[j], faces.face[j], *centroids[j], mode[j]]
    every = np.concatenate(mpi.allgather(best[None]))            # (ranks, nk, 6)
    out = {}
    for k, name in enumerate(names):
        rows = every[:, k]
        b = rows[np.lexsort((rows[:, 1], rows[:, 0]))[0]]
        found = bool(np.isfinite(b[0]))
        out[name] = {"min_drawdown_m": float(b[0]) if found else None,
                     "min_pore_pressure_pa": float(rho_g * b[0]) if found else None,
                     "min_mode": MODE_NAMES[int(b[5])] if found else None,
                     "min_face": int(b[1]) if found else None,
                     "min_xyz_m": [float(v) for v in b[2:5]] if found else None,
                     "faces_failed": int(sums[k, 0]), "failed_area_m2": float(sums[k, 1]),
                     "faces_never": int(sums[k, 2]),
                     "area_within_m2": {f"{thr:g}": float(v) for thr, v in zip(thresholds, sums[k, 3:])}}
    return out


class MarginHooks:
    """A fault term's hooks of the margins to failure (pfault.solver.terms.Term): the load's and the residual's
    rates per metre of further drawdown, the faces that need the response, and every face's margin. Mixed into
    pfault.faults.term.FaultTerm (its ``faces``, ``settings``, ``pressure``)."""

    def load_rate(self, t: float, cell_dp: np.ndarray | None, cell_rate: np.ndarray, alpha: np.ndarray,
                  out: np.ndarray) -> FaultLoadRate:
        """The rate of ``load`` per metre of further drawdown (``cell_rate``: Pa/m per local cell)."""
        return load_rate(self, t, cell_dp, cell_rate, alpha, out)

    def residual_rate(self, x_loc: np.ndarray, load: Any, rate: FaultLoadRate, history: Any,
                      out: np.ndarray) -> None:
        residual_rate(self, x_loc, load, rate, history, out)

    def margin_parts(self, x_loc: np.ndarray, load: Any, history: Any) -> int:
        """Faces whose margin needs the response (stuck, not broken), on all ranks. Collective."""
        return live_faces(self, x_loc, load, history)

    def margins(self, x_loc: np.ndarray, dx_loc: np.ndarray, load: Any, rate: FaultLoadRate,
                history: Any, mesh: Any, settings: Any) -> FaultMargins:
        """Every owned face's margin to failure at x_loc, with the state's rate dx_loc, and each fault's figures
        (``settings``: pfault.solver.terms.MarginSettings). Collective."""
        lam, mode, failed = face_margins(self, x_loc, dx_loc, load, rate, history)
        centroids = mesh.coords[self.faces.verts].mean(axis=1) + np.asarray(settings.origin)
        names = [f.name for f in self.settings]
        return FaultMargins(lam, mode, settings.rho_g, fault_figures(
            self.faces, names, lam, mode, failed, centroids, settings.thresholds, settings.rho_g))

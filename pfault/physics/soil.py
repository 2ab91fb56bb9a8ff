"""Soils that remember: the compression-index law of a compressible layer in 3-D, vectorised over cells (pure NumPy).

Conventions
- pfault's stresses and strains are tension positive; the law acts on the effective stress sigma' = sigma + alpha p I
  and returns it, tension positive. Its scalars are compression positive: the mean effective stress
  p' = -tr(sigma')/3 and the volumetric strain eps_v = -tr(eps). Deviators stay tension positive: s = dev(sigma'),
  e = dev(eps). I is the identity, r = G/K = 3(1-2 nu)/(2(1+nu)) (constant Poisson ratio nu).
- History (per cell, plain data, returned anew by every step): the effective stress, the preconsolidation p'_c (the
  largest mean effective stress the cell has borne, its memory) and the plastic (irrecoverable) strain.
- Two forms of the volumetric law, per cell (a material takes one):
  index form (compression indices, as in an oedometer report): kappa = Cr / ((1+e0) ln 10), lambda = Cc / ((1+e0) ln 10)
      swelling/recompression line  d eps_v = kappa d ln p'          virgin line  d eps_v = lambda d ln p'
  storage form (MODFLOW CSUB's HEAD_BASED skeletal specific storage, constant per branch): with the oedometric
      compressibility m = Ssk / (alpha gamma_w) and K = (1+nu) / (3 (1-nu) m), kappa = 1/K_e and lambda = 1/K_v (1/Pa)
      recompression  d eps_v = kappa d p'                            virgin         d eps_v = lambda d p'
  0 < kappa < lambda; rho = kappa / lambda = Cr/Cc (or Sske/Sskv).

The law: an elastoplastic cap in the Cam-clay family.
- Elasticity (the swelling line): dp' = K de_v^e, ds = 2 G de^e with K = p'/kappa (index) or 1/kappa (storage), G = r K.
- Yield surface p' = p'_c (a cap on the mean effective stress), hardening d ln p'_c = d eps_v^p / (lambda - kappa)
  (index; d p'_c = d eps_v^p / (lambda - kappa) in the storage form).
- Flow rule: d eps^p = d lam (-I/3 + s / (2 r p')): the plastic strain has the direction of the elastic strain of a
  radial stress increment (d sigma' proportional to sigma'). Along any radial stress path the virgin response is
  therefore the swelling response scaled by lambda/kappa = Cc/Cr, in every component; under oedometric strain from a
  state at K0 = nu/(1-nu) (pfault's geostatic default) the stress stays at K0, p' = sigma'_v (1+nu)/(3(1-nu)), and
  the oedometric tangent is (1+e0) sigma'_v / (0.4343 C): exactly the 1-D compression-index law on loading, unloading
  and reloading. Deviatoric loading at constant p' is elastic; the stress is a Lipschitz-continuous function of the
  strain (docs/theory.md, "Soils that remember", for the choice against a hypoelastic law with a branch-dependent
  shear modulus and against Modified Cam-Clay).

Integration over a step along the straight strain path eps_n -> eps_n + d eps, exact (the result does not depend on
how a monotonic path is cut into steps), in closed form:
    eps_1 = kappa ln(p'_c / p'_n)   [storage: kappa (p'_c - p'_n)]   volumetric strain that reaches the cap
    x = d eps_v - eps_1             x <= 0: elastic (swelling or recompression); x > 0: virgin loading
    elastic: p' = p'_n exp(d eps_v / kappa)        d lam = 0
    virgin:  p' = p'_c exp(x / lambda) = p'_c,new  d lam = (1 - rho) x      [storage: p' = p'_c + x / lambda]
    de_v^e = d eps_v - d lam,  Kbar = (p' - p'_n) / de_v^e = (p'_n/kappa) expm1(v)/v, v = de_v^e / kappa   [1/kappa]
    s = (s_n + 2 r Kbar d e) / (1 + Kbar d lam / p')     (the deviatoric rate law integrated with the secant modulus
                                                          and the flow direction at the end of the step)
The consistent tangent d sigma'/d eps of this map is a (x) I + 2 mu (I_sym - I (x) I / 3), with a (n,3,3) and mu (n,)
(``update(..., tangent=True)``); it is not symmetric (the secant modulus depends on d eps_v), so it needs a Krylov
method for non-symmetric operators (GMRES) or LU, not CG.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

ELASTIC, VIRGIN = 0, 1
BRANCH_NAMES = ("elastic", "virgin")
LN10 = np.log(10.0)
SERIES = 1e-3            # |v| below which expm1(v)/v and its derivative are taken from their Taylor series


@dataclass(frozen=True)
class SoilLaw:
    """Per-cell parameters (arrays of one length): the form (True: compression indices, False: skeletal storage),
    the compliances of the swelling (kappa) and virgin (lambda) lines (d eps_v / d ln p' in the index form, 1/Pa in
    the storage form) and the Poisson ratio."""
    index_form: np.ndarray
    kappa: np.ndarray
    lam: np.ndarray
    poisson: np.ndarray

    def __getitem__(self, idx: np.ndarray | slice) -> SoilLaw:
        return SoilLaw(*(getattr(self, f.name)[idx] for f in fields(self)))

    def __len__(self) -> int:
        return len(self.kappa)

    @property
    def shear_ratio(self) -> np.ndarray:
        """r = G/K = 3 (1 - 2 nu) / (2 (1 + nu))."""
        return 1.5 * (1 - 2 * self.poisson) / (1 + self.poisson)

    @property
    def oedometric_ratio(self) -> np.ndarray:
        """dp' / d sigma'_v under oedometric strain, (1 + nu) / (3 (1 - nu))."""
        return (1 + self.poisson) / (3 * (1 - self.poisson))


def index_law(cc: np.ndarray, cr: np.ndarray, e0: np.ndarray, poisson: np.ndarray) -> SoilLaw:
    """The law of compression indices Cc, Cr (per decade of effective stress) and initial void ratio e0."""
    cc, cr, e0, nu = np.broadcast_arrays(*(np.asarray(v, float) for v in (cc, cr, e0, poisson)))
    scale = 1.0 / ((1 + e0) * LN10)
    return SoilLaw(np.ones(cc.shape, bool), cr * scale, cc * scale, nu.copy())


def storage_law(sske: np.ndarray, sskv: np.ndarray, poisson: np.ndarray, alpha: np.ndarray,
                gamma_w: float) -> SoilLaw:
    """The law of CSUB's head-based elastic and inelastic skeletal specific storage Sske, Sskv (1/m): an oedometric
    column of thickness b compacts by Ssk b dh for a head change dh, its vertical effective stress changing by
    alpha gamma_w dh (gamma_w = rho_w g, Pa/m)."""
    sske, sskv, nu, alpha = np.broadcast_arrays(*(np.asarray(v, float) for v in (sske, sskv, poisson, alpha)))
    bulk_per_m = (1 + nu) / (3 * (1 - nu)) * alpha * gamma_w       # K m = (1+nu)/(3(1-nu)); m = Ssk/(alpha gamma_w)
    return SoilLaw(np.zeros(sske.shape, bool), sske / bulk_per_m, sskv / bulk_per_m, nu.copy())


def concatenate(laws: list[SoilLaw]) -> SoilLaw:
    return SoilLaw(*(np.concatenate([getattr(w, f.name) for w in laws]) for f in fields(SoilLaw)))


@dataclass(frozen=True)
class SoilHistory:
    """A step's state of every cell: effective stress (n,3,3, Pa, tension positive), preconsolidation p'_c (n, Pa,
    mean effective stress, compression positive) and plastic strain (n,3,3, tension positive)."""
    stress: np.ndarray
    preconsolidation: np.ndarray
    plastic_strain: np.ndarray

    def __getitem__(self, idx: np.ndarray | slice) -> SoilHistory:
        return SoilHistory(*(getattr(self, f.name)[idx] for f in fields(self)))

    def __len__(self) -> int:
        return len(self.preconsolidation)


def trace(t: np.ndarray) -> np.ndarray:
    """tr(t) of (n,3,3) tensors (np.trace's sum, in its order, without its generality's cost)."""
    return t[:, 0, 0] + t[:, 1, 1] + t[:, 2, 2]


def plus_diagonal(t: np.ndarray, d: np.ndarray) -> np.ndarray:
    """t + d I for (n,3,3) tensors t and (n,) scalars d (a new array)."""
    out = np.array(t, dtype=float, copy=True)
    for i in range(3):
        out[:, i, i] += d
    return out


def mean_stress(stress: np.ndarray) -> np.ndarray:
    """p' = -tr(sigma')/3 (compression positive) of tension-positive stresses (n,3,3)."""
    return -trace(stress) / 3.0


def deviator(t: np.ndarray) -> np.ndarray:
    return plus_diagonal(t, -(trace(t) / 3.0))


# -- the initial state ---------------------------------------------------------------------------------------
def vertical_preconsolidation(kind: str, value: np.ndarray | float | None, sigma_v0: np.ndarray,
                              alpha: np.ndarray | float = 1.0, gamma_w: float = 9806.65) -> np.ndarray:
    """The preconsolidation as a vertical effective stress sigma'_vc (Pa, compression positive) per cell, from the
    initial vertical effective stress sigma'_v0 and what the material gives: ``normal`` (normally consolidated,
    sigma'_vc = sigma'_v0), ``stress`` (sigma'_vc), ``ratio`` (OCR = sigma'_vc / sigma'_v0) or ``head`` (the lowest
    head before, relative to the initial heads, m, <= 0: sigma'_vc = sigma'_v0 - alpha gamma_w h)."""
    sv0 = np.asarray(sigma_v0, float)
    if kind == "normal":
        return sv0.copy()
    v = np.broadcast_to(np.asarray(value, float), sv0.shape)
    if kind == "stress":
        return v.copy()
    if kind == "ratio":
        return v * sv0
    if kind == "head":
        return sv0 - np.asarray(alpha, float) * gamma_w * v
    raise ValueError(kind)


def initial_history(law: SoilLaw, stress0: np.ndarray, sigma_vc: np.ndarray) -> SoilHistory:
    """The history before the first step: the initial effective stress (n,3,3, tension positive), the memory p'_c
    of the vertical preconsolidation sigma'_vc (n, compression positive), no plastic strain. p'_c is the mean
    stress at which this law, reloaded oedometrically from the initial state, reaches sigma'_vc:
    p'_c = p'_0 + (1+nu)/(3(1-nu)) (sigma'_vc - sigma'_v0). Cells whose sigma'_vc lies below their initial stress
    are the caller's to reject first (``below_initial``)."""
    p0 = mean_stress(stress0)
    pc = p0 + law.oedometric_ratio * (np.asarray(sigma_vc, float) - (-stress0[:, 2, 2]))
    return SoilHistory(np.array(stress0, dtype=float), np.maximum(pc, p0), np.zeros_like(stress0, dtype=float))


def below_initial(law: SoilLaw, stress0: np.ndarray, sigma_vc: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
    """Cells that cannot start from the given state: a preconsolidation below the initial vertical effective stress,
    or (index form) no compression at the start (p'_0 <= 0, a cell without initial effective stress)."""
    sv0 = -stress0[:, 2, 2]
    low = np.asarray(sigma_vc, float) < sv0 - rtol * np.abs(sv0)
    return low | (law.index_form & ~(mean_stress(stress0) > 0))


# -- one step ------------------------------------------------------------------------------------------------
def _phi(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """expm1(v)/v and its derivative, accurate at v -> 0."""
    small = np.abs(v) < SERIES
    w = np.where(small, 1.0, v)
    e = np.expm1(w)
    phi = np.where(small, 1 + v / 2 + v * v / 6 + v ** 3 / 24, e / w)
    dphi = np.where(small, 0.5 + v / 3 + v * v / 8 + v ** 3 / 30, (w * np.exp(w) - e) / (w * w))
    return phi, dphi


def _volumetric(law: SoilLaw, p_n: np.ndarray, p_c: np.ndarray, deps_v: np.ndarray,
                branch: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Mean stress p', plastic multiplier d lam, secant bulk modulus Kbar, their derivatives in d eps_v, and the
    branch, of the closed-form step (module docstring); ``branch``: the branches to take instead of the strain's."""
    log, k, lm = law.index_form, law.kappa, law.lam
    with np.errstate(divide="ignore", invalid="ignore"):
        eps1 = np.where(log, k * np.log(p_c / p_n), k * (p_c - p_n))
    # p'_c >= p'_n; a cell on its cap (eps_1 = 0 up to round-off of the trace) with no volumetric strain is on the
    # elastic branch, the stiffer one: a Newton iteration from d eps = 0 then cannot overshoot an unloading step
    x = deps_v - np.maximum(eps1, 0.0)
    virgin = x > 0 if branch is None else np.asarray(branch) == VIRGIN
    dlam_de = np.where(virgin, 1.0 - k / lm, 0.0)
    dlam = dlam_de * x
    dve = deps_v - dlam                                       # elastic volumetric strain of the step
    phi, dphi = _phi(np.where(log, dve / k, 0.0))
    kbar = np.where(log, p_n / k * phi, 1.0 / k)
    dkbar = np.where(log, p_n / (k * k) * dphi * (1.0 - dlam_de), 0.0)
    p = p_n + kbar * dve
    dp = np.where(log, p, 1.0) / np.where(virgin, lm, k)     # dp'/d eps_v: p'/lambda or p'/kappa (storage 1/...)
    return {"p": p, "dp": dp, "dlam": dlam, "dlam_de": dlam_de, "kbar": kbar, "dkbar": dkbar,
            "branch": np.where(virgin, VIRGIN, ELASTIC)}


def update(law: SoilLaw, history: SoilHistory, d_strain: np.ndarray, tangent: bool = False,
           branch: np.ndarray | None = None) -> tuple[SoilHistory, np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """One step of every cell from ``history`` under the strain increment ``d_strain`` (n,3,3, tension positive):
    the new history, the branch of each cell (ELASTIC, VIRGIN) and, with ``tangent``, the consistent tangent
    d sigma'/d(d eps) = a (x) I + 2 mu (I_sym - I (x) I / 3) as (a (n,3,3), mu (n,)).

    ``branch``: the branch each cell takes instead of the one its strain decides (a semismooth Newton's given
    configuration): ELASTIC continues the swelling line past the cap, VIRGIN the virgin line below it, from the
    cap (a cell off its cap then starts the step from its cap: meaningful only for cells on it)."""
    p_n = mean_stress(history.stress)
    s_n = deviator(history.stress)
    deps_v = -trace(d_strain)
    de = deviator(d_strain)
    vol = _volumetric(law, p_n, history.preconsolidation, deps_v, branch)
    r = law.shear_ratio
    p, dlam, kbar = vol["p"], vol["dlam"], vol["kbar"]
    pv = np.where(vol["branch"] == VIRGIN, p, 1.0)  # p' where it divides: on the virgin branch, p' > 0
    denom = 1.0 + kbar * dlam / pv
    s = (s_n + (2 * r * kbar)[:, None, None] * de) / denom[:, None, None]
    stress = plus_diagonal(s, -p)
    flow = plus_diagonal(s / (2 * r * pv)[:, None, None], np.full(len(p), -1.0 / 3.0))
    new = SoilHistory(stress, np.maximum(history.preconsolidation, p),
                      history.plastic_strain + dlam[:, None, None] * flow)
    if not tangent:
        return new, vol["branch"], None
    ddenom = (vol["dkbar"] * dlam + kbar * vol["dlam_de"] - kbar * dlam * vol["dp"] / pv) / pv
    ds = ((2 * r * vol["dkbar"])[:, None, None] * de - ddenom[:, None, None] * s) / denom[:, None, None]
    a = plus_diagonal(-ds, vol["dp"])                        # d eps_v = -tr(d eps): d sigma'/d tr = dp' I - ds/d eps_v
    return new, vol["branch"], (a, r * kbar / denom)


def tangent_tensor(a: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """The tangent as a full (n,3,3,3,3) tensor D[i,j,k,l] = d sigma'_ij / d eps_kl (eps symmetric: the minor
    symmetric part in k,l)."""
    eye = np.eye(3)
    sym = 0.5 * (np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye))
    vol = np.einsum("ij,kl->ijkl", eye, eye)
    return np.einsum("nij,kl->nijkl", a, eye) + 2 * mu[:, None, None, None, None] * (sym - vol / 3)[None]


# -- measures ------------------------------------------------------------------------------------------------
def vertical_preconsolidation_of(law: SoilLaw, history: SoilHistory) -> np.ndarray:
    """The preconsolidation as a vertical effective stress (Pa, compression positive): p'_c over the oedometric
    ratio (1+nu)/(3(1-nu)), the vertical stress at which a cell consolidated at K0 reaches its cap."""
    return history.preconsolidation / law.oedometric_ratio


def vertical_margin(law: SoilLaw, history: SoilHistory) -> np.ndarray:
    """How much more vertical effective stress (Pa) a cell bears before it reaches its preconsolidation: the
    vertical preconsolidation less the current vertical effective stress; 0 on the virgin line. On the K0 path it
    is (p'_c - p') / ((1+nu)/(3(1-nu))), the oedometric reloading's; off it, it is what a hydrogeologist compares a
    head with (CSUB's preconsolidation stress against the vertical effective stress), and its mean over a horizontal
    slab of cells is the one the slab's weight and heads fix (equilibrium), whatever the cells' stiffness."""
    return vertical_preconsolidation_of(law, history) + history.stress[:, 2, 2]


def head_margin(law: SoilLaw, history: SoilHistory, alpha: np.ndarray | float, gamma_w: float) -> np.ndarray:
    """The further drawdown (m of head) that brings each cell to its preconsolidation under oedometric conditions:
    the current head minus the critical head."""
    return vertical_margin(law, history) / (np.asarray(alpha, float) * gamma_w)

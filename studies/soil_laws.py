"""Modified Cam-Clay reduced to the oedometer, measured against the 1-D compression-index law.

    .venv/bin/python -m studies.soil_laws

Modified Cam-Clay (Roscoe & Burland 1968) in triaxial invariants, compression positive: p' and q = sigma'_v -
sigma'_h, volumetric and shear strains eps_v and eps_q = 2/3 (eps_a - eps_r); yield f = q^2 + M^2 p'(p' - p'_c),
associated flow, hardening d ln p'_c = d eps_v^p / (lambda* - kappa*); elasticity K = p'/kappa* with either a constant
Poisson ratio (G = 3K(1-2nu)/(2(1+nu)), as in textbook and PLAXIS Cam-clay) or a constant shear modulus (GEOS's
ElasticIsotropicPressureDependent, which its ModifiedCamClay builds on), G fixed at its value at the start of the
unloading. lambda* = Cc/((1+e0) ln 10), kappa* = Cr/((1+e0) ln 10): the small-strain index law's own slopes, so any
difference below is the model's, not the parameters'.

Under oedometric strain (eps_q = 2/3 eps_v) the path is integrated with the continuum elastoplastic tangent in
strain steps of 1e-6 (forward Euler: about 1e-4 relative): virgin loading from an isotropic state until the stress
ratio is steady (the model's K0 on the normal compression line), then unloading to sigma'_v,max / OCR and reloading to
sigma'_v,max. The index law gives eps = Cr/(1+e0) log10(OCR) for that unloading, a straight e - log sigma'_v line,
and reloading retraces it. Printed per variant: the model's K0 on virgin loading, its virgin slope in e - log sigma'_v
over Cc, the rebound at OCR 2, 4 and 8 over the index law's, whether the unloading path yields (reaches the yield
surface on the passive side), and the strain left when reloaded to sigma'_v,max.
"""

from __future__ import annotations

import math

CC, CR, E0, NU = 0.35, 0.05, 0.9, 0.3
LAMBDA, KAPPA = CC / ((1 + E0) * math.log(10)), CR / ((1 + E0) * math.log(10))


def m_from_friction(phi_deg: float) -> float:
    """M of triaxial compression for the friction angle phi': 6 sin phi / (3 - sin phi)."""
    s = math.sin(math.radians(phi_deg))
    return 6 * s / (3 - s)


def m_for_k0(nu: float = NU) -> float:
    """The M for which MCC's oedometric virgin loading holds K0 = nu/(1-nu) (so that elastic unloading from it stays
    radial): the plastic strain ratio 2 eta/(M^2 - eta^2) equals the oedometer's 2/3 at eta = 3(1-2nu)/(1+nu),
    M^2 = eta^2 + 3 eta."""
    eta = 3 * (1 - 2 * nu) / (1 + nu)
    return math.sqrt(eta * eta + 3 * eta)


class CamClay:
    """One MCC point under oedometric strain: state p', q, p'_c and the vertical strain (compression positive)."""

    def __init__(self, M: float, constant_shear: bool, p0: float) -> None:
        self.M, self.constant_shear = M, constant_shear
        self.p, self.q, self.pc, self.eps = p0, 0.0, p0, 0.0
        self.g_fixed: float | None = None

    def state(self) -> tuple[float, float, float, float]:
        return self.p, self.q, self.pc, self.eps

    def restore(self, state: tuple[float, float, float, float]) -> None:
        self.p, self.q, self.pc, self.eps = state

    def shear_modulus(self) -> float:
        if self.constant_shear and self.g_fixed is not None:
            return self.g_fixed
        return 1.5 * (1 - 2 * NU) / (1 + NU) * self.p / KAPPA

    def step(self, de: float) -> bool:
        """Oedometric strain increment de (d eps_v = de, d eps_q = 2/3 de), forward Euler on the continuum
        elastoplastic tangent, the state put back on its yield surface after a plastic step; True if plastic."""
        K, G = self.p / KAPPA, self.shear_modulus()
        dp, dq = K * de, 3 * G * 2.0 / 3.0 * de
        fp, fq = self.M ** 2 * (2 * self.p - self.pc), 2 * self.q
        on_surface = self.q ** 2 + self.M ** 2 * self.p * (self.p - self.pc) > -1e-9 * self.pc ** 2
        load = fp * dp + fq * dq
        plastic = on_surface and load > 0
        if plastic:
            hard = self.M ** 2 * self.p * self.pc * fp / (LAMBDA - KAPPA)
            lam = load / (fp * K * fp + fq * 3 * G * fq + hard)
            dp, dq = dp - lam * K * fp, dq - lam * 3 * G * fq
        self.p, self.q, self.eps = self.p + dp, self.q + dq, self.eps + de
        if plastic:
            self.pc = self.p + self.q ** 2 / (self.M ** 2 * self.p)
        return plastic

    @property
    def sigma_v(self) -> float:
        return self.p + 2.0 / 3.0 * self.q

    @property
    def sigma_h(self) -> float:
        return self.p - self.q / 3.0


def drive_to(pt: CamClay, target_sv: float, de: float = 1e-6) -> bool:
    """Oedometric strain steps of de until sigma'_v reaches target_sv, the last one cut to hit it (bisection on that
    step); True if any step was plastic."""
    sign = 1.0 if target_sv > pt.sigma_v else -1.0
    plastic = False
    while True:
        before = pt.state()
        yielded = pt.step(sign * de)
        if (pt.sigma_v - target_sv) * sign >= 0:
            lo, hi = 0.0, de
            for _ in range(60):
                pt.restore(before)
                mid = 0.5 * (lo + hi)
                pt.step(sign * mid)
                lo, hi = (mid, hi) if (pt.sigma_v - target_sv) * sign < 0 else (lo, mid)
            return plastic or yielded
        plastic = plastic or yielded


def measure(M: float, constant_shear: bool) -> dict[str, float | bool]:
    """One variant's figures (module docstring)."""
    pt = CamClay(M, constant_shear, 100e3)
    drive_to(pt, 1e6, 1e-5)                               # virgin loading from isotropic: the stress ratio settles
    drive_to(pt, 2e6)
    k0 = pt.sigma_h / pt.sigma_v
    e1, s1 = pt.eps, pt.sigma_v
    drive_to(pt, 4e6)
    out: dict[str, float | bool] = {"K0": k0, "virgin slope / Cc": (pt.eps - e1) / math.log10(pt.sigma_v / s1)
                                    * (1 + E0) / CC}
    smax, emax, top = pt.sigma_v, pt.eps, pt.state()
    for ocr in (2.0, 4.0, 8.0):
        pt.restore(top)
        pt.g_fixed = pt.shear_modulus() if constant_shear else None
        yielded = drive_to(pt, smax / ocr)
        rebound = emax - pt.eps
        out[f"rebound OCR {ocr:g} / index law"] = rebound / (CR / (1 + E0) * math.log10(ocr))
        out[f"yields unloading to OCR {ocr:g}"] = yielded
        drive_to(pt, smax)
        out[f"strain left on reloading to the maximum, OCR {ocr:g}, / rebound"] = (pt.eps - emax) / rebound
    return out


def main() -> None:
    variants = [("M 0.98 (phi' 25 deg), constant nu", m_from_friction(25), False),
                ("M 1.20 (phi' 30 deg), constant nu", m_from_friction(30), False),
                ("M 1.20 (phi' 30 deg), constant G", m_from_friction(30), True),
                (f"M {m_for_k0():.2f} (K0 = nu/(1-nu)), constant nu", m_for_k0(), False)]
    print(f"Cc {CC}, Cr {CR}, e0 {E0}, nu {NU} (nu/(1-nu) = {NU / (1 - NU):.3f})")
    print(f"{'variant':<38} {'K0':>6} {'slope/Cc':>9} {'rebound / index law at OCR 2, 4, 8':>36} {'yields':>7} "
          f"{'left':>8}")
    for name, M, cg in variants:
        r = measure(M, cg)
        reb = ", ".join(f"{r[f'rebound OCR {o:g} / index law']:.3f}" for o in (2, 4, 8))
        ylds = any(r[f"yields unloading to OCR {o:g}"] for o in (2, 4, 8))
        left = max(abs(r[f"strain left on reloading to the maximum, OCR {o:g}, / rebound"]) for o in (2, 4, 8))
        print(f"{name:<38} {r['K0']:6.3f} {r['virgin slope / Cc']:9.4f} {reb:>36} {str(ylds):>7} {left:8.1e}")


if __name__ == "__main__":
    main()

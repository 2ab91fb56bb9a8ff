"""Settlement of a laterally confined column of compressible layers under head changes, three ways side by side.

    .venv/bin/python -m studies.soil_column

1. Closed form: the exact integral over depth of the 1-D compression-index law (or of CSUB's constant skeletal storage
   per branch) with the running maximum of the effective stress as memory, for layers whose initial vertical
   effective stress grows linearly with depth. Per point, compression positive, sigma_0 the initial, sigma_c the
   preconsolidation, sigma_m the largest and sigma the current vertical effective stress:
       eps = kappa ln(min(sigma_m, sigma_c)/sigma_0) + lambda ln(max(sigma_m, sigma_c)/sigma_c)
             - kappa ln(sigma_m/sigma)
   with kappa = Cr/((1+e0) ln 10), lambda = Cc/((1+e0) ln 10); with storage, eps = m_e (min - sigma_0) +
   m_v (max - sigma_c) - m_e (sigma_m - sigma), m = Ssk/(alpha gamma_w). Every stress is linear in depth within a
   layer (a drawdown h adds alpha gamma_w h, uniform in the layer), so the integrand is a sum of logarithms of linear
   functions between the depths where sigma_m = sigma_c: integrated exactly.
2. pfault's soil law (pfault.physics.soil) driven through the oedometric strain path, one cell per Gauss point of each
   piece: for each stage, the vertical strain that gives the stage's vertical effective stress (Newton on the law's
   own tangent), summed with the Gauss weights.
3. MODFLOW 6 CSUB's no-delay interbed relation in head units (gwf-csub.f90, csub_nodelay_fc/_calc_comp), one interbed
   per Gauss point: per time step, with effective stresses in metres of water (sigma'/gamma_w),
       elastic:  db = Sske b (es - es0)
       virgin:   db = Sske b (pcs - es0) + Ssk b (es - pcs),  then pcs = es
   where Ssk = Sske, Sskv are the elastic and inelastic skeletal specific storage: constant with HEAD_BASED, and with
   COMPRESSION_INDICES Ssk = 0.4342942 C / ((1+e0) es_f), es_f the effective stress at the end of the step (the
   default; the previous one with EFFECTIVE_STRESS_LAG). The storage that makes this relation the exact index law
   over any step is Ssk = 0.4342942 C / ((1+e0) es_lm), es_lm = (es_b - es_a)/ln(es_b/es_a) the logarithmic mean of
   the branch's end stresses: the equivalent storage values. MODFLOW 6's end-of-step value is first order in the
   step (measured below).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pfault.physics import soil as sl

GAMMA_W = 9806.65          # Pa/m, CSUB's default GAMMAW
DLOG10ES = 0.4342942       # CSUB's dlog10es: 1/ln 10 as MODFLOW 6 writes it


@dataclass(frozen=True)
class Layer:
    """A compressible layer: depth of its top and thickness (m), initial vertical effective stress at its top (Pa)
    and its gradient (Pa/m: the buoyant unit weight below the water table), Biot coefficient, the law (Cc, Cr, e0, or
    Sske, Sskv in 1/m) and the preconsolidation (pfault.physics.soil.vertical_preconsolidation's kinds: normal,
    stress, ratio, head)."""
    top: float
    thickness: float
    sigma_top: float
    gradient: float
    cc: float = math.nan
    cr: float = math.nan
    e0: float = math.nan
    sske: float = math.nan
    sskv: float = math.nan
    alpha: float = 1.0
    precon: str = "normal"
    precon_value: float = 0.0

    @property
    def index_form(self) -> bool:
        return not math.isnan(self.cc)

    def slopes(self) -> tuple[float, float]:
        """kappa, lambda of the 1-D law: per ln of sigma'_v (index), per Pa (storage)."""
        if self.index_form:
            return self.cr / ((1 + self.e0) * math.log(10)), self.cc / ((1 + self.e0) * math.log(10))
        return self.sske / (self.alpha * GAMMA_W), self.sskv / (self.alpha * GAMMA_W)

    def lines(self, largest: float, current: float) -> dict[str, tuple[float, float]]:
        """The vertical effective stresses as lines a + b zeta in the depth zeta below the layer's top: initial,
        preconsolidation, largest and current (drawdowns ``largest``, ``current`` in m of head)."""
        s0 = (self.sigma_top, self.gradient)
        if self.precon == "normal":
            sc = s0
        elif self.precon == "stress":
            sc = (self.precon_value, 0.0)
        elif self.precon == "ratio":
            sc = (self.precon_value * s0[0], self.precon_value * s0[1])
        else:                                                  # head: the lowest head before, relative, <= 0
            sc = (s0[0] - self.alpha * GAMMA_W * self.precon_value, s0[1])
        k = self.alpha * GAMMA_W
        return {"0": s0, "c": sc, "m": (s0[0] + k * largest, s0[1]), "s": (s0[0] + k * current, s0[1])}


def _value(line: tuple[float, float], z: np.ndarray | float) -> np.ndarray:
    return line[0] + line[1] * np.asarray(z, float)


def mean_log(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """The mean of ln(u) over a segment where u is linear from u1 to u2 (>= 0): (u2 ln u2 - u1 ln u1)/(u2 - u1) - 1."""
    u1, u2 = np.broadcast_arrays(np.asarray(u1, float), np.asarray(u2, float))
    lo, hi = np.minimum(u1, u2), np.maximum(u1, u2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (hi - lo) / lo
        small = t < 1e-4
        f = np.where(small, t / 2 - t * t / 6 + t ** 3 / 12, ((1 + t) * np.log1p(t) - t) / t)
        out = np.where(lo > 0, np.log(lo) + f, np.log(hi) - 1.0)        # lo = 0: u ln u -> 0 at the end
    return out


def breakpoints(layer: Layer, largest: float) -> list[float]:
    """Depths below the top where the largest stress meets the preconsolidation (the integrand's kink)."""
    ln = layer.lines(largest, largest)
    da, db = ln["m"][0] - ln["c"][0], ln["m"][1] - ln["c"][1]
    if db == 0.0:
        return []
    z = -da / db
    return [z] if 0.0 < z < layer.thickness else []


def point_strain(layer: Layer, z: np.ndarray, largest: float, current: float) -> np.ndarray:
    """The vertical strain (compression positive) at depths z below the layer's top."""
    ln = layer.lines(largest, current)
    s0, sc, sm, s = (_value(ln[k], z) for k in ("0", "c", "m", "s"))
    kap, lam = layer.slopes()
    lo, hi = np.minimum(sm, sc), np.maximum(sm, sc)
    if layer.index_form:
        return kap * np.log(lo / s0) + lam * np.log(hi / sc) - kap * np.log(sm / s)
    return kap * (lo - s0) + lam * (hi - sc) - kap * (sm - s)


def layer_settlement(layer: Layer, largest: float, current: float) -> float:
    """The exact integral of point_strain over the layer (m)."""
    edges = [0.0] + breakpoints(layer, largest) + [layer.thickness]
    ln = layer.lines(largest, current)
    kap, lam = layer.slopes()
    total = 0.0
    for z1, z2 in zip(edges[:-1], edges[1:]):
        mid = 0.5 * (z1 + z2)
        m_below = _value(ln["m"], mid) <= _value(ln["c"], mid)
        lo, hi = (ln["m"], ln["c"]) if m_below else (ln["c"], ln["m"])
        if layer.index_form:
            def ml(line):
                return mean_log(_value(line, z1), _value(line, z2))
            mean = kap * (ml(lo) - ml(ln["0"])) + lam * (ml(hi) - ml(ln["c"])) - kap * (ml(ln["m"]) - ml(ln["s"]))
        else:
            mean = (kap * (_value(lo, mid) - _value(ln["0"], mid)) + lam * (_value(hi, mid) - _value(ln["c"], mid))
                    - kap * (_value(ln["m"], mid) - _value(ln["s"], mid)))
        total += float(mean) * (z2 - z1)
    return total


def settlement(layers: list[Layer], drawdowns: np.ndarray) -> np.ndarray:
    """Settlement of the column (m) after each stage of ``drawdowns`` (stages x layers, m of head, positive a drop,
    relative to the initial heads), the exact closed form."""
    dd = np.asarray(drawdowns, float)
    largest = np.maximum.accumulate(np.maximum(dd, 0.0), axis=0)
    return np.array([sum(layer_settlement(ly, largest[k, j], dd[k, j]) for j, ly in enumerate(layers))
                     for k in range(len(dd))])


def pieces(layers: list[Layer], drawdowns: np.ndarray) -> list[tuple[int, float, float]]:
    """(layer, top, bottom) sub-intervals of every layer between the kinks of every stage: where each stage's
    integrand is smooth (Gauss quadrature on them converges exponentially)."""
    dd = np.asarray(drawdowns, float)
    largest = np.maximum.accumulate(np.maximum(dd, 0.0), axis=0)
    out = []
    for j, ly in enumerate(layers):
        cuts = sorted({0.0, ly.thickness, *(z for k in range(len(dd)) for z in breakpoints(ly, largest[k, j]))})
        out += [(j, a, b) for a, b in zip(cuts[:-1], cuts[1:])]
    return out


def gauss_points(layers: list[Layer], drawdowns: np.ndarray, n: int = 24) -> tuple[np.ndarray, ...]:
    """Layer index, depth below the layer's top and weight (m) of n Gauss points on each smooth piece."""
    x, w = np.polynomial.legendre.leggauss(n)
    idx, z, wt = [], [], []
    for j, a, b in pieces(layers, drawdowns):
        idx.append(np.full(n, j))
        z.append(0.5 * (a + b) + 0.5 * (b - a) * x)
        wt.append(0.5 * (b - a) * w)
    return np.concatenate(idx), np.concatenate(z), np.concatenate(wt)


# -- pfault's law along the oedometric path --------------------------------------------------------------------
def points_law(layers: list[Layer], idx: np.ndarray, poisson: float) -> sl.SoilLaw:
    get = {k: np.array([getattr(layers[j], k) for j in idx]) for k in ("cc", "cr", "e0", "sske", "sskv", "alpha")}
    form = np.array([layers[j].index_form for j in idx])
    nu = np.full(len(idx), poisson)
    a = sl.index_law(np.where(form, get["cc"], 1.0), np.where(form, get["cr"], 0.1), np.where(form, get["e0"], 1.0),
                     nu)
    b = sl.storage_law(np.where(form, 1.0, get["sske"]), np.where(form, 2.0, get["sskv"]), nu, get["alpha"], GAMMA_W)
    return sl.SoilLaw(form, np.where(form, a.kappa, b.kappa), np.where(form, a.lam, b.lam), nu)


def kernel_settlement(layers: list[Layer], drawdowns: np.ndarray, poisson: float = 0.3, substeps: int = 1,
                      n: int = 24) -> np.ndarray:
    """Settlement after each stage from pfault's soil law at Gauss points, each stage in ``substeps`` equal steps of
    the vertical effective stress, each step solved for its vertical strain by Newton on the law's tangent."""
    dd = np.asarray(drawdowns, float)
    idx, z, w = gauss_points(layers, dd, n)
    law = points_law(layers, idx, poisson)
    sv0 = np.array([_value(layers[j].lines(0, 0)["0"], zz) for j, zz in zip(idx, z)])
    svc = np.array([_value(layers[j].lines(0, 0)["c"], zz) for j, zz in zip(idx, z)])
    k0 = poisson / (1 - poisson)
    stress0 = np.zeros((len(idx), 3, 3))
    stress0[:, 0, 0] = stress0[:, 1, 1] = -k0 * sv0
    stress0[:, 2, 2] = -sv0
    hist = sl.initial_history(law, stress0, svc)
    alpha = np.array([layers[j].alpha for j in idx])
    eps, out, prev = np.zeros(len(idx)), [], np.zeros(len(layers))
    for stage in dd:
        for k in range(1, substeps + 1):
            target = sv0 + alpha * GAMMA_W * (prev + (stage - prev) * k / substeps)[idx]
            hist, de = _oedometric_step(law, hist, target)
            eps += de
        prev = stage
        out.append(float(np.sum(w * eps)))
    return np.array(out)


def _oedometric_step(law: sl.SoilLaw, hist: sl.SoilHistory, target: np.ndarray) -> tuple[sl.SoilHistory, np.ndarray]:
    """The vertical strain increment (compression positive) that brings sigma'_v to ``target`` under lateral
    confinement, by Newton on the step map; the new history."""
    de = np.zeros(len(target))
    for _ in range(50):
        d = np.zeros((len(de), 3, 3))
        d[:, 2, 2] = -de
        new, _, (a, mu) = sl.update(law, hist, d, tangent=True)
        res = -new.stress[:, 2, 2] - target
        if np.all(np.abs(res) <= 1e-13 * np.abs(target)):
            return new, de
        de = de - res / (a[:, 2, 2] + 4.0 / 3.0 * mu)          # d sigma'_v / d eps_v = D_zzzz on this path
    raise RuntimeError("oedometric step did not converge")


# -- MODFLOW 6 CSUB's no-delay interbeds --------------------------------------------------------------------------
def csub_nodelay(es_path: np.ndarray, es_start: np.ndarray, pcs: np.ndarray, ssv_cc: np.ndarray, sse_cr: np.ndarray,
                 void_ratio: np.ndarray, thickness: np.ndarray, storage: str = "current") -> np.ndarray:
    """Cumulative compaction (m) of no-delay interbeds after each step of effective stresses ``es_path`` (steps x
    interbeds, m of water), from ``es_start`` with preconsolidation ``pcs`` (m). ``storage``: ``head`` (HEAD_BASED,
    ssv_cc / sse_cr are Sskv / Sske in 1/m), or with compression indices ``current`` (MODFLOW 6's default: the storage
    at the step's new effective stress), ``previous`` (EFFECTIVE_STRESS_LAG), ``equivalent`` (at the logarithmic
    mean of each branch's end stresses: exact)."""
    es0, pc = np.array(es_start, float), np.array(pcs, float)
    comp, out = np.zeros_like(es0), []
    for es in np.asarray(es_path, float):
        virgin = es > pc
        top = np.where(virgin, pc, es)                       # the elastic part runs es0 -> top, the virgin pc -> es
        if storage == "head":
            f_e = f_v = 1.0
            ci, rci = ssv_cc, sse_cr
        else:
            ci, rci = DLOG10ES * ssv_cc, DLOG10ES * sse_cr
            if storage == "equivalent":
                f_e, f_v = 1 / ((1 + void_ratio) * _log_mean(es0, top)), 1 / ((1 + void_ratio) * _log_mean(pc, es))
            else:
                f_e = f_v = 1 / ((1 + void_ratio) * (es if storage == "current" else es0))
        comp = comp + thickness * (rci * f_e * (top - es0) + np.where(virgin, ci * f_v * (es - pc), 0.0))
        pc, es0 = np.maximum(pc, es), es
        out.append(comp.copy())
    return np.array(out)


def _log_mean(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        lm = (b - a) / np.log(b / a)
    return np.where(np.abs(b - a) > 1e-12 * np.abs(a), lm, a)


def csub_settlement(layers: list[Layer], drawdowns: np.ndarray, storage: str, steps: int = 1,
                    n: int = 24) -> np.ndarray:
    """Settlement after each stage from CSUB no-delay interbeds at the Gauss points (thickness = weight), each stage
    in ``steps`` time steps of linear head change; ``storage`` as csub_nodelay. With compression indices the
    interbeds' effective stress is pfault's in metres of water, sigma'/gamma_w (a drawdown h adds alpha h); HEAD_BASED
    (``head``, storage layers) works on the heads themselves: es = h, the preconsolidation
    (sigma'_c - sigma'_0) / (alpha gamma_w) metres of drawdown."""
    dd = np.asarray(drawdowns, float)
    idx, z, w = gauss_points(layers, dd, n)
    lines = [layers[j].lines(0, 0) for j in idx]
    s0 = np.array([_value(ln["0"], zz) for ln, zz in zip(lines, z)]) / GAMMA_W
    sc = np.array([_value(ln["c"], zz) for ln, zz in zip(lines, z)]) / GAMMA_W
    alpha = np.array([layers[j].alpha for j in idx])
    head = storage == "head"
    es0, pcs, scale = (np.zeros_like(s0), (sc - s0) / alpha, np.ones_like(s0)) if head else (s0, sc, alpha)
    ssv = np.array([getattr(layers[j], "sskv" if head else "cc") for j in idx])
    sse = np.array([getattr(layers[j], "sske" if head else "cr") for j in idx])
    e0 = np.array([layers[j].e0 for j in idx])
    heads = [np.zeros(len(layers))] + list(dd)
    path = [es0 + scale * (h0 + (h1 - h0) * k / steps)[idx] for h0, h1 in zip(heads[:-1], heads[1:])
            for k in range(1, steps + 1)]
    comp = csub_nodelay(np.array(path), es0, pcs, ssv, sse, e0, w, storage)
    return comp[steps - 1::steps].sum(axis=1)


# -- the example column ----------------------------------------------------------------------------------------
def example_column(storage: bool = False) -> tuple[list[Layer], np.ndarray]:
    """Clay over sand over clay under a 2 m dry crust (water table 2 m deep), Wuxi-like unit weights (saturated
    19.6 kN/m^3, buoyant 9.8 kN/m^3); the upper clay overconsolidated (OCR 1.3), the lower clay preconsolidated 3 m
    below the initial heads, the sand normally consolidated. Stages (m of drawdown, sands / clays): loading past the
    preconsolidation, unloading, reloading past the earlier maximum, partial recovery."""
    g = 9.8e3
    top = 2 * 17.0e3                                        # 2 m of dry crust
    if storage:
        clay1 = dict(sske=3e-5, sskv=6e-4)
        sand = dict(sske=5e-6, sskv=2e-5)
        clay2 = dict(sske=2e-5, sskv=4e-4)
    else:
        clay1 = dict(cc=0.35, cr=0.05, e0=0.95)
        sand = dict(cc=0.05, cr=0.01, e0=0.75)
        clay2 = dict(cc=0.25, cr=0.04, e0=0.80)
    layers = [Layer(2.0, 18.0, top, g, precon="ratio", precon_value=1.3, **clay1),
              Layer(20.0, 30.0, top + 18 * g, g, **sand),
              Layer(50.0, 30.0, top + 48 * g, g, alpha=0.95, precon="head", precon_value=-3.0, **clay2)]
    clays = np.array([4.0, 10.0, 3.0, 14.0, 8.0])
    sands = np.array([8.0, 20.0, 6.0, 28.0, 16.0])
    return layers, np.column_stack([clays, sands, clays])


def main() -> None:
    layers, dd = example_column()
    exact = settlement(layers, dd)
    kern = kernel_settlement(layers, dd)
    eq = csub_settlement(layers, dd, "equivalent")
    print("stage  drawdown clay/sand (m)  closed form (m)  pfault law rel.err  CSUB equivalent rel.err  "
          "CSUB MODFLOW 6 rel.err at 1 / 10 / 100 steps per stage")
    mf = [csub_settlement(layers, dd, "current", steps) for steps in (1, 10, 100)]
    for k in range(len(dd)):
        errs = " / ".join(f"{abs(m[k] / exact[k] - 1):.2e}" for m in mf)
        print(f"{k + 1:5d}  {dd[k, 0]:5.1f} / {dd[k, 1]:5.1f}          {exact[k]:.6f}        "
              f"{abs(kern[k] / exact[k] - 1):.1e}              {abs(eq[k] / exact[k] - 1):.1e}            {errs}")
    sl_, ds = example_column(storage=True)
    ex, ke, hb = settlement(sl_, ds), kernel_settlement(sl_, ds), csub_settlement(sl_, ds, "head")
    print("storage form (HEAD_BASED): closed form " + ", ".join(f"{v:.5f}" for v in ex) + " m; largest rel. error "
          f"pfault law {np.max(np.abs(ke / ex - 1)):.1e}, CSUB {np.max(np.abs(hb / ex - 1)):.1e}")


if __name__ == "__main__":
    main()

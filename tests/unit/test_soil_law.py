"""The soil law with memory (pfault.physics.soil): the 1-D compression-index law under oedometric strain on loading,
unloading and reloading, independent of the step count; the consistent tangent by a Taylor test (second order) and
by finite differences, with cells on both branches and at the switch; continuity of the stress at the switch (where
a hypoelastic law with a branch-dependent shear modulus jumps); the elastic and plastic parts of the strain; the
initial state from each form of the preconsolidation."""

import numpy as np
import pytest

from pfault.physics import soil as sl

RNG = np.random.default_rng(11)


@pytest.fixture(autouse=True)
def seeded():
    """Every test draws from the same seed, whichever tests ran before it in this process (the suite's workers
    share the tests out in another order)."""
    global RNG
    RNG = np.random.default_rng(11)
NU = 0.3
K0 = NU / (1 - NU)
GAMMA_W = 9806.65


def geostatic(sv0, k0=K0):
    """Initial effective stresses (n,3,3, tension positive) at vertical effective stresses sv0 (compression
    positive)."""
    sv0 = np.atleast_1d(np.asarray(sv0, float))
    out = np.zeros((len(sv0), 3, 3))
    out[:, 0, 0] = out[:, 1, 1] = -k0 * sv0
    out[:, 2, 2] = -sv0
    return out


def uniaxial(deps):
    """Oedometric strain increments (n,3,3): eps_zz = -deps (deps > 0 compresses)."""
    d = np.zeros((len(deps), 3, 3))
    d[:, 2, 2] = -np.asarray(deps, float)
    return d


def index_laws(n):
    return sl.index_law(RNG.uniform(0.2, 0.6, n), RNG.uniform(0.02, 0.08, n), RNG.uniform(0.6, 1.2, n), np.full(n, NU))


def mixed_laws(n):
    """Half the cells with compression indices, half with CSUB storage."""
    idx = index_laws(n - n // 2)
    sto = sl.storage_law(RNG.uniform(1e-5, 3e-5, n // 2), RNG.uniform(2e-4, 6e-4, n // 2), np.full(n // 2, NU),
                         np.ones(n // 2), GAMMA_W)
    return sl.concatenate([idx, sto])


def index_law_vertical(law, sv0, svc, path):
    """sigma'_v after each oedometric strain in ``path`` (compression positive, from the initial state) by the 1-D
    index law, eps = C/(1+e0) log10 of the stress ratio on each branch (and its linear analogue for storage), with the
    running maximum of the strain as memory."""
    idx = law.index_form
    c = law.oedometric_ratio
    kap, lam = np.where(idx, law.kappa, law.kappa * c), np.where(idx, law.lam, law.lam * c)   # per ln or per Pa of s'_v
    ratio_or_step = (lambda s, e, k: s * np.exp(e / k)) , (lambda s, e, k: s + e / k)

    def along(s, e, k):
        return np.where(idx, ratio_or_step[0](s, np.where(idx, e, 0.0), k), ratio_or_step[1](s, e, k))

    e1 = np.where(idx, kap * np.log(svc / sv0), kap * (svc - sv0))             # strain that reaches sigma'_vc
    emax, out = np.zeros_like(sv0), []
    for e in path:
        emax = np.maximum(emax, e)
        smax = np.where(emax <= e1, along(sv0, emax, kap), along(svc, emax - e1, lam))
        out.append(along(smax, e - emax, kap))
    return np.array(out)


def drive(law, hist, path, steps):
    """The law driven through the oedometric strains of ``path`` (compression positive, cumulative), each leg cut into
    ``steps`` equal steps; sigma'_v (compression positive) and the history after each leg."""
    out, hists, prev = [], [], 0.0
    for e in path:
        for _ in range(steps):
            hist, _, _ = sl.update(law, hist, uniaxial(np.full(len(law), (e - prev) / steps)))
        prev = e
        out.append(-hist.stress[:, 2, 2].copy())
        hists.append(hist)
    return np.array(out), hists


def test_oedometric_path_is_the_index_law_whatever_the_steps():
    """Loading past the preconsolidation, unloading, reloading past the earlier maximum: sigma'_v equals the 1-D
    compression-index law (and its storage analogue) to round-off, with 1, 3 or 40 steps per leg; the horizontal
    stress stays at K0 = nu/(1-nu)."""
    n = 40
    law = mixed_laws(n)
    sv0 = RNG.uniform(50e3, 400e3, n)
    svc = sv0 * RNG.uniform(1.0, 2.0, n)
    hist = sl.initial_history(law, geostatic(sv0), svc)
    path = [np.where(law.index_form, a, b) for a, b in                 # load, unload twice, reload past the maximum
            ((0.01, 5e-4), (0.06, 3e-3), (0.045, 2.95e-3), (0.04, 2.9e-3), (0.09, 4e-3))]
    exact = index_law_vertical(law, sv0, svc, path)
    assert np.all(exact > 0.05 * sv0) and np.all(exact[1] > svc) and np.all(exact[-1] > exact[1])
    for steps in (1, 3, 40):
        got, hists = drive(law, hist, [np.asarray(p) for p in path], steps)
        assert np.abs(got / exact - 1).max() < 1e-11, steps
        h = hists[-1].stress
        assert np.abs(h[:, 0, 0] / h[:, 2, 2] - K0).max() < 1e-12
        assert np.abs(h[:, 0, 1]).max() == 0.0


def test_plastic_and_elastic_strain_on_the_oedometric_path():
    """After loading past the preconsolidation and unloading: the plastic vertical strain is (lambda - kappa)
    ln(p'_c/p'_c0), the plastic strain uniaxial (no horizontal part), and the rest kappa ln(p'/p'_0)."""
    n = 12
    law = index_laws(n)
    sv0 = RNG.uniform(50e3, 300e3, n)
    hist0 = sl.initial_history(law, geostatic(sv0), 1.3 * sv0)
    _, hists = drive(law, hist0, [np.full(n, 0.08), np.full(n, 0.05)], 4)
    h = hists[-1]
    ep = -h.plastic_strain[:, 2, 2]
    assert np.allclose(ep, (law.lam - law.kappa) * np.log(h.preconsolidation / hist0.preconsolidation), rtol=1e-12)
    assert np.abs(h.plastic_strain[:, :2, :2]).max() < 1e-15
    elastic = 0.05 - ep
    assert np.allclose(elastic, law.kappa * np.log(sl.mean_stress(h.stress) / sl.mean_stress(hist0.stress)),
                       rtol=1e-12)


def test_elastic_cycle_closes():
    """A strain increment and its reverse inside the elastic range give back the stress exactly (a seasonal cycle
    below the preconsolidation leaves no residual), in any direction of strain."""
    n = 30
    law = mixed_laws(n)
    sv0 = RNG.uniform(50e3, 300e3, n)
    hist = sl.initial_history(law, geostatic(sv0), 3.0 * sv0)
    d = RNG.normal(size=(n, 3, 3)) * 1e-4
    d = 0.5 * (d + d.transpose(0, 2, 1))
    h1, b1, _ = sl.update(law, hist, d)
    h2, b2, _ = sl.update(law, h1, -d)
    assert np.all(b1 == sl.ELASTIC) and np.all(b2 == sl.ELASTIC)
    assert np.abs(h2.stress - hist.stress).max() < 1e-9 * np.abs(hist.stress).max()


def test_on_the_cap_without_volumetric_strain_is_elastic():
    """After a virgin step the cell is on its cap (p'_c = p' up to the round-off of the trace); a zero increment, or
    one without volumetric part, starts on the elastic (stiffer) branch: a Newton iteration from zero then does not take
    the soft virgin tangent into an unloading step."""
    law = index_laws(8)
    sv0 = RNG.uniform(50e3, 300e3, 8)
    hist, branch, _ = sl.update(law, sl.initial_history(law, geostatic(sv0), sv0), uniaxial(np.full(8, 0.03)))
    assert np.all(branch == sl.VIRGIN)
    dev = np.zeros((8, 3, 3))
    dev[:, 0, 0], dev[:, 1, 1], dev[:, 0, 1], dev[:, 1, 0] = 1e-3, -1e-3, 5e-4, 5e-4     # trace exactly zero
    for d in (np.zeros((8, 3, 3)), dev):
        _, branch, _ = sl.update(law, hist, d)
        assert np.all(branch == sl.ELASTIC)


# -- the tangent ----------------------------------------------------------------------------------------------
def states(n):
    """Cells on every branch, each away from the kink x = 0 by more than the perturbations: elastic inside the cap
    (unloading and reloading), on the cap and unloading, on the cap and loading (virgin), and crossing from inside the
    cap to the virgin line within the step; random deviatoric increments and initial shear; both forms."""
    law = mixed_laws(n)
    sv0 = RNG.uniform(50e3, 300e3, n)
    stress0 = geostatic(sv0, RNG.uniform(0.4, 0.8, n))
    shear = RNG.normal(size=(n, 3, 3)) * 5e3
    stress0 = stress0 + 0.5 * (shear + shear.transpose(0, 2, 1))
    kind = np.arange(n) % 4                  # 0 inside, 1 on the cap unloading, 2 on the cap loading, 3 crossing
    ocr = np.where((kind == 1) | (kind == 2), 1.0, RNG.uniform(1.2, 1.5, n))
    hist = sl.initial_history(law, stress0, -stress0[:, 2, 2] * ocr)
    p0 = sl.mean_stress(stress0)
    eps1 = np.where(law.index_form, law.kappa * np.log(hist.preconsolidation / p0),
                    law.kappa * (hist.preconsolidation - p0))
    dev = RNG.normal(size=(n, 3, 3)) * 2e-3
    dev = sl.deviator(0.5 * (dev + dev.transpose(0, 2, 1)))
    size = np.where(law.index_form, 1.0, 0.2)
    vol = np.select([kind == 0, kind == 1, kind == 2], [0.5 * eps1, -0.01 * size, 0.02 * size],
                    eps1 + 0.02 * size)
    d = dev * size[:, None, None] - (vol / 3)[:, None, None] * np.eye(3)
    return law, hist, d, kind


def test_branches_of_the_sample():
    law, hist, d, kind = states(64)
    _, branch, _ = sl.update(law, hist, d)
    assert np.array_equal(branch == sl.VIRGIN, kind >= 2)


def test_taylor_second_order():
    """|sigma(d + h w) - sigma(d) - h D w| falls as h^2 (rate 2.00 +- 0.05 over h = 1e-2 ... 1e-4 of the increment) in
    every cell: elastic, on the cap unloading, virgin, crossing the switch within the step, both forms. The elastic
    cells of the storage form are linear: their remainder is round-off."""
    law, hist, d, kind = states(64)
    w = RNG.normal(size=d.shape)
    w = 0.5 * (w + w.transpose(0, 2, 1)) * np.abs(d).max(axis=(1, 2))[:, None, None]
    h0, branch, (a, mu) = sl.update(law, hist, d, tangent=True)
    dw = np.einsum("nijkl,nkl->nij", sl.tangent_tensor(a, mu), w)
    hs = np.array([1e-2, 1e-3, 1e-4])
    err = np.array([np.linalg.norm(sl.update(law, hist, d + h * w)[0].stress - h0.stress - h * dw, axis=(1, 2))
                    for h in hs])
    linear = ~law.index_form & (branch == sl.ELASTIC)
    assert np.all(err[:, linear] < 1e-9 * np.linalg.norm(dw[linear], axis=(1, 2)))
    rate = np.log(err[:-1, ~linear] / err[1:, ~linear]) / np.log(hs[:-1] / hs[1:])[:, None]
    assert np.all(np.abs(rate - 2.0) < 0.05), (rate.min(), rate.max())
    for k in range(4):                                           # every kind of cell, of both forms, is in the sample
        assert np.sum((kind == k) & law.index_form) >= 6 and np.sum((kind == k) & ~law.index_form) >= 6


def test_tangent_against_finite_differences():
    """The tangent applied to each symmetric unit strain against central differences of the step map: within 1e-6
    of the tangent's size in every cell."""
    law, hist, d, _ = states(48)
    _, _, (a, mu) = sl.update(law, hist, d, tangent=True)
    full = sl.tangent_tensor(a, mu)
    scale = np.abs(full).max(axis=(1, 2, 3, 4))
    h = 1e-8
    for k in range(3):
        for m in range(k, 3):
            e = np.zeros((3, 3))
            e[k, m] = e[m, k] = 1.0
            num = (sl.update(law, hist, d + h * e)[0].stress - sl.update(law, hist, d - h * e)[0].stress) / (2 * h)
            ana = np.einsum("nijkl,kl->nij", full, e)
            assert np.all(np.abs(num - ana).max(axis=(1, 2)) < 1e-6 * scale), (k, m)


def hypoelastic_bilinear(law, hist, d):
    """The alternative this law avoids: tangent bulk and shear moduli K = p'/C, G = r K with C = lambda on loading at
    the cap (d eps_v > 0) and kappa otherwise, integrated in closed form for a cell starting on the cap."""
    p_n = sl.mean_stress(hist.stress)
    deps_v = -np.trace(d, axis1=1, axis2=2)
    c = np.where(deps_v > 0, law.lam, law.kappa)
    p = p_n * np.exp(deps_v / c)
    s = sl.deviator(hist.stress) + (2 * law.shear_ratio * (p - p_n) / deps_v)[:, None, None] * sl.deviator(d)
    return s - p[:, None, None] * np.eye(3)


def test_stress_is_continuous_at_the_switch():
    """A cell on its cap under a deviatoric strain and a volumetric strain -t or +t: the stress difference across the
    switch vanishes with t (Lipschitz, about 2 K t) here; the hypoelastic law with a branch-dependent shear modulus
    jumps by 2 (G_r - G_c) |d e| however small t."""
    law = sl.index_law([0.4], [0.05], [0.9], [NU])
    hist = sl.initial_history(law, geostatic([200e3]), [200e3])
    dev = sl.deviator(np.array([[[1e-3, 2e-4, 0.0], [2e-4, -4e-4, 0.0], [0.0, 0.0, -6e-4]]]))
    jumps, jumps_bilinear = [], []
    for t in (1e-6, 1e-9, 1e-12):
        up, down = dev - t / 3 * np.eye(3), dev + t / 3 * np.eye(3)       # d eps_v = +t (loading) and -t
        su, bu, _ = sl.update(law, hist, up)
        sd, bd, _ = sl.update(law, hist, down)
        assert bu[0] == sl.VIRGIN and bd[0] == sl.ELASTIC
        jumps.append(np.abs(su.stress - sd.stress).max())
        jumps_bilinear.append(np.abs(hypoelastic_bilinear(law, hist, up) - hypoelastic_bilinear(law, hist, down)).max())
    k_r = 200e3 * (1 + 2 * K0) / 3 / law.kappa[0]
    assert jumps[0] < 4 * k_r * 1e-6 and jumps[-1] < 1e-3          # Pa
    g_jump = 2 * law.shear_ratio[0] * k_r * (1 - law.kappa[0] / law.lam[0]) * np.abs(dev).max()
    assert min(jumps_bilinear) > 0.9 * g_jump > 1e3                 # a jump of kPa that does not shrink


# -- the initial state ----------------------------------------------------------------------------------------
def test_initial_preconsolidation_from_each_form():
    """sigma'_vc from a stress, a ratio or a head; p'_c is where oedometric reloading reaches it (K0 = nu/(1-nu):
    p'_c = sigma'_vc (1+nu)/(3(1-nu))); the head margin of a cell preconsolidated 5 m below its initial head is 5 m
    (alpha = 0.9), and an OCR below 1 or a cell without initial stress cannot start."""
    law = sl.index_law(np.full(4, 0.3), np.full(4, 0.03), np.full(4, 0.8), np.full(4, NU))
    sv0 = np.array([100e3, 200e3, 300e3, 50e3])
    st = geostatic(sv0)
    assert np.allclose(sl.vertical_preconsolidation("ratio", 1.5, sv0), 1.5 * sv0)
    assert np.allclose(sl.vertical_preconsolidation("stress", 4e5, sv0), 4e5)
    svc = sl.vertical_preconsolidation("head", -5.0, sv0, 0.9, GAMMA_W)
    assert np.allclose(svc - sv0, 0.9 * GAMMA_W * 5.0)
    hist = sl.initial_history(law, st, svc)
    assert np.allclose(hist.preconsolidation, svc * (1 + NU) / (3 * (1 - NU)), rtol=1e-13)
    assert np.allclose(sl.head_margin(law, hist, 0.9, GAMMA_W), 5.0, rtol=1e-12)
    normal = sl.initial_history(law, st, sl.vertical_preconsolidation("normal", None, sv0))
    assert np.allclose(sl.vertical_margin(law, normal), 0.0, atol=1e-9)
    bad = sl.below_initial(law, np.concatenate([st[:3], np.zeros((1, 3, 3))]), np.array([0.9, 1.0, 1.2, 1.0]) * sv0)
    assert bad.tolist() == [True, False, False, True]

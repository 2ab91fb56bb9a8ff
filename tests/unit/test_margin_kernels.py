"""The margin to failure of a stuck face (pfault.faults.margins), serial NumPy: the closed form (a quadratic per
linear piece of the traction's path) against brute force, the path sampled and the first exit bisected."""

import numpy as np
import pytest

from pfault.faults import margins as fm

TAN30 = np.tan(np.radians(30.0))


def surface(n, cohesion, tan_phi, cutoff, broken=True):
    full = lambda v: np.broadcast_to(np.asarray(v, float), (n,)).copy()       # noqa: E731
    b = np.broadcast_to(np.asarray(broken), (n,))
    return fm.FailureSurface(full(cohesion), full(tan_phi), full(cutoff), np.where(b, fm.SLIP, fm.BREAK),
                             np.where(b, fm.OPEN, fm.BREAK))


def excess(t, s):
    """How far tractions t (k, nf, 3) lie outside the surfaces s (Pa; <= 0 inside)."""
    cone = np.linalg.norm(t[..., 1:], axis=-1) - (s.cohesion - s.tan_phi * t[..., 0])
    return np.maximum(cone, t[..., 0] - s.cutoff)


def brute_force(path, s, lam_max, samples=4001, halvings=60):
    """The first lam in [0, lam_max] at which path(lam) (nf, 3) leaves s: sampled, then bisected (inf: never)."""
    lam = np.linspace(0.0, lam_max, samples)
    e = excess(np.stack([path(v) for v in lam]), s)           # (samples, nf)
    out = e > 0
    first = np.argmax(out, axis=0)
    found = out.any(axis=0)
    lo = lam[np.maximum(first - 1, 0)]
    hi = lam[first]
    for _ in range(halvings):
        mid = 0.5 * (lo + hi)
        em = excess(path(mid)[None], s)[0]
        # per face: the bisection of that face's own path (path(mid) evaluates every face at its own mid)
        hi, lo = np.where(em > 0, mid, hi), np.where(em > 0, lo, mid)
    return np.where(found, np.where(first == 0, 0.0, hi), np.inf)


def per_face_path(t0, r1, lam_dry, r2):
    def path(lam):
        lam = np.broadcast_to(lam, (len(t0),))
        k = np.minimum(lam, lam_dry)
        return t0 + k[:, None] * r1 + np.maximum(lam - lam_dry, 0.0)[:, None] * r2
    return path


def random_faces(rng, n):
    """Faces inside their surfaces: compressed, sheared below their strength, with cohesion or without."""
    c = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(1e4, 2e5, n))
    tan_phi = np.tan(np.radians(rng.uniform(15.0, 40.0, n)))
    tn = -rng.uniform(1e4, 1e6, n)
    tau = (c - tan_phi * tn) * rng.uniform(0.0, 0.95, n)
    ang = rng.uniform(0, 2 * np.pi, n)
    t0 = np.column_stack([tn, tau * np.cos(ang), tau * np.sin(ang)])
    r = rng.normal(size=(n, 3)) * np.array([2e3, 3e3, 3e3])
    return t0, r, c, tan_phi


def test_closed_form_matches_bisection_on_random_straight_paths():
    rng = np.random.default_rng(7)
    n = 400
    t0, r, c, tan_phi = random_faces(rng, n)
    s = surface(n, c, tan_phi, np.where(c > 0, c / tan_phi, 0.0))
    lam, mode = fm.crossing(t0, r, s)
    ref = brute_force(per_face_path(t0, r, np.full(n, np.inf), r), s, 2000.0)
    hit = np.isfinite(ref)
    assert hit.sum() > n // 3 and (~hit).sum() >= 10                   # both kinds are exercised
    np.testing.assert_allclose(lam[hit], ref[hit], rtol=1e-9, atol=1e-9)
    assert np.all(~np.isfinite(lam[~hit]) | (lam[~hit] > 2000.0))       # beyond the sampled range or never
    assert set(np.unique(mode[hit])) <= {fm.SLIP, fm.OPEN}
    assert np.all(mode[~np.isfinite(lam)] == fm.NEVER)


def test_closed_form_matches_bisection_where_the_face_dries_on_the_way():
    """The path turns where the face's pore pressure reaches zero (its own alpha dp/dlam stops)."""
    rng = np.random.default_rng(11)
    n = 300
    t0, r2, c, tan_phi = random_faces(rng, n)
    r1 = r2.copy()
    r1[:, 0] -= rng.uniform(0.0, 9.81e3, n)            # the face's own pore pressure falls while it is wet
    lam_dry = np.where(rng.random(n) < 0.7, rng.uniform(0.0, 300.0, n), np.inf)
    s = surface(n, c, tan_phi, np.where(c > 0, c / tan_phi, 0.0))
    lam, _ = fm.piecewise_crossing(t0, r1, lam_dry, r2, s)
    ref = brute_force(per_face_path(t0, r1, lam_dry, r2), s, 2000.0)
    hit = np.isfinite(ref)
    assert hit.sum() > n // 3
    beyond = hit & np.isfinite(lam_dry) & (ref > lam_dry)
    assert beyond.sum() > 10                           # crossings on the second piece are exercised
    np.testing.assert_allclose(lam[hit], ref[hit], rtol=1e-9, atol=1e-9)


def test_intact_faces_break_at_their_cut_off_below_the_apex():
    """An intact face of a candidate surface breaks in tension at min(T, c / tan(phi)) or in shear, both 'break';
    here a face pulled straight (no shear) reaches T = 50 kPa after (50e3 + 2e5) / 1e3 = 250 m."""
    t0 = np.array([[-2e5, 0.0, 0.0], [-2e5, 0.0, 1e4]])
    r = np.array([[1e3, 0.0, 0.0], [0.0, 0.0, 1e3]])
    s = surface(2, 1e5, TAN30, 5e4, broken=False)
    lam, mode = fm.crossing(t0, r, s)
    assert lam[0] == pytest.approx(250.0, rel=1e-14)
    # shear: 1e4 + 1e3 lam = 1e5 + 2e5 tan(30)
    assert lam[1] == pytest.approx((1e5 + 2e5 * TAN30 - 1e4) / 1e3, rel=1e-12)
    assert list(mode) == [fm.BREAK, fm.BREAK]


def test_a_face_pulled_open_through_the_apex_opens_and_one_unloaded_never_fails():
    """c = 0.1 MPa, phi = 30: apex at c / tan(phi) = 173.2 kPa. Pulled straight from -100 kPa at 1 kPa per metre,
    the cone and the cut-off meet at the apex (a double root): open at 273.2 m. Pressed harder: never (inf)."""
    t0 = np.array([[-1e5, 0.0, 0.0], [-1e5, 0.0, 0.0], [-1e5, 5e4, 0.0]])
    r = np.array([[1e3, 0.0, 0.0], [-1e3, 0.0, 0.0], [-1e3, 0.0, 0.0]])
    s = surface(3, 1e5, TAN30, 1e5 / TAN30)
    lam, mode = fm.crossing(t0, r, s)
    assert lam[0] == pytest.approx(1e5 / TAN30 / 1e3 + 100.0, rel=1e-12)
    assert mode[0] == fm.OPEN
    assert np.isinf(lam[1:]).all() and list(mode[1:]) == [fm.NEVER, fm.NEVER]


def test_a_face_already_outside_has_no_margin():
    t0 = np.array([[-1e5, 2e5, 0.0], [3e5, 0.0, 0.0]])
    s = surface(2, 1e5, TAN30, 1e5 / TAN30)
    lam, mode = fm.crossing(t0, np.zeros((2, 3)), s)
    assert list(lam) == [0.0, 0.0]
    assert list(mode) == [fm.SLIP, fm.OPEN]


def test_the_cells_each_source_draws_down():
    """A uniform further drawdown lowers the cells whose pore pressure the source changes: a table's materials with
    a table that is not zero throughout, every cell of the flow model, the cells of a groundwater model's heads that
    change at some saved time."""
    from pfault.physics.loading import MaterialDrawdown, Table
    from pfault.sources import FlowSource, TableSource
    from pfault.sources.heads import HeadsSource

    tables = MaterialDrawdown([Table((0.0, 1.0), (0.0, -9.8e4)), None, Table((0.0, 1.0), (0.0, 0.0))])
    cells = np.array([0, 1, 2, 0, 2, 1])
    assert list(TableSource(tables, cells).loaded_cells(0.5)) == [True, False, False, True, False, False]
    heads = HeadsSource(np.array([0.0, 10.0]), np.array([[0.0, 0.0, 0.0], [-5.0, 0.0, 3.0]]))
    assert list(heads.loaded_cells(5.0)) == [True, False, True]

    class Flow:
        active, time = True, 0.0

        def cell_dp(self):
            return np.zeros(4)
    assert FlowSource(Flow()).loaded_cells(0.0).tolist() == [True] * 4

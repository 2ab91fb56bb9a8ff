"""The strength of candidate surfaces (pfault.faults.breaking), serial NumPy: the intact strength surface
(Mohr-Coulomb with the cut-off min(T, c / tan(phi))), the relative tolerance of a break, and the cohesion a face's
law takes once broken."""

import numpy as np
import pytest

from pfault.faults import breaking as br
from pfault.faults.settings import FaultSettings


def settings(**kw):
    base = dict(name="f", cohesion=100e3, friction_angle=30.0, method="lagrange", penalty_normal=0.0,
                penalty_tangential=0.0, tensile_strength=50e3, residual_cohesion=20e3)
    base.update(kw)
    return FaultSettings(**base)


def strength(*faults, n=None):
    fault = np.arange(len(faults)) if n is None else np.zeros(n, np.int64)
    return br.face_strength(list(faults), fault)


TAN = np.tan(np.radians(30.0))


def test_cut_off_is_the_tensile_strength_or_the_apex():
    s = strength(settings(), settings(cohesion=10e3, residual_cohesion=5e3), settings(friction_angle=0.0), settings(tensile_strength=0.0))
    assert s.cutoff[0] == 50e3                               # T below the apex c / tan(phi) = 173 kPa
    assert s.cutoff[1] == pytest.approx(10e3 / TAN, rel=1e-15)   # the apex, 17.3 kPa, below T
    assert s.cutoff[2] == 50e3                               # phi = 0: no apex
    assert list(s.candidate) == [True, True, True, False]
    assert list(s.initially_broken()) == [False, False, False, True]
    # broken: the residual cohesion on a candidate surface, the cohesion on a pre-existing fault
    assert list(s.law_cohesion(np.ones(4, bool))) == [20e3, 5e3, 20e3, 100e3]
    assert list(s.law_cohesion(np.zeros(4, bool))) == [100e3, 10e3, 100e3, 100e3]


@pytest.mark.parametrize("direction", ["tension", "shear"])
def test_a_face_breaks_beyond_its_strength_by_more_than_the_tolerance(direction):
    s = strength(settings(), n=4)
    f = np.array([1 - 1e-8, 1 - 1e-12, 1 + 1e-12, 1 + 1e-8])
    t = np.zeros((4, 3))
    if direction == "tension":
        t[:, 0] = 50e3 * f
    else:                                   # at t_N = -100 kPa: |t_T| <= c + 100 kPa tan(phi)
        t[:, 0] = -100e3
        t[:, 2] = (100e3 + 100e3 * TAN) * f
    out = br.exceeding(s, t, np.zeros(4, bool))
    assert list(out) == [False, False, False, True]          # within 1e-10 of the strength: intact
    assert not br.exceeding(s, t, np.ones(4, bool)).any()    # a broken face does not break again


def test_a_pre_existing_fault_never_breaks_and_tension_breaks_a_cohesionless_candidate():
    s = strength(settings(tensile_strength=0.0), settings(cohesion=0.0, residual_cohesion=0.0))
    t = np.array([[1e6, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert list(br.exceeding(s, t, s.initially_broken())) == [False, True]
    # compressed and unsheared: inside every strength surface
    assert not br.exceeding(s, np.array([[-1e5, 0, 0], [-1e5, 0, 0]]), np.zeros(2, bool)).any()


def test_margin_changes_at_most_by_its_sensitivity_times_the_traction_error():
    """breaking.margin_sensitivity bounds how far a face's margin moves when each traction component moves by at
    most e (max norm): sampled on tractions in tension, shear and compression, the worst ratio reaches the bound
    within 2 % and never passes it."""
    rng = np.random.default_rng(7)
    s = strength(settings(), n=4000)
    t = rng.normal(0.0, 80e3, (4000, 3))
    e = 5e3
    worst = 0.0
    for _ in range(20):
        d = rng.choice([-e, e], size=t.shape) * rng.uniform(0.0, 1.0, (len(t), 1)) ** 0.1
        change = np.abs(br.margin(s, t + d) - br.margin(s, t))
        worst = max(worst, float(np.max(change / (e * br.margin_sensitivity(s)))))
    assert 0.98 < worst <= 1.0


def test_a_verdict_is_open_where_the_error_can_move_the_traction_across_the_threshold():
    """At tractions known to within e, a face breaks for sure beyond sensitivity x e past its threshold, stays for
    sure short of it by as much, and is open between; with e = 0 the verdicts are exceeding's."""
    s = strength(settings(), n=6)
    e = 100.0
    reach = e * br.margin_sensitivity(s)[0]
    t = np.zeros((6, 3))
    t[:, 0] = 50e3 + np.array([-2.0, -0.5, -1e-3, 1e-3, 0.5, 2.0]) * reach     # around the cut-off T = 50 kPa
    new, undecided = br.verdicts(s, t, np.zeros(6, bool), e)
    assert list(undecided) == [False, True, True, True, True, False]
    assert list(new) == [False, False, False, True, True, True]
    exact, none_open = br.verdicts(s, t, np.zeros(6, bool))
    assert list(exact) == list(br.exceeding(s, t, np.zeros(6, bool))) and not none_open.any()
    # a broken face has no verdict, open or not
    _, undecided = br.verdicts(s, t, np.ones(6, bool), e)
    assert not undecided.any()

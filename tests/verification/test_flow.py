"""Groundwater flow: NumPy kernels (E1, Theis, element matrices, storage, well lines) and the PETSc model
verified against Theis at two mesh levels, at 1 and 2 ranks, with wells on the partition interface."""

import numpy as np
import pytest

from conftest import run_script
from pfault.mesh.box import box_mesh
from pfault.physics import flow as fl

# -- exponential integral and Theis ------------------------------------------------------------------


def test_e1_known_values():
    u = np.array([1.0, 0.01, 10.0])
    ref = np.array([0.21938393439552026, 4.037929576538114, 4.156968929685324e-06])
    assert np.allclose(fl.exp_integral_e1(u), ref, rtol=1e-13, atol=0)


def test_e1_against_quadrature_on_the_whole_range():
    """E1(a) = E1(50) + int_a^50 exp(-s)/s ds, the integral by Gauss-Legendre in t = ln s (1e-13)."""
    a = np.geomspace(1e-12, 40.0, 60)
    t_nodes, w = np.polynomial.legendre.leggauss(30)
    e50 = fl.exp_integral_e1(50.0)
    for ai in a:
        edges = np.linspace(np.log(ai), np.log(50.0), 201)
        mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
        t = mid[:, None] + half[:, None] * t_nodes
        integral = np.sum(half[:, None] * w * np.exp(-np.exp(t)))
        assert abs(fl.exp_integral_e1(ai) - (e50 + integral)) <= 1e-12 * (e50 + integral)
    # the two branches meet at u = 1
    assert abs(fl.exp_integral_e1(1 - 1e-12) / fl.exp_integral_e1(1 + 1e-12) - 1) < 1e-11


def test_theis_matches_cooper_jacob_at_small_u():
    Q, T, S, r, t = 0.02, 1e-3, 1e-4, 5.0, 1e6
    u = r ** 2 * S / (4 * T * t)
    cj = Q / (4 * np.pi * T) * (-fl.EULER_GAMMA - np.log(u) + u)
    assert abs(fl.theis_drawdown(r, t, Q, T, S) / cj - 1) < u ** 2


# -- element matrices and storage --------------------------------------------------------------------


def random_tets(n=50, seed=1):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 4, 3))
    vol = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
    x[vol < 0, 2], x[vol < 0, 3] = x[vol < 0, 3].copy(), x[vol < 0, 2].copy()
    return x


def test_conductivity_matrix():
    x = random_tets()
    grad, vol = fl.tet_geometry(x)
    k = np.linspace(1e-6, 1e-4, len(vol))
    a = fl.conductivity(grad, vol, k)
    assert np.allclose(a, np.transpose(a, (0, 2, 1)))
    assert np.allclose(a.sum(axis=2), 0.0, atol=1e-12 * np.abs(a).max())
    # a linear head c.x: A h = V K g_a . c (the flux through the faces)
    c = np.array([0.3, -1.2, 0.7])
    h = x @ c
    assert np.allclose(np.einsum("nab,nb->na", a, h), (vol * k)[:, None] * (grad @ c))
    assert np.all(np.linalg.eigvalsh(a) > -1e-12 * np.abs(a).max())


def test_consistent_mass_integrates_products_exactly():
    x = random_tets()
    _, vol = fl.tet_geometry(x)
    m = fl.mass(vol, 2.0)
    assert np.allclose(m.sum(axis=(1, 2)), 2.0 * vol)
    # int (c.x)^2 dV = h^T M h / S_s for linear h; quadrature with the degree-2 4-point rule
    c = np.array([0.3, -1.2, 0.7])
    h = x @ c
    A, B = 0.5854101966249685, 0.1381966011250105
    bary = np.full((4, 4), B) + np.eye(4) * (A - B)
    exact = vol * 0.25 * np.sum((np.einsum("qa,nai->nqi", bary, x) @ c) ** 2, axis=1)
    assert np.allclose(np.einsum("na,nab,nb->n", h, m, h) / 2.0, exact)
    lumped = fl.mass(vol, 2.0, lumped=True)
    assert np.allclose(lumped.sum(axis=(1, 2)), 2.0 * vol)


def test_specific_storage_formula():
    e_mod, nu, e, alpha = 1e7, 0.3, 0.7, 0.9
    c_m = (1 + nu) * (1 - 2 * nu) / (e_mod * (1 - nu))
    expected = 1000.0 * 9.80665 * (alpha * c_m + e / (1 + e) * 4.4e-10)
    assert np.isclose(fl.specific_storage(e_mod, nu, e, alpha), expected, rtol=1e-14)
    assert np.isclose(expected, 6.5742e-4, rtol=1e-4)   # by hand: 9806.65 * 6.7038e-8


# -- well lines ------------------------------------------------------------------------------------------

BOX = (120.0, 120.0, 12.0)
AXES = [(33.3, 41.7), (20.0, 40.0), (20.0, 47.0), (47.0, 20.0),      # generic, vertical edge, two faces
        (0.0, 0.0), (120.0, 120.0), (0.0, 120.0), (120.0, 33.0), (33.0, 0.0)]   # outer corners and faces


@pytest.mark.parametrize("xy", AXES)
def test_vertical_line_load_is_exact_for_linear_fields(xy):
    """Some tie-breaking side covers the screen once; the P1 load reproduces the mean of a linear field."""
    mesh = box_mesh(BOX, (6, 6, 3), zs=np.linspace(-12.0, 0.0, 4))
    x = mesh.points[mesh.tets]
    grad, vol = fl.tet_geometry(x)
    zb, zt = -11.0, -1.5
    covered = []
    for side in ((1, 1), (-1, 1), (1, -1), (-1, -1)):
        length, mid = fl.vertical_line_in_tets(grad, vol, x[:, 0], *xy, zb, zt, side)
        covered.append(length.sum())
        if abs(length.sum() - (zt - zb)) < 1e-9:
            break
    else:
        raise AssertionError(f"no side covers the screen: {covered}")
    assert covered[-1] == pytest.approx(zt - zb, rel=1e-12)
    assert np.all((length == 0) | (length > 1e-9))
    load = np.bincount(mesh.tets.ravel(), weights=(length[:, None] * mid).ravel(),
                       minlength=len(mesh.points)) / (zt - zb)
    assert load.sum() == pytest.approx(1.0, rel=1e-13)
    c, c0 = np.array([0.02, -0.05, 0.3]), 4.0
    mean_on_axis = c0 + c[0] * xy[0] + c[1] * xy[1] + c[2] * 0.5 * (zb + zt)
    assert load @ (mesh.points @ c + c0) == pytest.approx(mean_on_axis, rel=1e-12)
    if 0 < xy[0] < BOX[0] and 0 < xy[1] < BOX[1]:
        assert len(covered) == 1  # inside the box the default side always works


# -- the PETSc model -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def theis_serial():
    return run_script("theis.py", ranks=1, args=["24", "48"])


def test_theis_two_levels(theis_serial):
    """Drawdown at 20 m <= r <= 200 m after one day; measured max relative error 1.42 % (n = 24,
    h_min 1.46 m) and 0.43 % (n = 48, h_min 0.68 m), i.e. an error ratio of 3.3 per halving."""
    err = np.array(theis_serial["max_rel_err"])
    assert err[1] <= 0.006
    assert err[0] <= 0.02
    rate = np.log2(err[0] / err[1])
    assert 1.4 < rate < 2.2, err   # two-sided: space O(h^2) dominates, time O(dt) smaller
    assert all(0 < its for its in theis_serial["ksp_its"])


def test_theis_one_and_two_ranks_agree(theis_serial):
    par = run_script("theis.py", ranks=2, args=["24"])
    h1, h2 = np.array(theis_serial["head_serial"]), np.array(par["head_serial"])
    assert h1.min() < -1.0
    assert np.max(np.abs(h1 - h2)) <= 1e-8 * np.max(np.abs(h1))
    assert par["max_rel_err"][0] == pytest.approx(theis_serial["max_rel_err"][0], rel=1e-6)


INTERFACE = ["interface", "-pfault_material_soil_hydraulic_conductivity", "1*m/day",
             "-pfault_flow_well_screen", "-1,-11", "-pfault_flow_well_rate", "0:0,1*day:3*L/s",
             "-pfault_flow_fixed_head_surfaces", "xmin,xmax,ymin,ymax", "-pfault_flow_substeps", "3"]


@pytest.mark.parametrize("ranks", [1, 2])
def test_wells_on_the_partition_interface(ranks):
    """Wells on a vertical edge and in a vertical face shared by the two ranks: each load sums to one and
    equals the serial load; advance_to advances in substeps, repeats and refuses to go back."""
    res = run_script("theis.py", ranks=ranks, args=INTERFACE)
    assert res["load_sum"] == pytest.approx([1.0, 1.0], rel=1e-13)
    assert max(res["load_diff_vs_serial"]) < 1e-14
    assert res["conductivity"] == pytest.approx([1.0 / 86400.0])
    assert res["storage"] == pytest.approx([float(fl.specific_storage(1e7, 0.3, 0.7))], rel=1e-14)
    assert res["rate_at_1day"] == pytest.approx(3e-3)
    assert res["dp_min"] < res["dp_min_half_day"] < 0      # drawdown grows: dp = rho_w g h < 0
    assert res["dp_mean_check"] == 0.0
    assert res["repeat_identical"] and not res["went_back"]
    assert [h["time_s"] for h in res["history"]] == pytest.approx([14400.0 * k for k in range(1, 7)])

"""The geostatic initial stress's kernels (pfault.physics.geostatic): the overburden of a column, exact in layers and
against a quadrature along the vertical on an unstructured mesh; the K0 rule."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from pfault.mesh.box import box_mesh
from pfault.physics import geostatic as gs

G = 9.80665
LAYERS = ((0.0, 10.0, 1800.0), (10.0, 20.0, 2000.0), (20.0, 30.0, 2400.0))     # top, bottom depth (m), density


def weight_above(depth):
    """int rho g dz over the layers from the land surface down to ``depth`` (Pa)."""
    return G * sum(rho * np.clip(depth - a, 0.0, b - a) for a, b, rho in LAYERS)


def test_overburden_of_a_layered_column_is_exact():
    """Three layers of 1800, 2000 and 2400 kg/m^3 (10 m each, 5 m cells, 6 tetrahedra each): the weight above every
    cell's centroid to round-off."""
    mesh = box_mesh((10.0, 10.0, 30.0), (2, 2, 6), ("top", "mid", "bot"), (10.0, 20.0))
    density = np.array([rho for _, _, rho in LAYERS])[mesh.cell_material]
    x = mesh.points[mesh.tets]
    weight = gs.overburden(x, density, G)
    expected = weight_above(-x.mean(axis=1)[:, 2])
    assert np.abs(weight - expected).max() <= 1e-12 * expected.max()
    assert weight.min() > 0 and weight.max() > 0.9 * weight_above(30.0)


def test_overburden_on_an_unstructured_mesh_against_a_quadrature():
    """A Delaunay mesh of 2,000 random points in a 100 m x 100 m x 50 m box, a random density in each cell: at 20
    cells the weight above the centroid against the midpoint rule on 100,000 points of the vertical, each located in
    its cell (the rule's error: a few 1e-6)."""
    rng = np.random.default_rng(3)
    corners = np.array([[x, y, z] for x in (0.0, 100.0) for y in (0.0, 100.0) for z in (-50.0, 0.0)])
    points = np.concatenate([rng.uniform((0.0, 0.0, -50.0), (100.0, 100.0, 0.0), (2000, 3)), corners])
    mesh = Delaunay(points)
    x = points[mesh.simplices]
    density = rng.uniform(1000.0, 3000.0, len(x))
    weight = gs.overburden(x, density, G)
    centroid = x.mean(axis=1)
    for i in rng.choice(len(x), 20, replace=False):
        z = np.linspace(centroid[i, 2], 0.0, 100001)
        mid = np.column_stack([np.full(len(z) - 1, centroid[i, 0]), np.full(len(z) - 1, centroid[i, 1]),
                               0.5 * (z[1:] + z[:-1])])
        quadrature = np.sum(density[mesh.find_simplex(mid)] * G * np.diff(z))
        assert weight[i] == pytest.approx(quadrature, rel=1e-4), i


def test_k0_rule():
    """sigma'_h = K0 sigma'_v with p0 = rho_w g (z_w - z) below the water table (alpha p0 in the effective stress);
    K0 = nu / (1 - nu) of each cell when not given; no shear."""
    sv = np.array([-100e3, -200e3, -50e3])
    z = np.array([-5.0, -10.0, 2.0])                       # the last cell above the water table (z_w = 0)
    alpha, nu = np.array([1.0, 0.5, 1.0]), np.array([0.25, 0.3, 0.2])
    s = gs.k0_stress(sv, z, alpha, nu, -1.0, 1000.0, G, 0.0)
    p0 = 1000.0 * G * np.array([5.0, 10.0, 0.0])
    k0 = nu / (1 - nu)
    assert np.allclose(s[:, 0, 0], k0 * (sv + alpha * p0) - alpha * p0, rtol=1e-15, atol=0)
    assert np.array_equal(s[:, 0, 0], s[:, 1, 1]) and np.array_equal(s[:, 2, 2], sv)
    assert not np.any(s[:, [0, 0, 1], [1, 2, 2]])
    assert np.allclose(gs.k0_stress(sv, z, alpha, nu, 1.0, 1000.0, G, 0.0)[:, 0, 0], sv, rtol=1e-15, atol=0)

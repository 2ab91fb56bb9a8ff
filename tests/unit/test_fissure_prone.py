"""Fissure-prone length and area of the land surface (pfault.io.hazard.fissure_prone) on structured triangle
grids with displacements whose strain is known in closed form (NumPy only)."""

import numpy as np
import pytest

from pfault.io.hazard import fissure_prone


def grid(nx, ny, lx, ly, angle=0.0):
    """Points (k, 3) and triangles of a rectangle [0, lx] x [0, ly] cut in 2 nx ny triangles, rotated by angle."""
    x, y = np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + ny + 1, a + ny + 2, a + 1
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    pts[:, :2] = pts[:, :2] @ rot.T
    return pts, tris, rot


@pytest.mark.parametrize("angle", [0.0, 0.6])
def test_uniform_tension_gives_the_extent_normal_to_it(angle):
    """u = eps x' (tension along the rectangle's long side x', 3 km x 1 km): every triangle is fissure-prone and
    a fissure runs along y', so the length is the 1 km side and the area the rectangle's."""
    pts, tris, rot = grid(30, 10, 3000.0, 1000.0, angle)
    local = pts[:, :2] @ rot
    u = np.zeros_like(pts)
    u[:, :2] = (3e-4 * local[:, :1] * np.array([[1.0, 0.0]])) @ rot.T
    out = fissure_prone(pts, tris, u, 2e-4)
    assert out["fissure_prone_length_m"] == pytest.approx(1000.0, rel=1e-12)
    assert out["fissure_prone_area_m2"] == pytest.approx(3e6, rel=1e-12)
    assert fissure_prone(pts, tris, u, 4e-4) == {"fissure_prone_length_m": 0.0, "fissure_prone_area_m2": 0.0}


def test_a_band_of_tension_gives_its_length():
    """u_x = eps * clamp(x - 1000, 0, 200) over a 4 km x 2 km grid: tension only where 1000 < x < 1200, a band
    along y: 2 km long, 0.2 km wide."""
    pts, tris, _ = grid(40, 20, 4000.0, 2000.0)
    u = np.zeros_like(pts)
    u[:, 0] = 5e-4 * np.clip(pts[:, 0] - 1000.0, 0.0, 200.0)
    out = fissure_prone(pts, tris, u, 2e-4)
    assert out["fissure_prone_length_m"] == pytest.approx(2000.0, rel=1e-12)
    assert out["fissure_prone_area_m2"] == pytest.approx(200.0 * 2000.0, rel=1e-12)


def test_separate_zones_add_each_along_its_own_fissure_direction():
    """Two disjoint surfaces (as on the two sides of a split fault): 3 km x 1 km in tension along x (fissures
    along y: 1 km) and, 10 km away, the same rectangle in tension along y (fissures along x: 3 km)."""
    pa, ta, _ = grid(30, 10, 3000.0, 1000.0)
    pb = pa + [10000.0, 0.0, 0.0]
    ua, ub = np.zeros_like(pa), np.zeros_like(pa)
    ua[:, 0] = 3e-4 * pa[:, 0]
    ub[:, 1] = 3e-4 * pa[:, 1]
    out = fissure_prone(np.concatenate([pa, pb]), np.concatenate([ta, ta + len(pa)]), np.concatenate([ua, ub]),
                        2e-4)
    assert out["fissure_prone_length_m"] == pytest.approx(4000.0, rel=1e-12)
    assert out["fissure_prone_area_m2"] == pytest.approx(6e6, rel=1e-12)


def test_compression_and_pure_tilt_are_not_fissure_prone():
    pts, tris, _ = grid(10, 10, 100.0, 100.0)
    u = np.zeros_like(pts)
    u[:, 0] = -1e-3 * pts[:, 0]
    u[:, 2] = 1e-2 * pts[:, 1]
    assert fissure_prone(pts, tris, u, 1e-6)["fissure_prone_length_m"] == 0.0

"""Fissure-prone length and area of the land surface (pfault.hazard.fissure_prone) on structured triangle
grids with displacements whose strain is known in closed form (NumPy only)."""

import numpy as np
import pytest

from pfault.hazard import fissure_prone


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
    """Two disjoint surfaces: 3 km x 1 km in tension along x (fissures along y: 1 km) and, 10 km away, the same
    rectangle in tension along y (fissures along x: 3 km)."""
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


# A fault trace on the land surface: the output mesh holds every vertex on it twice, once per side (the plus side's
# triangles use the copies, at the same place), and the displacement jumps across it.
LX, LY, X0, WIDTH, EPS = 4000.0, 2000.0, 2000.0, 200.0, 5e-4


def split_grid(angle):
    """The LX x LY grid (40 x 20 cells) rotated by ``angle``, split along the line x' = X0 (a fault trace LY long):
    points (the copies of the trace's vertices appended), triangles (the plus side x' > X0 on the copies), the
    rotation and each point's coordinates x' in the grid's frame."""
    pts, tris, rot = grid(40, 20, LX, LY, angle)
    local = pts[:, :2] @ rot
    on = np.flatnonzero(np.abs(local[:, 0] - X0) < 1e-6)
    plus = local[tris].mean(axis=1)[:, 0] > X0
    copy = np.full(len(pts), -1)
    copy[on] = len(pts) + np.arange(len(on))
    tris = tris.copy()
    tris[plus] = np.where(copy[tris[plus]] >= 0, copy[tris[plus]], tris[plus])
    pts = np.concatenate([pts, pts[on]])
    return pts, tris, rot, np.concatenate([local, local[on]]), plus


def fault_displacement(local, plus_point, rot, minus_band, plus_band):
    """u along x' (rotated back): an opening of 0.1 m across the trace, and tension EPS in a band WIDTH wide
    beside it on the minus side (x' in [X0 - WIDTH, X0]) and/or the plus side ([X0, X0 + WIDTH])."""
    x = local[:, 0]
    ux = np.zeros(len(x))
    if minus_band:
        ux = np.where(plus_point, ux, EPS * np.clip(x - (X0 - WIDTH), 0.0, WIDTH))
    edge = EPS * WIDTH if minus_band else 0.0
    ux = np.where(plus_point, edge + 0.1 + (EPS * np.clip(x - X0, 0.0, WIDTH) if plus_band else 0.0), ux)
    u = np.zeros((len(x), 3))
    u[:, :2] = (ux[:, None] * np.array([[1.0, 0.0]])) @ rot.T
    return u


@pytest.mark.parametrize("angle", [0.0, 0.6])
@pytest.mark.parametrize("minus_band, plus_band", [(True, True), (True, False), (False, True)])
def test_a_band_beside_a_fault_counts_its_trace_once(angle, minus_band, plus_band):
    """A band of tension along a fault trace LY long, on both sides of it or on one: the fissure-prone length is
    the trace's, LY, whichever sides it lies on (the two sides are one zone across the trace); the area is the
    band's. The jump across the trace is not a strain."""
    pts, tris, rot, local, plus = split_grid(angle)
    plus_point = np.zeros(len(pts), bool)
    plus_point[np.unique(tris[plus])] = True
    plus_point[np.unique(tris[~plus])] = False          # the trace's own vertices are the minus side's
    u = fault_displacement(local, plus_point, rot, minus_band, plus_band)
    out = fissure_prone(pts, tris, u, 2e-4)
    assert out["fissure_prone_length_m"] == pytest.approx(LY, rel=1e-12)
    assert out["fissure_prone_area_m2"] == pytest.approx((minus_band + plus_band) * WIDTH * LY, rel=1e-12)


def test_two_separate_bands_add():
    """Two bands of tension along y, 2 km long, 2 km apart, on a surface with a fault trace between them that
    neither touches: two stretches of land surface, 4 km."""
    pts, tris, rot, local, plus = split_grid(0.0)
    x = local[:, 0]
    u = np.zeros((len(pts), 3))
    u[:, 0] = EPS * (np.clip(x - 500.0, 0.0, WIDTH) + np.clip(x - 3000.0, 0.0, WIDTH))
    out = fissure_prone(pts, tris, u, 2e-4)
    assert out["fissure_prone_length_m"] == pytest.approx(2 * LY, rel=1e-12)
    assert out["fissure_prone_area_m2"] == pytest.approx(2 * WIDTH * LY, rel=1e-12)


def test_a_triangle_touching_a_zone_at_a_corner_is_part_of_it():
    """A band of tension 2 km long and one small triangle beyond it that touches the band at one corner only, in
    tension across the band's direction (its own fissure would run 10 m along x): one stretch of land surface,
    2 km; counted apart, it would add its 10 m."""
    pts, tris, _ = grid(40, 20, 4000.0, 2000.0)
    u = np.zeros_like(pts)
    u[:, 0] = 5e-4 * np.clip(pts[:, 0] - 1000.0, 0.0, 200.0)
    band = pts[tris].mean(axis=1)[:, 0] < 1200.0
    corner = int(np.flatnonzero((pts[:, 0] == 1200.0) & (pts[:, 1] == 1000.0))[0])
    extra = pts[corner] + np.array([[10.0, 0.0, 0.0], [10.0, 10.0, 0.0]])
    u_extra = u[corner] + np.array([[0.0, 0.0, 0.0], [0.0, 10.0 * 1e-3, 0.0]])     # strain 1e-3 along y
    points = np.concatenate([pts, extra])
    triangles = np.concatenate([tris[band], [[corner, len(pts), len(pts) + 1]]])
    out = fissure_prone(points, triangles, np.concatenate([u, u_extra]), 2e-4)
    assert out["fissure_prone_area_m2"] == pytest.approx(200.0 * 2000.0 + 50.0, rel=1e-12)
    assert out["fissure_prone_length_m"] == pytest.approx(2000.0, rel=1e-12)

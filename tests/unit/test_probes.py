"""Locating points in the serial mesh (pfault.io.probes): P1 weights, the smallest-id rule on shared faces, the
fault side, and the pixels of a raster over the land surface (NumPy only)."""

import numpy as np
import pytest

from pfault.errors import InputError
from pfault.io.probes import locate_pixels, locate_points, mesh_to_site
from pfault.mesh.box import box_mesh, parse_planes
from pfault.mesh.fault import split_faults


def test_mesh_to_site_adds_the_origin_and_its_inverse_removes_it():
    x = np.array([[1.0, 2.0, -3.0]])
    assert np.array_equal(mesh_to_site(x), x) and np.array_equal(mesh_to_site(x, inverse=True), x)
    origin = (500000.0, 3500000.0, 5.0)
    assert np.array_equal(mesh_to_site(x, origin), [[500001.0, 3500002.0, 2.0]])
    assert np.array_equal(mesh_to_site(x[:, :2], origin), [[500001.0, 3500002.0]])
    assert np.array_equal(mesh_to_site(mesh_to_site(x, origin), origin, inverse=True), x)


def test_stations_and_pixels_in_site_coordinates_follow_the_origin():
    mesh = box_mesh((3.0, 2.0, 1.0), (3, 2, 2))
    origin = (1000.0, 2000.0, 10.0)
    xyz = np.array([[0.7, 1.3, -0.4]])
    here = locate_points(mesh.points, mesh.tets, xyz)
    there = locate_points(mesh.points, mesh.tets, mesh_to_site(mesh_to_site(xyz, origin), origin, inverse=True))
    assert here.cell[0] == there.cell[0] and np.allclose(here.weights, there.weights, atol=1e-12)
    raster, _ = locate_pixels(mesh, "top", 0.5)
    moved, _ = locate_pixels(mesh, "top", 0.5, origin)
    assert np.allclose(np.asarray(moved.x) - np.asarray(raster.x), origin[0])
    assert np.allclose(np.asarray(moved.y) - np.asarray(raster.y), origin[1])


def test_points_get_their_cell_and_p1_weights():
    mesh = box_mesh((3.0, 2.0, 1.0), (3, 2, 2))
    rng = np.random.default_rng(1)
    xyz = rng.uniform([0, 0, -1], [3, 2, 0], size=(20, 3))
    loc = locate_points(mesh.points, mesh.tets, xyz)
    assert (loc.cell >= 0).all() and (loc.weights >= -1e-12).all()
    assert np.allclose(loc.weights.sum(axis=1), 1.0)
    # the weights reproduce the point from its cell's vertices, hence any linear field exactly
    assert np.allclose(np.einsum("nk,nkc->nc", loc.weights, mesh.points[mesh.tets[loc.cell]]), xyz, atol=1e-12)
    out = locate_points(mesh.points, mesh.tets, np.array([[3.5, 1.0, -0.5], [1.0, 1.0, 0.01]]))
    assert (out.cell == -1).all()


def test_a_point_on_shared_faces_takes_the_cell_of_smallest_id():
    mesh = box_mesh((2.0, 2.0, 2.0), (2, 2, 2))
    centre = np.array([[1.0, 1.0, -1.0]])             # a vertex shared by many cells
    loc = locate_points(mesh.points, mesh.tets, centre)
    v = mesh.points[mesh.tets]
    around = np.flatnonzero(np.isclose(v, centre).all(axis=2).any(axis=1))
    assert len(around) > 8 and loc.cell[0] == around.min() and loc.side[0] == 0
    assert np.isclose(loc.weights[0].max(), 1.0)


def test_a_point_on_a_fault_takes_the_side_it_asks_for():
    mesh = box_mesh((2.0, 1.0, 1.0), (4, 2, 2), planes=parse_planes(["fault:x:1"]))
    split = split_faults(mesh, ["fault"])
    xyz = np.array([[1.0, 0.43, -0.57]] * 2 + [[0.4, 0.5, -0.5]])
    loc = locate_points(mesh.points, mesh.tets, xyz, split.vert_sides, split.cell_side,
                        plus=np.array([False, True, True]))
    assert list(loc.side) == [1, 2, 0]                 # minus, plus, off the fault (its request has no effect)
    centroid = mesh.points[mesh.tets[loc.cell]].mean(axis=1)
    assert centroid[0, 0] < 1.0 < centroid[1, 0]       # the plus side of this fault is x > 1
    assert not split.cell_side[loc.cell[0]].any() and split.cell_side[loc.cell[1]].any()


def test_pixels_cover_the_land_surface_and_nothing_else():
    mesh = box_mesh((9.0, 5.0, 2.0), (3, 5, 1))
    raster, loc = locate_pixels(mesh, "top", 4.0)       # pixels aligned on multiples of 4 m
    assert np.array_equal(raster.x, [2.0, 6.0, 10.0]) and np.array_equal(raster.y, [2.0, 6.0])
    assert np.array_equal(raster.inside, [[True, True, False], [False, False, False]])
    # each inside pixel's weights reproduce its centre on the top face (z = 0), with no weight below
    px, py = np.meshgrid(raster.x, raster.y)
    centres = np.column_stack([px[raster.inside], py[raster.inside], np.zeros(raster.inside.sum())])
    assert np.allclose(np.einsum("nk,nkc->nc", loc.weights, mesh.points[mesh.tets[loc.cell]]), centres)
    auto, _ = locate_pixels(mesh, "top", None)         # default: the mean edge length of the surface triangles
    assert 1.5 < auto.x[1] - auto.x[0] < 3.0


def test_a_mesh_without_a_land_surface_has_no_raster():
    mesh = box_mesh((1.0, 1.0, 1.0), (1, 1, 1))
    mesh.surfaces.pop("top", None)
    mesh.points[:, 2] += mesh.points[:, 0] * 1e-3      # no face on the plane z = max z either
    with pytest.raises(InputError, match="no land surface"):
        locate_pixels(mesh, "top", 1.0)


def test_a_pixel_on_shared_edges_takes_the_triangle_of_smallest_cell_id():
    """Pixel centres at the centres of the box's top squares lie on their diagonals: by brute force over the land
    surface's triangles, each takes the smallest cell id among those that hold it."""
    from pfault.io.probes import ground_faces
    from pfault.mesh.serial import TET_FACES
    mesh = box_mesh((4.0, 4.0, 1.0), (2, 2, 1))
    raster, loc = locate_pixels(mesh, "top", 2.0)
    assert raster.inside.all() and len(loc.cell) == 4
    cell, lface = ground_faces(mesh, "top")
    corners = mesh.points[mesh.tets[cell[:, None], TET_FACES[lface]]][:, :, :2]
    px, py = np.meshgrid(raster.x, raster.y)
    for centre, got in zip(np.column_stack([px.ravel(), py.ravel()]), loc.cell):
        a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
        m = np.stack([b - a, c - a], axis=2)
        lam = np.linalg.solve(m, (centre - a)[:, :, None])[:, :, 0]
        holds = (lam >= -1e-12).all(axis=1) & (lam.sum(axis=1) <= 1 + 1e-12)
        assert holds.sum() >= 2 and got == cell[holds].min()

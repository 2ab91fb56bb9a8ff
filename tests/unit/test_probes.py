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


def test_a_raster_larger_than_memory_is_refused_before_it_is_made():
    """1 mm pixels on a 2 km site: 4e12 pixels, refused (exit 5) from the measured bytes a pixel costs against the
    memory available, naming the option, the pixel count and a spacing that fits, which locate_pixels then makes;
    two ranks on the node count the second rank's share. The check comes before any array of the raster: a
    spacing of 1e-300 m (whose pixel count overflows any integer) is refused the same way."""
    from pfault.errors import OutOfMemory
    mesh = box_mesh((2000.0, 2000.0, 100.0), (4, 4, 1))
    mb5 = 5e6                                                               # 5 MB: a small raster, a fast test
    with pytest.raises(OutOfMemory) as err:
        locate_pixels(mesh, "top", 1e-3, memory=mb5)
    assert str(err.value) == (
        "-pfault_insar_spacing 0.001 m: the raster over the land surface (2000 x 2000 m) would have 4e+12 pixels "
        "(2e+06 x 2e+06) and need about 1.6e+06 GB (400 B a pixel with 1 rank on this node), more than the 0.005 GB "
        "of memory available; give a spacing of at least 20 m (e.g. -pfault_insar_spacing 20*m; without the option, "
        "the land surface's mean edge, 569 m)")
    assert (2000 / 20 + 1) ** 2 * 400 <= 5e6 < (2000 / 10 + 1) ** 2 * 400      # 20 m fits, 10 m does not
    raster, _ = locate_pixels(mesh, "top", 20.0, memory=mb5)
    assert raster.inside.shape == (100, 100) and raster.inside.all()
    with pytest.raises(OutOfMemory, match=r"need about 2.6e\+06 GB \(650 B a pixel with 2 ranks on this node\).* at "
                                          r"least 50 m"):
        locate_pixels(mesh, "top", 1e-3, ranks_on_node=2, memory=mb5)
    with pytest.raises(OutOfMemory, match=r"-pfault_insar_spacing 1e-300 m: .* would have inf pixels"):
        locate_pixels(mesh, "top", 1e-300)


@pytest.mark.parametrize("los, message", [
    ([0.61, 0.11, -0.785], "-pfault_insar_los 0.61,0.11,-0.785: the up component is negative, a vector from the "
     "satellite into the ground; pfault takes the east, north, up components of the unit vector from the ground to "
     "the satellite (up positive, LOS positive towards the satellite): give -pfault_insar_los -0.61,-0.11,0.785"),
    ([1.0, 0.0, 0.0], "-pfault_insar_los 1,0,0: the up component is 0 (a satellite looks down, u = cos of the "
     "incidence angle); give the east, north, up components of the unit vector from the ground to the satellite "
     "(e.g. -0.61,-0.11,0.785)"),
    ([1.0, 0.0, 1.0], "-pfault_insar_los 1,0,1: not a unit vector (length 1.414; rounded direction cosines are "
     "within 0.01 of 1 and pfault normalises them); give the east, north, up components of the unit vector from "
     "the ground to the satellite (e.g. -0.61,-0.11,0.785)"),
    ([38.0, 0.0, 1.0], "-pfault_insar_los 38,0,1: not a unit vector (length 38.01;"),
    ([0.6, 0.8], "-pfault_insar_los 0.6,0.8: give three components e,n,u: the east, north, up components of"),
])
def test_line_of_sight_conventions(los, message):
    """pfault's LOS vector goes from the ground to the satellite (up positive); a vector into the ground, a
    horizontal one and one that is not of unit length are errors that say so; rounded cosines are normalised."""
    from pfault.io.insar import check_los
    with pytest.raises(InputError) as err:
        check_los(np.array(los))
    assert str(err.value).startswith(message), err.value
    check_los(np.array([-0.61, -0.11, 0.785]))          # length 0.9995: normalised when read

"""Split-node fault topology (pfault.mesh.fault.split_faults) on structured boxes with planar faults."""

import numpy as np
import pytest

from pfault.errors import InputError
from pfault.mesh.box import box_mesh
from pfault.mesh.fault import copy_index, split_faults, vertex_copies
from pfault.mesh.serial import TET_FACES, boundary_faces, face_keys


def unit_box(n):
    """Unit box [0,1]x[0,1]x[-1,0] with n cells per direction (n even: node planes at 0.5)."""
    return box_mesh((1.0, 1.0, 1.0), (n, n, n))


def grid(mesh, n):
    """Integer grid coordinates (i, j, k) of the nodes; k = 0 at the bottom z=-1, k = n at the top."""
    p = mesh.points.copy()
    p[:, 2] += 1.0
    return np.rint(p * n).astype(np.int64)


def all_faces(mesh):
    """Every distinct face of the mesh, as vertex triples."""
    f = mesh.tets[:, TET_FACES].reshape(-1, 3)
    _, first = np.unique(face_keys(f, len(mesh.points)), return_index=True)
    return f[np.sort(first)]


def add_fault(mesh, n, axis, level, select=None, name="fault"):
    """Faces whose three nodes lie on the grid plane ``axis == level`` and satisfy ``select(g)`` per node."""
    g = grid(mesh, n)
    f = all_faces(mesh)
    on = np.all(g[f, axis] == level, axis=1)
    if select is not None:
        on &= np.all(select(g[f]), axis=1)
    mesh.surfaces[name] = f[on]
    return f[on]


def split_mesh(mesh, fs):
    """Tets renumbered with a vertex id per piece: the vertex itself for piece 0, nv + its copy's index for the
    others (pfault.mesh.fault.vertex_copies, the output mesh's numbering)."""
    nv = len(mesh.points)
    assert np.all(fs.cell_side < fs.vert_sides[mesh.tets])
    copy = nv + copy_index(fs.vert_sides, mesh.tets, np.maximum(fs.cell_side, 1))
    tets = np.where(fs.cell_side > 0, copy, mesh.tets)
    return tets, nv + len(vertex_copies(fs.vert_sides)[0])


def check_split_mesh(mesh, fs, opened):
    """Boundary faces of the split mesh = the old ones plus both sides of every opened fault face."""
    old_c, old_l = boundary_faces(mesh.tets, len(mesh.points))
    tets, nv = split_mesh(mesh, fs)
    new_c, new_l = boundary_faces(tets, nv)
    assert len(new_c) == len(old_c) + 2 * int(opened.sum())
    expected = np.r_[4 * old_c + old_l, 4 * fs.minus_cell[opened] + fs.minus_lface[opened],
                     4 * fs.plus_cell[opened] + fs.plus_lface[opened]]
    assert np.array_equal(np.sort(4 * new_c + new_l), np.sort(expected))
    # the two sides of an opened face carry different vertex ids, the same ones otherwise
    mside = tets[fs.minus_cell[:, None], TET_FACES[fs.minus_lface]]
    pside = tets[fs.plus_cell[:, None], TET_FACES[fs.plus_lface]]
    differ = face_keys(mside, nv) != face_keys(pside, nv)
    assert np.array_equal(differ, opened)


def centroids(mesh, cells):
    return mesh.points[mesh.tets[cells]].mean(axis=1)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_full_plane(axis):
    """(a) A plane through the whole box: every fault vertex splits, minus side below, normal +axis."""
    n = 4
    mesh = unit_box(n)
    tris = add_fault(mesh, n, axis, n // 2)
    fs = split_faults(mesh, ["fault"])
    nf = len(tris)
    assert nf == 2 * n * n
    assert fs.names == ["fault"]
    assert np.array_equal(fs.fault_id, np.zeros(nf))
    g = grid(mesh, n)
    on_plane = np.flatnonzero(g[:, axis] == n // 2)
    assert len(on_plane) == (n + 1) ** 2 == 25
    assert np.array_equal(np.flatnonzero(fs.vert_sides == 2), on_plane)
    assert np.all(fs.vert_sides[g[:, axis] != n // 2] == 1)
    assert fs.tip_vertices.size == 0
    e = np.eye(3)[axis]
    assert np.allclose(fs.normal, e, atol=1e-14)
    assert fs.area.sum() == pytest.approx(1.0, rel=1e-14)
    assert np.allclose(fs.area, 1.0 / (2 * n * n))
    # the faces' own orientation agrees with the normal
    x = mesh.points[fs.faces]
    assert np.all(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]) @ e > 0)
    mid = 0.5 if axis < 2 else -0.5
    assert np.all(centroids(mesh, fs.minus_cell)[:, axis] < mid)
    assert np.all(centroids(mesh, fs.plus_cell)[:, axis] > mid)
    # every cell on the plus side uses side 1 at its plane vertices; nothing else uses side 1
    c = mesh.points[mesh.tets].mean(axis=1)[:, axis]
    at_plane = np.isin(mesh.tets, on_plane)
    assert np.all(fs.cell_side[c < mid] == 0)
    assert np.array_equal(fs.cell_side[c > mid], at_plane[c > mid].astype(np.int64))
    assert int(at_plane[c > mid].sum()) > 0
    assert fs.cell_side.dtype == np.int64 and fs.vert_sides.dtype == np.int64
    check_split_mesh(mesh, fs, np.ones(nf, bool))


def test_deterministic_under_input_order():
    """Shuffling and flipping the input triangles changes nothing but the face order."""
    n = 4
    mesh = unit_box(n)
    tris = add_fault(mesh, n, 0, 2)
    ref = split_faults(mesh, ["fault"])
    rng = np.random.default_rng(1)
    perm = rng.permutation(len(tris))
    shuffled = tris[perm].copy()
    flip = rng.random(len(tris)) < 0.5
    shuffled[flip] = shuffled[flip][:, ::-1]
    mesh.surfaces["fault"] = shuffled
    fs = split_faults(mesh, ["fault"])
    assert np.array_equal(fs.vert_sides, ref.vert_sides)
    assert np.array_equal(fs.cell_side, ref.cell_side)
    assert np.array_equal(fs.minus_cell, ref.minus_cell[perm])
    assert np.array_equal(fs.plus_cell, ref.plus_cell[perm])
    assert np.array_equal(fs.faces, ref.faces[perm])
    assert np.allclose(fs.normal, [1.0, 0.0, 0.0])


def test_partial_fault_from_the_top():
    """(b) Fault on x=0.5 from the land surface down to z=-0.5 across the whole width in y.

    Vertices on the buried lower edge z=-0.5 are tips, including the two points where that edge meets
    the sides y=0 and y=1: their star is a half ball cut by a quarter disc, which stays connected around
    the end of the tip edge. Vertices on y=0, y=1 (above z=-0.5) and on the land surface z=0 split.
    """
    n = 4
    mesh = unit_box(n)
    tris = add_fault(mesh, n, 0, 2, select=lambda g: g[..., 2] >= 2)
    fs = split_faults(mesh, ["fault"])
    nf = len(tris)
    assert nf == 2 * n * (n // 2) == 16
    g = grid(mesh, n)
    fv = np.unique(tris)
    assert len(fv) == 5 * 3
    tips = fv[g[fv, 2] == 2]
    split = fv[g[fv, 2] > 2]
    assert len(tips) == 5 and len(split) == 10
    assert np.array_equal(fs.tip_vertices, np.sort(tips))
    assert np.array_equal(np.flatnonzero(fs.vert_sides == 2), np.sort(split))
    # boundary-edge vertices: the corners of the tip edge are tips, the rest of y=0 / y=1 / z=0 split
    corners = fv[(g[fv, 2] == 2) & np.isin(g[fv, 1], [0, n])]
    assert len(corners) == 2 and np.all(fs.vert_sides[corners] == 1)
    side_edges = fv[(g[fv, 2] > 2) & np.isin(g[fv, 1], [0, n])]
    top_edge = fv[g[fv, 2] == n]
    assert len(side_edges) == 4 and len(top_edge) == 5
    assert np.all(fs.vert_sides[side_edges] == 2) and np.all(fs.vert_sides[top_edge] == 2)
    assert np.allclose(fs.normal, [1.0, 0.0, 0.0])
    assert fs.area.sum() == pytest.approx(0.5, rel=1e-14)
    # plus side (x > 0.5) uses side 1 exactly at split vertices; nothing touches the tips with side 1
    cx = mesh.points[mesh.tets].mean(axis=1)[:, 0]
    at_split = np.isin(mesh.tets, split)
    assert np.all(fs.cell_side[cx < 0.5] == 0)
    assert np.array_equal(fs.cell_side[cx > 0.5], at_split[cx > 0.5].astype(np.int64))
    assert np.all(fs.cell_side[np.isin(mesh.tets, tips)] == 0)
    # every fault face has a split vertex here, so every face opens: 2*nf new boundary faces
    assert np.all((fs.vert_sides[fs.faces] == 2).any(axis=1))
    check_split_mesh(mesh, fs, np.ones(nf, bool))


def test_buried_patch():
    """(d) A square patch x=0.5, 0.25<=y<=0.75, -0.75<=z<=-0.25, away from every boundary."""
    n = 8
    mesh = unit_box(n)
    tris = add_fault(mesh, n, 0, 4, select=lambda g: (g[..., 1] >= 2) & (g[..., 1] <= 6)
                     & (g[..., 2] >= 2) & (g[..., 2] <= 6))
    fs = split_faults(mesh, ["fault"])
    nf = len(tris)
    assert nf == 2 * 4 * 4 == 32
    g = grid(mesh, n)
    fv = np.unique(tris)
    assert len(fv) == 25
    rim = fv[np.isin(g[fv, 1], [2, 6]) | np.isin(g[fv, 2], [2, 6])]
    inner = fv[~np.isin(fv, rim)]
    assert len(rim) == 16 and len(inner) == 9
    assert np.array_equal(np.flatnonzero(fs.vert_sides == 2), np.sort(inner))
    assert np.array_equal(fs.tip_vertices, np.sort(rim))
    assert np.allclose(fs.normal, [1.0, 0.0, 0.0])
    assert fs.area.sum() == pytest.approx(0.25, rel=1e-14)
    cx = mesh.points[mesh.tets].mean(axis=1)[:, 0]
    at_inner = np.isin(mesh.tets, inner)
    assert np.all(fs.cell_side[cx < 0.5] == 0)
    assert np.array_equal(fs.cell_side[cx > 0.5], at_inner[cx > 0.5].astype(np.int64))
    # faces with all three vertices on the rim (Kuhn diagonals at two patch corners) stay closed
    opened = (fs.vert_sides[fs.faces] == 2).any(axis=1)
    assert int((~opened).sum()) == 2
    check_split_mesh(mesh, fs, opened)


def test_two_faults_and_order():
    """Two parallel full planes: ids follow the name order, the middle slab uses side 1 of x=0.25 only."""
    n = 4
    mesh = unit_box(n)
    a = add_fault(mesh, n, 0, 1, name="west")
    b = add_fault(mesh, n, 0, 3, name="east")
    fs = split_faults(mesh, ["east", "west"])
    assert fs.names == ["east", "west"]
    assert np.array_equal(fs.fault_id, np.r_[np.zeros(len(b)), np.ones(len(a))])
    assert int((fs.vert_sides == 2).sum()) == 50
    check_split_mesh(mesh, fs, np.ones(len(a) + len(b), bool))
    empty = split_faults(mesh, [])
    assert np.all(empty.vert_sides == 1) and np.all(empty.cell_side == 0) and empty.faces.shape == (0, 3)


def test_errors():
    """(c) Boundary triangles, unknown names and crossing faults are input errors naming the fault."""
    n = 4
    mesh = unit_box(n)
    mesh.surfaces["wall"] = mesh.surfaces["top"][:3]           # wholly on the outer boundary: not a fault
    with pytest.raises(InputError) as err:
        split_faults(mesh, ["wall"])
    assert str(err.value) == ("fault 'wall': it lies on the outer boundary of the mesh (each of its 3 triangles has a "
                              "tetrahedron on one side only); a fault must be an interior surface, with the body on "
                              "both sides: remove it from -pfault_faults (an outer surface takes boundary conditions, "
                              "-pfault_bc_wall_type)")
    inside = add_fault(mesh, n, 0, 2, name="inside")
    mesh.surfaces["part"] = np.vstack([inside, mesh.surfaces["top"][:3]])    # an interior plane and 3 outer faces
    with pytest.raises(InputError, match=r"fault 'part': 3 triangles are not shared by two tetrahedra \(3 on the "
                                         r"outer boundary, 0 not faces of the mesh\); embed"):
        split_faults(mesh, ["part"])
    with pytest.raises(InputError, match=r"fault 'nope' is not a physical surface of the mesh \(surfaces: .*top"):
        split_faults(mesh, ["nope"])
    add_fault(mesh, n, 0, 2, name="fx")
    with pytest.raises(InputError, match="listed twice"):
        split_faults(mesh, ["fx", "fx"])


def test_moderate_mesh_is_fast():
    """~50k tets with a mid-plane fault: well under a second."""
    import time
    n = 16
    mesh = unit_box(n)
    add_fault(mesh, n, 0, n // 2)
    t0 = time.perf_counter()
    fs = split_faults(mesh, ["fault"])
    assert time.perf_counter() - t0 < 2.0
    assert int((fs.vert_sides == 2).sum()) == (n + 1) ** 2


def test_bent_fault_orientation_propagates():
    """An L-shaped fault: x=0.5 from the top to z=-0.75, then z=-0.75 out to x=1. The block it cuts off
    (x>0.5, z>-0.75) is the plus side: normal +x on the vertical part (larger area), +z on the horizontal."""
    n = 4
    mesh = unit_box(n)
    g = grid(mesh, n)
    f = all_faces(mesh)
    gf = g[f]
    vert = np.all(gf[..., 0] == 2, axis=1) & np.all(gf[..., 2] >= 1, axis=1)
    horiz = np.all(gf[..., 2] == 1, axis=1) & np.all(gf[..., 0] >= 2, axis=1)
    mesh.surfaces["bent"] = f[vert | horiz]
    fs = split_faults(mesh, ["bent"])
    nvert = int(vert.sum())
    assert nvert == 24 and int(horiz.sum()) == 16
    assert np.allclose(fs.normal[:nvert], [1, 0, 0]) and np.allclose(fs.normal[nvert:], [0, 0, 1])
    fv = np.unique(f[vert | horiz])
    assert np.array_equal(np.flatnonzero(fs.vert_sides == 2), fv) and fs.tip_vertices.size == 0
    c = mesh.points[mesh.tets].mean(axis=1)
    block = (c[:, 0] > 0.5) & (c[:, 2] > -0.75)
    assert np.all(fs.cell_side[~block] == 0)
    assert np.array_equal(fs.cell_side[block], np.isin(mesh.tets[block], fv).astype(np.int64))
    check_split_mesh(mesh, fs, np.ones(len(fs.faces), bool))


def test_triangles_of_two_faults_are_an_error():
    n = 4
    mesh = unit_box(n)
    add_fault(mesh, n, 0, 2, name="main")
    mesh.surfaces["copy"] = mesh.surfaces["main"][:2]
    with pytest.raises(InputError, match=r"faults 'copy', 'main': 2 triangles belong to more than one fault"):
        split_faults(mesh, ["copy", "main"])


def components(tets, nv):
    """Connected components (through shared faces) of a tet mesh: the label of each cell."""
    from pfault.mesh.fault import _components
    keys = face_keys(tets[:, TET_FACES].reshape(-1, 3), nv)
    order = np.argsort(keys, kind="stable")
    same = np.flatnonzero(keys[order][1:] == keys[order][:-1])
    a, b = order[same] // 4, order[same + 1] // 4
    return _components(len(tets), np.r_[a, b], np.r_[b, a])[0]


def piece_dofs(mesh, fs):
    """The vertex id (split_mesh numbering) each fault face's minus and plus cell uses at the face's vertices."""
    tets, _ = split_mesh(mesh, fs)
    minus = tets[fs.minus_cell[:, None], TET_FACES[fs.minus_lface]]
    at = np.argmax(mesh.tets[fs.plus_cell][:, None, :] == fs.faces[:, :, None], axis=2)
    plus = tets[fs.plus_cell[:, None], at]
    assert np.array_equal(mesh.tets[fs.minus_cell[:, None], TET_FACES[fs.minus_lface]], fs.faces)
    return minus, plus


def junction_mesh(kind, n=4):
    """Fault 'fx' (x = 0.5, the whole box) and 'fy' (y = 0.5): the whole box (X) or x <= 0.5 only (T)."""
    mesh = unit_box(n)
    add_fault(mesh, n, 0, n // 2, name="fx")
    select = None if kind == "X" else (lambda g: g[..., 0] <= n // 2)
    add_fault(mesh, n, 1, n // 2, select=select, name="fy")
    return mesh, split_faults(mesh, ["fx", "fy"])


@pytest.mark.parametrize("kind, pieces, blocks", [("X", 4, 4), ("T", 3, 3)])
def test_junction_pieces_and_dofs(kind, pieces, blocks):
    """X: two planes crossing; T: fy ending on fx. The n + 1 vertices of the junction line split into 4 (X) or 3
    (T) pieces, the other fault vertices into 2; no tips (the T's branch is joined to fx, not a tip). Cut along
    every fault face the box falls into 4 (X) or 3 (T) blocks, and every fault face is open (its two cells use
    different dofs at each vertex): the split mesh's boundary is the box's plus both sides of every face."""
    n = 4
    mesh, fs = junction_mesh(kind, n)
    g = grid(mesh, n)
    line = np.flatnonzero((g[:, 0] == n // 2) & (g[:, 1] == n // 2))
    assert np.array_equal(np.flatnonzero(fs.vert_sides == pieces), line)
    fv = np.unique(fs.faces)
    assert np.all(fs.vert_sides[np.setdiff1d(fv, line)] == 2) and fs.tip_vertices.size == 0
    assert np.all(fs.vert_sides[np.setdiff1d(np.arange(len(g)), fv)] == 1)
    # displacement dofs: 3 per piece
    n_fx, n_fy = (n + 1) ** 2, (n + 1) * (n + 1 if kind == "X" else n // 2 + 1)
    assert int(fs.vert_sides.sum()) == len(g) + (n_fx + n_fy - 2 * (n + 1)) + (pieces - 1) * (n + 1)
    check_split_mesh(mesh, fs, np.ones(len(fs.faces), bool))
    tets, nv = split_mesh(mesh, fs)
    label = components(tets, nv)
    assert len(np.unique(label)) == blocks
    # each block holds the cells of one quadrant (X) or of x > 0.5 and the two halves of x < 0.5 (T)
    c = centroids(mesh, np.arange(len(mesh.tets)))
    quadrant = 2 * (c[:, 0] > 0.5) + (c[:, 1] > 0.5)
    if kind == "T":
        quadrant = np.where(c[:, 0] > 0.5, 2, quadrant)
    assert len(np.unique(np.c_[label, quadrant], axis=0)) == blocks
    # the sign rule: normals +x on fx, +y on fy; the minus cell below the plane
    assert np.allclose(fs.normal[fs.fault_id == 0], [1, 0, 0]) and np.allclose(fs.normal[fs.fault_id == 1], [0, 1, 0])


@pytest.mark.parametrize("kind", ["X", "T"])
def test_junction_jumps(kind):
    """The jump of a rigid-body motion taken by every piece is zero on every face; a uniform displacement d of the
    pieces one quadrant's cells use (X; T: the two quadrants of x < 0.5 and the half x > 0.5) opens exactly the
    faces that bound it, by +d where it is the plus side and -d where it is the minus side, at each vertex."""
    n = 4
    mesh, fs = junction_mesh(kind, n)
    tets, nv = split_mesh(mesh, fs)
    minus, plus = piece_dofs(mesh, fs)
    vertex = np.r_[np.arange(len(mesh.points)), vertex_copies(fs.vert_sides)[0]]
    x = mesh.points[vertex]
    rng = np.random.default_rng(3)
    a, w = rng.normal(size=3), rng.normal(size=3)
    u = a + np.cross(w, x)
    assert np.abs(u[plus] - u[minus]).max() < 1e-14
    c = centroids(mesh, np.arange(len(mesh.tets)))
    d = np.array([0.3, -0.2, 0.7])
    quadrant = 2 * (c[:, 0] > 0.5) + (c[:, 1] > 0.5)
    if kind == "T":
        quadrant = np.where(c[:, 0] > 0.5, 2, quadrant)     # x > 0.5 is one block: fy ends at x = 0.5
    for q in np.unique(quadrant):
        inside = quadrant == q
        u = np.zeros((nv, 3))
        u[np.unique(tets[inside])] = d
        jump = u[plus] - u[minus]
        m_in, p_in = inside[fs.minus_cell], inside[fs.plus_cell]
        assert np.array_equal(np.abs(jump).max(axis=(1, 2)) > 0, m_in != p_in)
        assert np.allclose(jump[p_in & ~m_in], d) and np.allclose(jump[m_in & ~p_in], -d)
        # every block is bounded by 2 n^2 triangles: two half planes (quadrants) or the whole of fx (T, x > 0.5)
        assert int((m_in != p_in).sum()) == 2 * n * n


@pytest.mark.parametrize("kind", ["X", "T"])
def test_junction_within_one_surface(kind):
    """Both planes of the X (T) as one physical surface: its sheets meet along the junction line, 4 (3) triangles
    an edge there, and are oriented one by one by the sign rule, so the split is the two faults' split."""
    n = 4
    mesh, two = junction_mesh(kind, n)
    mesh.surfaces["net"] = np.concatenate([mesh.surfaces["fx"], mesh.surfaces["fy"]])
    one = split_faults(mesh, ["net"])
    assert np.array_equal(one.vert_sides, two.vert_sides) and np.array_equal(one.cell_side, two.cell_side)
    assert np.array_equal(one.normal, two.normal) and np.all(one.fault_id == 0)

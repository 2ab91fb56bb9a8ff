"""Split-node fault topology on the serial mesh (pure NumPy).

A fault is a named physical surface made of interior tetrahedron faces. Each fault face gets an
orientation (normal from the minus to the plus side) and its two tetrahedra. The star of a fault vertex (the
tetrahedra containing it), cut along every fault face, falls into pieces; each piece has its own displacement
dofs. Two pieces where one fault passes; three or more where faults meet: a T junction (a fault ending on
another: its edge there is joined to the other fault, not a tip) or an X junction (faults crossing). A fault
vertex whose star stays in one piece (the fault edge buried in the solid) is a *tip* and is not split. A fault
face's jump at each of its vertices is u(piece of its plus cell) - u(piece of its minus cell).

Piece 0 of a vertex is the piece of the minus cell of its lowest-numbered fault face; the others follow in the
order of their smallest (cell, local vertex) of the star. Where a single fault passes, piece 0 is its minus
side and piece 1 its plus side.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .serial import TET_FACES, SerialMesh, face_keys, locate_faces

MAX_PIECES = 127       # pieces of one vertex's star: the fault_side label holds 7 bits per local vertex



@dataclass
class FaultSplit:
    names: list            # fault surface names in order
    vert_sides: np.ndarray  # (nv,) int64: the pieces of each vertex's star (2 where one fault passes, 3 or more
                            # at a junction, 1 off the faults and at tips)
    cell_side: np.ndarray  # (nc,4) int64: the piece whose dofs the cell uses at that local vertex
    faces: np.ndarray      # (nf,3) int64, (x1-x0)x(x2-x0) points from the minus to the plus side
    fault_id: np.ndarray   # (nf,) index into names
    minus_cell: np.ndarray
    minus_lface: np.ndarray
    plus_cell: np.ndarray
    plus_lface: np.ndarray
    normal: np.ndarray     # (nf,3) unit normals (minus -> plus)
    area: np.ndarray       # (nf,)
    tip_vertices: np.ndarray  # sorted ids of fault vertices that are not split

    @property
    def copies(self) -> tuple[np.ndarray, np.ndarray]:
        """The extra copies of split vertices on the output mesh: (vertex, piece) of each, see vertex_copies."""
        return vertex_copies(self.vert_sides)


def vertex_copies(vert_sides: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A vertex with k pieces appears k times on the output mesh: itself (piece 0), then, numbered after all
    vertices, a copy for each of its pieces 1..k-1, by vertex and then piece. Returns the (vertex, piece) of
    every copy in that order (the split vertices once each where no vertex has more than two pieces)."""
    extra = np.maximum(np.asarray(vert_sides, dtype=np.int64) - 1, 0)
    vertex = np.repeat(np.arange(len(extra)), extra)
    start = np.cumsum(extra) - extra
    return vertex, np.arange(len(vertex)) - start[vertex] + 1


def copy_index(vert_sides: np.ndarray, vertex: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """Index among the copies (vertex_copies) of piece ``piece`` >= 1 of ``vertex``."""
    extra = np.maximum(np.asarray(vert_sides, dtype=np.int64) - 1, 0)
    return (np.cumsum(extra) - extra)[vertex] + piece - 1


def output_mesh(points: np.ndarray, tets: np.ndarray, split: FaultSplit | None) -> tuple[np.ndarray, np.ndarray]:
    """The output mesh of a serial mesh (points, tets) and its fault split (None: none): a split fault vertex
    appears once per piece of its star (the copies after the serial vertices, ``vertex_copies``); each cell uses
    the copies of its pieces."""
    if split is None:
        return points, tets
    vertex, _ = split.copies
    piece = split.cell_side
    copy = len(points) + copy_index(split.vert_sides, tets, np.maximum(piece, 1))
    return np.concatenate([points, points[vertex]]), np.where(piece > 0, copy, tets)


def _components(n, a, b, rel=None):
    """Connected components of an undirected graph on n nodes by min-label propagation with pointer jumping.

    ``a, b`` hold every edge in both directions. With ``rel`` (0/1 per directed edge) a parity is carried
    along: ``parity[b] == parity[a] ^ rel`` is what the edges ask for, relative to the component's root.
    Returns (label, parity): label is the smallest node id of the component.
    """
    a = np.asarray(a, dtype=np.int64)
    b = np.asarray(b, dtype=np.int64)
    rel = np.zeros(len(a), np.int64) if rel is None else np.asarray(rel, dtype=np.int64)
    order = np.argsort(a, kind="stable")
    a, b, rel = a[order], b[order], rel[order]
    starts = np.flatnonzero(np.r_[True, a[1:] != a[:-1]]) if len(a) else np.zeros(0, np.int64)
    heads = a[starts]
    key = 2 * np.arange(n, dtype=np.int64)          # 2*label + parity
    while True:
        new = key.copy()
        if len(a):
            cand = (key[b] & ~np.int64(1)) | ((key[b] & 1) ^ rel)
            new[heads] = np.minimum(new[heads], np.minimum.reduceat(cand, starts))
        lab, par = new >> 1, new & 1
        new = 2 * lab[lab] + (par ^ (new[lab] & 1))  # pointer jumping: follow the label's own label
        if np.array_equal(new, key):
            break
        key = new
    return key >> 1, key & 1


def _fault_message(names, fault_ids, what):
    ids = sorted(set(int(i) for i in fault_ids))
    label = ", ".join(f"'{names[i]}'" for i in ids)
    return f"fault{'s' if len(ids) > 1 else ''} {label}: {what}"


def _empty(mesh, names):
    nv, nc = len(mesh.points), len(mesh.tets)
    z = np.zeros(0, np.int64)
    return FaultSplit(names=list(names), vert_sides=np.ones(nv, np.int64), cell_side=np.zeros((nc, 4), np.int64),
                      faces=np.zeros((0, 3), np.int64), fault_id=z, minus_cell=z, minus_lface=z, plus_cell=z,
                      plus_lface=z, normal=np.zeros((0, 3)), area=np.zeros(0), tip_vertices=z)


def _gather_triangles(mesh, names):
    """Fault triangles of all named surfaces (duplicates inside a surface dropped) and their fault id."""
    nv = len(mesh.points)
    tris, ids = [], []
    for i, name in enumerate(names):
        if name not in mesh.surfaces:
            raise InputError(f"fault '{name}' is not a physical surface of the mesh "
                             f"(surfaces: {', '.join(sorted(mesh.surfaces)) or 'none'})")
        if name in names[:i]:
            raise InputError(f"fault '{name}' is listed twice; name each fault surface once")
        t = np.asarray(mesh.surfaces[name], dtype=np.int64).reshape(-1, 3)
        if len(t) == 0:
            raise InputError(f"fault '{name}' has no triangles; give the physical surface its mesh faces")
        _, first = np.unique(face_keys(t, nv), return_index=True)
        tris.append(t[np.sort(first)])
        ids.append(np.full(len(first), i, np.int64))
    tris, ids = np.concatenate(tris), np.concatenate(ids)
    keys = face_keys(tris, nv)
    _, inv, counts = np.unique(keys, return_inverse=True, return_counts=True)
    shared = counts[inv] > 1
    if np.any(shared):
        raise InputError(_fault_message(names, ids[shared], f"{int(shared.sum()) // 2} triangles belong to more "
                                        "than one fault; give each triangle to one fault surface only"))
    return tris, ids, keys


def _orient(points, nv, faces, fault_id, names):
    """Flip bits that orient every edge-connected sheet of each fault consistently with the sign rule. A sheet
    continues across an edge where exactly two triangles of the same fault meet; where three or more of one
    fault's triangles meet (a junction inside one surface) its sheets are oriented apart, and triangles of
    different faults are never joined."""
    nf = len(faces)
    e0 = faces.ravel()
    e1 = faces[:, [1, 2, 0]].ravel()
    tri = np.repeat(np.arange(nf), 3)
    lo, hi = np.minimum(e0, e1), np.maximum(e0, e1)
    ekey = (lo * nv + hi) * max(len(names), 1) + fault_id[tri]     # an edge of one fault
    fwd = (e0 < e1).astype(np.int64)
    order = np.argsort(ekey, kind="stable")
    sk = ekey[order]
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    counts = np.diff(np.r_[starts, len(sk)])
    pair = starts[counts == 2]
    t, u = tri[order[pair]], tri[order[pair + 1]]
    rel = (fwd[order[pair]] == fwd[order[pair + 1]]).astype(np.int64)   # same direction: one must flip
    label, flip = _components(nf, np.r_[t, u], np.r_[u, t], np.r_[rel, rel])
    bad = flip[t] != (flip[u] ^ rel)
    if np.any(bad):
        raise InputError(_fault_message(names, fault_id[t[bad]], "the surface is not orientable; "
                                        "a fault must have two sides"))
    x = points[faces]
    cross = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    signed = np.where(flip[:, None] == 1, -cross, cross)
    comp, cinv = np.unique(label, return_inverse=True)
    mean = np.stack([np.bincount(cinv, weights=signed[:, k], minlength=len(comp)) for k in range(3)], axis=1)
    axis = np.argmax(np.abs(mean), axis=1)
    negative = mean[np.arange(len(comp)), axis] < 0
    return flip ^ negative[cinv].astype(np.int64)


def _two_cells(T, nv, tris, fault_id, names):
    """Rule 1: every fault triangle is an interior face with exactly two tetrahedra (of the star ``T``); returns
    the face, as seen from its first cell (its normal pointing into the second), and the two (cell, local face)."""
    nf = len(tris)
    ti, cell, lface = locate_faces(T, nv, tris)
    cnt = np.bincount(ti, minlength=nf)
    if np.any(cnt != 2):
        bad = cnt != 2
        nb, nz = int(np.sum(cnt == 1)), int(np.sum(cnt == 0))
        outer = [i for i in np.unique(fault_id[bad]) if np.all(cnt[fault_id == i] == 1)]
        if outer:
            name = names[outer[0]]
            raise InputError(f"fault '{name}': it lies on the outer boundary of the mesh (each of its "
                             f"{int(np.sum(fault_id == outer[0]))} triangles has a tetrahedron on one side only); a "
                             "fault must be an interior surface, with the body on both sides: remove it from "
                             f"-pfault_faults (an outer surface takes boundary conditions, -pfault_bc_{name}_type)")
        raise InputError(_fault_message(names, fault_id[bad], f"{int(bad.sum())} triangles are not shared by two "
                                        f"tetrahedra ({nb} on the outer boundary, {nz} not faces of the mesh); "
                                        "embed the fault surface in the volume mesh (gmsh: mesh.embed / fragment)"))
    c0, l0, c1, l1 = cell[0::2], lface[0::2], cell[1::2], lface[1::2]   # grouped by triangle, two each
    faces = T[c0[:, None], TET_FACES[l0]]       # outward from c0: n points from c0 into c1
    return faces, (c0, l0), (c1, l1)


def _star_components(T, nv, is_fv, fkeys):
    """Rule 3: the components of each fault vertex's star, connected through non-fault faces containing it.
    Nodes are (star cell s, local vertex k) -> 4*s + k; only those at fault vertices get edges. Returns each
    node's component label."""
    ns = len(T)
    F = T[:, TET_FACES]                                  # (ns,4,3)
    fl = np.flatnonzero(is_fv[F].any(axis=2).ravel())    # faces with a fault vertex, index 4*s + lf
    fverts = F.reshape(-1, 3)[fl]
    k = face_keys(fverts, nv)
    keep = ~np.isin(k, fkeys)
    fl, fverts, k = fl[keep], fverts[keep], k[keep]
    order = np.argsort(k, kind="stable")
    sk = k[order]
    same = np.flatnonzero(sk[1:] == sk[:-1])
    fa, fb = fl[order[same]], fl[order[same + 1]]        # the two sides of each interior non-fault face
    sa, la = fa // 4, fa % 4
    sb, lb = fb // 4, fb % 4
    oa = np.argsort(fverts[order[same]], axis=1)         # local corners sorted by vertex id on both sides
    ob = np.argsort(fverts[order[same + 1]], axis=1)
    ka = np.take_along_axis(TET_FACES[la], oa, axis=1)
    kb = np.take_along_axis(TET_FACES[lb], ob, axis=1)
    va = np.take_along_axis(fverts[order[same]], oa, axis=1)
    na, nb = 4 * sa[:, None] + ka, 4 * sb[:, None] + kb
    m = is_fv[va]
    na, nb = na[m], nb[m]
    label, _ = _components(4 * ns, np.r_[na, nb], np.r_[nb, na])
    return label


def _pieces(T, nv, is_fv, label, minus):
    """The pieces of each fault vertex's star (``label``: the star nodes' components) and the piece of each star
    node at a fault vertex: (vert_sides (nv,), the star nodes 4*s + k at fault vertices, their pieces). Piece 0
    is the piece of the minus cell of the vertex's lowest-numbered face, the others in the order of their
    components' labels (the smallest star node of each)."""
    ns = len(T)
    node_v = T.ravel()
    inc = np.flatnonzero(is_fv[node_v])                  # (vertex, cell) incidences at fault vertices
    iv = node_v[inc]
    keys, at = np.unique(iv * (4 * ns) + label[inc], return_inverse=True)   # one per piece, by vertex then label
    kv = keys // (4 * ns)
    nk = np.bincount(kv, minlength=nv)
    rank = np.arange(len(keys)) - (np.cumsum(nk) - nk)[kv]       # the piece's place among its vertex's pieces
    mc, ml = minus
    mnode = (4 * mc[:, None] + TET_FACES[ml]).ravel()    # corners of the faces in face order
    mv = node_v[mnode]
    v0, first = np.unique(mv, return_index=True)         # each fault vertex's lowest-numbered face
    zero = np.zeros(nv, np.int64)
    zero[v0] = rank[np.searchsorted(keys, v0 * (4 * ns) + label[mnode[first]])]
    z = zero[kv]
    piece = np.where(rank == z, 0, np.where(rank < z, rank + 1, rank))
    vert_sides = np.maximum(nk, 1).astype(np.int64)
    if vert_sides.max(initial=1) > MAX_PIECES:
        raise InputError(f"{int((vert_sides > MAX_PIECES).sum())} vertices where more than {MAX_PIECES} fault "
                         "pieces meet; coarsen the fault network there")
    return vert_sides, inc, piece[at]


def split_faults(mesh: SerialMesh, names: Iterable[str]) -> FaultSplit:
    """Orient the named fault surfaces and cut the stars of their vertices into pieces: which vertices split,
    into how many pieces, and which piece each cell uses at each of its vertices."""
    names = list(names)
    if not names:
        return _empty(mesh, names)
    points = np.asarray(mesh.points, dtype=np.float64)
    tets = np.asarray(mesh.tets, dtype=np.int64)
    nv, nc = len(points), len(tets)
    tris, fault_id, fkeys = _gather_triangles(mesh, names)

    # the cells touching a fault vertex: everything below happens among them
    is_fv = np.zeros(nv, bool)
    is_fv[tris.ravel()] = True
    star = np.flatnonzero(is_fv[tets].any(axis=1))
    T = tets[star]

    faces, (c0, l0), (c1, l1) = _two_cells(T, nv, tris, fault_id, names)
    # rule 2: orientation
    flip = _orient(points, nv, faces, fault_id, names).astype(bool)
    faces[flip] = faces[flip][:, [0, 2, 1]]
    mc, ml = np.where(flip, c1, c0), np.where(flip, l1, l0)
    pc, pl = np.where(flip, c0, c1), np.where(flip, l0, l1)

    label = _star_components(T, nv, is_fv, fkeys)
    vert_sides, nodes, piece = _pieces(T, nv, is_fv, label, (mc, ml))
    cell_side = np.zeros((nc, 4), np.int64)
    cell_side[star[nodes // 4], nodes % 4] = piece

    x = points[faces]
    cross = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    return FaultSplit(names=names, vert_sides=vert_sides, cell_side=cell_side, faces=faces, fault_id=fault_id,
                      minus_cell=star[mc], minus_lface=ml.astype(np.int64), plus_cell=star[pc],
                      plus_lface=pl.astype(np.int64), normal=cross / norm[:, None], area=0.5 * norm,
                      tip_vertices=np.flatnonzero(is_fv & (vert_sides == 1)))


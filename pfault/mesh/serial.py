"""The whole mesh as NumPy arrays, as read or generated on one rank before distribution."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

# local faces of a tetrahedron: face k is opposite vertex k
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


@dataclass
class SerialMesh:
    points: np.ndarray                 # (nv, 3) float64
    tets: np.ndarray                   # (nc, 4) int64, positively oriented
    cell_material: np.ndarray          # (nc,) int, index into material_names
    material_names: list
    surfaces: dict = field(default_factory=dict)   # name -> (nf, 3) int64 vertex triples
    source: str = ""

    def check(self) -> SerialMesh:
        """The mesh itself, after checking it has tetrahedra and none is degenerate (InputError)."""
        if self.tets.size == 0:
            raise InputError(f"mesh {self.source}: no tetrahedra in any physical volume")
        vol = signed_volumes(self.points, self.tets)
        if np.any(vol == 0.0):
            raise InputError(f"mesh {self.source}: {int(np.sum(vol == 0))} degenerate tetrahedra")
        return self


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volume of each tetrahedron: (x1 - x0) x (x2 - x0) . (x3 - x0) / 6."""
    x = points[tets]
    return np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6.0


def orient_positive(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Return tets with vertices ordered so that every volume is positive."""
    tets = np.array(tets, dtype=np.int64, copy=True)
    neg = signed_volumes(points, tets) < 0
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    return tets


def face_keys(tri: np.ndarray, nv: int) -> np.ndarray:
    """Order-independent integer key of each triangle (sorted vertex ids)."""
    s = np.sort(np.asarray(tri, dtype=np.int64), axis=1)
    return (s[:, 0] * nv + s[:, 1]) * nv + s[:, 2]


def boundary_faces(tets: np.ndarray, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """Faces that belong to a single tetrahedron: (cell, local face) arrays."""
    faces = tets[:, TET_FACES].reshape(-1, 3)
    keys = face_keys(faces, nv)
    _, inv, counts = np.unique(keys, return_inverse=True, return_counts=True)
    once = counts[inv] == 1
    idx = np.nonzero(once)[0]
    return idx // 4, idx % 4


def locate_faces(tets: np.ndarray, nv: int, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each triangle, the (cell, local face) pairs that have it: returns arrays (tri, cell, lface)."""
    faces = tets[:, TET_FACES].reshape(-1, 3)
    keys = face_keys(faces, nv)
    tkeys = face_keys(triangles, nv)
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    lo = np.searchsorted(sk, tkeys, side="left")
    hi = np.searchsorted(sk, tkeys, side="right")
    counts = hi - lo
    tri = np.repeat(np.arange(len(tkeys)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    pos = np.repeat(lo, counts) + (np.arange(len(tri)) - first)
    idx = order[pos]
    return tri, idx // 4, idx % 4

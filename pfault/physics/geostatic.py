"""The geostatic initial stress (pure NumPy): the K0 rule on a vertical stress, and the lithostatic vertical stress,
the weight of the column of material above a point.

Conventions: z up, the land surface at the top of the mesh; stresses positive in tension (sigma_v < 0 under an
overburden); the pore pressure p0 hydrostatic below the water table, positive in compression.
"""

from __future__ import annotations

import numpy as np

# local faces of a tetrahedron: face k is opposite vertex k (the order of pfault.mesh.serial.TET_FACES)
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
_UPWARD = 1e-12          # a face whose unit normal has n_z below this is vertical for a vertical line


def k0_stress(sigma_v: np.ndarray, z: np.ndarray, alpha: np.ndarray, nu: np.ndarray, k0: float,
              water_density: float, gravity: float, water_table: float) -> np.ndarray:
    """The initial stress per cell (n x 3 x 3, Pa) from its vertical stress ``sigma_v``: horizontal stresses by the
    K0 rule on effective stresses, sigma'_h = K0 sigma'_v, with the hydrostatic pore pressure p0 = rho_w g (z_w - z)
    below the water table at the cell's height ``z`` (sigma' = sigma + alpha p0); K0 = ``k0``, or nu / (1 - nu) of
    each cell where ``k0`` is negative (not given); no initial shear."""
    p0 = water_density * gravity * np.maximum(water_table - z, 0.0)
    ratio = np.full(len(z), k0) if k0 >= 0 else nu / (1 - nu)
    sh = ratio * (sigma_v + alpha * p0) - alpha * p0
    sigma0 = np.zeros((len(z), 3, 3))
    sigma0[:, 0, 0] = sigma0[:, 1, 1] = sh
    sigma0[:, 2, 2] = sigma_v
    return sigma0


def overburden(x: np.ndarray, density: np.ndarray, gravity: float) -> np.ndarray:
    """The weight per unit area of the material above each tetrahedron's centroid (Pa, >= 0), int rho g dz along the
    vertical from the centroid up to where the vertical leaves the mesh: exact for a density constant in each cell
    (``density``), whatever the layering. ``x``: the tetrahedra's vertices (n x 4 x 3); tetrahedra share a face
    where they share its three vertices' coordinates. The vertical is followed from cell to cell across the faces
    it leaves each cell through, all columns at once."""
    n = len(x)
    centroid = x.mean(axis=1)
    normal, offset = _outward_faces(x, centroid)
    neighbour = _face_neighbours(_vertex_ids(x))
    p = centroid
    weight = np.zeros(n)
    ray = np.arange(n)                                           # the columns still inside the mesh
    cell = np.arange(n)                                          # the cell each column is in
    z = p[:, 2].copy()
    for _ in range(n):
        if not len(ray):
            break
        nrm = normal[cell]
        nz = nrm[:, :, 2]
        # the height of each face's plane above the point, measured from the cell's centroid (to the round-off of
        # the cell's size, not of the coordinates)
        q = np.column_stack([p[ray, :2], z]) - centroid[cell]
        gap = offset[cell] - np.einsum("nkj,nj->nk", nrm, q)
        up = nz > _UPWARD
        rise = np.where(up, gap / np.where(up, nz, 1.0), np.inf)  # how far up each face's plane is
        face = np.argmin(rise, axis=1)
        dz = np.maximum(rise[np.arange(len(ray)), face], 0.0)
        dz = np.where(np.isfinite(dz), dz, 0.0)
        weight[ray] += density[cell] * gravity * dz
        z = z + dz
        nxt = neighbour[cell, face]
        inside = nxt >= 0
        ray, cell, z = ray[inside], nxt[inside], z[inside]
    return weight


def _outward_faces(x: np.ndarray, centroid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward normals (n, 4, 3) of each tetrahedron's faces and their planes' offsets n . (v - centroid)
    (n, 4)."""
    v = x[:, _FACES]                                             # (n, 4, 3 vertices, 3)
    normal = np.cross(v[:, :, 1] - v[:, :, 0], v[:, :, 2] - v[:, :, 0])
    normal /= np.linalg.norm(normal, axis=2)[:, :, None]
    inward = np.einsum("nkj,nkj->nk", normal, x - v[:, :, 0]) > 0  # the opposite vertex k on the normal's side
    normal[inward] *= -1.0
    return normal, np.einsum("nkj,nkj->nk", normal, v[:, :, 0] - centroid[:, None, :])


def _vertex_ids(x: np.ndarray) -> np.ndarray:
    """The tetrahedra (n x 4) as indices of their distinct vertex coordinates."""
    flat = x.reshape(-1, 3)
    order = np.lexsort(flat.T[::-1])
    new = np.ones(len(order), dtype=bool)
    new[1:] = np.any(flat[order][1:] != flat[order][:-1], axis=1)
    ids = np.empty(len(order), dtype=np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids.reshape(-1, 4)


def _face_neighbours(tets: np.ndarray) -> np.ndarray:
    """The tetrahedron across each local face (n, 4), -1 on the mesh's boundary."""
    faces = np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)
    order = np.lexsort(faces.T[::-1])
    same = np.all(faces[order][1:] == faces[order][:-1], axis=1)
    pair = np.nonzero(same)[0]
    a, b = order[pair], order[pair + 1]                          # tet * 4 + local face, on either side of a face
    neighbour = np.full(4 * len(tets), -1, dtype=np.int64)
    neighbour[a], neighbour[b] = b // 4, a // 4
    return neighbour.reshape(-1, 4)

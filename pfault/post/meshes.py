"""The geometry of a run's meshes as its files hold them: the land surface of the volume mesh, the fault faces'
normals, areas and centroids, the coordinate plane a fault lies in, and the displacement jumps across a split fault.

Sign conventions (pfault.mesh.fault): a fault triangle's vertex order gives the normal (x1-x0)x(x2-x0) from the
minus to the plus side; jumps are plus minus minus; opening is the normal jump (positive: open); the dip slip is the
slip component along the up-dip direction of the plane (positive: the plus side moves up relative to the minus side).
"""

from __future__ import annotations

import numpy as np

from .rundir import Snapshot

TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def top_surface(points: np.ndarray, tets: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
    """Triangles (k, 3) of the mesh faces lying on the plane z = max z (the land surface)."""
    z = points[:, 2]
    ztop = z.max()
    on = np.abs(z - ztop) <= rtol * max(np.ptp(points, axis=0).max(), 1.0)
    faces = tets[:, TET_FACES].reshape(-1, 3)
    return faces[on[faces].all(axis=1)]


def face_geometry(points: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normals (minus -> plus), areas and centroids of triangles."""
    x = points[tris]
    cross = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(area2, 1e-300)[:, None], 0.5 * area2, x.mean(axis=1)


def plane_axes(normals: np.ndarray) -> tuple[int, tuple[int, ...]]:
    """Axis index normal to a (near) coordinate-plane fault and the two in-plane axes, e.g. (0, (1, 2)) for
    a vertical fault x = const: plot it in (y, z)."""
    a = int(np.argmax(np.abs(normals).mean(axis=0)))
    return a, tuple(i for i in range(3) if i != a)


def dip_slip(slip: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Slip component along the up-dip direction of each face (positive: plus side up relative to minus);
    for a vertical fault this is the vertical slip u_z(plus) - u_z(minus)."""
    ez = np.array([0.0, 0.0, 1.0])
    d = ez[None, :] - normals[:, 2:3] * normals
    nd = np.linalg.norm(d, axis=1)
    d = np.where(nd[:, None] > 1e-12, d / np.maximum(nd, 1e-300)[:, None], 0.0)
    return np.einsum("ij,ij->i", slip, d)


def nodal_jumps(fields: Snapshot, fault: Snapshot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Displacement jumps at the split fault vertices (plus copy minus original), from fields.xdmf.

    fields.xdmf holds the serial vertices followed by a copy per further piece of each split vertex (the plus side
    of a single fault); fault.xdmf holds the serial vertices only, so copies are matched to their originals by their
    (bitwise equal) coordinates among the fault vertices. Returns (points (k, 3), jump (k, 3), normal (k, 3)),
    with the normal averaged over the fault faces at each vertex; tips (unsplit) are left out, and so are junction
    vertices (more than one copy: faults meeting there, no one normal and plus side)."""
    n_serial = len(fault.points)
    P = fields.points
    copies = np.arange(n_serial, len(P))
    cand = np.unique(fault.cells)
    keys = np.concatenate([P[cand], P[copies]])
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.ravel()
    first = np.full(inv.max() + 1, -1)
    first[inv[: len(cand)]] = cand
    orig = first[inv[len(cand):]]
    ok = orig >= 0
    ok[ok] = np.bincount(orig[ok], minlength=n_serial)[orig[ok]] == 1    # junction vertices: several copies
    copies, orig = copies[ok], orig[ok]
    u = fields.point_data["displacement"]
    normals, area, _ = face_geometry(fault.points, fault.cells)
    vn = np.zeros((n_serial, 3))
    for k in range(3):
        np.add.at(vn, fault.cells[:, k], normals * area[:, None])
    vn = vn[orig]
    vn /= np.maximum(np.linalg.norm(vn, axis=1), 1e-300)[:, None]
    return P[orig], u[copies] - u[orig], vn


def surface_fault_jumps(fields: Snapshot, fault: Snapshot, rtol: float = 1e-9) -> tuple[float, float]:
    """Largest nodal opening and slip magnitude (m) of the split fault vertices on the land surface z = max z
    (the width and offset one would measure across a fissure or scarp in the field)."""
    p, jump, n = nodal_jumps(fields, fault)
    ztop = fields.points[:, 2].max()
    top = np.abs(p[:, 2] - ztop) <= rtol * max(np.ptp(fields.points, axis=0).max(), 1.0)
    if not np.any(top):
        return 0.0, 0.0
    jn = np.einsum("ij,ij->i", jump, n)
    slip = np.linalg.norm(jump - jn[:, None] * n, axis=1)
    return float(np.max(jn[top], initial=0.0)), float(np.max(slip[top], initial=0.0))

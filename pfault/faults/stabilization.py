"""Traction-jump stabilisation of the piecewise-constant multipliers on P1 displacements.

Following Franceschini, Castelletto, White & Tchelepi (CMAME 2020): the constraint rows of two fault faces
sharing an edge are coupled through S (their traction increments' difference), with S built from the local
stiffness, so no user coefficient enters. The coupling enters the contact law through its jump argument
(the stabilised jump A g + S (dt_b - dt_a)), so it acts on the components the face's state constrains:
all three of a stuck face, the normal one of a slipping face, none of an open face.
"""

from __future__ import annotations

import numpy as np

from ..physics import elasticity as el
from . import contact as ct

# constrained components per state (stick, slip, open)
N_CONSTRAINED = np.array([3, 1, 0])


def stabilization_pairs(serial, split, materials, scale=1.0):
    """Pairs of fault faces sharing an edge and their stabilisation matrices (local frame).

    Following Franceschini, Castelletto, White & Tchelepi (CMAME 2020): for the two faces f0, f1 of a
    fault edge, S = R (K_-^-1 + K_+^-1) R^T * areafac, with K_+- a diagonal stiffness estimate of the
    edge nodes on each side (sum over the two faces' adjacent cells of
    E/((1+nu)(1-2nu)) 2/9 (2-3nu) V/box_j^2) and areafac = sum over the edge nodes of the products
    of the faces' nodal areas. No user coefficient.
    """
    faces = split.faces
    nf = len(faces)
    if nf == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3, 3))
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(nf), 3)
    e = np.sort(edges, axis=1)
    key = e[:, 0] * len(serial.points) + e[:, 1]
    order = np.argsort(key, kind="stable")
    ks = key[order]
    same = ks[1:] == ks[:-1]
    counts = np.bincount(np.unique(ks, return_inverse=True)[1])
    first = np.nonzero(same)[0]
    # keep edges shared by exactly two faces of the same fault
    uniq, inv = np.unique(ks, return_inverse=True)
    two = counts[inv[first]] == 2
    f0 = owner[order[first[two]]]
    f1 = owner[order[first[two] + 1]]
    keep = split.fault_id[f0] == split.fault_id[f1]
    f0, f1 = f0[keep], f1[keep]
    young = np.array([m.young_modulus for m in materials])[serial.cell_material]
    nu = np.array([m.poisson_ratio for m in materials])[serial.cell_material]
    x = serial.points[serial.tets]
    vol = np.abs(el.tet_geometry(x)[1])
    box = x.max(axis=1) - x.min(axis=1)
    kdiag = (scale * young / ((1 + nu) * (1 - 2 * nu)) * 2.0 / 9.0 * (2 - 3 * nu) * vol)[:, None] / box ** 2
    k_minus = kdiag[split.minus_cell[f0]] + kdiag[split.minus_cell[f1]]
    k_plus = kdiag[split.plus_cell[f0]] + kdiag[split.plus_cell[f1]]
    inv_k = 1.0 / k_minus + 1.0 / k_plus                                   # (np, 3) diagonal, global axes
    n = split.normal[f0] * split.area[f0, None] + split.normal[f1] * split.area[f1, None]
    R = ct.local_frames(n)
    S = np.einsum("nij,nj,nkj->nik", R, inv_k, R)
    areafac = 2.0 * (split.area[f0] / 3.0) * (split.area[f1] / 3.0)
    return np.column_stack([f0, f1]), S * areafac[:, None, None]


def stabilization_rows(pairs, S, pos, dt_all, g_lm_all):
    """Stabilisation of this rank's faces, in jump units (m^3): the terms S (dt_b - dt_a) that the stabilised
    jump A g + S (dt_b - dt_a) of each owned face adds (``pos``: serial face -> owned index or -1), and their
    derivatives as blocks [(owned index of the face, row dofs, col dofs, d/dt (n,3,3))]. ``dt_all``: the
    traction increments of the step of all faces (serial order). Every component of every pair is coupled,
    whatever the faces' states: the contact law takes the stabilised jump as its argument, so its residual
    stays continuous where a face or its neighbour changes state."""
    nf = int(np.count_nonzero(pos >= 0))
    r = np.zeros((nf, 3))
    blocks = []
    for a, b in ((0, 1), (1, 0)):
        fa, fb = pairs[:, a], pairs[:, b]
        mine = pos[fa] >= 0
        if not np.any(mine):
            continue
        fa, fb, Sm = fa[mine], fb[mine], S[mine]
        contrib = np.einsum("nij,nj->ni", Sm, dt_all[fb] - dt_all[fa])
        np.add.at(r, pos[fa], contrib)
        blocks.append((pos[fa], g_lm_all[fa], g_lm_all[fa], -Sm))
        blocks.append((pos[fa], g_lm_all[fa], g_lm_all[fb], Sm))
    return r, blocks


def stabilization_pattern(pairs, pos, g_lm_all):
    """(rows, cols) global index pairs of the stabilisation blocks in rows this rank owns."""
    rows, cols = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for a, b in ((0, 1), (1, 0)):
        fa, fb = pairs[:, a], pairs[:, b]
        mine = pos[fa] >= 0
        for f in (fa[mine], fb[mine]):
            rows.append(np.repeat(g_lm_all[fa[mine]], 3, axis=1).ravel())
            cols.append(np.tile(g_lm_all[f], (1, 3)).ravel())
    return np.concatenate(rows), np.concatenate(cols)

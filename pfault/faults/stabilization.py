"""Traction-jump stabilisation of the piecewise-constant multipliers on P1 displacements.

Following Franceschini, Castelletto, White & Tchelepi (CMAME 2020): the constraint rows of two fault faces
sharing an edge are coupled through S (the difference of their tractions' changes since the initial state),
with S built from the local stiffness, so no user coefficient enters. The coupling enters the contact law
through its jump argument (the stabilised jump A g + S (dt_b - dt_a)), so it acts on the components the face's
state constrains: all three of a stuck face, the normal one of a slipping face, none of an open face.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..physics import elasticity as el
from . import contact as ct

if TYPE_CHECKING:
    from ..mesh.fault import FaultSplit
    from ..mesh.serial import SerialMesh

# S as a fraction of the local compliance estimate. The stabilisation is a consistency error: a closed face
# next to a face whose traction changed differently takes a jump S (dt_b - dt_a) / A, so near an opening front
# the fault behaves as if held by springs of stiffness A / S. At the full estimate (fraction 1, S about 2.7
# times the multiplier Schur complement on the two-blocks fault) that is a penalty of about E/h: the fissure box
# (config/hard/fissure_box.opts) opened 185 m^3 against 15.5 m^3 at a fraction of 0.01, 14.3 m^3 at 0.001,
# 16.6 m^3 with penalty faces at 100 E/h, and 16.3 / 15.2 m^3 at h/2 (0.01 / 0.001). At 0.01 the spurious
# traction modes are still removed (smallest eigenvalue of the stabilised Schur complement 4e-4 of its
# largest on the two-blocks fault, tests/scripts/inf_sup.py), neighbouring faces' tractions are as smooth
# as at 1 (fissure box at h/2), and Newton takes at most 9 iterations in a step on the fissure box; at 0.001
# the tractions start to oscillate (2.8 times more at h/2) and Newton takes up to 14.
COMPLIANCE_FRACTION = 0.01


def stabilization_pairs(serial: SerialMesh, split: FaultSplit, young: np.ndarray, nu: np.ndarray,
                        fraction: float = COMPLIANCE_FRACTION) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of fault faces sharing an edge and their stabilisation matrices (local frame).

    Following Franceschini, Castelletto, White & Tchelepi (CMAME 2020): for the two faces f0, f1 of a
    fault edge, S = fraction R (K_-^-1 + K_+^-1) R^T * areafac, with K_+- a diagonal stiffness estimate of
    the edge nodes on each side (sum over the two faces' adjacent cells of
    E/((1+nu)(1-2nu)) 2/9 (2-3nu) V/box_j^2) and areafac = sum over the edge nodes of the products
    of the faces' nodal areas; ``young``, ``nu``: per serial cell; ``fraction``: see COMPLIANCE_FRACTION. No
    user coefficient.
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
    x = serial.points[serial.tets]
    vol = np.abs(el.tet_geometry(x)[1])
    box = x.max(axis=1) - x.min(axis=1)
    kdiag = (young / ((1 + nu) * (1 - 2 * nu)) * 2.0 / 9.0 * (2 - 3 * nu) * vol)[:, None] / box ** 2
    k_minus = kdiag[split.minus_cell[f0]] + kdiag[split.minus_cell[f1]]
    k_plus = kdiag[split.plus_cell[f0]] + kdiag[split.plus_cell[f1]]
    inv_k = 1.0 / k_minus + 1.0 / k_plus                                   # (np, 3) diagonal, global axes
    n = split.normal[f0] * split.area[f0, None] + split.normal[f1] * split.area[f1, None]
    R = ct.local_frames(n)
    S = fraction * np.einsum("nij,nj,nkj->nik", R, inv_k, R)
    areafac = 2.0 * (split.area[f0] / 3.0) * (split.area[f1] / 3.0)
    return np.column_stack([f0, f1]), S * areafac[:, None, None]


def stabilization_rows(pairs: np.ndarray, S: np.ndarray, pos: np.ndarray, dt_all: np.ndarray, g_lm_all: np.ndarray
                       ) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]]:
    """Stabilisation of this rank's faces, in jump units (m^3): the terms S (dt_b - dt_a) that the stabilised
    jump A g + S (dt_b - dt_a) of each owned face adds (``pos``: serial face -> owned index or -1), and their
    derivatives as blocks [(owned index of the face, row dofs, col dofs, d/dt (n,3,3))]. ``dt_all``: the
    tractions' changes since the initial state of all faces (serial order). Every component of every pair is coupled,
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


def stabilization_pattern(pairs: np.ndarray, pos: np.ndarray, g_lm_all: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) global index pairs of the stabilisation blocks in rows this rank owns."""
    rows, cols = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for a, b in ((0, 1), (1, 0)):
        fa, fb = pairs[:, a], pairs[:, b]
        mine = pos[fa] >= 0
        for f in (fa[mine], fb[mine]):
            rows.append(np.repeat(g_lm_all[fa[mine]], 3, axis=1).ravel())
            cols.append(np.tile(g_lm_all[f], (1, 3)).ravel())
    return np.concatenate(rows), np.concatenate(cols)

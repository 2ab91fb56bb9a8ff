"""The stress written per cell beside a fault includes the strain of the face bubbles (recovered after the solve).

Condensation solves K_uu u + K_ub b = f_u on the P1 rows, and K_uu u + K_ub b = sum_cells V sigma(u + b) . grad(l_a)
with the cell mean of the stress of P1 plus bubbles (the P1 gradients are constant in a cell). So the written
total stress is in equilibrium at every free vertex, those of the cells beside the fault included, where the
P1 part alone is not: on the fissure box after a year of drawdown (no body force, no load inside the box), the
vertices inside the box and off the fault carry no net force from the written stresses, to the solver's
tolerance, at 1 and 2 ranks (the P1 part alone leaves 1 % of the vertex forces unbalanced beside the fault). And a glued fault in a uniform stress state (the two blocks sheared by G delta / L) leaves every cell
with the unfaulted, analytic stress.
"""

import os

import numpy as np
import pytest

from conftest import FISSURE_BOX, TWO_BLOCKS, run_scene

ONE_YEAR = ["-pfault_time_end", "1*year", "-pfault_time_steps", "1"]


def last_fields(outdir):
    import h5py
    with h5py.File(os.path.join(str(outdir), "fields.h5"), "r") as f:
        pts, cells = f["mesh/points"][...], f["mesh/cells"][...]
        sig = f["steps"][sorted(f["steps"])[-1]]["stress"][...].reshape(-1, 3, 3)
    with h5py.File(os.path.join(str(outdir), "fault.h5"), "r") as f:
        fault_pts = f["mesh/points"][...][np.unique(f["mesh/cells"][...])]
    return pts, cells, sig, fault_pts


def nodal_forces(pts, cells, sig):
    """sum over the cells of each vertex of V sigma . grad(l_a) (n points, 3), and the sum of their magnitudes."""
    from pfault.physics import elasticity as el
    grad, vol = el.tet_geometry(pts[cells])
    vol = np.abs(vol)
    f = vol[:, None, None] * np.einsum("nij,naj->nai", sig, grad)
    out, mag = np.zeros((len(pts), 3)), np.zeros(len(pts))
    np.add.at(out, cells.ravel(), f.reshape(-1, 3))
    np.add.at(mag, cells.ravel(), np.linalg.norm(f, axis=2).ravel())
    return out, mag


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_written_stress_in_equilibrium_beside_the_fault(tmp_path, ranks):
    proc, s = run_scene(FISSURE_BOX, tmp_path / "run", ranks=ranks, extra=ONE_YEAR)
    assert s["converged"], proc.stdout[-2000:]
    step = s["steps"][-1]
    assert step["slip"] > 0 and step["open"] > 0, step        # faces in every state
    pts, cells, sig, fault_pts = last_fields(tmp_path / "run")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    inside = np.all((pts > lo + 1e-6) & (pts < hi - 1e-6), axis=1)
    on_fault = (np.abs(pts[:, None, :] - fault_pts[None, :, :]).max(axis=2) < 1e-6).any(axis=1)
    free = inside & ~on_fault
    # the vertices of the cells beside the fault (a face on it) that are off it: where the bubbles act
    on_fault_cell = on_fault[cells]
    beside = np.zeros(len(pts), bool)
    beside[cells[on_fault_cell.sum(axis=1) == 3].ravel()] = True
    beside &= free
    assert beside.sum() >= 20, beside.sum()
    f, mag = nodal_forces(pts, cells, sig)
    res = np.linalg.norm(f[free], axis=1) / mag[free]
    # measured 5.7e-11 at most (the step's tolerance), 2.4e-14 beside the fault; the P1 part alone: 9.7e-3 there
    assert res.max() < 1e-9, res.max()


def test_glued_fault_uniform_state_unfaulted_stress(tmp_path):
    """Two blocks glued (cohesion 1e12 Pa) and sheared with the top and bottom tractions of the uniform state
    tau = G delta / L = 1 MPa: every cell, those beside the fault included, has the stress of the same mesh
    without the fault, sigma_xx = -p, sigma_yy = sigma_zz = -p / 3, sigma_xz = tau, to round-off."""
    p, tau = 1.0e6, 1.0e6
    uniform = ["-pfault_bc_top_traction", f"{tau},0,{-p / 3}", "-pfault_bc_bottom_traction", f"{-tau},0,{p / 3}"]
    proc, s = run_scene(TWO_BLOCKS, tmp_path / "glued", extra=uniform + ["-pfault_fault_fault_cohesion", "1e12",
                                                                          "-pfault_box_cells", "6,3,3"])
    assert s["converged"] and s["steps"][-1]["stick"] == 18, proc.stdout[-2000:]
    _, _, sig, _ = last_fields(tmp_path / "glued")
    exact = np.array([[-p, 0, tau], [0, -p / 3, 0], [tau, 0, -p / 3]])
    assert np.abs(sig - exact).max() < 1e-8 * p, np.abs(sig - exact).max()

"""Oedometer: settlement = c_M alpha |dp| H, reproduced by P1 to 1e-8 relative, at 1 and 2 ranks."""

import numpy as np
import pytest

from conftest import OEDOMETER, read_last_step, run_scene

E, NU, ALPHA, DP, H = 10e6, 0.25, 1.0, 0.1e6, 100.0
C_M = (1 + NU) * (1 - 2 * NU) / (E * (1 - NU))
EXACT = C_M * ALPHA * DP * H


def test_analytic_value():
    assert EXACT == pytest.approx(0.833333333, rel=1e-8)


@pytest.mark.parametrize("ranks", [1, 2])
def test_oedometer_settlement(tmp_path, ranks):
    _, summary = run_scene(OEDOMETER, tmp_path, ranks=ranks, extra=["-pfault_box_cells", "2,2,10"])
    assert summary["converged"]
    assert summary["ranks"] == ranks
    assert abs(summary["max_subsidence_m"] - EXACT) / EXACT < 1e-8
    # settlement grows linearly with the drawdown over the 10 steps
    subs = np.array([s["max_subsidence_m"] for s in summary["steps"]])
    assert np.allclose(subs, EXACT * np.arange(1, 11) / 10, rtol=1e-8)
    assert summary["max_horizontal_displacement_m"] < 1e-10
    # the displacement field is the linear profile u_z = -c_M |dp| (z + H)
    points, t, pd, _ = read_last_step(tmp_path)
    assert t == pytest.approx(10.0)
    uz = pd["displacement"][:, 2]
    assert np.allclose(uz, -C_M * DP * (points[:, 2] + H), atol=1e-9 * EXACT)
    for key in ("scene", "ranks", "mesh", "steps", "max_subsidence_m", "max_horizontal_displacement_m", "wall_s",
                "converged"):
        assert key in summary
    assert set(summary["mesh"]) >= {"nodes", "cells", "fault_faces"}
    assert set(summary["wall_s"]) >= {"mesh", "setup", "solve", "output", "total"}
    assert set(summary["steps"][0]) >= {"time_s", "newton_its", "ksp_its", "wall_s"}


def test_oedometer_iterative_solver(tmp_path):
    """CG + GAMG with the rigid-body near-null space reaches the same settlement."""
    _, summary = run_scene(OEDOMETER, tmp_path, ranks=2,
                           extra=["-pfault_box_cells", "3,3,30", "-pfault_solver", "gamg"])
    assert abs(summary["max_subsidence_m"] - EXACT) / EXACT < 1e-8
    assert all(s["ksp_its"] > 1 for s in summary["steps"])

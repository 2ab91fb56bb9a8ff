"""The iterative fault solver (config/solver/iterative.opts) against MUMPS on scenes beyond the two blocks: the
fissure box (a fissure that opens above a stiff step, faces stuck, slipping and open in one step) and the
calibrated Queretaro scene on a coarse mesh (groundwater flow, geostatic start, a fault that starts to slip).
Both solvers must take the same Newton iterations and give the same fault fields and displacements to 1e-8 of
their size, in a bounded number of Krylov iterations per Newton iteration."""

import numpy as np
import pytest

from conftest import read_last_step, run_scene
from test_faults import read_fault

pytestmark = pytest.mark.mpi

SCENES = {
    "fissure_box": ("config/hard/fissure_box.opts", ()),
    "queretaro_flow": ("config/queretaro_calibrated.opts",
                       ("-pfault_mesh_size_factor", "6", "-pfault_time_end", "6*year", "-pfault_time_steps", "3")),
}


@pytest.mark.parametrize("name", list(SCENES))
def test_iterative_solver_reaches_the_direct_solution(tmp_path, name):
    scene, extra = SCENES[name]
    out = {}
    for solver, opts in (("mumps", ()), ("iterative", ("-ksp_rtol", "1e-12"))):
        _, s = run_scene(scene, tmp_path / solver, ranks=2, extra=[*extra, "-pfault_solver", solver, *opts])
        assert s["converged"], solver
        out[solver] = (s, read_fault(tmp_path / solver), read_last_step(tmp_path / solver))
    (sd, fd, ud), (si, fi, ui) = out["mumps"], out["iterative"]
    assert [r["newton_its"] for r in si["steps"]] == [r["newton_its"] for r in sd["steps"]]
    assert si["solver"]["pc_type"] == "fieldsplit"
    assert 1 < si["solver"]["ksp_per_newton"] <= 40, si["solver"]
    assert np.array_equal(fi["state"], fd["state"])
    assert np.any(fd["state"] != 0), "the scene must leave the stick state somewhere"
    for key in ("slip_magnitude", "opening", "traction_normal"):
        scale = np.abs(fd[key]).max()
        assert scale > 0 and np.abs(fi[key] - fd[key]).max() <= 1e-8 * scale, key
    du = ui[2]["displacement"] - ud[2]["displacement"]
    assert np.abs(du).max() <= 1e-8 * np.abs(ud[2]["displacement"]).max()

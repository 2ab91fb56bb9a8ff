"""Faces that hold: in every step of a scene, a stuck face adds no slip and a closed face has no opening, to the
solver's tolerance (below 1e-9 m, or 1e-8 of the largest jump of the step where that is larger). The face-mean
jump (P1 + face bubbles) is what the laws act on and what fault.xdmf reports (pfault.faults.bubbles).

Scenes with stuck, slipping and open faces in one run: the two blocks in the stick and slip cases, the
fissure box with a geostatic start (drawdown and recovery: faces slip, then stick with a permanent offset), the
two case studies at mesh size factor 4 (3 steps; Wuxi on 1 and 2 ranks). (A penalty face's closed opening is its
law's, -t_N / k: tests/verification/test_faults.py.)"""

import numpy as np
import pytest

from conftest import FISSURE_BOX, QUERETARO, TWO_BLOCKS, WUXI
from pfault.faults import contact as ct
from pfault.post import rundir

ABS = 1e-9          # m
REL = 1e-8          # of the largest jump of the step

SCENES = {
    "two_blocks_stick": (TWO_BLOCKS, ["-pfault_box_cells", "6,3,3", "-pfault_bc_xmax_displacement", "0,0,0.2",
                                      "-pfault_bc_top_traction", "8e5,0,-333333.3333333333",
                                      "-pfault_bc_bottom_traction", "-8e5,0,333333.3333333333"]),
    "two_blocks_slip": (TWO_BLOCKS, ["-pfault_box_cells", "6,3,3", "-pfault_time_steps", "3"]),
    "fissure_box": (FISSURE_BOX, ["-pfault_geostatic", "true", "-pfault_material_sand_head_drawdown",
                                  "0:0,1*year:20,2*year:0,3*year:0", "-pfault_time_steps", "3",
                                  "-pfault_time_end", "3*year"]),
    # the case studies' small runs (tests/verification/test_case_studies.py: conftest.shared_run)
    "wuxi": (WUXI, ["-pfault_mesh_size_factor", "4", "-pfault_time_steps", "3"]),
    "wuxi_2_ranks": (WUXI, ["-pfault_mesh_size_factor", "4", "-pfault_time_steps", "3"]),
    "queretaro": (QUERETARO, ["-pfault_mesh_size_factor", "4", "-pfault_time_steps", "3"]),
}


def jumps_by_step(out):
    first = rundir.read_fault(str(out), 0)
    steps = [first] + [rundir.read_fault(str(out), k) for k in range(1, first.num_steps)]
    return [s.cell_data for s in steps]


@pytest.mark.parametrize("name", list(SCENES))
def test_stuck_faces_add_no_slip_and_closed_faces_do_not_open(shared_run, name):
    scene, extra = SCENES[name]
    summary, out = shared_run(scene, 2 if name.endswith("2_ranks") else 1, extra)
    assert summary["converged"]
    steps = jumps_by_step(out)
    seen = np.zeros(3, np.int64)
    for prev, cur in zip(steps, steps[1:]):
        state = cur["state"]
        seen += np.bincount(state, minlength=3)
        largest = max(np.abs(cur["opening"]).max(), cur["slip_magnitude"].max())
        tol = max(ABS, REL * largest)
        closed = state != ct.OPEN
        stuck = state == ct.STICK
        assert np.abs(cur["opening"][closed]).max(initial=0.0) < tol, name
        increment = np.linalg.norm(cur["slip"] - prev["slip"], axis=1)
        assert increment[stuck].max(initial=0.0) < tol, name
    assert seen[ct.STICK] + seen[ct.SLIP] > 0, seen       # closed faces were tested

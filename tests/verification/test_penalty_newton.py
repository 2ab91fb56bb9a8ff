"""Newton on penalty faces stiffer than the cells around them (config/hard/fissure_box.opts, 2 ranks).

The fissure box with cells halved across the fault (32 x 8 x 10) and penalty faces at 100 E/h, the first year of
drawdown in one step. With full Newton steps the slipping faces' slip directions 2-cycle: a face in slip has no
stiffness along its slip, the elastic body sets its next slip increment and it overshoots the stick disc
(radius tau/k) to the other side; |F| stays at a few per cent of the load and no face changes state. Penalty
faces therefore default to backtracking steps (pfault.solver.setup.apply_solver_defaults).
"""

import re

import pytest

from conftest import FISSURE_BOX, run_scene

pytestmark = pytest.mark.mpi

SCENE = FISSURE_BOX
K = 8.0e6 / (100.0 / 8 * 100.0 / 10 / 2) ** 0.5 * 100        # 100 E/h of the clay on 12.5 m x 10 m halves
STEP = ["-pfault_box_cells", "32,8,10", "-pfault_fault_fissure_method", "penalty",
        "-pfault_fault_fissure_penalty_normal", f"{K!r}", "-pfault_fault_fissure_penalty_tangential", f"{K!r}",
        "-pfault_time_end", "1*year", "-pfault_time_steps", "1", "-pfault_time_max_cuts", "0",
        "-pfault_contact_monitor"]


def monitor(stdout):
    """(|F|, faces that changed state) per Newton iteration of the contact monitor."""
    return [(float(m.group(1)), int(m.group(2) or 0)) for m in
            re.finditer(r"newton +\d+ +\|F\| (\S+) .*?(?:\((\d+) faces changed state\))?$", stdout, re.M)]


def test_penalty_faces_converge_with_the_default_steps(tmp_path):
    """Backtracking steps: converged in 8 Newton iterations (elastic trial included), 13/27/24 faces
    stuck/slipping/open, |F| from 8.2e5 to 6e-5."""
    proc, s = run_scene(SCENE, tmp_path / "default", ranks=2, extra=STEP)
    assert s["converged"], proc.stdout[-3000:]
    step = s["steps"][-1]
    assert step["newton_its"] <= 12, step["newton_its"]
    assert (step["stick"], step["slip"], step["open"]) == (13, 27, 24), step
    history = monitor(proc.stdout)
    assert history[-1][0] <= 1e-9 * history[0][0], history


def test_full_steps_cycle_on_the_same_step(tmp_path):
    """The reason for the default: with full steps (-snes_linesearch_type basic) the faces that stick in the answer
    are driven into slip (0/40/24 stuck/slipping/open after 21 iterations) and Newton then cycles with period 4,
    |F| between 3.8e6 and 6.8e6, above its first value 8.2e5, until the 50 iterations are spent."""
    proc, s = run_scene(SCENE, tmp_path / "basic", ranks=2, extra=STEP + ["-snes_linesearch_type", "basic"],
                        check=False)
    assert s is not None and not s["converged"]
    step = s["steps"][-1]
    assert step["stick"] == 0, step
    history = monitor(proc.stdout)
    assert len(history) == 51, len(history)
    assert min(f for f, _ in history[-20:]) >= history[0][0], history[-20:]

"""1-rank and 2-rank runs agree in partition-independent quantities; geostatic start changes nothing."""

import numpy as np
import pytest

from conftest import read_last_step, run_scene

SMALL = ["-pfault_box_cells", "6,6,6", "-pfault_time_steps", "3"]


@pytest.fixture(scope="module")
def demo_runs(tmp_path_factory):
    out = {}
    for ranks in (1, 2):
        d = tmp_path_factory.mktemp(f"demo{ranks}")
        _, out[ranks] = run_scene("config/demo.opts", d, ranks=ranks, extra=SMALL)
        out[(ranks, "dir")] = d
    return out


def test_one_and_two_ranks_agree(demo_runs):
    s1, s2 = demo_runs[1], demo_runs[2]
    assert s1["ranks"] == 1 and s2["ranks"] == 2
    for key in ("max_subsidence_m",):
        assert abs(s1[key] - s2[key]) <= 1e-10 * abs(s1[key])
    p1, _, d1, c1 = read_last_step(demo_runs[(1, "dir")])
    p2, _, d2, c2 = read_last_step(demo_runs[(2, "dir")])
    assert np.array_equal(p1, p2)  # output is in the serial numbering
    u1, u2 = d1["displacement"], d2["displacement"]
    assert np.linalg.norm(u1 - u2) <= 1e-10 * np.linalg.norm(u1)
    s1c, s2c = c1["stress"][0], c2["stress"][0]
    assert np.linalg.norm(s1c - s2c) <= 1e-10 * np.linalg.norm(s1c)


def test_summary_records_the_peak_memory_of_every_rank(demo_runs):
    """memory_peak_mib: one entry per rank, in MiB (a Python process with PETSc takes tens of MiB at least; a
    value in KiB or bytes would be far above the upper bound)."""
    for ranks in (1, 2):
        mem = demo_runs[ranks]["memory_peak_mib"]
        assert isinstance(mem, list) and len(mem) == ranks, mem
        assert all(20.0 < m < 65536.0 for m in mem), mem


def test_geostatic_start_does_not_change_the_drawdown_response(demo_runs, tmp_path):
    _, s = run_scene("config/demo.opts", tmp_path, ranks=2, extra=SMALL + ["-pfault_geostatic", "false"])
    ref = demo_runs[2]
    assert abs(s["max_subsidence_m"] - ref["max_subsidence_m"]) <= 1e-9 * ref["max_subsidence_m"]
    assert ref["steps"][0].get("initial")  # the geostatic run has an initial equilibrium step
    assert not s["steps"][0].get("initial")


def test_demo_subsidence_is_one_dimensional(demo_runs):
    """Laterally uniform layers under rollers: subsidence = sum of c_M alpha |dp| thickness."""
    g, rho_w = 9.80665, 1000.0
    cm = lambda e, nu: (1 + nu) * (1 - 2 * nu) / (e * (1 - nu))  # noqa: E731
    exact = cm(8e6, 0.3) * rho_w * g * 10 * 40 + cm(12e6, 0.3) * rho_w * g * 20 * 100
    assert demo_runs[1]["max_subsidence_m"] == pytest.approx(exact, rel=1e-9)

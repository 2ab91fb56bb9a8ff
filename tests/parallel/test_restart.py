"""Restart: a run continued with -pfault_restart from its checkpoint equals the uninterrupted run.

A 4-step run against a 2-step run (to half the end time) continued to 4 steps, on 1 and 2 ranks, for a scene
without faults or flow (oedometer), one with groundwater flow and no fault (a box drained by a well), one with
faults and flow (Queretaro at size factor 6: geostatic start, wells, slipping faces), one with faults and
no flow (Wuxi at size factor 4: geostatic start, an opening fissure), two faults crossing (an X junction: its
checkpoint holds 4 sides a vertex) and one loaded by a MODFLOW model's heads (the example site: the continued run reads the heads again, between saved times). Compared: the summary maxima, and every
dataset of every output step in fields.h5, fault.h5 and surface.h5 (steps 1-2 copied from the first run, 3-4
recomputed), each relative to its largest magnitude. Observed: 1 rank, identical bit for bit (the first step
after the restart refactors the same Jacobian); 2 ranks, ~1e-14 (Wuxi, the flow box), as two uninterrupted
2-rank runs differ.

The flow model's CG + BoomerAMG is not bitwise reproducible from run to run on 2 ranks: two identical 2-rank
Queretaro runs differ by up to ~5e-10 at the default -flow_ksp_rtol 1e-10, a continued one by ~1.3e-9 (1 rank:
identical). The Queretaro runs here solve the flow to 1e-13, which puts that noise at ~1e-12, below the
tolerance of the comparison.

The fault scenes' Krylov solves run to -ksp_rtol here (-ksp_atol 0). At their default they stop at a tenth of
the step's nonlinear tolerance (StepSolver.load_tolerance), and two runs agree only to that tolerance where they
stop at different iterates: on another partition, or where the direct solver keeps its factors for a different
number of iterations (a decision timed in the run, so it follows the machine's load). Measured with the default,
on a machine loaded with two other processes: continued runs 1e-7 to 4e-6 of the displacement off.
"""

import json
import os

import numpy as np
import pytest

from conftest import (FISSURE_BOX, OEDOMETER, QUERETARO, TWO_BLOCKS, WUXI, compare_runs, run_scene,
                      write_flow_box)

RTOL = 1e-10
FLOW_BOX_FILE = "flow_box.opts"     # conftest.FLOW_BOX, written by write_flow_box
SCENES = {
    "oedometer": (OEDOMETER, (), "10", "5"),
    "queretaro": (QUERETARO, ("-pfault_mesh_size_factor", "6", "-flow_ksp_rtol", "1e-13", "-ksp_atol",
                                            "0"), "10*year", "5*year"),
    # slip and open faces in steps 3 and 4 (to 2 years no face slips in step 4 since the initial stress has the
    # face bubbles' strain)
    # Krylov solves on kept factors (whether factors are kept depends on measured times, so on the machine's load)
    # stop at -ksp_rtol: at 1e-12 two runs differ by round-off, not by the default 1e-8's Krylov error
    "wuxi": (WUXI, ("-pfault_mesh_size_factor", "4", "-ksp_atol", "0", "-ksp_rtol", "1e-12"), "1*year",
             "0.5*year"),
    "flow": (FLOW_BOX_FILE, (), "2*day", "1*day"),
    "heads": ("config/site_example/site.opts", (), "10*year", "5*year"),    # MODFLOW heads, mesh origin
    "junction": ("config/hard/two_faults.opts", ("-pfault_box_fault_planes", "fa:x:175:0:200:-40:0,"
                 "fb:y:175:0:200:-40:0", "-ksp_atol", "0"), "4*year", "2*year"),   # X junction: 4 sides a vertex
}


def scene_file(tmp_path, name):
    """Options file of SCENES[name] (the flow box is written into tmp_path)."""
    opts = SCENES[name][0]
    return write_flow_box(tmp_path) if opts == FLOW_BOX_FILE else opts


def _steps(extra, n, end):
    return [*extra, "-pfault_time_steps", str(n), "-pfault_time_end", end]


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("scene", sorted(SCENES))
def test_restart_equals_uninterrupted_run(tmp_path, scene, ranks):
    _, extra, end, half = SCENES[scene]
    opts = scene_file(tmp_path, scene)
    ref, part = tmp_path / "ref", tmp_path / "part"
    _, s_ref = run_scene(opts, ref, ranks=ranks, extra=_steps(extra, 4, end))
    _, s_part = run_scene(opts, part, ranks=ranks, extra=_steps(extra, 2, half))
    assert s_ref["converged"] and s_part["completed_steps"] == [1, 2]
    # continued in place (the default output directory of a restart is the run it continues)
    proc, s = run_scene(opts, part, ranks=ranks, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part)])
    assert "continuing" in proc.stdout
    assert s["converged"] and not s["interrupted"] and s["restart"]["step"] == 2
    assert s["completed_steps"] == [1, 2, 3, 4]
    if scene in ("queretaro", "wuxi"):
        # the steps after the restart move faces that slip and open
        assert all(r["slip"] > 0 and r["open"] > 0 for r in s["steps"] if r["step"] >= 3)
    if scene in ("queretaro", "flow"):
        assert s["steps"][-1]["max_drawdown_m"] > s["steps"][2]["max_drawdown_m"] > 0
    compare_runs(ref, part, RTOL)


@pytest.mark.parametrize("written, continued", [(1, 2), (2, 1), (2, 3)])
def test_restart_on_another_rank_count(tmp_path, written, continued):
    """A checkpoint does not depend on the partition: a run continued on another number of ranks (from a
    checkpoint gathered to rank 0 on 1 rank, or written by every rank on 2) agrees with the uninterrupted run
    to the agreement between rank counts of the flow's iterative solver (~1e-10, see
    tests/verification/test_case_studies.py), with the Krylov solves run to -ksp_rtol (SCENES; at the default, 2 ranks
    continued on 3 were 3e-8 of the displacement off)."""
    import h5py
    opts, extra, end, half = SCENES["queretaro"]
    ref, part, cont = tmp_path / "ref", tmp_path / "part", tmp_path / "cont"
    run_scene(opts, ref, ranks=written, extra=_steps(extra, 4, end))
    run_scene(opts, part, ranks=written, extra=_steps(extra, 2, half))
    with h5py.File(part / "checkpoint.h5", "r") as h5:
        assert h5.attrs["ranks"] == written and h5.attrs["step"] == 2
    _, s = run_scene(opts, cont, ranks=continued, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part)])
    assert s["ranks"] == continued and s["completed_steps"] == [1, 2, 3, 4]
    assert all(r["slip"] > 0 for r in s["steps"] if r["step"] >= 3)
    compare_runs(ref, cont, 1e-8)
    # the run it continued is left as it was
    with open(part / "summary.json") as fh:
        assert json.load(fh)["completed_steps"] == [1, 2]


def test_restart_rejects_a_time_grid_without_the_checkpoint(tmp_path):
    opts, extra, end, half = SCENES["oedometer"]
    part = tmp_path / "part"
    run_scene(opts, part, extra=_steps(extra, 2, half))
    before = sorted(os.listdir(part))
    proc, _ = run_scene(opts, part, extra=[*_steps(extra, 3, end), "-pfault_restart", str(part)], check=False)
    assert proc.returncode == 1 and "not a point of the time grid" in proc.stderr
    proc, _ = run_scene(opts, part, extra=[*_steps(extra, 2, half), "-pfault_restart", str(part)], check=False)
    assert proc.returncode == 1 and "later -pfault_time_end" in proc.stderr
    other = tmp_path / "other"
    proc, _ = run_scene("config/demo.opts", other, extra=["-pfault_box_cells", "3,3,3", "-pfault_restart", str(part)],
                        check=False)
    assert proc.returncode == 1 and "that run had" in proc.stderr
    assert sorted(os.listdir(part)) == before and not os.path.exists(other)


def test_restart_reads_a_format_5_checkpoint_with_every_face_broken(tmp_path):
    """Format 6 adds each fault face's broken flag and break time: a format-5 checkpoint (whose faults were all
    pre-existing) continues with every face broken, without a break time: slipped as in the uninterrupted run."""
    import h5py
    ref, part = tmp_path / "ref", tmp_path / "part"
    run_scene(TWO_BLOCKS, ref, extra=_steps(("-ksp_atol", "0"), 2, "1"))
    run_scene(TWO_BLOCKS, part, extra=_steps(("-ksp_atol", "0"), 1, "0.5"))
    with h5py.File(part / "checkpoint.h5", "r+") as h5:
        assert h5.attrs["format"] == 7 and h5["faults/broken"][()].all()
        assert np.isnan(h5["faults/break_time"][()]).all()
        h5.attrs["format"] = 5
        del h5["faults/broken"], h5["faults/break_time"]
    _, s = run_scene(TWO_BLOCKS, part, extra=[*_steps(("-ksp_atol", "0"), 2, "1"), "-pfault_restart", str(part)])
    assert s["converged"] and s["completed_steps"] == [1, 2]
    f = s["faults"]["fault"]
    assert f["faces_broken"] == f["faces"] and f["first_break_time_s"] is None
    with open(ref / "summary.json") as fh:
        s_ref = json.load(fh)
    assert s_ref["max_fault_slip_m"] > 0.1
    assert s["max_fault_slip_m"] == pytest.approx(s_ref["max_fault_slip_m"], rel=RTOL)


def test_restart_reads_a_format_6_checkpoint(tmp_path):
    """Format 6 also holds the faces' pore pressure and tractions (``faults/pn``, ``faults/traction``), which u and
    the loads of the checkpoint's time give: a format-6 checkpoint with them (here made up, to show they are not
    read) continues as the uninterrupted run does."""
    import h5py
    ref, part = tmp_path / "ref", tmp_path / "part"
    run_scene(TWO_BLOCKS, ref, extra=_steps(("-ksp_atol", "0"), 2, "1"))
    run_scene(TWO_BLOCKS, part, extra=_steps(("-ksp_atol", "0"), 1, "0.5"))
    with h5py.File(part / "checkpoint.h5", "r+") as h5:
        n = h5.attrs["fault_faces"]
        h5.attrs["format"] = 6
        h5["faults/pn"], h5["faults/traction"] = np.full(n, 1e9), np.full((n, 3), -1e9)
    _, s = run_scene(TWO_BLOCKS, part, extra=[*_steps(("-ksp_atol", "0"), 2, "1"), "-pfault_restart", str(part)])
    with open(ref / "summary.json") as fh:
        s_ref = json.load(fh)
    assert s["converged"] and s["completed_steps"] == [1, 2]
    assert s_ref["max_fault_slip_m"] > 0.1
    assert s["max_fault_slip_m"] == pytest.approx(s_ref["max_fault_slip_m"], rel=RTOL)


def test_restart_reads_a_format_4_checkpoint_without_faults_only(tmp_path):
    """Format 5 adds each fault face's slid flag: a format-4 checkpoint of a scene without faults continues as
    before; one with faults (it has no flags) is refused in one line, before anything is written."""
    import h5py
    opts, extra, end, half = SCENES["oedometer"]
    part = tmp_path / "part"
    run_scene(opts, part, extra=_steps(extra, 2, half))
    with h5py.File(part / "checkpoint.h5", "r+") as h5:
        h5.attrs["format"] = 4
    _, s = run_scene(opts, part, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part)])
    assert s["converged"] and s["completed_steps"][-1] == 4
    faulted = tmp_path / "faulted"
    run_scene(TWO_BLOCKS, faulted, extra=_steps((), 1, "0.5"))
    with h5py.File(faulted / "checkpoint.h5", "r+") as h5:
        assert h5.attrs["format"] == 7 and h5["faults/slid"].shape == (h5.attrs["fault_faces"],)
        h5.attrs["format"] = 4
        del h5["faults/slid"], h5["faults/broken"], h5["faults/break_time"]
    before = {f: os.stat(faulted / f).st_mtime_ns for f in os.listdir(faulted)}
    proc, _ = run_scene(TWO_BLOCKS, faulted, extra=[*_steps((), 2, "1"), "-pfault_restart", str(faulted)],
                        check=False)
    assert proc.returncode == 1, proc.stderr
    assert [line for line in proc.stderr.splitlines() if line.startswith("pfault:")] == [
        f"pfault: error: -pfault_restart {faulted}: its checkpoint.h5 has format 4, written by another version of "
        "pfault; this one reads formats 5 to 7 (continue that run with the pfault that wrote it, or run it again)"]
    assert {f: os.stat(faulted / f).st_mtime_ns for f in os.listdir(faulted)} == before


def test_restart_refuses_a_checkpoint_of_another_format(tmp_path):
    """A checkpoint of format 2 (fault multipliers per serial cell, u/cell_ids and u/cell) is an input error in
    one line, before anything is written."""
    import h5py
    opts, extra, end, half = SCENES["oedometer"]
    part = tmp_path / "part"
    run_scene(opts, part, extra=_steps(extra, 2, half))
    with h5py.File(part / "checkpoint.h5", "r+") as h5:
        assert h5.attrs["format"] == 7
        h5.attrs["format"] = 2
        h5["u/cell_ids"], h5["u/cell"] = np.zeros(0, np.int64), np.zeros((0, 0))
    before = {f: os.stat(part / f).st_mtime_ns for f in os.listdir(part)}
    proc, _ = run_scene(opts, part, ranks=2, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part)],
                        check=False)
    assert proc.returncode == 1, proc.stderr
    assert [line for line in proc.stderr.splitlines() if line.startswith("pfault:")] == [
        f"pfault: error: -pfault_restart {part}: its checkpoint.h5 has format 2, written by another version of "
        "pfault; this one reads formats 5 to 7 (continue that run with the pfault that wrote it, or run it again)"]
    assert {f: os.stat(part / f).st_mtime_ns for f in os.listdir(part)} == before


def test_restart_keeps_the_model_but_may_extend_the_loading(tmp_path):
    """A continued run with another material modulus (a model change) is an input error naming the option,
    before anything is written; one that extends a loading table past the old end time goes on."""
    opts, extra, end, half = SCENES["oedometer"]
    part = tmp_path / "part"
    run_scene(opts, part, extra=_steps(extra, 2, half))
    before = {f: os.stat(part / f).st_mtime_ns for f in os.listdir(part)}
    proc, _ = run_scene(opts, part, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part),
                                           "-pfault_material_soil_young_modulus", "20*MPa"], check=False)
    assert proc.returncode == 1, proc.stderr
    assert ("that run had -pfault_material_soil_young_modulus 10*MPa, this one -pfault_material_soil_young_modulus "
            "20*MPa") in proc.stderr, proc.stderr
    assert {f: os.stat(part / f).st_mtime_ns for f in os.listdir(part)} == before
    proc, s = run_scene(opts, part, extra=[*_steps(extra, 8, "20"), "-pfault_restart", str(part),
                                           "-pfault_material_soil_pressure_change", "0:0,10:-0.1*MPa,20:-0.2*MPa"])
    assert s["converged"] and s["completed_steps"] == list(range(1, 9))


def test_restart_may_change_the_load_only_after_the_checkpoint(tmp_path):
    """The oedometer (dp from 0 to -0.1 MPa over 10 s, settlement c_M alpha |dp| H = 8.3333e-8 1/Pa * |dp| *
    100 m) stopped at t = 5 s. A table that changes the load up to 5 s, at a step's time or between two, is an
    input error naming the option, before anything is written; one that agrees up to 5 s and triples the
    load at 10 s gives the uninterrupted run's answer with that table (2.5 m)."""
    opts, extra, end, half = SCENES["oedometer"]
    option = "-pfault_material_soil_pressure_change"
    part, ref = tmp_path / "part", tmp_path / "ref"
    run_scene(opts, part, extra=_steps(extra, 2, half))
    before = {f: os.stat(part / f).st_mtime_ns for f in os.listdir(part)}
    for table, at, now, was in [("0:0,10:-0.2*MPa", 5, -100000, -50000),           # at the checkpoint's time
                                ("0:0,2:-0.05*MPa,5:-0.05*MPa,10:-0.1*MPa", 2, -50000, -20000)]:  # between steps
        proc, _ = run_scene(opts, part, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part), option, table],
                            check=False)
        assert proc.returncode == 1, proc.stderr
        assert proc.stderr.splitlines()[-1] == (
            f"pfault: error: -pfault_restart {part}: {option} changes the pore-pressure change of soil before "
            f"t = 5 s, where that run's checkpoint is (at t = {at} s: {now} Pa, that run {was} Pa); a continued "
            f"run may change a loading table only after that time: keep the values of that run ({option} "
            "0:0,10:-0.1*MPa) up to it")
        assert {f: os.stat(part / f).st_mtime_ns for f in os.listdir(part)} == before
    later = "0:0,5:-50*kPa,10:-0.3*MPa"         # the same up to 5 s, written another way, then steeper
    _, s_ref = run_scene(opts, ref, extra=[*_steps(extra, 4, end), option, later])
    proc, s = run_scene(opts, part, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part), option, later])
    assert s["converged"] and s["completed_steps"] == [1, 2, 3, 4] and s["restart"]["step"] == 2
    assert [r["max_subsidence_m"] for r in s["steps"]] == pytest.approx([0.20833333, 0.41666667, 1.4583333, 2.5],
                                                                        rel=1e-7)
    compare_runs(ref, part, RTOL)


def test_restart_may_change_the_well_rate_only_after_the_checkpoint(tmp_path, flow_box):
    """The flow box on 2 ranks, pumped at 3 L/s from day 1 (ramped up from 0 at t = 0), stopped after 1 day:
    continued with another rate on the first day it is an input error; with the rate doubled from day 1 to
    day 2 it equals the run pumped so from the start, and its drawdown differs from the unchanged one's."""
    opts = flow_box
    part, ref, same = tmp_path / "part", tmp_path / "ref", tmp_path / "same"
    run_scene(opts, part, ranks=2, extra=_steps((), 2, "1*day"))
    proc, _ = run_scene(opts, part, ranks=2, extra=[*_steps((), 4, "2*day"), "-pfault_restart", str(part),
                                                    "-pfault_flow_well_rate", "0:0,1*day:4*L/s"], check=False)
    assert proc.returncode == 1, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("pfault: error")]
    assert lines == [f"pfault: error: -pfault_restart {part}: -pfault_flow_well_rate changes the pumping rate of "
                     "each well before t = 86400 s, where that run's checkpoint is (at t = 86400 s: 0.004 m**3/s, "
                     "that run 0.003 m**3/s); a continued run may change a loading table only after that time: "
                     "keep the values of that run (-pfault_flow_well_rate 0:0,1*day:3*L/s) up to it"]
    doubled = ["-pfault_flow_well_rate", "0:0,1*day:3*L/s,2*day:6*L/s"]
    _, s_same = run_scene(opts, same, ranks=2, extra=_steps((), 4, "2*day"))
    run_scene(opts, ref, ranks=2, extra=[*_steps((), 4, "2*day"), *doubled])
    _, s = run_scene(opts, part, ranks=2, extra=[*_steps((), 4, "2*day"), "-pfault_restart", str(part), *doubled])
    assert s["completed_steps"] == [1, 2, 3, 4] and s["restart"]["step"] == 2
    assert s["steps"][-1]["max_drawdown_m"] > 1.2 * s_same["steps"][-1]["max_drawdown_m"]
    compare_runs(ref, part, RTOL)


def test_loading_tables_are_compared_by_the_load_they_give():
    """run_options.check_loading on option sets alone (no run): what counts is the load up to the checkpoint's
    time, in SI, whichever option or unit gives it; a load no option gives is zero (a boundary's factor 1)."""
    from pfault.errors import InputError
    from pfault.io.run_options import LOADING, check_loading
    from pfault.options import SPECS
    rho_g = 1000.0 * 9.80665

    def check(theirs, mine, until):
        check_loading("run", theirs, mine, until, 1000.0, 9.80665)

    dp = {"pfault_material_soil_pressure_change": f"0:0,10:{-10 * rho_g}"}
    check(dp, {"pfault_material_soil_head_drawdown": "0:0,10:10"}, 10.0)       # 10 m of head is that change
    check(dp, {"pfault_material_soil_head_drawdown": "0:0,10:10,20:50"}, 10.0)
    with pytest.raises(InputError, match=r"-pfault_material_soil_head_drawdown changes the pore-pressure change "
                                         r"of soil before t = 10 s.* \(at t = 10 s: -107873 Pa, "
                                         r"that run -98066.5 Pa\)"):
        check(dp, {"pfault_material_soil_head_drawdown": "0:0,10:11"}, 10.0)
    check({}, {"pfault_bc_top_history": "0:1,5:1,10:2"}, 5.0)                   # the factor is 1 until 5 s
    with pytest.raises(InputError, match=r"at t = 10 s: 2, that run 1\); .* \(no -pfault_bc_top_history\)"):
        check({}, {"pfault_bc_top_history": "0:1,5:1,10:2"}, 10.0)
    with pytest.raises(InputError, match=r"-pfault_material_rock_pressure_change changes .*\(at t = 0 s: -1 Pa, "
                                         r"that run 0 Pa\)"):
        check(dp, {**dp, "pfault_material_rock_pressure_change": "0:-1,10:-1"}, 1.0)
    check({"pfault_flow_well_rate": "0:0,1*year:300*L/s"}, {"pfault_flow_well_rate": "0:0,1*year:0.3"}, 1e9)
    with pytest.raises(InputError, match=r"-pfault_flow_well_rate changes"):
        check({"pfault_flow_well_rate": "0:0,1*year:300*L/s"}, {"pfault_flow_well_rate": "0:0,2*year:0.3"}, 1e6)
    # every table option is a loading table (a table another kind of option would need its own rule)
    for spec in SPECS:
        name = spec.name.replace("<material>", "soil").replace("<surface>", "top")
        assert (spec.kind == "table") == any(pattern.match(name) for pattern, *_ in LOADING), spec.name


def test_a_failed_continuation_keeps_the_checkpoint(tmp_path):
    """A continued run whose first step does not converge (exit 3) replaces the directory with its output,
    which keeps the checkpoint it started from: the run can be continued again."""
    opts, extra, end, half = SCENES["oedometer"]
    part = tmp_path / "part"
    run_scene(opts, part, extra=_steps(extra, 2, half))
    failing = ["-ksp_type", "cg", "-pc_type", "jacobi", "-ksp_max_it", "1"]
    proc, s = run_scene(opts, part, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part), *failing],
                        check=False)
    assert proc.returncode == 3 and not s["converged"] and s["completed_steps"] == [1, 2]
    _, s = run_scene(opts, part, extra=[*_steps(extra, 4, end), "-pfault_restart", str(part)])
    assert s["converged"] and s["completed_steps"] == [1, 2, 3, 4]


@pytest.mark.parametrize("ranks", [1, 2])
def test_restart_keeps_the_penalty_faces_history(tmp_path, ranks):
    """A penalty face's shear traction is the return map of its history, not a function of its jump: after a
    slip and an unloading the face sticks with less than its slip traction. Fissure box with penalty faces, the
    drawdown raised to 20 m in 2 years and lowered to 8 m by 4: the run continued from step 3 (the checkpoint
    keeps the faces' tractions) equals the uninterrupted one. From the jumps alone it differed by 7 %."""
    extra = ["-pfault_fault_fissure_method", "penalty", "-pfault_material_sand_head_drawdown",
             "0:0,2*year:20,4*year:8", "-ksp_atol", "0"]      # Krylov to -ksp_rtol: see the module's docstring
    ref, part = tmp_path / "ref", tmp_path / "part"
    _, s_ref = run_scene(FISSURE_BOX, ref, ranks=ranks, extra=_steps(extra, 4, "4*year"))
    run_scene(FISSURE_BOX, part, ranks=ranks, extra=_steps(extra, 3, "3*year"))
    _, s = run_scene(FISSURE_BOX, part, ranks=ranks,
                     extra=[*_steps(extra, 4, "4*year"), "-pfault_restart", str(part)])
    assert s["completed_steps"] == [1, 2, 3, 4]
    # slip faces in every step; the unloading steps change states (and the slip decreases)
    assert all(r["slip"] > 0 for r in s_ref["steps"])
    assert s_ref["steps"][3]["stick"] != s_ref["steps"][1]["stick"]
    compare_runs(ref, part, RTOL)

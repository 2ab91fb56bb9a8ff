"""Output that survives interruption; a new run never mixes its files with an old result; figures and the
earth-fissure hazard map of a plain run.

Interruptions are real signals sent to real runs (Queretaro at size factor 6: faults, flow, 6 steps) once the
first step's progress line is printed: the run ends after its current step with exit code 7, every file is
readable (meshio's TimeSeriesReader, h5py), summary.json lists the completed steps, and -pfault_restart
continues it to the end of the uninterrupted run, equal to 1e-10.
"""

import json
import os
import selectors
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import OEDOMETER, QUERETARO, REPO, WUXI, command, compare_runs, mpi_env, run_scene
from pfault import hazard
from pfault.io.output import RunWriter
from pfault.post import rundir

QRO = QUERETARO
# -flow_ksp_rtol 1e-13: 2-rank flow solves are reproducible from run to run only to ~ksp_rtol; -ksp_atol 0: the
# fault steps' Krylov solves run to -ksp_rtol, not to their default stop at a tenth of the step's tolerance,
# where runs agree only to that tolerance (test_restart.py)
QRO_OPTS = ["-pfault_mesh_size_factor", "6", "-flow_ksp_rtol", "1e-13", "-ksp_atol", "0", "-pfault_time_steps", "6",
            "-pfault_time_end", "6*year", "-pfault_figures", "false"]
TIMEOUT = 120


# ------------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------------
def start_and_signal(args, ranks, send, after="step    1 ", ready=None, mpirun_args=()):
    """Run pfault, call ``send(proc)`` once a stdout line starts with ``after`` (or, given ``ready``, once
    ``ready()`` is true: it is asked at least every 0.1 s); returns (exit code, stdout, stderr). ``mpirun_args``
    go to mpirun. Everything under a timeout: a run that hangs fails the test."""
    cmd = command(["-m", "pfault", *args], ranks)
    if ranks > 1:
        cmd = cmd[:1] + list(mpirun_args) + cmd[1:]
    proc = subprocess.Popen(cmd, cwd=REPO, env=mpi_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + TIMEOUT
    lines = []
    try:
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        while True:
            if time.monotonic() > deadline:
                raise AssertionError("the run was not ready for the signal in time:\n" + "".join(lines))
            if sel.select(timeout=0.1 if ready else 1.0):
                line = proc.stdout.readline()
                if not line:
                    raise AssertionError("the run ended before the signal:\n" + "".join(lines)
                                         + proc.stderr.read())
                lines.append(line)
                if ready is None and line.startswith(after):
                    break
            if ready is not None and ready():
                break
        sel.close()
        send(proc)
        out, err = proc.communicate(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, "".join(lines) + out, err


def children(pid):
    with open(f"/proc/{pid}/task/{pid}/children") as fh:
        return [int(p) for p in fh.read().split()]


def read_series(path):
    """Every step of an XDMF time series through meshio (times, displacement or cell data per step)."""
    import meshio
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        reader.read_points_cells()
        return [reader.read_data(k) for k in range(reader.num_steps)]


def check_readable(run_dir):
    """A run directory as a reader finds it: summary.json, the XDMF series (meshio) and their HDF5 files
    (h5py), the checkpoint; returns the summary."""
    import h5py
    with open(os.path.join(run_dir, "summary.json")) as fh:
        summary = json.load(fh)
    done = summary["completed_steps"]
    assert done == list(range(1, len(done) + 1))
    for name in ("fields", "fault", "surface"):
        steps = read_series(os.path.join(run_dir, name + ".xdmf"))
        # the initial state (step 0) and every completed step
        assert len(steps) == len(done) + 1, name
        assert [t for t, _, _ in steps] == pytest.approx([0.0] + [r["time_s"] for r in summary["steps"]
                                                                  if r.get("step", 0) > 0])
        with h5py.File(os.path.join(run_dir, name + ".h5"), "r") as h5:
            assert sorted(int(k) for k in h5["steps"]) == [0] + done
    with h5py.File(os.path.join(run_dir, "checkpoint.h5"), "r") as h5:
        assert h5.attrs["step"] == done[-1]
    assert not [f for f in os.listdir(run_dir) if f.endswith(".tmp")]
    assert not [f for f in os.listdir(os.path.dirname(run_dir)) if ".pfault-" in f], "a staging directory is left"
    return summary


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = {}
    for ranks in (1, 2):
        d = tmp_path_factory.mktemp(f"ref{ranks}") / "run"
        _, s = run_scene(QRO, d, ranks=ranks, extra=QRO_OPTS)
        assert s["converged"] and s["completed_steps"] == [1, 2, 3, 4, 5, 6]
        out[ranks] = str(d)
    return out


# ------------------------------------------------------------------------------------------------------
# interruption
# ------------------------------------------------------------------------------------------------------
def _to_process(sig):
    return lambda proc: os.kill(proc.pid, sig)


def _to_one_rank(sig):
    return lambda proc: os.kill(children(proc.pid)[-1], sig)


@pytest.mark.parametrize("ranks, sig, send", [
    (1, signal.SIGTERM, _to_process), (1, signal.SIGINT, _to_process),
    (2, signal.SIGTERM, _to_one_rank),      # one rank only: the stop decision is collective
    (2, signal.SIGUSR1, _to_process),       # mpirun forwards SIGUSR1
], ids=["1-SIGTERM", "1-SIGINT", "2-SIGTERM-one-rank", "2-SIGUSR1-mpirun"])
def test_interrupted_run_is_readable_and_restarts(tmp_path, reference, ranks, sig, send):
    run_dir = str(tmp_path / "run")
    code, out, err = start_and_signal([QRO, "-pfault_output_dir", run_dir, *QRO_OPTS], ranks, send(sig))
    assert code == 7, f"exit {code}\n{out}\n{err}"
    assert f"{signal.Signals(sig).name} received" in err
    summary = check_readable(run_dir)
    assert summary["interrupted"] and not summary["running"] and summary["converged"]
    assert summary["stop_signal"] == signal.Signals(sig).name
    done = summary["completed_steps"]
    assert 1 <= len(done) < 6
    assert f"stopped after step {done[-1]}" in out
    # continue to the end: the same as the run that was not interrupted
    _, s = run_scene(QRO, run_dir, ranks=ranks, extra=[*QRO_OPTS, "-pfault_restart", run_dir])
    assert s["completed_steps"] == [1, 2, 3, 4, 5, 6] and not s["interrupted"]
    compare_runs(reference[ranks], run_dir, 1e-10)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGUSR1])
def test_stop_signal_before_the_time_loop_is_one_line(tmp_path, sig):
    """SIGINT (Ctrl-C), SIGTERM or SIGUSR1 while a run starts up or meshes (a 30x30x30-cell box: seconds before
    its first step) stops it at once with exit code 7 and one line naming the signal, not a traceback or a
    death by signal; nothing is written."""
    run_dir = tmp_path / "run"
    proc = subprocess.Popen(command(["-m", "pfault", OEDOMETER, "-pfault_box_cells", "30,30,30",
                                     "-pfault_output_dir", str(run_dir)], 1),
                            cwd=REPO, env=mpi_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)
    wait_for_handler(proc.pid, signal.SIGUSR1)      # pfault's own handlers are in place (however busy the machine)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 7, out + err
    assert "step " not in out, "the signal came too late for this test: " + out
    assert err.splitlines() == [f"pfault: stopped: {sig.name} outside the time loop (start-up, meshing, setup, or the "
                                "figures at the end): the run stopped at once; every step it completed is on disk"]
    assert not run_dir.exists() and not [f for f in os.listdir(tmp_path) if ".pfault-" in f]


def default_sigint():
    """In the child before it starts: SIGINT as a terminal gives it. A process started with SIGINT ignored (a job in the
    background of a shell without job control, as under nohup) keeps it ignored, as Python and pfault rightly do."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def wait_for_handler(pid, sig, timeout=TIMEOUT):
    """Waits until process ``pid`` catches ``sig`` (its SigCgt mask in /proc/PID/status): python -m pfault installs
    its stop handlers first thing, so from then on a signal meets pfault's handling, not the interpreter's start."""
    bit = 1 << (int(sig) - 1)
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        with open(f"/proc/{pid}/status") as fh:
            caught = next(int(line.split()[1], 16) for line in fh if line.startswith("SigCgt:"))
        if caught & bit:
            return
        time.sleep(0.01)
    raise AssertionError(f"process {pid} did not install a handler of {sig.name} within {timeout} s")


def completed_on_disk(run_dir):
    """The completed steps summary.json in ``run_dir`` lists (none before the run's directory is in place
    after its first step; summary.json is replaced whole, so it is never read half-written)."""
    try:
        with open(os.path.join(run_dir, "summary.json")) as fh:
            return json.load(fh)["completed_steps"]
    except FileNotFoundError:
        return []


def check_killed(run_dir):
    """A run directory as a run killed during a step leaves it: summary.json and checkpoint.h5 of its last
    completed step, and in each series every completed step, readable, and at most the fields of the step in
    progress besides (flushed before it was killed); returns the summary and the checkpoint's step. A run
    killed between a step's checkpoint and its summary has a checkpoint one step ahead of summary.json, with
    the step records up to its own step, from which it continues."""
    import h5py
    with open(os.path.join(run_dir, "summary.json")) as fh:
        summary = json.load(fh)
    done = summary["completed_steps"]
    assert done == list(range(1, len(done) + 1)) and done
    assert summary["running"] and not summary["interrupted"] and "error" not in summary
    times = [0.0] + [r["time_s"] for r in summary["steps"] if r.get("step", 0) > 0]
    for name in ("fields", "fault", "surface"):
        steps = read_series(os.path.join(run_dir, name + ".xdmf"))
        assert len(steps) - len(times) in (0, 1), name
        assert [t for t, _, _ in steps[:len(times)]] == pytest.approx(times)
        with h5py.File(os.path.join(run_dir, name + ".h5"), "r") as h5:
            written = sorted(int(k) for k in h5["steps"])
        assert written in ([0] + done, [0] + done + [done[-1] + 1]) and len(written) >= len(steps), name
    with h5py.File(os.path.join(run_dir, "checkpoint.h5"), "r") as h5:
        step = int(h5.attrs["step"])
        records = json.loads(bytes(h5["steps"][()]).decode())
    assert step in (done[-1], done[-1] + 1)
    assert [r["step"] for r in records if r["step"] > 0] == list(range(1, step + 1))
    return summary, step


def continue_one_more_step(run_dir, k, at_signal):
    """A run of 0.01-year steps stopped after step k (at least the steps on disk when it was signalled) continues
    from its checkpoint for one more step of the same length, and its directory is then whole."""
    assert at_signal and at_signal[-1] <= k < 600
    more = [*QRO_OPTS[:6], "-pfault_time_steps", str(k + 1), "-pfault_time_end", f"{(k + 1) / 100}*year",
            "-pfault_restart", run_dir]
    _, s = run_scene(QRO, run_dir, ranks=2, extra=more)
    assert s["completed_steps"] == list(range(1, k + 2)) and s["restart"]["step"] == k
    assert not s["running"] and not s["interrupted"] and s["converged"]
    check_readable(run_dir)


def test_sigterm_to_mpirun_leaves_completed_steps(tmp_path):
    """Open MPI 4.1's mpirun does not pass SIGTERM on: it sends the ranks SIGCONT, then SIGTERM
    ``odls_base_sigkill_timeout`` seconds later (default 1) and SIGKILL as long after that, and exits with 1.
    The signal goes to mpirun once step 1 is on disk (summary.json lists it). The ranks stop after their step if
    it ends in time, or are killed in the middle of the next: either way every step completed by the signal is
    still there and readable, and the directory is what the summary says. The run then continues from its last
    completed step (one more step of the same length), and the continued directory is whole.

    A clean stop is not required here: once it has the signal, mpirun stops reading the ranks' output, and a
    rank that prints a progress line after its pipe has filled blocks until it is killed (seen with a longer
    ``odls_base_sigkill_timeout``: rank 0 blocked in its progress line, rank 1 waiting for it to close a file).
    The clean stop is tested with SIGTERM to a rank and SIGUSR1 to mpirun
    (test_interrupted_run_is_readable_and_restarts)."""
    run_dir = str(tmp_path / "run")
    # 600 steps of 0.01 year: the run lasts minutes; it is stopped after some tens
    opts = [*QRO_OPTS[:6], "-pfault_time_steps", "600", "-pfault_time_end", "6*year", "-pfault_figures", "false"]
    at_signal = []

    def send(proc):
        at_signal.extend(completed_on_disk(run_dir))
        os.kill(proc.pid, signal.SIGTERM)

    code, out, err = start_and_signal([QRO, "-pfault_output_dir", run_dir, *opts], 2, send,
                                      ready=lambda: bool(completed_on_disk(run_dir)))
    assert code != 0, out[-2000:] + err[-2000:]
    with open(os.path.join(run_dir, "summary.json")) as fh:
        interrupted = json.load(fh)["interrupted"]
    if interrupted:
        summary = check_readable(run_dir)
        k = summary["completed_steps"][-1]
        assert not summary["running"] and summary["stop_signal"] == "SIGTERM" and "error" not in summary
        assert f"pfault: stopped after step {k} (SIGTERM)" in out
        assert sorted(line for line in err.splitlines() if "received" in line) == [
            f"pfault: SIGTERM received (rank {r}): stopping after the current step (send it again to stop at once)"
            for r in (0, 1)]
    else:
        _, k = check_killed(run_dir)
    continue_one_more_step(run_dir, k, at_signal)


def test_killed_run_leaves_completed_steps(tmp_path):
    """Ranks killed outright (SIGKILL, as by the out-of-memory killer or a node failure) in the middle of a
    run, once step 1 is on disk: every step completed by then is still there and readable, summary.json says
    the run was going on (it had no chance to say more), and the run continues from its last completed step."""
    run_dir = str(tmp_path / "run")
    opts = [*QRO_OPTS[:6], "-pfault_time_steps", "600", "-pfault_time_end", "6*year", "-pfault_figures", "false"]
    at_signal = []

    def kill(proc):
        at_signal.extend(completed_on_disk(run_dir))
        time.sleep(0.5)                 # into a later step
        for pid in children(proc.pid):
            os.kill(pid, signal.SIGKILL)

    code, out, err = start_and_signal([QRO, "-pfault_output_dir", run_dir, *opts], 2, kill,
                                      ready=lambda: bool(completed_on_disk(run_dir)))
    assert code != 0 and "received" not in err
    _, k = check_killed(run_dir)
    continue_one_more_step(run_dir, k, at_signal)


# ------------------------------------------------------------------------------------------------------
# a new run and an old result
# ------------------------------------------------------------------------------------------------------
def _snapshot(d):
    out = {}
    for name in sorted(os.listdir(d)):
        with open(os.path.join(d, name), "rb") as fh:
            out[name] = fh.read()
    return out


def test_new_run_replaces_an_old_result_only_after_its_first_step(tmp_path):
    run_dir = tmp_path / "run"
    # the old result: a fault scene, plus a file pfault does not write
    run_scene(QRO, run_dir, extra=[*QRO_OPTS[:6], "-pfault_time_steps", "1"])
    (run_dir / "notes.txt").write_text("kept")
    old = _snapshot(run_dir)
    assert "fault.xdmf" in old
    # a run that fails at its first solve (a misspelled solver option) leaves it as it was
    proc, _ = run_scene(OEDOMETER, run_dir, extra=["-ksp_typo", "1"], check=False)
    assert proc.returncode == 1 and "ksp_typo" in proc.stderr
    assert _snapshot(run_dir) == old
    # so does one killed before its first step
    proc = subprocess.Popen(command(["-m", "pfault", OEDOMETER, "-pfault_output_dir", str(run_dir)], 1),
                            cwd=REPO, env=mpi_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=TIMEOUT)
    assert proc.returncode != 0 and _snapshot(run_dir) == old
    # a run that completes a step replaces it: no file of the old run is left (no fault output now)
    code, out, err = start_and_signal([OEDOMETER, "-pfault_output_dir", str(run_dir),
                                       "-pfault_time_steps", "2000", "-pfault_output_every", "1000",
                                       "-pfault_figures", "false"], 1, _to_process(signal.SIGTERM))
    assert code == 7, err
    new = _snapshot(run_dir)
    assert new["notes.txt"] == b"kept"
    assert not {"fault.xdmf", "fault.h5"} & set(new)
    assert b"oedometer" in new["options.txt"] and b"queretaro" not in new["options.txt"]
    summary = json.loads(new["summary.json"])
    assert summary["scene"] == "oedometer" and summary["interrupted"]
    assert len(read_series(str(run_dir / "fields.xdmf"))) == 2      # step 0 and the step it stopped after
    assert not [f for f in os.listdir(tmp_path) if ".pfault-" in f]


def test_run_writer_stages_commits_and_abandons(tmp_path):
    """RunWriter alone: files go to a hidden sibling until commit; abandon removes it and nothing else."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text('{"old": true}')
    (out / "fields.h5").write_bytes(b"old")
    (out / "log.txt").write_text("driver log")
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    tets = np.array([[0, 1, 2, 3]])

    w = RunWriter(str(out), pts, tets, [0], ["m"])
    stage = w.dir
    assert os.path.dirname(stage) == str(tmp_path) and os.path.basename(stage).startswith(".out.pfault-")
    w.write_step(0, 0.0, {"displacement": np.zeros((4, 3))}, {})
    w.abandon()
    assert not os.path.exists(stage) and (out / "fields.h5").read_bytes() == b"old"

    w = RunWriter(str(out), pts, tets, [0], ["m"])
    for k in range(3):
        w.write_step(k, float(k), {"displacement": np.full((4, 3), float(k))}, {"stress": np.zeros((1, 9))})
        w.write_summary({"step": k})
        if k == 0:
            assert json.loads((out / "summary.json").read_text()) == {"old": True}
        w.commit()
        # readable after every step while the writer still has the file open: by another process, as a
        # viewer would (in this process HDF5 would share the writer's open file)
        probe = ("import meshio, sys; r = meshio.xdmf.TimeSeriesReader(sys.argv[1]); r.read_points_cells(); "
                 "print([(t, d['displacement'][0, 0]) for t, d, _ in map(r.read_data, range(r.num_steps))])")
        seen = subprocess.run([sys.executable, "-c", probe, str(out / "fields.xdmf")], capture_output=True,
                              text=True, timeout=TIMEOUT)
        assert seen.stdout.strip() == str([(float(i), float(i)) for i in range(k + 1)]), seen.stderr
    w.close()
    assert sorted(os.listdir(out)) == ["fields.h5", "fields.xdmf", "log.txt", "summary.json"]
    assert (out / "log.txt").read_text() == "driver log"
    assert not [f for f in os.listdir(tmp_path) if ".pfault-" in f]


# ------------------------------------------------------------------------------------------------------
# figures and the hazard map
# ------------------------------------------------------------------------------------------------------
def test_hazard_fields_of_an_affine_displacement():
    """For u = A (x, y) + c the strain and tilt are exact on any triangles."""
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.random((30, 2)) * 100.0, np.zeros(30)])
    tris = np.array([rng.choice(30, 3, replace=False) for _ in range(40)])
    A = np.array([[2e-3, -1e-3], [3e-3, -4e-3], [5e-4, -1.2e-3]])     # rows: u_x, u_y, u_z
    u = pts[:, :2] @ A.T + np.array([0.1, 0.2, -0.3])
    f = hazard.surface_fields(pts, tris, u)
    exx, eyy, exy = A[0, 0], A[1, 1], 0.5 * (A[0, 1] + A[1, 0])
    e1 = 0.5 * (exx + eyy) + np.hypot(0.5 * (exx - eyy), exy)
    ok = np.abs(np.cross(pts[tris[:, 1], :2] - pts[tris[:, 0], :2], pts[tris[:, 2], :2] - pts[tris[:, 0], :2])) > 1e-6
    assert np.allclose(f["horizontal_strain"][ok], e1, rtol=1e-9)
    assert np.allclose(f["angular_distortion"][ok], np.hypot(*A[2]), rtol=1e-9)


def test_post_processing_commands_name_a_directory_without_a_run(tmp_path):
    """python -m pfault.post.figures, and python -m pfault.io.figures (the command README gave before post-processing
    had its own package), on a directory that holds no run: exit 1, one line naming it; python -m pfault.post.gis
    on a path that is no directory: exit 2 and its usage line."""
    for module in ("pfault.post.figures", "pfault.io.figures"):
        proc = subprocess.run([sys.executable, "-m", module, str(tmp_path)], cwd=REPO, env=mpi_env(),
                              capture_output=True, text=True, timeout=120)
        assert (proc.returncode, proc.stdout) == (1, ""), module
        assert proc.stderr == f"figures: {tmp_path}: no summary.json (not a pfault run directory)\n", module
    proc = subprocess.run([sys.executable, "-m", "pfault.post.gis", str(tmp_path / "none")], cwd=REPO, env=mpi_env(),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr == "usage: python -m pfault.post.gis RUN_DIR  (a run written with -pfault_crs)\n"


def test_plain_run_writes_figures_and_the_fissure_hazard_map(tmp_path):
    """mpirun -n 2 python -m pfault config/wuxi.opts (coarse): the figures, and the land surface's largest
    tensile strain over the ridge crest, where the fissure opens (x = 1000 m): in a surface triangle that
    touches the fissure trace, two orders of magnitude above the strain 300 m away from it."""
    run_dir = tmp_path / "wuxi"
    proc, s = run_scene(WUXI, run_dir, ranks=2,
                        extra=["-pfault_mesh_size_factor", "4", "-pfault_time_steps", "2", "-pfault_figures", "true"])
    for name in ("fault_opening_slip.png", "subsidence_map.png", "histories.png", "hazard_map.png"):
        with open(run_dir / name, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n", name
    surf = rundir.read_surface(str(run_dir))
    strain, tilt = surf.cell_data["horizontal_strain"], surf.cell_data["angular_distortion"]
    i = int(np.argmax(strain))
    x = surf.points[surf.cells[i], 0]
    assert np.any(np.abs(x - 1000.0) < 1e-6), x
    centroid = surf.points[surf.cells].mean(axis=1)
    far = np.abs(centroid[:, 0] - 1000.0) > 300.0
    assert strain[far].max() < 0.02 * strain[i]
    assert s["max_horizontal_strain"] == pytest.approx(strain[i], rel=1e-12)
    assert s["max_horizontal_strain_xy"] == pytest.approx(centroid[i, :2].tolist(), rel=1e-12)
    assert s["max_angular_distortion"] == pytest.approx(tilt.max(), rel=1e-12)
    assert abs(s["max_angular_distortion_xy"][0] - 1000.0) < 100.0
    # the fissure opens by centimetres; the strain next to it is of order 1e-3
    assert 1e-3 < s["max_horizontal_strain"] < 1e-1 and s["max_fault_opening_m"] > 0.01

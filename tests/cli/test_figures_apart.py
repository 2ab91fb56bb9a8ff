"""-pfault_figures apart (the default): the run ends once its files are written, and a process of its own, outside
the MPI job, draws the figures after it (pfault.post.figures_apart)."""

import os
import re
import time

from conftest import OEDOMETER, run

from pfault.post import figures_apart


def test_run_ends_before_its_figures_drawn_apart(tmp_path):
    out = tmp_path / "oed"
    # a process of its own (here=False): the drawing must outlive mpirun and its ranks, which the MPI workers
    # of the suite's other runs do not end
    proc = run(["-m", "pfault", OEDOMETER, "-pfault_output_dir", str(out)], ranks=2, here=False)
    match = re.search(r"pfault: figures drawn apart by process (\d+) into (\S+) \(python -m pfault.post.figures",
                      proc.stdout)
    assert match and match.group(2) == str(out) and proc.stdout.count("figures drawn apart") == 1, proc.stdout
    pid, deadline = int(match.group(1)), time.monotonic() + 180
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)             # the drawing outlived mpirun and its ranks
        except ProcessLookupError:
            break
        time.sleep(0.2)
    else:
        raise AssertionError("the figures' process did not end in 180 s")
    for name in ("subsidence_map.png", "histories.png", "hazard_map.png"):
        with open(out / name, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n", name
    assert not (out / figures_apart.LOG).exists()          # nothing went wrong
    assert not list(out.glob("*.tmp"))


def test_the_drawing_is_no_rank_of_the_job(monkeypatch):
    for name, value in (("OMPI_COMM_WORLD_RANK", "0"), ("PMIX_RANK", "0"), ("PMI_RANK", "0"), ("OPAL_PREFIX", "/x"),
                        ("OMP_NUM_THREADS", "1")):
        monkeypatch.setenv(name, value)
    monkeypatch.setenv("PYTHONPATH", "/elsewhere")
    env = figures_apart._environment()
    assert not [k for k in env if k.startswith(("OMPI_", "PMIX_", "PMI_", "OPAL_"))]
    assert env["OMP_NUM_THREADS"] == "1"
    root = os.path.dirname(os.path.dirname(os.path.abspath(figures_apart.__file__)))
    assert env["PYTHONPATH"].split(os.pathsep) == [os.path.dirname(root), "/elsewhere"]


def test_a_failure_is_said_in_the_log(tmp_path):
    """A directory without a run's files: the drawing says why in figures.log and exits 0 (the run stands)."""
    assert figures_apart.main([str(tmp_path)]) == 0
    text = (tmp_path / figures_apart.LOG).read_text()
    assert text.startswith("pfault: warning: figures not written (") and text.count("\n") == 1, text

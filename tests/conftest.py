"""Shared helpers: run pfault (or a script) on 1 rank directly or on N ranks under mpirun, with timeouts.

They are studies/run.py's: the repository root goes first on the import path so that the tests import the
studies (studies/) beside the package."""

import json
import os
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from studies.run import command, read_summary, run_captured  # noqa: E402,F401  (command: tests that start runs)
from studies.run import mpi_env as study_mpi_env  # noqa: E402

PY = sys.executable
TIMEOUT = 600


def mpi_env():
    return study_mpi_env(oversubscribe=True)


def run(args, ranks=1, timeout=TIMEOUT, check=True):
    proc = run_captured(args, ranks, timeout=timeout, env=mpi_env())
    if check and proc.returncode != 0:
        raise AssertionError(f"{' '.join(args)} on {ranks} rank(s) exited {proc.returncode}\n"
                             f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}")
    return proc


def run_scene(scene, outdir, ranks=1, extra=(), check=True):
    # no PNG figures unless a test asks for them (-pfault_figures true): matplotlib adds ~3 s to every run
    figures = [] if "-pfault_figures" in extra else ["-pfault_figures", "false"]
    proc = run(["-m", "pfault", scene, "-pfault_output_dir", str(outdir), *figures, *extra], ranks=ranks,
               check=check)
    return proc, read_summary(outdir)


def run_script(script, ranks=1, args=()):
    """Run tests/scripts/<script> and parse the JSON it prints on its last line."""
    proc = run([os.path.join("tests", "scripts", script), *args], ranks=ranks)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def read_last_step(outdir):
    import meshio
    reader = meshio.xdmf.TimeSeriesReader(os.path.join(str(outdir), "fields.xdmf"))
    points, _ = reader.read_points_cells()
    for k in range(reader.num_steps):
        t, point_data, cell_data = reader.read_data(k)
    return points, t, point_data, cell_data


@pytest.fixture
def repo():
    return REPO

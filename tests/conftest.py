"""Shared helpers: run pfault (or a script) on 1 rank directly or on N ranks under mpirun, with timeouts."""

import json
import os
import subprocess
import sys

import pytest

from pfault.study import mpi_env as study_mpi_env

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = sys.executable
TIMEOUT = 600


def mpi_env():
    """Also puts this checkout first on the path: a script in tests/scripts (whose own folder is first on its
    path) imports the pfault of this checkout, not the one the virtual environment has installed."""
    env = study_mpi_env(oversubscribe=True)
    env["PYTHONPATH"] = os.pathsep.join([REPO] + [p for p in [env.get("PYTHONPATH")] if p])
    return env


def command(args, ranks):
    """Serial runs use plain python; parallel runs use mpirun (oversubscribed beyond the cores)."""
    if ranks == 1:
        return [PY] + args
    return ["mpirun", "-n", str(ranks), "--oversubscribe", PY] + args


def run(args, ranks=1, timeout=TIMEOUT, check=True):
    proc = subprocess.run(command(args, ranks), cwd=REPO, env=mpi_env(), capture_output=True, text=True,
                          timeout=timeout)
    if check and proc.returncode != 0:
        raise AssertionError(f"{' '.join(args)} on {ranks} rank(s) exited {proc.returncode}\n"
                             f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}")
    return proc


def run_scene(scene, outdir, ranks=1, extra=(), check=True):
    # no PNG figures unless a test asks for them (-pfault_figures true): matplotlib adds ~3 s to every run
    figures = [] if "-pfault_figures" in extra else ["-pfault_figures", "false"]
    proc = run(["-m", "pfault", scene, "-pfault_output_dir", str(outdir), *figures, *extra], ranks=ranks,
               check=check)
    summary = None
    path = os.path.join(str(outdir), "summary.json")
    if os.path.exists(path):
        with open(path) as fh:
            summary = json.load(fh)
    return proc, summary


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

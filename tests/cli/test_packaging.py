"""pfault installed, not run from this checkout: pip installs the package into a folder of its own, and that copy
runs from a working directory outside the repository on copies of the scenes, so nothing is found through the
checkout. -pfault_solver NAME finds the solver files the package carries (importlib.resources), a user's
solver/NAME.opts beside the scene wins over them, and an unknown name lists the known ones.

About 30 s: the install (pip, offline, no build isolation) and three small runs."""

import json
import os
import shutil
import subprocess

import pytest

from conftest import PY, REPO

SOLVERS = ("gamg", "iterative", "mumps")
TIMEOUT = 300
FIND = "import sys; from pfault.solver.setup import find_solver_file as f; print(f(sys.argv[1], sys.argv[2]))"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(folder holding the installed pfault, a working directory outside the repository)."""
    base = tmp_path_factory.mktemp("packaging")
    source = base / "source"             # a copy of the sources: the build leaves nothing in the checkout
    shutil.copytree(os.path.join(REPO, "pfault"), source / "pfault", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(os.path.join(REPO, name), source / name)
    site = base / "site"
    subprocess.run([PY, "-m", "pip", "install", "-q", "--disable-pip-version-check", "--no-deps", "--no-index",
                    "--no-build-isolation", "--target", str(site), str(source)], check=True, capture_output=True,
                   timeout=TIMEOUT)
    work = base / "work"
    work.mkdir()
    return site, work


def packaged(site, name):
    return str(site / "pfault" / "solver" / "options" / f"{name}.opts")


def python(installed, *args, check=True):
    """``python ARGS`` in the working directory, importing the installed pfault (PYTHONPATH), not this one."""
    site, work = installed
    env = dict(os.environ, PYTHONPATH=str(site), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    proc = subprocess.run([PY, *args], cwd=work, env=env, capture_output=True, text=True, timeout=TIMEOUT)
    if check:
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc


def scene(installed, name, folder="."):
    """A copy of config/NAME in a folder of the working directory (no solver/ beside it unless a test adds one)."""
    path = installed[1] / folder / name
    path.parent.mkdir(exist_ok=True)
    shutil.copy(os.path.join(REPO, "config", name), path)
    return str(path)


def test_the_installed_copy_carries_the_solver_files(installed):
    site, _ = installed
    assert python(installed, "-c", "import pfault; print(pfault.__file__)").stdout.strip() == \
        str(site / "pfault" / "__init__.py")
    assert sorted(os.listdir(site / "pfault" / "solver" / "options")) == [f"{s}.opts" for s in SOLVERS]


@pytest.mark.parametrize("name", SOLVERS)
def test_a_solver_name_is_the_package_file_from_any_directory(installed, name):
    site, _ = installed
    assert python(installed, "-c", FIND, name, scene(installed, "oedometer.opts")).stdout.strip() == \
        packaged(site, name)


def test_a_solver_file_beside_the_scene_wins(installed):
    _, work = installed
    own = work / "own" / "solver" / "mumps.opts"
    own.parent.mkdir(parents=True)
    own.write_text("-pc_type lu\n")
    assert python(installed, "-c", FIND, "mumps", scene(installed, "oedometer.opts", "own")).stdout.strip() == \
        str(own)


def test_an_unknown_solver_lists_the_known_ones(installed):
    proc = python(installed, "-m", "pfault", scene(installed, "oedometer.opts"), "-pfault_output_dir", "unknown",
                  "-pfault_solver", "superfast", check=False)
    assert proc.returncode == 1, proc.stderr
    assert "-pfault_solver superfast" in proc.stderr and f"({', '.join(SOLVERS)})" in proc.stderr, proc.stderr


@pytest.mark.parametrize("name,solver", [("oedometer.opts", "mumps"), ("oedometer.opts", "gamg"),
                                         ("two_blocks.opts", "iterative")])
def test_a_scene_runs_with_the_package_solver_file(installed, name, solver):
    site, work = installed
    out = work / f"out_{name}_{solver}"
    python(installed, "-m", "pfault", scene(installed, name), "-pfault_output_dir", str(out), "-pfault_figures",
           "false", "-pfault_solver", solver)
    with open(out / "summary.json") as fh:
        summary = json.load(fh)
    assert summary["converged"]
    assert summary["solver"]["file"] == packaged(site, solver)

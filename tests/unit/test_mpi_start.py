"""Open MPI's start as ``python -m pfault`` sets it before MPI_Init (pfault.__main__._mpi_on_one_node): the ob1
messaging layer on one node, the isolated singleton without a launcher, and whatever the user chose kept."""

import os
import subprocess
import sys

import pytest

from pfault import __main__ as pfault_main
from pfault.tools.runs import environment

LAUNCH = ("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE", "OMPI_COMM_WORLD_LOCAL_SIZE", "PMIX_RANK", "PMI_RANK",
          "OMPI_MCA_pml", "OMPI_MCA_ess_singleton_isolated", "OPAL_PREFIX")


@pytest.fixture
def env(monkeypatch, tmp_path):
    for var in LAUNCH:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))          # no user parameter file unless a test writes one
    return monkeypatch


def test_singleton_is_isolated_and_on_ob1(env):
    pfault_main._mpi_on_one_node()
    assert os.environ["OMPI_MCA_ess_singleton_isolated"] == "1"
    assert os.environ["OMPI_MCA_pml"] == "ob1"


def test_ranks_on_one_node_take_ob1(env):
    for var, value in (("OMPI_COMM_WORLD_RANK", "1"), ("OMPI_COMM_WORLD_SIZE", "2"),
                       ("OMPI_COMM_WORLD_LOCAL_SIZE", "2")):
        env.setenv(var, value)
    pfault_main._mpi_on_one_node()
    assert os.environ["OMPI_MCA_pml"] == "ob1"
    assert "OMPI_MCA_ess_singleton_isolated" not in os.environ


def test_ranks_across_nodes_keep_open_mpis_selection(env):
    for var, value in (("OMPI_COMM_WORLD_RANK", "1"), ("OMPI_COMM_WORLD_SIZE", "64"),
                       ("OMPI_COMM_WORLD_LOCAL_SIZE", "32")):
        env.setenv(var, value)
    pfault_main._mpi_on_one_node()
    assert "OMPI_MCA_pml" not in os.environ


def test_the_users_choice_stays(env, tmp_path):
    env.setenv("OMPI_MCA_pml", "ucx")
    pfault_main._mpi_on_one_node()
    assert os.environ["OMPI_MCA_pml"] == "ucx"
    env.delenv("OMPI_MCA_pml")
    (tmp_path / ".openmpi").mkdir()
    (tmp_path / ".openmpi" / "mca-params.conf").write_text("# mine\npml = ucx   # the fabric\n")
    pfault_main._mpi_on_one_node()
    assert "OMPI_MCA_pml" not in os.environ
    (tmp_path / ".openmpi" / "mca-params.conf").write_text("pml = ^ucx\n")       # an exclusion is not a choice
    pfault_main._mpi_on_one_node()
    assert os.environ["OMPI_MCA_pml"] == "ob1"


STARTS = """
import os, sys
sys.argv = ["pfault"]
from pfault import __main__ as pfault_main
pfault_main._mpi_on_one_node()
from mpi4py import MPI
total = MPI.COMM_WORLD.allreduce(MPI.COMM_WORLD.rank + 1)
if MPI.COMM_WORLD.rank == 0:
    print(os.environ["OMPI_MCA_pml"], total)
"""


@pytest.mark.parametrize("ranks", [1, 2])
def test_the_ranks_talk_with_the_start_on_one_node(ranks):
    cmd = [sys.executable, "-c", STARTS]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks)] + cmd
    env = {k: v for k, v in environment().items() if k not in ("OMPI_MCA_pml", "OMPI_MCA_ess_singleton_isolated")}
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["ob1", str(ranks * (ranks + 1) // 2)]

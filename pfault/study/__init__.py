"""Studies built on runs: figures of a run directory (``figures``), the two case studies of Franceschini et al.
(Proc. IAHS 372, 2015) against the paper (``casestudies``), the contact solver's hard cases (``hard_cases``) and
accuracy against cost on problems with a known answer (``accuracy``)."""

import os


def mpi_env(oversubscribe=False):
    """Environment for running pfault under Open MPI here: one BLAS thread per rank, Open MPI allowed as root,
    optionally more ranks than cores (the same settings as scripts/env.sh), and this checkout of pfault first
    on the import path."""
    env = dict(os.environ)
    # the subprocesses import this pfault (not another checkout an editable install may point to)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", OMPI_MCA_btl_vader_single_copy_mechanism="none")
    if oversubscribe:
        env["OMPI_MCA_rmaps_base_oversubscribe"] = "1"
    if os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env

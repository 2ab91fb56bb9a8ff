"""Studies built on finished runs: figures of a run directory (``figures``) and the two case studies of
Franceschini et al. (Proc. IAHS 372, 2015) against the paper (``casestudies``)."""

import os


def mpi_env(oversubscribe=False):
    """Environment for running pfault under Open MPI here: one BLAS thread per rank, Open MPI allowed as root,
    optionally more ranks than cores (the same settings as scripts/env.sh)."""
    env = dict(os.environ)
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", OMPI_MCA_btl_vader_single_copy_mechanism="none")
    if oversubscribe:
        env["OMPI_MCA_rmaps_base_oversubscribe"] = "1"
    if os.geteuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env

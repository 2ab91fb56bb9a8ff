"""Input errors that every rank raises together."""


class InputError(Exception):
    """A problem with user input: an option, a file or a value. One line, naming the fix."""


def collective_check(comm, message):
    """Raise InputError on every rank if any rank reports a problem.

    ``message`` is this rank's verdict: None when fine, otherwise a one-line text. The first
    non-empty message (lowest rank) is raised everywhere, so no rank is left waiting.
    """
    from mpi4py import MPI  # noqa: F401  (mpi4py is the communicator layer of petsc4py)

    mpicomm = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
    messages = mpicomm.allgather(message)
    for m in messages:
        if m:
            raise InputError(m)


def run_on_root(comm, func, *args, **kwargs):
    """Run ``func`` on rank 0 only and share its InputError verdict with every rank.

    Returns func's result on rank 0 and None elsewhere; an InputError on rank 0 is raised on all ranks.
    """
    mpicomm = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
    result, message = None, None
    if mpicomm.rank == 0:
        try:
            result = func(*args, **kwargs)
        except InputError as exc:
            message = str(exc)
    message = mpicomm.bcast(message, root=0)
    if message:
        raise InputError(message)
    return result

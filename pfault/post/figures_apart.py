"""The PNG figures of a finished run drawn by a process of their own, which the run does not wait for
(``-pfault_figures apart``, the default).

matplotlib takes 2-5 s of one core for the four figures of a paper-size run (16 CPU s on a loaded machine), as long
as the rest of the main job's end: the run starts

    python -m pfault.post.figures_apart RUN_DIR

once its summary.json is written, in a session of its own (out of reach of mpirun's and the terminal's signals),
outside MPI (the launcher's variables removed: it is no rank of the job), at a lower priority, and ends. That
process draws the figures into RUN_DIR (pfault.post.figures.write_run_figures: each written whole and renamed into
place) and writes what went wrong, if anything, into RUN_DIR/figures.log (removed when nothing did).
``python -m pfault.post.figures RUN_DIR`` draws them again at any time.
"""

from __future__ import annotations

import os
import subprocess
import sys

from .figures import write_run_figures

LOG = "figures.log"
NICE = 10               # the drawing yields to the work the user starts next
# variables through which a process takes part in an MPI job (Open MPI, PMIx, MPICH's PMI, Hydra)
_LAUNCHER_PREFIXES = ("OMPI_", "PMIX_", "PMI_", "OPAL_", "PRTE_", "HYDRA_", "MPI_LOCAL")


def _environment() -> dict[str, str]:
    """This process's environment without the MPI launcher's variables, with this pfault first on the path."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(_LAUNCHER_PREFIXES)}
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def start(run_dir: str) -> int:
    """Start the process that draws the figures of ``run_dir`` and return its id, without waiting for it."""
    proc = subprocess.Popen([sys.executable, "-m", "pfault.post.figures_apart", os.path.abspath(run_dir)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=_environment(), start_new_session=True, close_fds=True)
    return proc.pid


def main(argv: list[str] | None = None) -> int:
    """Draw the figures of RUN_DIR, the messages into RUN_DIR/figures.log (kept only when there are any)."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        sys.stderr.write("usage: python -m pfault.post.figures_apart RUN_DIR\n")
        return 2
    run_dir = args[0]
    log = os.path.join(run_dir, LOG)
    with open(log, "w") as fh:
        sys.stderr = fh
        try:
            write_run_figures(run_dir)
        except Exception as exc:  # noqa: BLE001  (a figure that fails is said in the log; the run's results stand)
            fh.write(f"pfault: figures not written ({type(exc).__name__}: {exc}); python -m pfault.post.figures "
                     f"{run_dir} makes them\n")
        finally:
            sys.stderr = sys.__stderr__
    if os.path.getsize(log) == 0:
        os.remove(log)
    return 0


if __name__ == "__main__":
    try:
        os.nice(NICE)
    except OSError:
        pass
    raise SystemExit(main())

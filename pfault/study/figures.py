"""PNG figures of run directories:

    python -m pfault.study.figures RUN_DIR [RUN_DIR ...] [--step K]

``K`` is the index of the output time (default -1: the last one). The figures and the readers of a run
directory (``read_summary``, ``read_fields``, ``read_fault``, ``top_surface``, ...) live in pfault.io.figures,
which a plain run also uses to draw them at its end; they are re-exported here for the case studies.
"""

from __future__ import annotations

import argparse
import os
import sys

from ..io.figures import *  # noqa: F401,F403  (the readers and figures, under their names)
from ..io.figures import __doc__ as _figures_doc
from ..io.figures import make_figures


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m pfault.study.figures", description=__doc__.splitlines()[0],
                                 epilog=_figures_doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="a pfault output directory")
    ap.add_argument("--step", type=int, default=-1, help="output time index (default -1: the last)")
    args = ap.parse_args(argv)
    status = 0
    for d in args.run_dirs:
        if not os.path.exists(os.path.join(d, "summary.json")):
            sys.stderr.write(f"figures: {d}: no summary.json (not a pfault run directory)\n")
            status = 1
            continue
        for p in make_figures(d, args.step):
            print(p)
    return status


if __name__ == "__main__":
    sys.exit(main())

"""What the figures of a run directory share: pyplot on matplotlib's Agg backend, a PNG written whole, the titles."""

from __future__ import annotations

import os
from typing import Any

from ..units import YEAR
from .rundir import read_summary


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (files, no display)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save(fig: Any, out: str) -> str:
    """Write a figure whole (temporary file, then os.replace) and close it; returns the path."""
    import matplotlib.pyplot as plt
    fig.savefig(out + ".tmp", dpi=110, format="png")
    plt.close(fig)
    os.replace(out + ".tmp", out)
    return out


def title_time(t: float) -> str:
    return f"t = {t / YEAR:.3g} years"


def scene_name(run_dir: str) -> str:
    """The scene's name in summary.json, else the run directory's name."""
    try:
        summary = read_summary(run_dir)
    except (OSError, ValueError):
        summary = None
    return (summary or {}).get("scene", os.path.basename(os.path.abspath(run_dir)))

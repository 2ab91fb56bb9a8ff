"""What the step records, fields.h5 and summary.json report of the materials with memory, measured from their
memory at a state (collective where it says so), and the checks of their initial state.

Compression is positive in what is reported: the preconsolidation as a vertical effective stress (p'_c over the
oedometric ratio (1+nu)/(3(1-nu)): the vertical stress at which a cell consolidated at K0 reaches its cap; in an
oedometer the largest vertical stress it has borne), the compaction as vertical strain, its inelastic part the
plastic one (-eps^p_zz) and its elastic part the rest (-(eps_zz - eps^p_zz), relative to the initial state). Heads
are relative to the initial heads (m; the pore-pressure change over rho_w g): the preconsolidation (critical) head is
the head at which a cell reaches its preconsolidation under oedometric conditions, the current head less the margin
(pfault.physics.soil.head_margin), so the margin is the further drawdown a cell bears before it compacts
inelastically again (0 while it does).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

from ..errors import InputError
from ..physics import soil as sl
from ..scene import soil_cell_message
from .cells import SoilCells
from .history import SoilLoad, SoilMemory

REPORT_STRAIN = 1e-12       # plastic volumetric strain of a step below which a cell is reported elastic (round-off)


@dataclass(frozen=True)
class LayerFigures:
    """A material with memory at a step: its cells, those that compacted on the virgin line in the last step, the
    mean head margin and critical head of its cells (m, weighted by their volumes: pfault.soils.columns on why a mean),
    its largest inelastic compaction (vertical strain) and the smallest head margin of its cells (m: 0 where a cell
    compacts on its virgin line)."""
    cells: int
    cells_virgin: int
    head_margin_m: float
    critical_head_m: float
    max_compaction_inelastic: float
    min_head_margin_m: float


@dataclass(frozen=True)
class SoilMeasures:
    """The materials with memory at a step: each one's figures (by name)."""
    layers: dict

    def as_json(self) -> dict:
        return {"soils": {name: asdict(f) for name, f in self.layers.items()}}


def check_start(soil: SoilCells, mpi: Any, below: np.ndarray) -> None:
    """InputError on every rank for the first layer whose cells cannot start (pfault.scene.soil_cell_message, on the
    cells of every rank). Collective."""
    parts = mpi.gather((soil.layer, soil.compression, soil.recompression, below), root=0)
    message = None
    if mpi.rank == 0:
        layer, comp, recomp, low = (np.concatenate([p[i] for p in parts]) for i in range(4))
        for k, settings in enumerate(soil.layers):
            at = layer == k
            message = message or soil_cell_message(settings, comp[at], recomp[at], low[at])
    message = mpi.bcast(message, root=0)
    if message is not None:
        raise InputError(message)


def column_sums(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """(n, q): the rows of ``values`` (k, q) summed by ``index`` (k,), as np.add.at into zeros (the same sums, in
    the same order), by one np.bincount per column: a tenth of numpy 1.24's ufunc.at time."""
    out = np.empty((n, values.shape[1]))
    for j in range(values.shape[1]):
        out[:, j] = np.bincount(index, weights=values[:, j], minlength=n)
    return out


def per_cell(soil: SoilCells, memory: SoilMemory, load: SoilLoad) -> dict:
    """The reported quantities of each cell of ``soil`` at ``memory``'s state: preconsolidation_stress (Pa),
    preconsolidation_head and head_margin (m), compaction_elastic and compaction_inelastic (vertical strains)."""
    law = memory.law
    margin = sl.head_margin(soil.law, law, soil.alpha, soil.gamma_w)
    inelastic = -law.plastic_strain[:, 2, 2]
    return {"preconsolidation_stress": sl.vertical_preconsolidation_of(soil.law, law),
            "preconsolidation_head": load.dp / soil.gamma_w - margin, "head_margin": margin,
            "compaction_elastic": -memory.strain[:, 2, 2] - inelastic, "compaction_inelastic": inelastic}


def cell_fields(soil: SoilCells, n_cells: int, memory: SoilMemory, load: SoilLoad) -> dict:
    """fields.h5's cell fields (``per_cell``) per local cell, NaN outside the materials with memory."""
    out = {}
    for name, values in per_cell(soil, memory, load).items():
        full = np.full(n_cells, np.nan)
        full[soil.cells] = values
        out[name] = full
    return out


def layer_figures(soil: SoilCells, mpi: Any, memory: SoilMemory, load: SoilLoad, volume: np.ndarray) -> SoilMeasures:
    """Per layer (by name): its cells, those that compacted on the virgin line in the last step, the mean head margin
    and critical head of its cells (the further drawdown it bears before it compacts inelastically again, and the
    head at which that happens; weighted by the cells' ``volume``), and its largest inelastic compaction (vertical
    strain). Collective."""
    n = len(soil.layers)
    q = per_cell(soil, memory, load)
    sums = column_sums(soil.layer, np.column_stack([np.ones(len(soil.layer)), memory.branch == sl.VIRGIN, volume,
                                                   volume * q["head_margin"], volume * q["preconsolidation_head"]]), n)
    largest = np.array([q["compaction_inelastic"][soil.layer == k].max(initial=-np.inf) for k in range(n)])
    smallest = np.array([q["head_margin"][soil.layer == k].min(initial=np.inf) for k in range(n)])
    mpi.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    mpi.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
    mpi.Allreduce(MPI.IN_PLACE, smallest, op=MPI.MIN)
    v = np.where(sums[:, 2] > 0, sums[:, 2], 1.0)
    return SoilMeasures({name: LayerFigures(int(c[0]), int(c[1]), float(c[3] / w), float(c[4] / w), float(m),
                                            float(h))
                         for name, c, w, m, h in zip(soil.names, sums, v, largest, smallest)})


def _smallest(values) -> float:
    """The smallest finite value (NaN when none: a record written before the figure existed)."""
    return float(min((v for v in values if np.isfinite(v)), default=np.nan))


def soil_summary(soil: SoilCells, mpi: Any, steps: list) -> dict:
    """summary.json's ``soils`` (per layer: its cells, the largest inelastic compaction and the smallest head margin
    over the steps ``steps``, and at the last of them the cells that compacted on the virgin line, the mean head
    margin and critical head), ``min_head_margin_m`` (the smallest head margin of any cell of any layer over the
    steps: 0 when some cell compacted on its virgin line, the further drawdown the soils would have borne elastically
    otherwise) and the land surface's inelastic and elastic subsidence (pfault.soils.columns.SoilSurface's figures:
    their largest over the steps, and at the last)."""
    per = [r["soils"] for r in steps if "soils" in r]
    last = per[-1] if per else {}
    out = {name: {**last.get(name, {}),
                  "max_compaction_inelastic": max([p[name]["max_compaction_inelastic"] for p in per], default=0.0),
                  "min_head_margin_m": _smallest(p[name].get("min_head_margin_m", np.nan) for p in per)}
           for name in soil.names}
    surface = [r for r in steps if "max_subsidence_inelastic_m" in r]
    figures = {"soils": out, "min_head_margin_m": _smallest(f["min_head_margin_m"] for f in out.values())}
    for key in ("max_subsidence_inelastic_m", "max_subsidence_elastic_m"):
        figures[key] = max([r[key] for r in surface], default=0.0)
    for key in ("subsidence_inelastic_at_max_m", "subsidence_elastic_at_max_m"):
        figures["final_" + key] = surface[-1][key] if surface else 0.0
    return figures

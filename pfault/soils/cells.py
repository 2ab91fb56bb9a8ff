"""The cells of the materials with memory and what their law needs, built once with the model.

A material given compression indices (or CSUB's skeletal storages) has no drained modulus. Its cells take their
effective stress from the law (pfault.soils.term), which needs the initial stress; before it, the geostatic gravity
solve and a flow model's default storage need an elastic modulus: the law's own swelling-line modulus at an
estimate of the initial stress (``reference_young``), the overburden of the cell's depth below the land surface's
highest point, buoyant below the water table; the face bubbles of a fault beside them take the law's virgin
tangent at that stress (``bubble_moduli``). In flat layers the gravity solve's vertical stress does not depend on
the moduli; where it does (arching around a stiff body) only their ratios matter, which the estimate gets from the
law.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from mpi4py import MPI

from ..errors import InputError
from ..materials.properties import per_cell
from ..physics import soil as sl

# Krylov methods for symmetric operators only: the law's consistent tangent is not symmetric
SYMMETRIC_KRYLOV = ("cg", "pipecg", "pipecgrr", "groppcg", "pipelcg", "fcg", "pipefcg", "cr", "pipecr", "minres",
                    "symmlq", "stcg", "nash", "gltr", "qcg")


@dataclass(frozen=True)
class SoilCells:
    """The local cells of the materials with memory (``cells``, local ids, ascending) and per cell: its layer
    (index into ``layers``, the settings of the materials with memory, pfault.scene.Soil, in the mesh's order), its
    law, Biot coefficient, the hydrostatic pore pressure of the geostatic start at its centroid (Pa), the
    preconsolidation's value (NaN for a normally consolidated layer) and the two compressions as given (Cc and Cr,
    or Sskv and Sske: the cells' checks); ``gamma_w`` = rho_w g (Pa/m)."""
    cells: np.ndarray
    layer: np.ndarray
    layers: tuple
    law: sl.SoilLaw
    alpha: np.ndarray
    static_pressure: np.ndarray
    precon_value: np.ndarray
    compression: np.ndarray
    recompression: np.ndarray
    gamma_w: float

    def elastic(self, n_cells: int) -> np.ndarray:
        """Which of ``n_cells`` local cells are not these (the elastic operator's stiffness mask)."""
        out = np.ones(n_cells, bool)
        out[self.cells] = False
        return out

    @property
    def names(self) -> tuple:
        return tuple(s.name for s in self.layers)

    @property
    def kinds(self) -> tuple:
        """Each layer's preconsolidation: normal, stress, ratio or head."""
        return tuple(s.preconsolidation for s in self.layers)


def soil_cells(soils: list, cell_material: np.ndarray, poisson: np.ndarray, alpha: np.ndarray, z: np.ndarray,
               settings: Any, field_values: dict | None = None, cell_ids: np.ndarray | None = None) -> SoilCells:
    """SoilCells of a mesh's cells (``cell_material``; Poisson ratio, Biot coefficient and centroid height ``z`` per
    cell) for ``soils``, one pfault.scene.Soil or None per material; fields' values at ``cell_ids`` as
    pfault.materials.properties.per_cell reads them."""
    mats = [k for k, s in enumerate(soils) if s is not None]
    layer_of = np.full(len(soils), -1, np.int64)
    layer_of[mats] = np.arange(len(mats))
    layer = layer_of[cell_material]
    cells = np.flatnonzero(layer >= 0)

    def values(attr: str) -> np.ndarray:
        return per_cell([getattr(s, attr) if s is not None else None for s in soils], cell_material, field_values,
                        cell_ids)[cells]
    compression, recompression = values("compression"), values("recompression")
    index = np.array([s is not None and s.form == "index" for s in soils])[cell_material][cells]
    nu, a = poisson[cells], alpha[cells]
    gamma_w = settings.water_density * settings.gravity
    law = sl.concatenate([sl.index_law(compression[index], recompression[index], values("void_ratio")[index],
                                       nu[index]),
                          sl.storage_law(recompression[~index], compression[~index], nu[~index], a[~index],
                                         gamma_w)])
    order = np.concatenate([np.flatnonzero(index), np.flatnonzero(~index)])
    law = law[np.argsort(order, kind="stable")]              # back to the cells' order
    p0 = gamma_w * np.maximum(settings.water_table - z[cells], 0.0)
    return SoilCells(cells, layer[cells], tuple(soils[k] for k in mats), law, a, p0,
                     values("preconsolidation_value"), compression, recompression, float(gamma_w))


def reference_young(cells: SoilCells, density: np.ndarray, z: np.ndarray, z_top: float, settings: Any) -> np.ndarray:
    """The modulus E (Pa) per cell of ``cells`` before the initial stress is known: the law's swelling line at the
    mean stress of the estimated overburden, K = p'/kappa (index form; 1/kappa in the storage form), E = 3 K (1 - 2 nu).
    The estimate: sigma'_v = g (rho d - rho_w max(min(water table, z_top) - z, 0)) at the depth d = z_top - z below the
    land surface's highest point (``z_top``), the cell's dry weight where that is not positive (a soil lighter than
    water), and p' = sigma'_v (1 + 2 K0)/3 (K0 the geostatic start's)."""
    c, g, law = cells.cells, settings.gravity, cells.law
    d = z_top - z[c]
    wet = np.maximum(min(settings.water_table, z_top) - z[c], 0.0)
    sv = g * (density[c] * d - settings.water_density * wet)
    sv = np.where(sv > 0, sv, g * density[c] * d)
    nu = law.poisson
    k0 = np.full(len(c), settings.k0) if settings.k0 >= 0 else nu / (1 - nu)
    bulk = np.where(law.index_form, sv * (1 + 2 * k0) / 3, 1.0) / law.kappa
    return 3 * bulk * (1 - 2 * nu)


def bubble_moduli(cells: SoilCells, lam: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Lame parameters of a fault's face bubbles (pfault.faults.bubbles) in every local cell: the cell's own
    (``lam``, ``mu``), except in the cells of the materials with memory, which take the law's tangent on its virgin
    line at their reference stress: the bulk modulus of the reference (``reference_young``, the swelling line's)
    times kappa/lambda (Cr/Cc or Sske/Sskv), its shear modulus unchanged (the law's shear modulus is the swelling
    line's on both branches).

    Condensing a cell's bubbles takes K_ub K_bb^-1 K_bu off its P1 stiffness: all an elastic cell of the bubbles'
    modulus can give (a Schur complement of the cell with its bubbles, which is positive). A cell with memory takes
    its P1 stiffness from the law's tangent, whose bulk modulus on the virgin line is Cc/Cr times its swelling
    line's: with bubbles at the swelling line's bulk modulus the condensation took off more than such a cell holds
    once it compacted (docs/theory.md, "Soils that remember": the faulted aquifer's sand cells beside the fault
    indefinite, a near-null mode of the Jacobian on the faces' multipliers, Newton stalled). A cell unloaded to
    its swelling line is stiffer in bulk than its bubbles, which then take off less than it holds."""
    c = cells.cells
    lam, mu = np.array(lam, dtype=float, copy=True), np.array(mu, dtype=float, copy=True)
    bulk = (lam[c] + 2.0 / 3.0 * mu[c]) * (cells.law.kappa / cells.law.lam)
    lam[c] = bulk - 2.0 / 3.0 * mu[c]
    return lam, mu


def check_krylov(soil_names: tuple, ksp_type: str) -> None:
    """A Krylov method for symmetric operators cannot solve with the law's tangent: InputError naming the fix."""
    if soil_names and ksp_type.lower() in SYMMETRIC_KRYLOV:
        raise InputError(f"-ksp_type {ksp_type}: a method for symmetric operators, and the materials with memory "
                         f"({', '.join(soil_names)}) give a non-symmetric tangent; use -pfault_solver auto, mumps or "
                         "iterative (FGMRES), or -ksp_type gmres")


def land_top(coords: np.ndarray, ground: np.ndarray, mpi: Any = None) -> float:
    """The height of the land surface's highest point: of the vertices ``ground`` (on every rank with ``mpi``)."""
    top = float(np.max(coords[ground, 2], initial=-np.inf))
    if mpi is not None:
        top = mpi.allreduce(top, op=MPI.MAX)
    return top


def with_reference(props: Any, soils: list, cell_material: np.ndarray, z: np.ndarray, z_top: float, settings: Any,
                   field_values: dict | None = None, cell_ids: np.ndarray | None = None) -> tuple[SoilCells, Any]:
    """The SoilCells of the cells (``soil_cells``) and their properties ``props``
    (pfault.materials.properties.CellProperties) with the reference modulus (``reference_young``) as the Young's
    modulus of the materials with memory."""
    cells = soil_cells(soils, cell_material, props.poisson_ratio, props.biot_coefficient, z, settings, field_values,
                       cell_ids)
    young = np.array(props.young_modulus, dtype=float, copy=True)
    young[cells.cells] = reference_young(cells, props.density, z, z_top, settings)
    return cells, replace(props, young_modulus=young)

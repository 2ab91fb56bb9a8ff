"""Material properties per cell: a number per material, or a spatial field interpolated at the cell centroids.

A material property option (``-pfault_material_<material>_<property>``) takes a number, as it always did, or
names a field, as PyLith's spatial databases do::

    -pfault_material_clay_young_modulus field:config/site_example/clay_modulus.csv
    -pfault_material_clay_young_modulus field:maps/clay.nc,variable=E,outside=nearest

The file (pfault.materials.field_files: CSV, HDF5 or NetCDF; points or a regular grid in x, y and/or z) holds the
value in the option's unit unless it states its own. A grid is interpolated (multi)linearly, scattered points
linearly over their Delaunay triangulation (scipy.interpolate), at the centroids of the material's cells in
site coordinates (mesh + ``-pfault_mesh_origin``, pfault.io.probes.mesh_to_site). A centroid outside the grid or
the points' convex hull is an error
unless the option says ``outside=nearest``: the grid's value at the nearest point of its box, or the nearest
point's value. A relative path is taken from the current directory, else from the scene file's directory.

The model builds the per-cell arrays once (``CellProperties``); every consumer (the elastic assembly, the
Biot load, gravity, the geostatic state, the fault stiffness estimates, the flow model's storage) reads them.
A property given as a number fills its material's cells with that number, as before fields existed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..io.probes import mesh_to_site
from ..paths import beside_scene
from ..physics import flow as fl
from .field_files import read_field

FIELD_PREFIX = "field:"
OUTSIDE = ("error", "nearest")

# each property's admissible values: (test on an array, the range as words)
RANGES = {
    "young_modulus": (lambda v: v > 0, "positive"),
    "poisson_ratio": (lambda v: (v > -1.0) & (v < 0.5), "in (-1, 0.5)"),
    "biot_coefficient": (lambda v: (v >= 0.0) & (v <= 1.0), "in [0, 1]"),
    "density": (lambda v: v > 0, "positive"),
    # materials with memory; the storages before specific_storage, whose suffix they share
    "recompression_index": (lambda v: v > 0, "positive"),
    "compression_index": (lambda v: v > 0, "positive"),
    "inelastic_skeletal_specific_storage": (lambda v: v > 0, "positive"),
    "elastic_skeletal_specific_storage": (lambda v: v > 0, "positive"),
    "preconsolidation_stress": (lambda v: v > 0, "positive"),
    "overconsolidation_ratio": (lambda v: v >= 1, "at least 1"),
    "preconsolidation_head": (lambda v: v <= 0, "zero or negative (m below the initial heads)"),
    "hydraulic_conductivity": (lambda v: v > 0, "positive"),
    "specific_storage": (lambda v: v > 0, "positive"),
    "void_ratio": (lambda v: v > 0, "positive"),
}
MECHANICAL = ("young_modulus", "poisson_ratio", "biot_coefficient", "density")


@dataclass(frozen=True)
class FieldRef:
    """A property option that names a field: the option, the file, the variable in it ('' for the file's
    only one), what a centroid outside the field gets, the option's unit."""
    option: str
    path: str
    variable: str = ""
    outside: str = "error"
    unit: str = ""

    def text(self) -> str:
        return f"-{self.option} {FIELD_PREFIX}{self.path}"


def parse_field(text: str, option: str, unit: str) -> FieldRef:
    """``field:PATH[,variable=NAME][,outside=error|nearest]`` -> FieldRef."""
    body = text.strip()[len(FIELD_PREFIX):]
    parts = [p.strip() for p in body.split(",")]
    path, kw = parts[0], {}
    if not path:
        raise InputError(f"-{option}: '{text}' names no file; give field:PATH (CSV, HDF5 or NetCDF)")
    for p in parts[1:]:
        key, eq, value = p.partition("=")
        if not eq or key.strip() not in ("variable", "outside"):
            raise InputError(f"-{option}: '{p}' in '{text}' is not variable=NAME or outside=error|nearest")
        kw[key.strip()] = value.strip()
    outside = kw.get("outside", "error")
    if outside not in OUTSIDE:
        raise InputError(f"-{option}: outside={outside} in '{text}'; give outside=error or outside=nearest")
    return FieldRef(option, path, kw.get("variable", ""), outside, unit)


def is_field(value: Any) -> bool:
    return isinstance(value, FieldRef)


def property_name(option: str) -> str:
    """The property of a material property option (``pfault_material_clay_young_modulus`` -> young_modulus)."""
    return next(p for p in RANGES if option.endswith("_" + p))


# -- evaluation at points ----------------------------------------------------------------------------------
def interpolate(field: Any, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values of ``field`` (pfault.materials.field_files.SpatialField) at ``points`` (n, 3) in site coordinates, and
    the points outside the field (a grid's box, the points' convex hull) as a mask; their values are the
    nearest ones (the grid's value at the nearest point of its box, the nearest point's value)."""
    from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator, RegularGridInterpolator
    cols = [("x", "y", "z").index(n) for n in field.names]
    q = np.asarray(points, dtype=float)[:, cols]
    if field.is_grid:
        lo = np.array([a[0] for a in field.axes])
        hi = np.array([a[-1] for a in field.axes])
        tol = 1e-9 * np.maximum(hi - lo, 1.0)           # a centroid on the box's side, up to round-off
        outside = np.any((q < lo - tol) | (q > hi + tol), axis=1)
        interp = RegularGridInterpolator(field.axes, field.values, method="linear")
        return interp(np.clip(q, lo, hi)), outside
    from scipy.spatial import QhullError
    try:
        interp = LinearNDInterpolator(field.points, field.values)
    except QhullError:
        raise InputError(f"field {field.path}: its points lie on one {'line' if len(cols) == 2 else 'plane'}, "
                         f"they span no {len(cols)}-D field; give points that surround the mesh") from None
    values = interp(q)
    outside = np.isnan(values)
    if np.any(outside):
        values[outside] = NearestNDInterpolator(field.points, field.values)(q[outside])
    return values, outside


def cell_values(ref: FieldRef, field: Any, centroids: np.ndarray, material: str) -> np.ndarray:
    """The field of ``ref`` at the centroids (site coordinates) of the cells of ``material``; InputError where
    cells lie outside it and ``ref`` does not say ``outside=nearest``."""
    values, outside = interpolate(field, centroids)
    if np.any(outside) and ref.outside == "error":
        c = centroids[outside]
        span = ", ".join(f"{n} {c[:, i].min():g}..{c[:, i].max():g}" for n, i in
                         (("x", 0), ("y", 1), ("z", 2)) if n in field.names)
        raise InputError(f"{ref.text()}: {int(outside.sum())} of {len(centroids)} cells of '{material}' lie "
                         f"outside the field (their centroids at {span} m; the field spans {field.extent()}); "
                         "extend the file or add ,outside=nearest to the option")
    return values


def check_range(ref: FieldRef, field: Any) -> None:
    """The file's values must lie in the property's range (interpolated values lie between them)."""
    test, words = RANGES[property_name(ref.option)]
    bad = ~test(field.values)
    if np.any(bad):
        v = field.values[bad].ravel()[0]
        raise InputError(f"{ref.text()}: {int(bad.sum())} values are not {words} (e.g. {v:g}); fix the file's "
                         "values (in the option's unit unless the file states its own)")


def read_fields(refs: Sequence[FieldRef], scene_file: str, notes: list | None = None) -> dict[str, Any]:
    """{option: SpatialField} of the field options, read and checked (rank 0); the files' notes (points that
    look like a grid and are not one) are appended to ``notes``."""
    out = {}
    for ref in refs:
        prop = property_name(ref.option)
        field = read_field(beside_scene(ref.path, scene_file), ref.option, ref.unit, ref.variable, prop)
        check_range(ref, field)
        if field.note and notes is not None:
            notes.append(field.note)
        out[ref.option] = field
    return out


# -- per-cell arrays --------------------------------------------------------------------------------------
SOIL = ("compression", "recompression", "void_ratio", "preconsolidation_value")   # pfault.scene.Soil's numbers


def field_refs(materials: Sequence[Any], flow: Any = None, soils: Sequence[Any] = ()) -> list[FieldRef]:
    """The field options of the materials' mechanical properties and, with ``flow`` (the flow model's settings,
    pfault.solver.flow.FlowSettings), of their flow properties, and of the laws with memory ``soils`` (one
    pfault.scene.Soil or None per material)."""
    refs = [getattr(m, p) for m in materials for p in MECHANICAL if is_field(getattr(m, p))]
    if flow is not None:
        refs += [v for seq in (flow.conductivity, flow.storage, flow.void_ratio) for v in seq if is_field(v)]
    refs += [getattr(s, p) for s in soils if s is not None for p in SOIL if is_field(getattr(s, p))]
    return list({ref.option: ref for ref in refs}.values())      # a void ratio of both the flow and the law once


def serial_field_values(names: Sequence[str], refs: Sequence[FieldRef], points: np.ndarray, tets: np.ndarray,
                        cell_material: np.ndarray, scene_file: str,
                        origin: Sequence[float] = (0.0, 0.0, 0.0), notes: list | None = None) -> dict[str, np.ndarray]:
    """{option: values on the cells of its material (serial order; NaN on the others)} of every field option
    (rank 0, on the serial mesh whose materials are ``names``; fields are given in site coordinates, mesh +
    ``origin``); the files' notes are appended to ``notes`` (read_fields)."""
    fields = read_fields(refs, scene_file, notes)
    centroids = mesh_to_site(points[tets].mean(axis=1), origin)
    out = {}
    for ref in refs:
        k = next(i for i, n in enumerate(names) if ref.option == f"pfault_material_{n}_{property_name(ref.option)}")
        sel = cell_material == k
        v = np.full(len(tets), np.nan)
        v[sel] = cell_values(ref, fields[ref.option], centroids[sel], names[k])
        out[ref.option] = v
    return out


def per_cell(values: Sequence[Any], cell_material: np.ndarray, field_values: Mapping[str, np.ndarray] | None = None,
             cell_ids: np.ndarray | None = None) -> np.ndarray:
    """One property per cell from its value per material: a number, or a field whose values (``field_values``:
    option -> values in serial order) are read at ``cell_ids``, the cells' serial ids (None: the cells are the
    serial ones). A None entry gives NaN."""
    consts = np.array([np.nan if v is None or is_field(v) else v for v in values], dtype=float)
    out = consts[cell_material]
    for k, ref in enumerate(values):
        if is_field(ref):
            sel = cell_material == k
            out[sel] = field_values[ref.option][cell_ids[sel] if cell_ids is not None else sel]
    return out


@dataclass(frozen=True)
class CellProperties:
    """The mechanical properties of every cell (Pa, -, -, kg/m^3)."""
    young_modulus: np.ndarray
    poisson_ratio: np.ndarray
    biot_coefficient: np.ndarray
    density: np.ndarray

    @classmethod
    def of_cells(cls, materials: Sequence[Any], cell_material: np.ndarray,
                 field_values: Mapping[str, np.ndarray] | None = None,
                 cell_ids: np.ndarray | None = None) -> CellProperties:
        return cls(*(per_cell([getattr(m, p) for m in materials], cell_material, field_values, cell_ids)
                     for p in MECHANICAL))


def flow_cell_properties(flow: Any, props: CellProperties, cell_material: np.ndarray,
                         field_values: Mapping[str, np.ndarray] | None, cell_ids: np.ndarray | None,
                         water_density: float, gravity: float) -> tuple[np.ndarray, np.ndarray]:
    """Hydraulic conductivity (m/s) and specific storage (1/m) per cell of the flow model's settings ``flow``;
    a storage left to its default is the skeleton's (pfault.physics.flow.specific_storage) of each cell."""
    k = per_cell(flow.conductivity, cell_material, field_values, cell_ids)
    ss = per_cell(flow.storage, cell_material, field_values, cell_ids)
    default = np.array([v is None for v in flow.storage])[cell_material]
    if np.any(default):
        e = per_cell(flow.void_ratio, cell_material, field_values, cell_ids)
        ss[default] = fl.specific_storage(props.young_modulus, props.poisson_ratio, e, props.biot_coefficient,
                                          water_density, gravity)[default]
    return k, ss

"""Spatial fields from files: values at points or on a regular grid, read from CSV, HDF5 or NetCDF.

A field has coordinates named ``x``, ``y`` and/or ``z`` (metres, site coordinates; any non-empty subset: a
clay-thickness map has x and y, a profile with depth has z) and one value:

- CSV: a header row naming the columns, then one row per point (``#`` lines are comments). The value
  column is the one column that is not a coordinate, or the one ``variable=`` names. Its unit may follow
  its name in brackets, ``young_modulus [MPa]``. Points that fill a rectilinear grid (every combination
  of the distinct x, y, z values once) are a grid; other points are scattered.
- HDF5 or NetCDF (NetCDF-4 is HDF5; classic NetCDF is read with scipy): 1-D coordinate variables ``x``,
  ``y``, ``z`` and the value variable (``variable=``, or the only other numeric variable), its unit in its
  ``units`` attribute (CF). A value variable as long as each coordinate variable is scattered points;
  otherwise it is a grid of shape (nz, ny, nx) with x varying fastest (as CF-NetCDF and GDAL write it),
  or in the order of its named dimensions.

Values are returned in SI units; a unit of another dimension than the option's is an error.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..paths import file_problem
from ..units import DIMENSION_NAMES, UNITS, dimension

AXES = ("x", "y", "z")
_LENGTH_UNITS = {"m": 1.0, "metre": 1.0, "metres": 1.0, "meter": 1.0, "meters": 1.0, "km": 1e3}


@dataclass(frozen=True)
class SpatialField:
    """A field read from ``path``: its coordinate names (a subset of x, y, z in that order), and either grid
    axes (``axes``: one strictly increasing array per coordinate, ``values`` of shape (len(axes[0]), ...)) or
    scattered points (``points`` (n, len(names)), ``values`` (n,)). Values in SI units."""
    path: str
    names: tuple
    values: np.ndarray
    axes: tuple | None = None
    points: np.ndarray | None = None

    @property
    def is_grid(self) -> bool:
        return self.axes is not None

    def extent(self) -> str:
        """The field's bounding box, for messages."""
        lo_hi = ([(a[0], a[-1]) for a in self.axes] if self.is_grid
                 else list(zip(self.points.min(axis=0), self.points.max(axis=0))))
        return ", ".join(f"{n} {lo:g}..{hi:g} m" for n, (lo, hi) in zip(self.names, lo_hi))


def read_field(path: str, option: str, unit: str, variable: str = "", default_variable: str = "") -> SpatialField:
    """The field in ``path`` for the option ``option`` (declared in ``unit``). ``variable``: the value's name
    given by the user; ``default_variable``: the name tried when the file has several candidates."""
    where = f"-{option} field:{path}"
    problem = file_problem(path)
    if problem:
        raise InputError(f"{where}: {problem}; give the path of a CSV, HDF5 or NetCDF file")
    with open(path, "rb") as fh:
        magic = fh.read(8)
    if magic.startswith(b"\x89HDF"):
        names, coords, values, dims, vunit, vname = _read_hdf5(path, where, variable, default_variable)
    elif magic.startswith(b"CDF"):
        names, coords, values, dims, vunit, vname = _read_netcdf3(path, where, variable, default_variable)
    else:
        return _read_csv(path, where, unit, variable, default_variable)
    values = np.asarray(values, dtype=float) * _value_factor(vunit, unit, where, vname)
    _check_finite(values, where, vname)
    if values.ndim == 1 and all(len(c) == len(values) for c in coords) and len(names) > 1:
        return _scattered(path, where, names, np.column_stack(coords), values)
    if dims is not None and sorted(dims) == sorted(names):
        values = np.transpose(values, [dims.index(n) for n in names])
    else:
        values = np.transpose(values)               # (nz, ny, nx) -> (nx, ny, nz)
    shape = tuple(len(c) for c in coords)
    if values.shape != shape:
        want = " x ".join(f"n{n} = {len(c)}" for n, c in reversed(list(zip(names, coords))))
        raise InputError(f"{where}: variable '{vname}' has shape {tuple(reversed(values.shape))}, the coordinates "
                         f"ask for {want} (x varying fastest) or one value per point; fix the variable's shape")
    return _grid(path, where, names, coords, values)


# -- formats --------------------------------------------------------------------------------------
def _pick_variable(candidates: list[str], where: str, variable: str, default_variable: str) -> str:
    if variable:
        if variable not in candidates:
            raise InputError(f"{where}: no variable '{variable}' (the file has {', '.join(candidates) or 'none'}); "
                             "give one of them as variable=NAME")
        return variable
    if len(candidates) == 1:
        return candidates[0]
    if default_variable in candidates:
        return default_variable
    raise InputError(f"{where}: {len(candidates)} candidate variables ({', '.join(candidates) or 'none'}); "
                     "name one with ,variable=NAME after the path")


def _coordinate_names(names: list[str], where: str) -> list[str]:
    coords = [a for a in AXES if a in names]
    if not coords:
        raise InputError(f"{where}: no coordinate named x, y or z; name the coordinates x, y and/or z (m)")
    return coords


def _read_hdf5(path, where, variable, default_variable):
    import h5py
    try:
        h5 = h5py.File(path, "r", locking=False)
    except OSError as exc:
        raise InputError(f"{where}: cannot read the HDF5 file ({exc}); give a readable HDF5 or NetCDF file") from None
    with h5:
        datasets = {k: v for k, v in h5.items() if isinstance(v, h5py.Dataset) and v.dtype.kind in "fiu"}
        names = _coordinate_names(list(datasets), where)
        vname = _pick_variable([k for k in datasets if k not in AXES], where, variable, default_variable)
        var = datasets[vname]
        coords = [_coordinate(datasets[n][()], datasets[n].attrs.get("units"), where, n) for n in names]
        dims = None
        try:
            dims = [d[0].name.rsplit("/", 1)[-1] if len(d) else d.label for d in var.dims]
        except (RuntimeError, ValueError, IndexError):
            dims = None
        return names, coords, var[()], dims, _text(var.attrs.get("units")), vname


def _read_netcdf3(path, where, variable, default_variable):
    from scipy.io import netcdf_file
    try:
        nc = netcdf_file(path, "r", mmap=False)
    except (OSError, TypeError, ValueError) as exc:
        raise InputError(f"{where}: cannot read the NetCDF file ({exc}); give a readable NetCDF file") from None
    with nc:
        variables = {k: v for k, v in nc.variables.items() if v.data.dtype.kind in "fiu"}
        names = _coordinate_names(list(variables), where)
        vname = _pick_variable([k for k in variables if k not in AXES], where, variable, default_variable)
        var = variables[vname]
        coords = [_coordinate(variables[n].data.copy(), getattr(variables[n], "units", None), where, n)
                  for n in names]
        values = var.data.copy().astype(float)
        fill = getattr(var, "_FillValue", None)
        if fill is not None:
            values[values == fill] = np.nan
        return names, coords, values, list(var.dimensions), _text(getattr(var, "units", None)), vname


def _read_csv(path, where, unit, variable, default_variable):
    with open(path, newline="") as fh:
        rows = [r for r in csv.reader(line for line in fh if line.strip() and not line.lstrip().startswith("#"))]
    if len(rows) < 2:
        raise InputError(f"{where}: needs a header row (x,y,value ...) and at least one row of values")
    header = [h.strip() for h in rows[0]]
    parsed = [re.fullmatch(r"([^\[\]]*?)\s*(?:\[\s*([^\]]*?)\s*\])?", h) for h in header]
    col_names = [m.group(1).strip().lower() if m.group(1).strip().lower() in AXES else m.group(1).strip()
                 for m in parsed]
    names = _coordinate_names(col_names, where)
    vname = _pick_variable([n for n in col_names if n not in AXES], where, variable, default_variable)
    vcol = col_names.index(vname)
    try:
        data = np.array([[float(v) for v in r] for r in rows[1:]], dtype=float)
    except ValueError as exc:
        raise InputError(f"{where}: a row that is not numbers ({exc}); give one number per column") from None
    if data.ndim != 2 or data.shape[1] != len(header):
        raise InputError(f"{where}: every row needs {len(header)} values, one per header column")
    values = data[:, vcol] * _value_factor(parsed[vcol].group(2), unit, where, vname)
    _check_finite(values, where, vname)
    coords = []
    for n in names:
        c = col_names.index(n)
        coords.append(data[:, c] * _length_factor(parsed[c].group(2), where, n))
    _check_finite(np.concatenate(coords), where, "coordinates")
    pts = np.column_stack(coords)
    axes = [np.unique(c) for c in coords]
    if len(names) > 1 and int(np.prod([len(a) for a in axes])) != len(values):
        return _scattered(path, where, names, pts, values)
    idx = tuple(np.searchsorted(a, c) for a, c in zip(axes, coords))
    grid = np.full(tuple(len(a) for a in axes), np.nan)
    count = np.zeros(grid.shape, dtype=int)
    np.add.at(count, idx, 1)
    if np.any(count != 1):
        if len(names) == 1:
            raise InputError(f"{where}: {names[0]} = {axes[0][np.argmax(count > 1)]:g} appears more than once; "
                             "give each position once")
        return _scattered(path, where, names, pts, values)
    grid[idx] = values
    return _grid(path, where, names, axes, grid)


# -- checks and units -----------------------------------------------------------------------------
def _grid(path, where, names, coords, values):
    axes = []
    for n, c in zip(names, coords):
        c = np.asarray(c, dtype=float)
        if len(c) < 2:
            raise InputError(f"{where}: the grid has one {n} value; give at least two, or leave {n} out of the "
                             f"file for a field that does not vary with {n}")
        if np.any(np.diff(c) <= 0):
            raise InputError(f"{where}: the grid's {n} values do not increase strictly; sort them")
        axes.append(c)
    _check_finite(values, where, "values")
    return SpatialField(path, tuple(names), np.asarray(values, dtype=float), axes=tuple(axes))


def _scattered(path, where, names, points, values):
    if len(values) < len(names) + 1:
        raise InputError(f"{where}: {len(values)} points cannot span a {len(names)}-D field; give at least "
                         f"{len(names) + 1} points not all on one {'line' if len(names) == 2 else 'plane'}")
    return SpatialField(path, tuple(names), np.asarray(values, dtype=float), points=np.asarray(points, float))


def _check_finite(values, where, what):
    bad = ~np.isfinite(np.asarray(values, dtype=float))
    if np.any(bad):
        raise InputError(f"{where}: {int(bad.sum())} of {bad.size} {what} are NaN or infinite; fill them "
                         "(or remove those points) and run again")


def _text(value):
    if value is None:
        return None
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray):
        return _text(value.item() if value.size == 1 else None)
    return str(value)


def _value_factor(given, unit, where, vname):
    """Factor from the file's unit of the value to SI; the file's unit must have the option's dimension."""
    given = _text(given)
    if given is None or not given.strip() or given.strip() == unit:
        return 1.0
    given = given.strip()
    if given in ("1", "-", "dimensionless") and not unit:
        return 1.0
    want = DIMENSION_NAMES.get(dimension(unit), unit) if unit else "plain number"
    if given not in UNITS:
        raise InputError(f"{where}: unknown unit '{given}' of '{vname}'; give a unit such as {unit or '1'} "
                         f"({want})")
    factor, dim = UNITS[given]
    if dim != dimension(unit):
        have = DIMENSION_NAMES.get(dim, given)
        raise InputError(f"{where}: '{vname}' is in {given}, a {have}, but the option takes a {want}"
                         f"{' in ' + unit if unit else ''}; give the variable in that unit")
    return factor


def _length_factor(given, where, name):
    given = _text(given)
    if given is None or not given.strip():
        return 1.0
    if given.strip() not in _LENGTH_UNITS:
        raise InputError(f"{where}: coordinate {name} is in '{given}'; give coordinates in m (or km)")
    return _LENGTH_UNITS[given.strip()]


def _coordinate(values, units, where, name):
    values = np.asarray(values, dtype=float)
    if values.ndim != 1:
        raise InputError(f"{where}: coordinate variable {name} is not 1-D; give 1-D x, y, z variables")
    _check_finite(values, where, f"{name} coordinates")
    return values * _length_factor(units, where, name)

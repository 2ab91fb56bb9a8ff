"""Spatial fields from files: values at points or on a regular grid, read from CSV, HDF5 or NetCDF.

A field has coordinates named ``x``, ``y`` and/or ``z`` (metres, site coordinates; any non-empty subset: a
clay-thickness map has x and y, a profile with depth has z) and one value:

- CSV: a header row naming the columns, then one row per point (``#`` lines are comments). The value
  column is the one column that is not a coordinate, or the one ``variable=`` names. Its unit may follow
  its name in brackets, ``young_modulus [MPa]``. Points that fill a rectilinear grid (every combination
  of the distinct x, y, z values once) are a grid; other points are scattered, with a note (``note``, which
  the run prints as a warning) when they fill at least half of that grid: a node left out, a coordinate off
  by round-off.
- HDF5 or NetCDF (NetCDF-4 is HDF5; classic NetCDF is read with scipy): 1-D coordinate variables ``x``,
  ``y``, ``z`` and the value variable (``variable=``, or the only other numeric variable), its unit in its
  ``units`` attribute (CF). A value variable as long as each coordinate variable is scattered points;
  otherwise it is a grid of shape (nz, ny, nx) with x varying fastest (as CF-NetCDF and GDAL write it),
  or in the order of its named dimensions; a decreasing coordinate variable is turned round with the values.

A position given twice is an error in every form (which value holds there is not pfault's to choose), as are
a CSV line short of a value or not numbers (named by its line), NaN or infinite values, a file without a value
or without coordinates (named by what it has). Values are returned in SI units; a unit of another dimension
than the option's is an error.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass

import h5py
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
    note: str = ""              # why points that look like a grid are read as scattered points ('' : none)

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
    elif magic[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        raise InputError(f"{where}: a (Geo)TIFF, which pfault does not read; convert it to NetCDF (gdal_translate "
                         "-of netCDF in.tif out.nc) and give that file, with its units attribute")
    else:
        return _read_csv(path, where, unit, variable, default_variable)
    values = np.asarray(values, dtype=float)
    factor = _value_factor(vunit, unit, where, vname)
    _check_finite(values, where, vname)
    if values.ndim == 1 and all(len(c) == len(values) for c in coords) and len(names) > 1:
        pts = np.column_stack(coords)
        _check_repeated_points(pts, values, names, vname, where, "entries", np.arange(len(values)))
        return _scattered(path, where, names, pts, values * factor)
    values = values * factor
    if dims is not None and sorted(dims) == sorted(names):
        values = np.transpose(values, [dims.index(n) for n in names])
    else:
        values = np.transpose(values)               # (nz, ny, nx) -> (nx, ny, nz)
    shape = tuple(len(c) for c in coords)
    if values.shape != shape:
        want = " x ".join(f"n{n} = {len(c)}" for n, c in reversed(list(zip(names, coords))))
        raise InputError(f"{where}: variable '{vname}' has shape {tuple(reversed(values.shape))}, the coordinates "
                         f"ask for {want} (x varying fastest) or one value per point; fix the variable's shape")
    coords, values = _increasing_axes(names, coords, values, where)
    return _grid(path, where, names, coords, values)


# -- formats --------------------------------------------------------------------------------------
def _pick_variable(names: list[str], where: str, variable: str, default_variable: str, kind: str) -> str:
    """The value's name among ``names`` (every column or numeric variable of the file; ``kind``: 'columns' or
    'variables')."""
    candidates = [n for n in names if n not in AXES]
    if not candidates:
        example = f"{','.join(names)},{default_variable or 'value'} [unit]" if kind == "columns" else \
            f"a variable {default_variable or 'value'} with a units attribute"
        raise InputError(f"{where}: the file has only coordinate {kind} ({', '.join(names)}) and no value; add the "
                         f"value's {kind[:-1]} (e.g. {example})")
    if variable:
        if variable not in candidates:
            raise InputError(f"{where}: no variable '{variable}' (the file has {', '.join(candidates)}); "
                             "give one of them as variable=NAME")
        return variable
    if len(candidates) == 1:
        return candidates[0]
    if default_variable in candidates:
        return default_variable
    raise InputError(f"{where}: {len(candidates)} candidate variables ({', '.join(candidates)}); "
                     "name one with ,variable=NAME after the path")


def _coordinate_names(names: list[str], where: str, kind: str) -> list[str]:
    coords = [a for a in AXES if a in names]
    if not coords:
        found = ", ".join(names) if names else "none"
        raise InputError(f"{where}: no coordinate named x, y or z (its {kind}: {found}); name the coordinate "
                         f"{kind} x, y and/or z (m, site coordinates)")
    return coords


def _read_hdf5(path, where, variable, default_variable):
    try:
        h5 = h5py.File(path, "r", locking=False)
    except OSError as exc:
        raise InputError(f"{where}: cannot read the HDF5 file ({exc}); give a readable HDF5 or NetCDF file") from None
    with h5:
        datasets = {k: v for k, v in h5.items() if isinstance(v, h5py.Dataset) and v.dtype.kind in "fiu"}
        names = _coordinate_names(list(datasets), where, "variables")
        vname = _pick_variable(list(datasets), where, variable, default_variable, "variables")
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
        names = _coordinate_names(list(variables), where, "variables")
        vname = _pick_variable(list(variables), where, variable, default_variable, "variables")
        var = variables[vname]
        coords = [_coordinate(variables[n].data.copy(), getattr(variables[n], "units", None), where, n)
                  for n in names]
        values = var.data.copy().astype(float)
        fill = getattr(var, "_FillValue", None)
        if fill is not None:
            values[values == fill] = np.nan
        return names, coords, values, list(var.dimensions), _text(getattr(var, "units", None)), vname


def _read_csv(path, where, unit, variable, default_variable):
    header, units, rows, lines = _csv_table(path, where)
    names = _coordinate_names(header, where, "columns")
    vname = _pick_variable(header, where, variable, default_variable, "columns")
    data = _csv_numbers(rows, lines, header, where)
    vcol = header.index(vname)
    raw = data[:, vcol]
    _check_finite(raw, where, vname, lines)
    coords = []
    for n in names:
        c = header.index(n)
        coords.append(data[:, c] * _length_factor(units[c], where, n))
        _check_finite(data[:, c], where, f"{n} coordinates", lines)
    pts = np.column_stack(coords)
    _check_repeated_points(pts, raw, names, vname, where, "lines", lines)
    values = raw * _value_factor(units[vcol], unit, where, vname)
    if len(values) == 1:
        need = "two points" if len(names) == 1 else \
            f"{len(names) + 1} points not on one {'line' if len(names) == 2 else 'plane'}"
        raise InputError(f"{where}: one point (line {lines[0]}); a field in {', '.join(names)} needs at least {need}: "
                         "give more points, or the property as a number instead of field:")
    axes = [np.unique(c) for c in coords]
    nodes = math.prod(len(a) for a in axes)
    if nodes != len(values):            # no point twice: the points fill the grid of their coordinates or not
        note = _near_grid_note(where, names, axes, pts, nodes) if nodes <= 2 * len(values) else ""
        return _scattered(path, where, names, pts, values, note)
    grid = np.full(tuple(len(a) for a in axes), np.nan)
    grid[tuple(np.searchsorted(a, c) for a, c in zip(axes, coords))] = values
    return _grid(path, where, names, axes, grid)


def _csv_table(path, where):
    """The header's names (x, y, z lower case) and units (None where not given), the data rows and their line
    numbers in the file, of a CSV file (``#`` lines and blank lines skipped; empty fields at a line's end
    dropped, as spreadsheets write them; a UTF-8 byte-order mark ignored)."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            text = fh.read().splitlines()
    except UnicodeDecodeError:
        raise InputError(f"{where}: neither a text (CSV) file nor HDF5 or NetCDF; give a CSV file with a header "
                         "line, or an HDF5 or NetCDF file") from None
    lines = [n for n, t in enumerate(text, start=1) if t.strip() and not t.lstrip().startswith("#")]
    rows = list(csv.reader(text[n - 1] for n in lines))
    for r in rows:
        while r and not r[-1].strip():
            r.pop()
    if len(rows) < 2:
        raise InputError(f"{where}: needs a header line (x,y,value ...) and at least one line of values")
    fields = [h.strip() for h in rows[0]]
    if len(fields) == 1 and any(sep in fields[0] for sep in ";\t"):
        raise InputError(f"{where}: the header line '{fields[0]}' is one column; separate the columns with commas")
    if all(_is_number(h) for h in fields):
        raise InputError(f"{where}: the first line ({', '.join(fields)}) is numbers, not a header; add a line "
                         "naming the columns first, e.g. x,y,value [unit]")
    parsed = [re.fullmatch(r"([^\[\]]*?)\s*(?:\[\s*([^\]]*?)\s*\])?", h) for h in fields]
    header = [m.group(1).strip() if m else h for m, h in zip(parsed, fields)]
    header = [h.lower() if h.lower() in AXES else h for h in header]
    units = [m.group(2) if m else None for m in parsed]
    for i, h in enumerate(header):
        if h in header[:i]:
            raise InputError(f"{where}: column '{h}' is named twice in the header (columns {header.index(h) + 1} "
                             f"and {i + 1}); name each column once")
    return header, units, rows[1:], np.array(lines[1:])


def _is_number(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


def _csv_numbers(rows, lines, header, where):
    """The rows as an (n, columns) array; InputError naming the first line that is short, long or not numbers."""
    for n, r in zip(lines, rows):
        if len(r) < len(header):
            raise InputError(f"{where} line {n}: no value for {', '.join(header[len(r):])} (the line has {len(r)} "
                             f"of the {len(header)} columns {', '.join(header)}); give a number in every column "
                             "or remove the line")
        if len(r) > len(header):
            raise InputError(f"{where} line {n}: {len(r)} values, but the header names {len(header)} columns "
                             f"({', '.join(header)}); give one value per column")
    try:
        return np.array(rows, dtype=float).reshape(len(rows), len(header))
    except ValueError:
        pass
    for n, r in zip(lines, rows):
        for name, cell in zip(header, r):
            if not _is_number(cell):
                what = f"no value for {name}" if not cell.strip() else f"{name} is '{cell.strip()}', not a number"
                raise InputError(f"{where} line {n}: {what}; give a number in every column or remove the line")
    return np.array([[float(c) for c in r] for r in rows])        # numbers Python reads and NumPy does not


# -- checks and units -----------------------------------------------------------------------------
def _grid(path, where, names, coords, values):
    axes = []
    for n, c in zip(names, coords):
        c = np.asarray(c, dtype=float)
        if len(c) < 2:
            raise InputError(f"{where}: the grid has one {n} value; give at least two, or leave {n} out of the "
                             f"file for a field that does not vary with {n}")
        axes.append(c)
    _check_finite(values, where, "values")
    return SpatialField(path, tuple(names), np.asarray(values, dtype=float), axes=tuple(axes))


def _increasing_axes(names, coords, values, where):
    """A grid's coordinate variables in increasing order: a decreasing one (north-up rasters store y so) is
    turned round with the values along it; one that repeats a value or goes back and forth is an error."""
    coords = [np.asarray(c, dtype=float) for c in coords]
    for i, (n, c) in enumerate(zip(names, coords)):
        step = np.diff(c)
        if len(c) > 1 and np.all(step < 0):
            coords[i], values = c[::-1], np.flip(values, axis=i)
        elif np.any(step == 0):
            j = int(np.argmax(step == 0))
            raise InputError(f"{where}: the coordinate variable {n} gives {n} = {c[j]:g} twice (indices {j} and "
                             f"{j + 1}); a grid gives each {n} once")
        elif np.any(step < 0) and np.any(step > 0):
            j = int(np.argmax(np.sign(step) != np.sign(step[0])))
            raise InputError(f"{where}: the coordinate variable {n} is not in order ({n}[{j}] = {c[j]:g}, "
                             f"{n}[{j + 1}] = {c[j + 1]:g}); sort it, increasing or decreasing, with the values "
                             "along it")
    return coords, values


def _scattered(path, where, names, points, values, note=""):
    if len(values) < len(names) + 1:
        raise InputError(f"{where}: {len(values)} points cannot span a {len(names)}-D field; give at least "
                         f"{len(names) + 1} points not all on one {'line' if len(names) == 2 else 'plane'}")
    return SpatialField(path, tuple(names), np.asarray(values, dtype=float), points=np.asarray(points, float),
                        note=note)


def _check_repeated_points(points, values, names, vname, where, label, index):
    """No position twice: which of two values would hold there is the file's mistake, not pfault's choice.
    ``label`` ('lines', 'entries') and ``index`` (per point) say where each point is in the file."""
    _, inverse, counts = np.unique(points, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    if np.all(counts == 1):
        return
    first = int(np.argmax(counts[inverse] > 1))
    same = np.flatnonzero(inverse == inverse[first])
    at = ", ".join(f"{n} = {v:g}" for n, v in zip(names, points[first]))
    given = values[same]
    how = ("with the same value" if np.all(given == given[0]) else
           f"with different values of {vname} ({_and([f'{v:g}' for v in given])})")
    more = int(np.sum(counts > 1)) - 1
    others = f"; {more} more point{'s are' if more > 1 else ' is'} given more than once" if more else ""
    times = "twice" if len(same) == 2 else f"{len(same)} times"
    raise InputError(f"{where}: the point {at} is given {times} ({label} {_and(index[same])}) "
                     f"{how}{others}; give each point once (remove the extra {label})")


def _and(items):
    """'a', 'a and b', 'a, b and c'."""
    items = [str(i) for i in items]
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def _near_grid_note(where, names, axes, points, nodes):
    """Why points that fill at least half of the grid of their distinct coordinates (as no scattered set
    does: n scattered points have n distinct values along each axis) are not a grid, for a warning: the
    nodes left empty, and coordinates that differ by round-off (a gap under 1e-3 of the axis' median)."""
    present = np.zeros(nodes, bool)
    present[np.ravel_multi_index(tuple(np.searchsorted(a, points[:, i]) for i, a in enumerate(axes)),
                                 tuple(len(a) for a in axes))] = True
    empty = np.unravel_index(int(np.argmin(present)), tuple(len(a) for a in axes))
    node = ", ".join(f"{n} = {a[k]:g}" for n, a, k in zip(names, axes, empty))
    close = ""
    for n, a in zip(names, axes):
        gaps = np.diff(a)
        if len(gaps) > 1 and gaps.min() < 1e-3 * np.median(gaps):
            k = int(np.argmin(gaps))
            close = f", and {n} = {a[k]:.10g} and {a[k + 1]:.10g} differ by only {gaps[k]:.3g} m (round-off?)"
            break
    shape = " x ".join(str(len(a)) for a in axes)
    return (f"{where}: the {len(points)} points lie on the {shape} grid of their distinct {', '.join(names)} values "
            f"but leave {nodes - len(points)} of its nodes empty (e.g. {node}){close}; they are read as scattered "
            "points (linear between neighbouring points), not as a grid; give every node of the grid once for "
            "(multi)linear interpolation on it")


def _check_finite(values, where, what, lines=None):
    """No NaN or infinite value; ``lines``: the CSV line of each value, to name the first ones."""
    bad = ~np.isfinite(np.asarray(values, dtype=float))
    if np.any(bad):
        at = "" if lines is None else \
            f" (line{'s' if bad.sum() > 1 else ''} {', '.join(str(n) for n in lines[bad][:5])}" \
            f"{', ...' if bad.sum() > 5 else ''})"
        raise InputError(f"{where}: {int(bad.sum())} of {bad.size} {what} are NaN or infinite{at}; fill them "
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

"""Head files of a site's groundwater model: MODFLOW 6 binary heads with their grid file (read with flopy), and
pfault's generic HDF5 / NetCDF-4 layout (read with h5py). Each reader gives the saved times (in the file's
time unit), a spatial lookup for points of the mesh (pfault.sources.lookup) and the values at saved time i as a
flat array; a file that cannot be used raises InputError naming the file and the fix.

The generic layout (README "Pore pressure from a groundwater model", docs/site_models.md):

- ``time`` (nt,): the saved times, increasing; attribute ``units`` (``s``, ``day``, ``year``, or CF's
  ``days since 2000-01-01``) or -pfault_heads_time_unit;
- ``head`` (m) or ``pressure_change`` (Pa): values (nt, ...);
- on a regular grid: ``x`` (nx,), ``y`` (ny,), optionally ``z`` (nz,), increasing, values (nt, [nz,] ny, nx);
- on scattered points in the plane: ``points`` (n, 2), values (nt, n), applied at every depth.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, replace
from typing import Any

import h5py
import numpy as np

from ..errors import InputError
from ..paths import file_problem
from ..units import parse_quantity
from . import lookup


# what to do about a head file that ends inside a record
CUT_FIX = ("the copy or the model run that wrote it stopped before the end: copy the file again, or run the model to "
           "its end")


# what each file option takes, for the message of a path that names no readable file
WANTED = {"pfault_heads_file": "give the head file the model saved (MODFLOW's HEAD FILEOUT, e.g. model.hds) or an "
                               "HDF5/NetCDF file in the layout of README",
          "pfault_heads_grid": "give the model's binary grid file (MODEL.dis.grb or MODEL.disv.grb)"}


def starts_like_heads(path: str) -> bool:
    """Whether the file begins with the header of a head record (KSTP, KPER, PERTIM, TOTIM, TEXT 'HEAD', NCOL,
    NROW, ILAY, in double or single precision): a file that does and that flopy cannot index was cut short."""
    with open(path, "rb") as fh:
        start = fh.read(64)
    for real in ("<f8", "<f4"):
        dtype = np.dtype([("kstp", "<i4"), ("kper", "<i4"), ("pertim", real), ("totim", real), ("text", "S16"),
                          ("ncol", "<i4"), ("nrow", "<i4"), ("ilay", "<i4")])
        if len(start) < dtype.itemsize:
            continue
        h = np.frombuffer(start[:dtype.itemsize], dtype=dtype)[0]
        if b"HEAD" in bytes(h["text"]).upper() and min(h["kstp"], h["kper"], h["ncol"], h["nrow"], h["ilay"]) >= 1:
            return True
    return False


def _need(path: str, option: str) -> None:
    problem = file_problem(path)
    if problem:
        raise InputError(f"-{option} {path}: {problem}; {WANTED[option]}")


@dataclass(frozen=True)
class Mf6Grid:
    """A DIS or DISV grid from a MODFLOW 6 binary grid file, lengths in the model's unit."""
    kind: str                   # DIS | DISV
    nlay: int
    ncpl: int
    shape: tuple                # (nlay, nrow, ncol) or (nlay, ncpl): the shape of a saved head array
    top: np.ndarray             # (ncpl,)
    botm: np.ndarray            # (nlay, ncpl)
    idomain: np.ndarray         # (nlay, ncpl)
    xorigin: float
    yorigin: float
    angrot: float
    delr: np.ndarray | None = None
    delc: np.ndarray | None = None
    vertices: np.ndarray | None = None
    iavert: np.ndarray | None = None
    javert: np.ndarray | None = None

    def cells(self, points: np.ndarray) -> np.ndarray:
        """Flat cell number (layer * ncpl + cell2d; -1 outside) of points (n, 3) in the model's coordinates."""
        x, y = lookup.to_model_xy(points[:, 0], points[:, 1], self.xorigin, self.yorigin, self.angrot)
        if self.kind == "DIS":
            c2d = lookup.structured_cell(self.delr, self.delc, x, y)
        else:
            c2d = lookup.polygon_cell(self.vertices, self.iavert, self.javert, x, y)
        k = lookup.layer_of(self.top, self.botm, c2d, points[:, 2])
        return np.where(k >= 0, k * self.ncpl + c2d, -1)

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """The model's bounding box in site coordinates: (lo, hi), each x, y, z (for messages)."""
        if self.kind == "DIS":
            w, h = float(np.sum(self.delr)), float(np.sum(self.delc))
            corners = np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]])
        else:
            corners = self.vertices
        a = np.deg2rad(self.angrot)
        x = self.xorigin + corners[:, 0] * np.cos(a) - corners[:, 1] * np.sin(a)
        y = self.yorigin + corners[:, 0] * np.sin(a) + corners[:, 1] * np.cos(a)
        return (np.array([x.min(), y.min(), float(np.min(self.botm))]),
                np.array([x.max(), y.max(), float(np.max(self.top))]))


GRB_LINE = 50                   # the four header lines of a binary grid file: GRID, VERSION, NTXT, LENTXT
GRB_BYTES = {"INTEGER": 4, "DOUBLE": 8}


def grid_file_cut(path: str) -> str | None:
    """How a MODFLOW 6 binary grid file is cut short, from its text header (the header, then each variable's
    values), or None: it is whole, or it does not start like a grid file (flopy then says what it is not)."""
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        if not fh.read(GRB_LINE).startswith(b"GRID "):
            return None
        try:
            lines = [fh.read(GRB_LINE).decode("ascii").split() for _ in range(3)]
            ntxt, lentxt = int(lines[1][1]), int(lines[2][1])
            total = 4 * GRB_LINE + ntxt * lentxt
            for _ in range(ntxt):
                name, kind, _, ndim, *dims = fh.read(lentxt).decode("ascii").split()
                total += GRB_BYTES[kind] * int(np.prod([int(d) for d in dims[:int(ndim)]]))
        except (UnicodeDecodeError, IndexError, ValueError, KeyError):
            return "cut short: the file ends inside its text header" if fh.tell() >= size else None
    return f"cut short: the file is {size:,} bytes, its header describes {total:,}" if size < total else None


def read_mf6_grid(path: str) -> Mf6Grid:
    _need(path, "pfault_heads_grid")
    from flopy.mf6.utils import MfGrdFile
    cut = grid_file_cut(path)
    if cut:
        raise InputError(f"-pfault_heads_grid {path}: {cut}; {CUT_FIX}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = MfGrdFile(path)
        kind = g.grid_type
    except Exception as exc:  # noqa: BLE001  (flopy raises whatever its parser meets)
        raise InputError(f"-pfault_heads_grid {path}: not a MODFLOW 6 binary grid file ({type(exc).__name__}: "
                         f"{exc}); give the .dis.grb or .disv.grb file MODFLOW 6 writes beside the model") from None
    if kind not in ("DIS", "DISV"):
        raise InputError(f"-pfault_heads_grid {path}: a {kind} grid; pfault reads DIS and DISV grids (a DISU "
                         "model's heads can be given in the generic HDF5 layout)")
    nlay = int(g.nlay)
    ncpl = int(g.nrow) * int(g.ncol) if kind == "DIS" else int(g.ncpl)
    common = dict(kind=kind, nlay=nlay, ncpl=ncpl, top=np.asarray(g.top, float).ravel(),
                  botm=np.asarray(g.bot, float).reshape(nlay, ncpl),
                  idomain=np.asarray(g.idomain).reshape(nlay, ncpl), xorigin=float(g.xorigin),
                  yorigin=float(g.yorigin), angrot=float(g.angrot))
    if kind == "DIS":
        return Mf6Grid(shape=(nlay, int(g.nrow), int(g.ncol)), delr=np.asarray(g.delr, float),
                       delc=np.asarray(g.delc, float), **common)
    return Mf6Grid(shape=(nlay, ncpl), vertices=np.asarray(g.verts, float), iavert=np.asarray(g.iavert),
                   javert=np.asarray(g.javert), **common)


def scaled(grid: Mf6Grid, length: float) -> Mf6Grid:
    """The grid in metres when its lengths are in units of ``length`` m (feet: 0.3048)."""
    if length == 1.0:
        return grid
    return replace(grid, top=grid.top * length, botm=grid.botm * length, xorigin=grid.xorigin * length,
                   yorigin=grid.yorigin * length,
                   delr=None if grid.delr is None else grid.delr * length,
                   delc=None if grid.delc is None else grid.delc * length,
                   vertices=None if grid.vertices is None else grid.vertices * length)


class Mf6Heads:
    """The saved heads of a MODFLOW 6 head file whose grid is ``grid``: ``times`` (model time unit) and
    ``values(i)`` (flat, layer by layer)."""

    def __init__(self, path: str, grid: Mf6Grid, grid_path: str) -> None:
        _need(path, "pfault_heads_file")
        import flopy
        self.path = path
        try:
            with warnings.catch_warnings():             # a file that is not a head file makes flopy warn first
                warnings.simplefilter("ignore")
                self.file = flopy.utils.HeadFile(path, precision="auto")
            records = self.file.recordarray
        except EOFError as exc:     # flopy's index ran past the end of the file in a record's header
            if not starts_like_heads(path):
                raise InputError(f"-pfault_heads_file {path}: not a MODFLOW head file (EOFError: {exc}); give the "
                                 "binary head file of the model's output control (HEAD FILEOUT)") from None
            raise InputError(f"-pfault_heads_file {path}: cut short: the file ends inside the header of a record; "
                             f"{CUT_FIX}") from None
        except Exception as exc:  # noqa: BLE001  (flopy raises whatever its parser meets)
            raise InputError(f"-pfault_heads_file {path}: not a MODFLOW head file ({type(exc).__name__}: {exc}); "
                             "give the binary head file of the model's output control (HEAD FILEOUT)") from None
        self._check_complete(records)
        nrow, ncol = (grid.shape[1], grid.shape[2]) if grid.kind == "DIS" else (1, grid.ncpl)
        dims = {(int(r), int(c)) for r, c in zip(records["nrow"], records["ncol"])}
        if dims != {(nrow, ncol)} or int(records["ilay"].max()) > grid.nlay:
            got = ", ".join(f"{r} x {c}" for r, c in sorted(dims))
            raise InputError(f"-pfault_heads_file {path}: its records are {got} (rows x columns) in up to "
                             f"{int(records['ilay'].max())} layers, but the grid file {grid_path} has "
                             f"{grid.nlay} layers of {nrow} x {ncol}; give the grid file of the model that wrote "
                             "these heads")
        totim = np.asarray(records["totim"], float)
        change = np.concatenate([[True], totim[1:] != totim[:-1]])
        times = totim[change]
        back = np.nonzero(np.diff(times) <= 0)[0]
        if len(back):
            i = back[0]
            raise InputError(f"-pfault_heads_file {path}: its saved times are not increasing (time {times[i + 1]:g} "
                             f"after {times[i]:g}); give the head file of one run, its records in time order")
        per_time = np.diff(np.concatenate([np.nonzero(change)[0], [len(totim)]]))
        if np.any(per_time != grid.nlay):
            i = int(np.nonzero(per_time != grid.nlay)[0][0])
            raise InputError(f"-pfault_heads_file {path}: time {times[i]:g} has {per_time[i]} layer records, the "
                             f"grid {grid.nlay}; save the heads of every layer (output control SAVE HEAD ALL)")
        self.times = times
        self.shape = grid.shape

    def _check_complete(self, records: np.ndarray) -> None:
        """InputError when the last record's values run past the end of the file (a copy or a model run cut
        short): flopy indexes a file by its records' headers and reads their values only when asked, so a cut
        inside the values of the last record would otherwise surface as EOFError when the heads are read."""
        f = self.file
        end = int(f.iposarray[-1]) + int(f.get_databytes(records[-1]))
        if end > f.totalbytes:
            last = records[-1]
            self.close()
            raise InputError(f"-pfault_heads_file {self.path}: cut short: the file is {f.totalbytes:,} bytes, but "
                             f"its last record (time {float(last['totim']):g}, layer {int(last['ilay'])}) ends at "
                             f"byte {end:,}; {CUT_FIX}")

    def values(self, i: int) -> np.ndarray:
        try:
            a = np.asarray(self.file.get_data(totim=self.times[i]), float).ravel()
        except EOFError:        # the file was cut after it was opened
            raise InputError(f"-pfault_heads_file {self.path}: cut short: the file ends inside the heads of time "
                             f"{self.times[i]:g}; {CUT_FIX}") from None
        if np.isnan(a).any():
            raise InputError(f"-pfault_heads_file {self.path}: {int(np.isnan(a).sum())} heads are NaN at time "
                             f"{self.times[i]:g}; MODFLOW writes dry cells as -1e30 and inactive ones as 1e30: "
                             "give the file MODFLOW wrote, or mark such cells that way")
        return a

    def close(self) -> None:
        self.file.close()


class TableHeads:
    """The generic HDF5 / NetCDF-4 layout (module docstring): ``times`` (in ``time_unit`` s when the file says
    so, else None), ``quantity`` (``head`` or ``pressure_change``), ``weights(points)`` and ``values(i)``."""

    def __init__(self, path: str) -> None:
        _need(path, "pfault_heads_file")
        self.path = path
        try:
            self.file = h5py.File(path, "r")
        except OSError as exc:
            if "truncated file" in str(exc):
                raise InputError(f"-pfault_heads_file {path}: cut short (HDF5: {exc}); {CUT_FIX}") from None
            raise InputError(f"-pfault_heads_file {path}: not an HDF5 or NetCDF-4 file ({exc}); give a MODFLOW "
                             "head file with -pfault_heads_grid, or the layout in README") from None
        f = self.file
        found = [q for q in ("head", "pressure_change") if q in f]
        if len(found) != 1 or "time" not in f:
            self._bad("needs a 'time' dataset and one of 'head' (m) or 'pressure_change' (Pa)")
        self.quantity = found[0]
        self.times = np.asarray(f["time"][...], float).ravel()
        self.time_unit = _unit_seconds(f["time"].attrs.get("units"), path)
        self.data = f[self.quantity]
        if len(self.times) == 0 or np.any(~np.isfinite(self.times)):
            self._bad("'time' is empty or holds NaN")
        back = np.nonzero(np.diff(self.times) <= 0)[0]
        if len(back):
            i = back[0]
            self._bad(f"'time' is not increasing ({self.times[i + 1]:g} after {self.times[i]:g}); sort the records")
        if "points" in f:
            self.nodes = np.asarray(f["points"][...], float)
            self.axes = None
            if self.nodes.ndim != 2 or self.nodes.shape[1] != 2 or len(self.nodes) < 3:
                self._bad("'points' must be (n, 2), x and y of at least 3 points")
            expect = (len(self.times), len(self.nodes))
        else:
            names = [a for a in ("x", "y", "z") if a in f]
            if names[:2] != ["x", "y"]:
                self._bad("needs 'points' (n, 2) or the grid axes 'x', 'y' (and 'z')")
            self.axes = [np.asarray(f[a][...], float).ravel() for a in names]
            for a, ax in zip(names, self.axes):
                if len(ax) == 0 or np.any(np.diff(ax) <= 0) or np.any(~np.isfinite(ax)):
                    self._bad(f"axis '{a}' must be finite and increasing")
            expect = (len(self.times),) + tuple(len(ax) for ax in self.axes[::-1])
        if tuple(self.data.shape) != expect:
            self._bad(f"'{self.quantity}' is {tuple(self.data.shape)}, the times and axes ask for {expect}")

    def _bad(self, what: str) -> None:
        raise InputError(f"-pfault_heads_file {self.path}: {what} (layout: README, 'Pore pressure from a "
                         "groundwater model')")

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """The file's bounding box: (lo, hi), each x, y, z (z infinite where the file holds none; for messages)."""
        lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
        if self.axes is None:
            lo[:2], hi[:2] = self.nodes.min(axis=0), self.nodes.max(axis=0)
        else:
            for i, ax in enumerate(self.axes):
                lo[i], hi[i] = ax[0], ax[-1]
        return lo, hi

    def weights(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.axes is None:
            try:
                return lookup.scattered_weights(self.nodes, points[:, :2])
            except (ValueError, RuntimeError):
                self._bad("'points' cannot be triangulated; give distinct points, not all on one line")
        return lookup.regular_grid_weights(self.axes, points[:, :len(self.axes)])

    def values(self, i: int) -> np.ndarray:
        a = np.asarray(self.data[i], float).ravel()
        if not np.all(np.isfinite(a)):
            self._bad(f"'{self.quantity}' holds {int(np.sum(~np.isfinite(a)))} NaN or infinite values at time "
                      f"{self.times[i]:g}; give a value everywhere (no-data is not allowed)")
        return a

    def close(self) -> None:
        self.file.close()


def _unit_seconds(units, path: str) -> float | None:
    """Seconds per unit of a ``units`` attribute (``day``, ``s``, ``years since 2000-01-01``), None if absent."""
    if units is None:
        return None
    if isinstance(units, bytes):
        units = units.decode()
    word = str(units).split(" since ")[0].strip().lower()
    word = {"seconds": "s", "second": "s", "sec": "s", "days": "day", "years": "year", "hours": "hour",
            "minutes": "minute", "d": "day"}.get(word, word)
    try:
        return parse_quantity(f"1*{word}", "time units", "s")
    except InputError:
        raise InputError(f"-pfault_heads_file {path}: time units '{units}' are not a time unit pfault knows "
                         "(s, minute, hour, day, year); fix the attribute 'units' of 'time'") from None


def set_seconds(heads: Any, settings: Any) -> None:
    """``heads.seconds``: the saved times in seconds, in the file's own unit of 'time' where it gives one, else in
    -pfault_heads_time_unit (``settings``: the heads settings); the option contradicting the file's unit is an error
    (the file closed first)."""
    unit = heads.time_unit if heads.time_unit is not None else settings.time_unit
    if heads.time_unit is not None and settings.time_unit_given and abs(unit - settings.time_unit) > 1e-12 * unit:
        heads.close()
        raise InputError(f"-pfault_heads_time_unit contradicts the units of 'time' in {settings.file}; remove the "
                         "option (the file's units are used)")
    heads.seconds = heads.times * unit

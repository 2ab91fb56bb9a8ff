"""Pore pressure from a site's groundwater model: heads saved at times by MODFLOW 6 (a binary head file and the
model's binary grid file) or pressure changes / heads in pfault's generic HDF5 layout (pfault.sources.head_files).

Each cell of the mesh takes the value at its centroid, in site coordinates (mesh coordinates plus
-pfault_mesh_origin): the head of the MODFLOW cell that contains it, or the interpolant of the generic layout.
The pore-pressure change at saved time t_i is

    dp_i = rho_w g (h_i - h_ref)            h_ref the head at the reference time (the first saved time unless
                                            -pfault_heads_reference_time names another saved time)

and between saved times dp is linear in time (before the first saved time it is that time's). A MODFLOW cell
that is dry (head -1e30) holds water at atmospheric pressure: pore pressure 0, so dp = -rho_w g max(h_ref - z, 0)
at the centroid's elevation z (and rho_w g max(h - z, 0) when it was dry at the reference time and is wet
again; 0 when dry at both). A cell that is inactive in the model (IDOMAIN <= 0, head 1e30) is not part of the
groundwater model: it counts as outside, like a centroid beyond the model's extent, and outside cells are an
error unless -pfault_heads_outside zero says that their pore pressure does not change. Generic files with
``pressure_change`` are used as they are (no reference subtracted).

Heads that change the pore pressure of no cell up to the run's end are an error naming the reason (every cell
outside, a file of one saved time, heads equal to the reference); a reference left to its default whose time is
after the run's time 0 is a warning, recorded with the reference in the source's ``notes`` (summary.json).

The map cell -> model cell and its weights is computed once; the values at every saved time are then gathered
for this rank's cells only (every rank reads the whole file, once: reading costs each rank the file's size in
I/O; it keeps nt x (its cells) values).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from mpi4py import MPI

from ..errors import InputError, collective_check, run_on_all, warn
from . import head_files
from ..paths import beside_scene
from ..units import UNITS, parse_quantity
from . import zero_on
from .netcdf_heads import is_mf6_netcdf, open_mf6_netcdf

OUTSIDE_ERROR, OUTSIDE_ZERO = "error", "zero"
DRY = -1e29             # MODFLOW 6 writes a dry cell's head as -1e30 (DHDRY): at or below this, dry
INACTIVE = 1e29         # and an inactive cell's as 1e30 (DHNOFLO)


@dataclass(frozen=True)
class HeadsSettings:
    file: str
    grid: str                       # MODFLOW binary grid file ('' for the generic layout)
    time_unit: float                # seconds per unit of the file's times
    time_unit_given: bool
    length_unit: float              # metres per unit of a MODFLOW model's lengths
    reference_time: float | None    # s; None: the first saved time
    outside: str                    # error | zero
    origin: tuple                   # site coordinates of the mesh's (0, 0, 0), m
    water_density: float
    gravity: float
    crs: Any = None                 # the scene's CRS (-pfault_crs; pyproj), to which a file's own CRS is reprojected


def _seconds_per(text: str, option: str) -> float:
    """A time unit given as a word (day, days, year, s) or a quantity (86400, 1*day), in seconds."""
    word = text.strip()
    for w in (word, word[:-1] if word.endswith("s") else word):
        if w in UNITS and UNITS[w][1] == UNITS["s"][1]:
            return UNITS[w][0]
    value = parse_quantity(text, option, "s")
    if value <= 0:
        raise InputError(f"-{option} {text}: give a positive time unit, e.g. day or 86400")
    return value


def read_mesh_origin(reader: Any) -> tuple:
    """-pfault_mesh_origin x,y,z: site coordinates = mesh coordinates + origin (m)."""
    origin = reader.get("pfault_mesh_origin")
    if len(origin) != 3:
        raise InputError(f"-pfault_mesh_origin: give three coordinates x,y,z (m), got {len(origin)}")
    return tuple(float(v) for v in origin)


def read_heads_settings(reader: Any, water_density: float, gravity: float, origin: tuple = (0.0, 0.0, 0.0),
                        scene_file: str = "", crs: Any = None) -> HeadsSettings | None:
    """The settings of -pfault_heads_file, or None when it is not given (its companions are then unused). The
    files are found from the working directory or, failing that, beside the scene file."""
    path = beside_scene(reader.get("pfault_heads_file"), scene_file)
    if not path:
        return None
    grid = beside_scene(reader.get("pfault_heads_grid"), scene_file)
    if not grid and not re.search(r"\.(h5|hdf5|nc|nc4|cdf)$", path, re.IGNORECASE):
        raise InputError(f"-pfault_heads_file {path}: a MODFLOW head file needs its binary grid file, "
                         "-pfault_heads_grid MODEL.dis.grb (or .disv.grb); an HDF5/NetCDF-4 file ends in .h5 or .nc")
    given = reader.has("pfault_heads_time_unit")
    time_unit = _seconds_per(reader.get("pfault_heads_time_unit"), "pfault_heads_time_unit")
    length = reader.get("pfault_heads_length_unit")
    if length <= 0:
        raise InputError(f"-pfault_heads_length_unit: give a positive length, e.g. 0.3048 for feet, got {length:g}")
    return HeadsSettings(file=path, grid=grid, time_unit=time_unit, time_unit_given=given, length_unit=length,
                         reference_time=reader.get("pfault_heads_reference_time"),
                         outside=reader.get("pfault_heads_outside"), origin=tuple(origin),
                         water_density=water_density, gravity=gravity, crs=crs)


def open_heads(settings: HeadsSettings) -> tuple[Any, Any]:
    """(the head file's reader, the MODFLOW grid or None); the reader's ``times`` in seconds as ``seconds``."""
    if is_mf6_netcdf(settings.file):
        return open_mf6_netcdf(settings)
    if settings.grid:
        grid = head_files.scaled(head_files.read_mf6_grid(settings.grid), settings.length_unit)
        heads = head_files.Mf6Heads(settings.file, grid, settings.grid)
        heads.seconds = heads.times * settings.time_unit
        return heads, grid
    heads = head_files.TableHeads(settings.file)
    head_files.set_seconds(heads, settings)
    return heads, None


def reference_index(settings: HeadsSettings, seconds: np.ndarray) -> int:
    if settings.reference_time is None:
        return 0
    tol = 1e-9 * max(abs(seconds[-1]), 1.0)
    hit = np.nonzero(np.abs(seconds - settings.reference_time) <= tol)[0]
    if not len(hit):
        shown = ", ".join(f"{t / settings.time_unit:g}" for t in seconds[:8]) + (", ..." if len(seconds) > 8 else "")
        raise InputError(f"-pfault_heads_reference_time {settings.reference_time:g} s is not a time saved in "
                         f"{settings.file} (saved, in units of {settings.time_unit:g} s: {shown}); give one of them")
    return int(hit[0])


def check_heads_files(settings: HeadsSettings, time_end: float) -> None:
    """Every check the files allow before the mesh exists: they open, match, their times increase, the
    reference time is saved, and the run ends within the saved times."""
    heads, _ = open_heads(settings)
    try:
        reference_index(settings, heads.seconds)
        last = heads.seconds[-1]
        if time_end > last * (1 + 1e-12) + 1e-9:
            raise InputError(f"-pfault_time_end {time_end:g} s is after the last time saved in {settings.file} "
                             f"({last:g} s); end the run by then or give heads up to its end")
    finally:
        heads.close()


class HeadsSource:
    """dp per local cell at the saved times (``table``, nt x cells, Pa) at ``seconds``, linear in between;
    ``outside``: the local cells outside the groundwater model, which get no change (-pfault_heads_outside zero);
    ``notes``: what summary.json records of the heads (the reference time, whether the user chose it, warnings)."""

    has_state = False       # a function of time: nothing to checkpoint
    kind = "heads"

    def __init__(self, seconds: np.ndarray, table: np.ndarray, outside: np.ndarray | None = None,
                 notes: dict | None = None) -> None:
        self.seconds = np.asarray(seconds, float)
        self.table = table
        self.outside = np.zeros(table.shape[1], dtype=bool) if outside is None else outside
        self.notes = dict(notes or {})
        self._changed = np.any(table != 0, axis=0)          # per cell: changes at some saved time

    @property
    def active(self) -> bool:
        return True

    def advance_to(self, t: float) -> None:
        """The saved heads are known at every time: nothing to do."""

    def cell_dp(self, t: float) -> np.ndarray:
        s = self.seconds
        if len(s) == 1 or t <= s[0]:
            return self.table[0].copy()
        if t >= s[-1]:
            return self.table[-1].copy()
        i = int(np.searchsorted(s, t, side="right")) - 1
        theta = (t - s[i]) / (s[i + 1] - s[i])
        return (1.0 - theta) * self.table[i] + theta * self.table[i + 1]

    def unchanged(self, t_end: float) -> np.ndarray:
        """Per local cell: dp is zero at every time of [0, t_end]."""
        return zero_on(self.seconds, self.table, t_end)
    def loaded_cells(self, t: float) -> np.ndarray:
        """The cells whose pore pressure changes at some saved time (cells outside the groundwater model, with
        -pfault_heads_outside zero, never do)."""
        return self._changed.copy()

    def step_record(self) -> dict:
        return {}

    def vertex_head(self) -> None:
        return None

    def state(self) -> None:
        return None

    def restore(self, state: None) -> None:
        """A function of time: nothing to restore."""

    def destroy(self) -> None:
        pass


def _mf6_table(heads: Any, grid: Any, points: np.ndarray, ref: int, rho_g: float,
               length: float) -> tuple[np.ndarray, np.ndarray]:
    """(dp table nt x n, outside mask) for points (n, 3, site coordinates, m) in a MODFLOW model whose lengths
    are in units of ``length`` m."""
    cell = grid.cells(points)
    outside = cell < 0
    outside[~outside] |= grid.idomain.ravel()[cell[~outside]] <= 0
    take = np.where(outside, 0, cell)
    h = np.empty((len(heads.times), len(points)))
    for i in range(len(heads.times)):
        h[i] = heads.values(i)[take]
    outside |= np.any(h >= INACTIVE, axis=0)           # inactive (HNOFLO) at some time
    dry = h <= DRY
    h *= length
    table = h - h[ref][None, :]
    table *= rho_g
    if dry.any():
        _dry_cells(table, h, dry, ref, points[:, 2], rho_g)
    table[:, outside] = 0.0
    return table, outside


def _dry_cells(table: np.ndarray, h: np.ndarray, dry: np.ndarray, ref: int, z: np.ndarray, rho_g: float) -> None:
    """dp where a cell is dry now or at the reference: its pore pressure is atmospheric (0) then, and the wet
    pore pressure at the other time rho_w g max(h - z, 0) at the centroid's elevation z."""
    cols = np.nonzero(dry.any(axis=0))[0]
    p = rho_g * np.maximum(h[:, cols] - z[None, cols], 0.0)
    p[dry[:, cols]] = 0.0
    either = dry[:, cols] | dry[ref, cols][None, :]
    sub = table[:, cols]
    sub[either] = (p - p[ref][None, :])[either]
    table[:, cols] = sub


def _generic_table(heads: Any, points: np.ndarray, ref: int, rho_g: float) -> tuple[np.ndarray, np.ndarray]:
    index, weight = heads.weights(points)
    outside = index[:, 0] < 0
    take = np.where(index < 0, 0, index)
    v = np.empty((len(heads.times), len(points)))
    for i in range(len(heads.times)):
        v[i] = np.sum(heads.values(i)[take] * weight, axis=1)
    table = rho_g * (v - v[ref]) if heads.quantity == "head" else v
    table[:, outside] = 0.0
    return table, outside


@dataclass(frozen=True)
class ReadHeads:
    """What ``build_heads_source`` read: the saved times (s), dp per cell at them (nt x cells, Pa), the cells
    outside the model, the reference's index, the quantity (``head`` or ``pressure_change``) and the model's
    bounding box in site coordinates (lo, hi)."""
    seconds: np.ndarray
    table: np.ndarray
    outside: np.ndarray
    ref: int
    quantity: str
    extent: tuple


def build_heads_source(comm: Any, settings: HeadsSettings, centroids: np.ndarray,
                       time_end: float | None = None) -> HeadsSource:
    """Collective: the source for this rank's cells (centroids in mesh coordinates). Cells outside the
    groundwater model are an InputError on every rank unless -pfault_heads_outside zero; so are heads that change
    the pore pressure in no cell up to ``time_end`` (s; None: the last saved time). A default reference that is
    not the run's time 0 is a warning (``reference_notes``)."""
    points = centroids + np.asarray(settings.origin)[None, :]
    rho_g = settings.water_density * settings.gravity

    def read():
        heads, grid = open_heads(settings)
        try:
            ref = reference_index(settings, heads.seconds)
            if grid is not None:
                table, outside = _mf6_table(heads, grid, points, ref, rho_g,
                                            getattr(heads, "scale", settings.length_unit))
            else:
                table, outside = _generic_table(heads, points, ref, rho_g)
            extent = (grid if grid is not None else heads).extent()
            quantity = "head" if grid is not None else heads.quantity
            return ReadHeads(heads.seconds.copy(), table, outside, ref, quantity, extent)
        finally:
            heads.close()

    got = run_on_all(comm, read)
    _check_outside(comm, settings, points, got)
    end = float(got.seconds[-1]) if time_end is None else float(time_end)
    _check_change(comm, settings, got, end)
    return HeadsSource(got.seconds, got.table, got.outside, reference_notes(comm, settings, got))


def _check_outside(comm: Any, settings: HeadsSettings, points: np.ndarray, got: ReadHeads) -> None:
    mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
    outside = got.outside
    n_out = mpi.allreduce(int(outside.sum()), op=MPI.SUM)
    if n_out == 0 or settings.outside == OUTSIDE_ZERO:
        return
    n_all = mpi.allreduce(len(points), op=MPI.SUM)
    p = points[outside]
    lo, hi = np.empty(3), np.empty(3)
    mpi.Allreduce(p.min(axis=0) if len(p) else np.full(3, np.inf), lo, op=MPI.MIN)
    mpi.Allreduce(p.max(axis=0) if len(p) else np.full(3, -np.inf), hi, op=MPI.MAX)
    collective_check(comm, f"-pfault_heads_file {settings.file}: {n_out:,} of {n_all:,} mesh cells have their "
                           f"centroid {_outside_words(settings)} (site coordinates {_box(lo, hi)} m; the "
                           f"{'model' if settings.grid else 'file'} spans {_box(*got.extent)} m); "
                           f"{_placement(settings)}, or say what they get: -pfault_heads_outside zero (no "
                           "pore-pressure change there)")


def _outside_words(settings: HeadsSettings) -> str:
    return "outside the groundwater model or in its inactive cells" if settings.grid else \
        "outside the extent of the file's grid or points"


def _box(lo: np.ndarray, hi: np.ndarray) -> str:
    """x lo..hi, y lo..hi[, z lo..hi] (a coordinate the box does not bound is left out)."""
    return ", ".join(f"{a} {lo[i]:.6g}..{hi[i]:.6g}" for i, a in enumerate("xyz") if np.isfinite(lo[i] + hi[i]))


def _placement(settings: HeadsSettings) -> str:
    """Every option that places the mesh in the groundwater model's coordinates."""
    if settings.grid:
        return ("check what places the mesh in the model: -pfault_mesh_origin (site = mesh + origin), "
                "-pfault_heads_length_unit (the model's length unit in metres, 0.3048 for feet; now "
                f"{settings.length_unit:g}) and -pfault_heads_grid {settings.grid} (the grid file of the model that "
                "wrote the heads, whose XORIGIN, YORIGIN and ANGROT place it)")
    return ("check what places the mesh in the file's coordinates (site metres): -pfault_mesh_origin (site = mesh "
            "+ origin) and the file's x, y (and z)")


def _days(seconds: float) -> str:
    """A time for messages: in days from a day on, else in seconds."""
    days = seconds / 86400.0
    return f"{days:.10g} day{'' if days == 1 else 's'}" if abs(seconds) >= 86400.0 else f"{seconds:.10g} s"


def _check_change(comm: Any, settings: HeadsSettings, got: ReadHeads, time_end: float) -> None:
    """InputError on every rank when the heads change the pore pressure of no cell on [0, time_end]: the run
    would compute nothing, and the reason is a mistake in the files or the options (said in the line)."""
    mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else comm
    counts = np.array([int(np.count_nonzero(~zero_on(got.seconds, got.table, time_end))),
                       len(got.outside), int(got.outside.sum())])
    changed, n_all, n_out = mpi.allreduce(counts, op=MPI.SUM)
    if changed or n_all == 0:
        return
    head = f"-pfault_heads_file {settings.file}"
    if n_out == n_all:
        reason = (f"all {n_all:,} mesh cells have their centroid {_outside_words(settings)}, so "
                  "-pfault_heads_outside zero gives none of them a pore-pressure change and the run has no load; "
                  f"{_placement(settings)}")
    elif got.quantity == "pressure_change":
        reason = (f"its pressure changes are zero in every mesh cell at every saved time up to the run's end "
                  f"({_days(time_end)}); give the file of the run that changed the pore pressure")
    elif len(got.seconds) == 1:
        reason = (f"it holds the heads of one saved time ({_days(got.seconds[0])}), which are the reference heads "
                  "h_ref, so dp = rho_w g (h - h_ref) is zero at every time; give a file with the heads of the "
                  "times after the reference too (MODFLOW: SAVE HEAD at every stress period)")
    else:
        inside = f" of the {n_all - n_out:,} cells inside the model" if n_out else ""
        reason = (f"the heads{inside} at every saved time up to the run's end ({_days(time_end)}) equal the "
                  f"reference heads, those of {_days(got.seconds[got.ref])}, so there is no pore-pressure change; "
                  "give the head file of the run whose heads change, or choose the reference with "
                  "-pfault_heads_reference_time (a saved time)")
    raise InputError(f"{head}: {reason}")


def reference_notes(comm: Any, settings: HeadsSettings, got: ReadHeads) -> dict:
    """What summary.json records of the reference heads; a warning (printed once, and recorded) when the user
    left the reference to its default and the first saved time is after the run's time 0: the file may start
    after pumping did (MODFLOW saves no time 0; a steady-state first stress period gives the heads at rest)."""
    t_ref = float(got.seconds[got.ref])
    chosen = settings.reference_time is not None
    notes: dict[str, Any] = {"reference_time_s": t_ref if got.quantity == "head" else None,
                             "reference_chosen": chosen, "saved_times": int(len(got.seconds)), "warnings": []}
    if chosen or got.quantity != "head" or t_ref <= 0.0:
        return notes
    text = (f"-pfault_heads_file {settings.file}: the reference heads h_ref are those of its first saved time, "
            f"{_days(t_ref)}, not of the run's time 0: drawdown before that time (pumping that started earlier) is "
            "not in the load; if the model was at rest then, say so with -pfault_heads_reference_time "
            f"{t_ref / 86400.0:.10g}*day (this warning then goes), else give heads from before pumping (a "
            "steady-state first stress period)")
    warn(comm, text)
    notes["warnings"].append(text)
    return notes


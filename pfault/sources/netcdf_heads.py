"""Heads MODFLOW 6 saves as NetCDF (its NetCDF output, MODFLOW 6.6 and later: ``NETCDF_STRUCTURED`` or
``NETCDF_MESH2D`` in the model's output control; CF-1.11, UGRID-1.0 for the mesh), read with h5py.

The file says what it is in its global attributes ``modflow_grid`` (``STRUCTURED``, or ``LAYERED MESH`` for a DISV or
DIS model written as a UGRID layered mesh) and ``modflow_model``. As MODFLOW 6 writes it:

- structured: dimensions ``time``, ``z`` (layer numbers), ``y`` (rows), ``x`` (columns); ``head`` (time, z, y, x);
  ``x``, ``y`` the cell centres (``x_bnds``, ``y_bnds`` their edges), rows from the north (``y`` decreasing; a file
  whose ``y`` increases is turned round); for a rotated grid (ANGROT) MODFLOW writes the grid's own coordinates, so
  its XORIGIN, YORIGIN and ANGROT are taken from ``-pfault_heads_grid``;
- layered mesh: ``mesh_node_x``, ``mesh_node_y`` (world coordinates), ``mesh_face_nodes`` (1-based, counter-clockwise,
  padded with its ``_FillValue``), one variable per layer ``head_l1`` ... ``head_lN`` (time, nmesh_face);
- ``time``: TOTIM in the model's time unit, ``units`` ``days since <start>`` (MODFLOW writes days); ``head``'s
  ``units`` ``m`` or ``ft``; ``_FillValue`` 1e30 at inactive cells and -1e30 at dry ones (as in binary files);
- the CRS in the grid-mapping variable named by ``grid_mapping`` (``crs_wkt``, or ``wkt`` in a mesh file, written
  from the model's NCF package ``WKT``); with ``-pfault_crs`` and a file in another CRS, the centroids are
  reprojected into the file's (pyproj) before the lookup; a file without a CRS is taken to be in the site
  coordinates, as binary files are;
- layer elevations: the file's ``TOP`` and ``BOTM`` arrays when the DIS/DISV package exported them
  (``EXPORT_ARRAY_NETCDF``; variables whose ``modflow_input`` ends in ``/TOP``, ``/BOTM``), else those of
  ``-pfault_heads_grid``.

The reader gives what pfault.sources.heads takes of a MODFLOW model: an ``Mf6Grid`` (pfault.sources.head_files) for the
lookup, wrapped in ``Reprojected`` when the CRSs differ, and ``times`` / ``values(i)`` (flat, layer by layer) like
``Mf6Heads``; anything that cannot be used is an InputError naming the file and the fix.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import h5py
import numpy as np

from ..errors import InputError
from ..georef import Transform, crs_from_cf, same_crs
from .head_files import Mf6Grid, _unit_seconds, read_mf6_grid, scaled, set_seconds

FT = 0.3048
LAYOUT = "MODFLOW 6's NetCDF output (NETCDF_STRUCTURED or NETCDF_MESH2D in the output control)"


def is_mf6_netcdf(path: str) -> bool:
    """Whether ``path`` is an HDF5-based NetCDF file with MODFLOW 6's ``modflow_grid`` global attribute."""
    try:
        with h5py.File(path, "r") as f:
            return "modflow_grid" in f.attrs
    except OSError:
        return False


def _text(value: Any) -> str:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray) and value.size == 1:
        return _text(value.item())
    return str(value)


class Mf6NetcdfHeads:
    """A MODFLOW 6 NetCDF head file: ``times`` (model time unit), ``time_unit`` (s per unit), ``length_unit`` (m per
    unit of its heads), ``crs`` (pyproj or None), ``grid`` (Mf6Grid in the file's coordinates) and ``values(i)``."""

    def __init__(self, path: str, grb: Any = None) -> None:
        self.path = path
        self.file = h5py.File(path, "r")
        f = self.file
        self.kind = _text(f.attrs["modflow_grid"]).upper()
        if "time" not in f:
            self._bad("has no 'time' variable")
        self.times = np.asarray(f["time"][()], float).ravel()
        units = f["time"].attrs.get("units")
        self.time_unit = _unit_seconds(units, path) if units is not None else None
        if len(self.times) == 0 or not np.all(np.isfinite(self.times)) or np.any(np.diff(self.times) <= 0):
            self._bad("its saved times are empty, not finite or not increasing; give the file of one model run")
        self.head: Any = None           # structured: the (time, z, y, x) variable; a layered mesh: self.layers
        self.layers: list = []
        if "STRUCTURED" in self.kind and "MESH" not in self.kind:
            self._structured(grb)
        elif "MESH" in self.kind:
            self._mesh(grb)
        else:
            self._bad(f"modflow_grid '{self.kind}' is neither STRUCTURED nor LAYERED MESH")
        self.crs = self._crs()

    # -- the two layouts
    def _structured(self, grb: Any) -> None:
        f = self.file
        if "head" not in f:
            self._bad("has no 'head' variable (a GWF model's heads)")
        head = f["head"]
        x, y = np.asarray(f["x"][()], float), np.asarray(f["y"][()], float)
        nt, nlay = len(self.times), head.shape[1] if head.ndim == 4 else 0
        if head.ndim != 4 or head.shape != (nt, nlay, len(y), len(x)):
            self._bad(f"'head' is {head.shape}, but time, z, y, x ask for (nt, nlay, ny, nx) = "
                      f"({nt}, nlay, {len(y)}, {len(x)})")
        self.flip_x, self.flip_y = _order(x, "x", self) < 0, _order(y, "y", self) > 0
        x, y = (x[::-1] if self.flip_x else x), (y[::-1] if self.flip_y else y)    # x increasing, y decreasing
        xe = _edges(f, "x", x, self.flip_x)
        ye = _edges(f, "y", y, self.flip_y)[::-1]                                  # from the north edge down
        self.head, self.nlay = head, nlay
        top, botm = self._elevations(nlay, (len(y), len(x)), grb)
        xo, yo, angrot = float(xe[0]), float(ye[-1]), 0.0
        if grb is not None and grb.angrot != 0.0:       # MODFLOW wrote the rotated grid's own coordinates
            xo, yo, angrot = grb.xorigin + xo, grb.yorigin + yo, grb.angrot
        self.grid = Mf6Grid(kind="DIS", shape=(nlay, len(y), len(x)), nlay=nlay, ncpl=len(x) * len(y), top=top,
                            botm=botm, idomain=np.ones((nlay, len(x) * len(y)), int), xorigin=xo, yorigin=yo,
                            angrot=angrot, delr=np.diff(xe), delc=-np.diff(ye))

    def _mesh(self, grb: Any) -> None:
        f = self.file
        names = sorted((k for k in f if k.startswith("head_l") and k[6:].isdigit()), key=lambda k: int(k[6:]))
        if not names or any(int(k[6:]) != i + 1 for i, k in enumerate(names)):
            self._bad("has no per-layer heads head_l1, head_l2, ... (a layered mesh's GWF heads)")
        for k in ("mesh_node_x", "mesh_node_y", "mesh_face_nodes"):
            if k not in f:
                self._bad(f"has no '{k}' (the UGRID mesh)")
        nodes = np.column_stack([f["mesh_node_x"][()], f["mesh_node_y"][()]]).astype(float)
        faces = np.asarray(f["mesh_face_nodes"][()], np.int64)
        fill = f["mesh_face_nodes"].attrs.get("_FillValue", -2147483647)
        start = int(np.asarray(f["mesh_face_nodes"].attrs.get("start_index", 1)).ravel()[0])
        valid = (faces != int(np.asarray(fill).ravel()[0])) & (faces >= start)
        counts = valid.sum(axis=1)
        if np.any(counts < 3) or np.any(faces[valid] - start >= len(nodes)):
            self._bad("'mesh_face_nodes' has a face of fewer than 3 nodes or a node number beyond mesh_node_x")
        nt, ncpl = len(self.times), len(faces)
        for k in names:
            if f[k].shape != (nt, ncpl):
                self._bad(f"'{k}' is {f[k].shape}, but time and nmesh_face ask for ({nt}, {ncpl})")
        self.layers, self.nlay = [f[k] for k in names], len(names)
        top, botm = self._elevations(self.nlay, (ncpl,), grb)
        javert = faces[valid] - start
        iavert = np.concatenate([[0], np.cumsum(counts)])
        self.grid = Mf6Grid(kind="DISV", shape=(self.nlay, ncpl), nlay=self.nlay, ncpl=ncpl, top=top, botm=botm,
                            idomain=np.ones((self.nlay, ncpl), int), xorigin=0.0, yorigin=0.0, angrot=0.0,
                            vertices=nodes, iavert=iavert, javert=javert)

    def _elevations(self, nlay: int, shape: tuple, grb: Any) -> tuple[np.ndarray, np.ndarray]:
        """(top (ncpl,), botm (nlay, ncpl)) in MODFLOW's row order: the file's TOP and BOTM, else the grid file's."""
        top, botm = self._tagged("TOP"), self._tagged("BOTM")
        ncpl = int(np.prod(shape))
        if top and botm:
            t = self._oriented(np.asarray(top[0][1][()], float)).reshape(ncpl)
            if len(botm) == 1 and botm[0][1].ndim == len(shape) + 1:       # structured: (z, y, x)
                b = self._oriented(np.asarray(botm[0][1][()], float))
            else:                                                           # per layer, by their 'layer' attribute
                b = np.stack([np.asarray(v[()], float) for _, v in sorted(botm, key=lambda lv: lv[0])])
            if b.size != nlay * ncpl:
                self._bad(f"its BOTM has {b.size} values, the heads' {nlay} layers of {ncpl} cells ask for "
                          f"{nlay * ncpl}")
            return t, b.reshape(nlay, ncpl)
        if grb is None:
            raise InputError(f"-pfault_heads_file {self.path}: holds no layer elevations (TOP, BOTM); export them "
                             "from the model (EXPORT_ARRAY_NETCDF in its DIS/DISV package) or give the model's "
                             "binary grid file, -pfault_heads_grid MODEL.dis.grb")
        if grb.nlay != nlay or grb.ncpl != ncpl:
            raise InputError(f"-pfault_heads_grid: {grb.nlay} layers of {grb.ncpl} cells, but "
                             f"-pfault_heads_file {self.path} has {nlay} of {ncpl}; give the grid file of the "
                             "model that wrote these heads")
        return grb.top, grb.botm

    def _tagged(self, name: str) -> list:
        """(layer, variable) of the input arrays MODFLOW tagged ``.../<name>`` (modflow_input)."""
        out = []
        for k, v in self.file.items():
            tag = _text(v.attrs.get("modflow_input", "")).upper()
            if tag.endswith("/" + name):
                out.append((int(np.asarray(v.attrs.get("layer", 0)).ravel()[0]), v))
        return out

    def _oriented(self, a: np.ndarray) -> np.ndarray:
        """A structured array (..., y, x) turned to MODFLOW's order (rows from the north, columns from the west)."""
        if getattr(self, "flip_y", False):
            a = a[..., ::-1, :]
        if getattr(self, "flip_x", False):
            a = a[..., ::-1]
        return a

    def _crs(self) -> Any:
        var = self.file["head"] if "head" in self.file else self.layers[0]
        name = _text(var.attrs.get("grid_mapping", "")).strip()
        if not name:
            gm = [k for k, v in self.file.items() if any(a in v.attrs for a in ("crs_wkt", "wkt", "spatial_ref"))]
            name = gm[0] if gm else ""
        if not name:
            return None
        if name not in self.file:
            self._bad(f"its grid_mapping '{name}' names no variable")
        return crs_from_cf(dict(self.file[name].attrs), f"-pfault_heads_file {self.path}")

    @property
    def length_unit(self) -> float | None:
        var = self.file["head"] if "head" in self.file else self.layers[0]
        unit = _text(var.attrs.get("units", "")).strip().lower()
        return {"m": 1.0, "meters": 1.0, "metres": 1.0, "ft": FT, "feet": FT}.get(unit)

    def values(self, i: int) -> np.ndarray:
        if self.head is not None:
            a = self._oriented(np.asarray(self.head[i], float))
        else:
            a = np.stack([np.asarray(v[i], float) for v in self.layers])
        if np.isnan(a).any():
            raise InputError(f"-pfault_heads_file {self.path}: {int(np.isnan(a).sum())} heads are NaN at time "
                             f"{self.times[i]:g}; MODFLOW writes dry cells as -1e30 and inactive ones as 1e30: "
                             "give the file MODFLOW wrote, or mark such cells that way")
        return a.ravel()

    def _bad(self, what: str) -> None:
        self.close()
        raise InputError(f"-pfault_heads_file {self.path}: {what} ({LAYOUT}: docs/groundwater_models.md)")

    def close(self) -> None:
        self.file.close()


def _order(axis: np.ndarray, name: str, reader: Mf6NetcdfHeads) -> int:
    """1 if a coordinate variable increases, -1 if it decreases, 0 for one value; an axis that is neither is an
    error."""
    step = np.diff(axis)
    if len(axis) < 2:
        return 0
    if np.all(step > 0) or np.all(step < 0):
        return 1 if step[0] > 0 else -1
    reader._bad(f"coordinate '{name}' is not in order (neither increasing nor decreasing)")
    return 0


def _edges(f: Any, name: str, centres: np.ndarray, flipped: bool) -> np.ndarray:
    """Increasing cell edges along x or y: from ``<name>_bnds`` when the file has them, else halfway between the
    centres (the outer edges as far out as the inner ones)."""
    bnds = f.get(f"{name}_bnds")
    if bnds is not None and bnds.shape == (len(centres), 2):
        b = np.sort(np.asarray(bnds[()], float), axis=1)
        b = b[np.argsort(b[:, 0])]
        return np.concatenate([b[:, 0], b[-1:, 1]])
    c = np.sort(centres)
    if len(c) == 1:
        raise InputError(f"coordinate '{name}' has one cell and no {name}_bnds: its width is unknown; give the "
                         "file MODFLOW wrote (with x_bnds, y_bnds)")
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


class Reprojected:
    """A grid in the file's CRS looked up with points in the scene's: ``cells`` moves the points' x, y into the
    file's CRS first; ``extent`` (for messages) is the file's box moved into the scene's CRS."""

    def __init__(self, grid: Any, scene_crs: Any, file_crs: Any) -> None:
        self.grid = grid
        self.to_file, self.to_scene = Transform(scene_crs, file_crs), Transform(file_crs, scene_crs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.grid, name)

    def cells(self, points: np.ndarray) -> np.ndarray:
        x, y = self.to_file(points[:, 0], points[:, 1])
        return self.grid.cells(np.column_stack([x, y, points[:, 2]]))

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.grid.extent()
        x, y = self.to_scene(np.array([lo[0], hi[0], lo[0], hi[0]]), np.array([lo[1], lo[1], hi[1], hi[1]]))
        return np.array([x.min(), y.min(), lo[2]]), np.array([x.max(), y.max(), hi[2]])


def open_mf6_netcdf(settings: Any) -> tuple[Mf6NetcdfHeads, Any]:
    """(reader, grid to look points up in) of a MODFLOW 6 NetCDF head file under the heads settings: the time unit
    of the file (an -pfault_heads_time_unit that contradicts it is an error), its length unit, its CRS."""
    grb = read_mf6_grid(settings.grid) if settings.grid else None
    heads = Mf6NetcdfHeads(settings.file, grb)
    set_seconds(heads, settings)
    length = heads.length_unit or settings.length_unit
    if heads.length_unit and settings.length_unit != 1.0 and abs(settings.length_unit - length) > 1e-12:
        heads.close()
        raise InputError(f"-pfault_heads_length_unit {settings.length_unit:g} contradicts the heads' units in "
                         f"{settings.file} ({length:g} m); remove the option")
    heads.scale = length
    grid = heads.grid
    if heads.crs is None or settings.crs is None:
        grid = scaled(grid, length)                 # coordinates in the model's length unit, as binary files
    elif length != 1.0:                             # coordinates in the CRS's unit: only the elevations scale
        grid = replace(grid, top=grid.top * length, botm=grid.botm * length)
    if heads.crs is not None and settings.crs is not None:
        if not same_crs(heads.crs, settings.crs):
            grid = Reprojected(grid, settings.crs, heads.crs)
    return heads, grid

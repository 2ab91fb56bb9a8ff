"""MODFLOW 6 NetCDF head files written with xarray as MODFLOW 6 writes them (its NetCDF output: src/Utilities/Export
DisNCStructured.f90 and MeshNCModel.f90, CF-1.11 / UGRID-1.0), for tests and examples where MODFLOW 6 itself is not at
hand (as pfault.tools.mf6_write is for the binary files): a structured file (time, z, y, x) and a UGRID layered mesh
(head_l1 ... per layer), with the DIS package's TOP and BOTM exported (EXPORT_ARRAY_NETCDF) or not, and a CRS in the
grid-mapping variable ``projection``. Needs xarray (the tests' extra)."""

from typing import Any

import numpy as np
import xarray as xr

GLOBAL = {"title": "col hydraulic head", "source": "MODFLOW 6 6.6.0", "modflow_model": "col: MODFLOW 6 Groundwater "
          "Flow (GWF) model", "history": "first created 2025/1/1 0:0:0.0"}
TIME = {"calendar": "standard", "units": "days since 1970-01-01T00:00:00", "axis": "T", "standard_name": "time",
        "long_name": "time"}
HNOFLO = 1e30


def _projection(crs: Any, key: str) -> Any:
    return xr.DataArray(np.int32(1), attrs={key: crs.to_wkt()})


def structured(path: str, times: Any, heads: Any, xorigin: float, yorigin: float, delr: Any, delc: Any,
               top: Any = None, botm: Any = None, crs: Any = None, flip_y: bool = False) -> str:
    """heads (nt, nlay, nrow, ncol), rows from the north as MODFLOW numbers them; top (nrow, ncol), botm (nlay,
    nrow, ncol) exported when given. ``flip_y``: y increasing (rows from the south), as a file turned round would
    have it."""
    delr, delc = np.asarray(delr, float), np.asarray(delc, float)
    xe = xorigin + np.concatenate([[0.0], np.cumsum(delr)])
    ye = yorigin + np.sum(delc) - np.concatenate([[0.0], np.cumsum(delc)])       # north edge first
    x, y = 0.5 * (xe[1:] + xe[:-1]), 0.5 * (ye[1:] + ye[:-1])
    xb, yb = np.column_stack([xe[:-1], xe[1:]]), np.column_stack([ye[1:], ye[:-1]])
    heads = np.asarray(heads, float)
    if flip_y:
        y, yb, heads = y[::-1], yb[::-1], heads[:, :, ::-1]
        top = None if top is None else np.asarray(top)[::-1]
        botm = None if botm is None else np.asarray(botm)[:, ::-1]
    grid_map = {"grid_mapping": "projection"} if crs is not None else {}
    ds = xr.Dataset(
        {"head": (("time", "z", "y", "x"), heads, {"units": "m", "standard_name": "", "long_name": "head",
                                                   **grid_map}),
         "x_bnds": (("x", "bnd"), xb), "y_bnds": (("y", "bnd"), yb)},
        coords={"time": ("time", np.asarray(times, float), TIME),
                "z": ("z", np.arange(1, heads.shape[1] + 1, dtype=float), {"units": "layer", "long_name": "layer number"}),
                "y": ("y", y, {"units": "m", "axis": "Y", "standard_name": "projection_y_coordinate",
                               "long_name": "Northing", "bounds": "y_bnds", **grid_map}),
                "x": ("x", x, {"units": "m", "axis": "X", "standard_name": "projection_x_coordinate",
                               "long_name": "Easting", "bounds": "x_bnds", **grid_map})},
        attrs={**GLOBAL, "modflow_grid": "STRUCTURED", "Conventions": "CF-1.11"})
    if top is not None:
        ds["dis_top"] = (("y", "x"), np.asarray(top, float), {"modflow_input": "COL/DIS/TOP", "units": "m"})
        ds["dis_botm"] = (("z", "y", "x"), np.asarray(botm, float), {"modflow_input": "COL/DIS/BOTM", "units": "m"})
    if crs is not None:
        ds["projection"] = _projection(crs, "crs_wkt")
    ds["head"].encoding["_FillValue"] = HNOFLO
    ds.to_netcdf(path, engine="h5netcdf")
    return path


def mesh(path: str, times: Any, heads: Any, vertices: Any, faces: Any, top: Any = None, botm: Any = None,
         crs: Any = None, time_units: str = "") -> str:
    """A UGRID layered mesh: vertices (nvert, 2) in world coordinates, faces (per cell its vertex numbers, 0-based,
    counter-clockwise), heads (nt, nlay, ncpl); top (ncpl,), botm (nlay, ncpl) exported when given; ``time_units``
    (default days since 1970-01-01, MODFLOW's without a start date)."""
    width = max(len(f) for f in faces)
    fill = np.int32(-2147483647)
    face_nodes = np.full((len(faces), width), fill, np.int32)
    for i, f in enumerate(faces):
        face_nodes[i, :len(f)] = np.asarray(f) + 1
    centres = np.array([np.asarray(vertices)[f].mean(axis=0) for f in faces])
    heads = np.asarray(heads, float)
    grid_map = {"grid_mapping": "projection", "coordinates": "mesh_face_x mesh_face_y"} if crs is not None else {}
    data = {
        "mesh": ((), np.int32(1), {"cf_role": "mesh_topology", "long_name": "2D mesh topology",
                                   "topology_dimension": np.int32(2), "face_dimension": "nmesh_face",
                                   "node_coordinates": "mesh_node_x mesh_node_y",
                                   "face_coordinates": "mesh_face_x mesh_face_y",
                                   "face_node_connectivity": "mesh_face_nodes"}),
        "mesh_node_x": (("nmesh_node",), np.asarray(vertices, float)[:, 0], {"units": "m"}),
        "mesh_node_y": (("nmesh_node",), np.asarray(vertices, float)[:, 1], {"units": "m"}),
        "mesh_face_x": (("nmesh_face",), centres[:, 0], {"units": "m"}),
        "mesh_face_y": (("nmesh_face",), centres[:, 1], {"units": "m"}),
        "mesh_face_nodes": (("nmesh_face", "max_nmesh_face_nodes"), face_nodes,
                            {"cf_role": "face_node_connectivity", "start_index": np.int32(1)}),
    }
    for k in range(heads.shape[1]):
        data[f"head_l{k + 1}"] = (("time", "nmesh_face"), heads[:, k],
                                  {"units": "m", "long_name": f"head (layer {k + 1})", "mesh": "mesh",
                                   "location": "face", **grid_map})
    if top is not None:
        data["dis_top"] = (("nmesh_face",), np.asarray(top, float), {"modflow_input": "COL/DIS/TOP", "mesh": "mesh",
                                                                     "location": "face"})
        for k, b in enumerate(np.asarray(botm, float)):
            data[f"dis_botm_l{k + 1}"] = (("nmesh_face",), b, {"modflow_input": "COL/DIS/BOTM",
                                                               "layer": np.int32(k + 1), "mesh": "mesh",
                                                               "location": "face"})
    ds = xr.Dataset(data, coords={"time": ("time", np.asarray(times, float),
                                           {**TIME, **({"units": time_units} if time_units else {})})},
                    attrs={**GLOBAL, "modflow_grid": "LAYERED MESH", "modflow_mesh": "LAYERED",
                           "Conventions": "CF-1.11 UGRID-1.0"})
    if crs is not None:
        ds["projection"] = _projection(crs, "wkt")
    ds["mesh_face_nodes"].encoding["_FillValue"] = fill
    for k in range(heads.shape[1]):
        ds[f"head_l{k + 1}"].encoding["_FillValue"] = HNOFLO
    ds.to_netcdf(path, engine="h5netcdf")
    return path

"""A GeoPackage (OGC 12-128r18, version 1.3) of vector layers, written with Python's sqlite3: what QGIS, GDAL/OGR and
ArcGIS open as layers with their CRS.

A layer is a table of features, each a geometry (Point, LineString or Polygon, in x, y or, for a layer of 3-D
geometries, x, y, z: the standard GeoPackage binary blob, the ``GP`` header with the CRS id and the envelope (xy or
xyz), then little-endian ISO WKB, a Z geometry's type code plus 1000) and attributes (REAL, INTEGER or TEXT columns;
NaN and infinite values are NULL). The CRS is written into ``gpkg_spatial_ref_sys`` as its WKT 1 (the definition every reader takes)
under its EPSG code when it has one, else under a code of the file's own (organization ``NONE``). The file is
written into ``path``.tmp and renamed: a reader never sees half of it.
"""

from __future__ import annotations

import os
import sqlite3
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

APPLICATION_ID = 0x47504B47          # 'GPKG'
USER_VERSION = 10300                 # version 1.3.0
OWN_SRS_ID = 100000                  # srs_id of a CRS without an EPSG code
WKB_TYPES = {"POINT": 1, "LINESTRING": 2, "POLYGON": 3}
SQL_TYPES = {"f": "REAL", "i": "INTEGER", "u": "INTEGER", "b": "INTEGER", "U": "TEXT", "O": "TEXT", "S": "TEXT"}

CORE_TABLES = """
CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT NOT NULL, srs_id INTEGER NOT NULL PRIMARY KEY,
  organization TEXT NOT NULL, organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT);
CREATE TABLE gpkg_contents (table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT NULL, identifier TEXT UNIQUE,
  description TEXT DEFAULT '', last_change DATETIME NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')),
  min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER,
  CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id));
CREATE TABLE gpkg_geometry_columns (table_name TEXT NOT NULL, column_name TEXT NOT NULL,
  geometry_type_name TEXT NOT NULL, srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT NULL,
  CONSTRAINT pk_geom_cols PRIMARY KEY (table_name, column_name),
  CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name),
  CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id));
"""
UNDEFINED_SRS = [("Undefined cartesian SRS", -1, "NONE", -1, "undefined", "undefined cartesian coordinate reference system"),
                 ("Undefined geographic SRS", 0, "NONE", 0, "undefined", "undefined geographic coordinate reference system")]


@dataclass
class Layer:
    """A layer: its name, geometry type (POINT, LINESTRING or POLYGON), the geometries (per feature: an (n, 2) array
    of points for a line, a list of rings (each (n, 2), the exterior first) for a polygon, (2,) for a point) and
    the attribute columns ({name: array or list, one value per feature}); ``dims`` 3: the points are (n, 3), x, y, z
    (a Z geometry: QGIS draws x, y on a map and the whole in its 3-D view)."""
    name: str
    geometry_type: str
    geometries: list
    attributes: dict = field(default_factory=dict)
    description: str = ""
    dims: int = 2


def _ring_bytes(ring: np.ndarray, dims: int = 2) -> bytes:
    ring = np.asarray(ring, dtype="<f8").reshape(-1, dims)
    if not np.array_equal(ring[0], ring[-1]):
        ring = np.vstack([ring, ring[:1]])
    return struct.pack("<I", len(ring)) + ring.tobytes()


def geometry_blob(kind: str, geometry: Any, srs_id: int, dims: int = 2) -> bytes:
    """The GeoPackage binary of one geometry in ``dims`` (2 or 3) coordinates: header (little endian, envelope xy or
    xyz; none for a point) and ISO WKB."""
    code = WKB_TYPES[kind] + (1000 if dims == 3 else 0)
    if kind == "POINT":
        xy = np.asarray(geometry, dtype="<f8").reshape(dims)
        return b"GP\x00\x01" + struct.pack("<i", srs_id) + struct.pack("<BI", 1, code) + xy.tobytes()
    if kind == "LINESTRING":
        pts = np.asarray(geometry, dtype="<f8").reshape(-1, dims)
        body = struct.pack("<BI", 1, code) + struct.pack("<I", len(pts)) + pts.tobytes()
    else:
        rings = [np.asarray(r, dtype="<f8").reshape(-1, dims) for r in geometry]
        pts = np.vstack(rings)
        body = struct.pack("<BII", 1, code, len(rings)) + b"".join(_ring_bytes(r, dims) for r in rings)
    env = struct.pack(f"<{2 * dims}d", *np.column_stack([pts.min(axis=0), pts.max(axis=0)]).ravel())
    flags = b"\x03" if dims == 2 else b"\x05"       # little endian, envelope code 1 (xy) or 2 (xyz)
    return b"GP\x00" + flags + struct.pack("<i", srs_id) + env + body


def _srs_row(crs) -> tuple:
    epsg = crs.to_epsg()
    wkt = crs.to_wkt("WKT1_GDAL")
    if epsg:
        return (crs.name, int(epsg), "EPSG", int(epsg), wkt, crs.name)
    return (crs.name, OWN_SRS_ID, "NONE", OWN_SRS_ID, wkt, crs.name)


def _column_type(values) -> str:
    return SQL_TYPES.get(np.asarray(values).dtype.kind, "TEXT")


def _python(value):
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    if isinstance(value, (np.integer, np.bool_, bool)):
        return int(value)
    return value if value is None or isinstance(value, (int, str)) else str(value)


def _add_layer(db: sqlite3.Connection, layer: Layer, srs_id: int) -> None:
    kind = layer.geometry_type.upper()
    cols = list(layer.attributes)
    defs = "".join(f', "{c}" {_column_type(layer.attributes[c])}' for c in cols)
    db.execute(f'CREATE TABLE "{layer.name}" (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom {kind}{defs})')
    blobs = [geometry_blob(kind, g, srs_id, layer.dims) for g in layer.geometries]
    rows = [(b, *(_python(layer.attributes[c][i]) for c in cols)) for i, b in enumerate(blobs)]
    marks = ", ".join("?" * (len(cols) + 1))
    names = ", ".join(["geom"] + [f'"{c}"' for c in cols])
    db.executemany(f'INSERT INTO "{layer.name}" ({names}) VALUES ({marks})', rows)
    if layer.geometries:
        pts = np.vstack([np.vstack(g) if kind == "POLYGON" else np.asarray(g, float).reshape(-1, layer.dims)
                         for g in layer.geometries])
        box = (float(pts[:, 0].min()), float(pts[:, 1].min()), float(pts[:, 0].max()), float(pts[:, 1].max()))
    else:
        box = (None, None, None, None)
    db.execute("INSERT INTO gpkg_contents (table_name, data_type, identifier, description, min_x, min_y, max_x, "
               "max_y, srs_id) VALUES (?, 'features', ?, ?, ?, ?, ?, ?, ?)",
               (layer.name, layer.name, layer.description, *box, srs_id))
    db.execute("INSERT INTO gpkg_geometry_columns VALUES (?, 'geom', ?, ?, ?, 0)",
               (layer.name, kind, srs_id, int(layer.dims == 3)))


def write_geopackage(path: str, crs: Any, layers: Sequence[Layer]) -> str:
    """The GeoPackage ``path`` with ``layers`` in ``crs`` (a pyproj CRS), replacing any file there."""
    tmp = path + ".tmp"
    if os.path.exists(tmp):
        os.remove(tmp)
    db = sqlite3.connect(tmp)
    try:
        db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        db.execute(f"PRAGMA user_version = {USER_VERSION}")
        db.executescript(CORE_TABLES)
        srs = _srs_row(crs)
        from pyproj import CRS
        wgs84 = [] if srs[1] == 4326 else [_srs_row(CRS.from_epsg(4326))]      # a GeoPackage always defines it
        db.executemany("INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, ?, ?, ?, ?)", UNDEFINED_SRS + wgs84 + [srs])
        for layer in layers:
            _add_layer(db, layer, srs[1])
        db.commit()
    finally:
        db.close()
    os.replace(tmp, path)
    return path

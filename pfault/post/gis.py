"""A run's answer as GIS layers in ``gis/`` (``-pfault_crs``), read from the run's files at its end, or by ``python -m
pfault.post.gis RUN_DIR`` for any run directory written with a CRS:

- rasters, each a GeoTIFF with its CRS and geotransform (GDAL, QGIS, ArcGIS, rasterio): ``subsidence.tif`` (m,
  downward positive), ``horizontal_strain.tif`` (largest principal horizontal strain, tension positive) and
  ``angular_distortion.tif`` (|grad u_z|) of the land surface at the last output time, on square pixels aligned on
  multiples of ``-pfault_map_spacing`` in site coordinates (the LOS raster's rule, pfault.io.probes); their every
  output time in ``surface_maps.nc`` (CF NetCDF with its grid mapping: QGIS's temporal controller, xarray); the LOS
  raster's last time, ``insar_los.tif`` and ``insar_los_velocity.tif`` (m, m/s), from ``insar_los.nc`` (whose CRS is
  the scene's, or the InSAR product's for ``-pfault_insar_grid``); with materials that remember, on the same grid,
  ``subsidence_inelastic.tif``, ``subsidence_elastic.tif`` and per compressible layer ``critical_head_<layer>.tif``
  and ``head_margin_<layer>.tif`` (m, relative to the initial heads) from surface.h5's point data;
- ``pfault.gpkg``, a GeoPackage of vector layers: ``fault_faces`` (each fault face as a 3-D triangle with its fault,
  state, slip, opening and margin to failure at the last output time), ``fault_traces`` (each fault face's edge on
  the land surface, with its face's fields), ``fissure_traces`` (those of faces that broke, with
  when), ``hazard_zones`` (the land surface whose horizontal strain exceeds ``-pfault_hazard_strain_threshold`` at the
  last output time: one polygon per edge-connected zone, its area and peak strain) and ``stations`` (each station
  with its last displacement);
- ``stations_enu.csv``: each station's displacement as a GNSS time series: geodetic east, north and up in mm (the
  site axes turned by the meridian convergence at the station), with the date and decimal year when the scene has
  ``-pfault_start_date``.

A pixel takes the P1 value of the land-surface triangle under its centre (the displacement on the side of a fault
trace its triangle lies; the hazard fields are per triangle); pixels off the land surface are no-data (NaN). Every
coordinate is a site coordinate, mesh + ``-pfault_mesh_origin``. Rank 0 only, from the files; each file is written
whole and renamed.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..georef import Transform, cf_time_units, crs_from_cf, dates, decimal_year, parse_date, true_east_north
from ..hazard import _zones
from ..io.geopackage import Layer, write_geopackage
from ..io.insar import read_netcdf
from ..io.output import open_h5, replace_text
from ..io.probes import _pixels_in_triangles
from ..io.rasters import add_grid_mapping, write_geotiff
from ..units import parse_quantity
from . import fissures
from .rundir import read_options, read_station_series, read_summary, read_surface_steps

DIR = "gis"
STATE_NAMES = ("stick", "slip", "open")
MAPS = (("subsidence", "m", "vertical displacement of the land surface, downward positive"),
        ("horizontal_strain", "1", "largest principal horizontal strain of the land surface, tension positive"),
        ("angular_distortion", "1", "slope of the differential subsidence, |grad u_z|"))
SOIL_MAPS = (("subsidence_inelastic", "m", "inelastic compaction of the column under the land surface, downward "
              "positive: it stays when the heads recover"),
             ("subsidence_elastic", "m", "the rest of the subsidence, which comes back when the heads recover"))
LAYER_MAPS = (("critical_head", "m", "critical (preconsolidation) head of layer {}, relative to the initial heads: the "
               "mean over the column's length in the layer"),
              ("head_margin", "m", "further drawdown before layer {} compacts inelastically again"))
MODE_NAMES = {0: "slip", 1: "open", 2: "break", -1: "never"}


@dataclass(frozen=True)
class GisContext:
    """What the layers need of a run: its CRS (pyproj), start date (or None), site = mesh + origin, the maps' pixel
    size (None: the land surface's mean edge), the hazard threshold and the faults' names."""
    crs: Any
    start: Any
    origin: np.ndarray
    spacing: float | None
    threshold: float
    faults: list


def read_context(run_dir: str) -> GisContext | None:
    """The run's GIS context from its summary.json (``georef``) and options.txt; None without a CRS."""
    try:
        georef = (read_summary(run_dir) or {}).get("georef") or {}
    except (OSError, ValueError):
        return None
    if not georef.get("crs"):
        return None
    from pyproj import CRS
    opts = read_options(run_dir)
    origin = np.array([float(v) for v in opts.get("pfault_mesh_origin", "0,0,0").split(",")])
    spacing = opts.get("pfault_map_spacing") or opts.get("pfault_insar_spacing")
    start = georef.get("start_date")
    return GisContext(CRS.from_wkt(georef["crs"]["wkt"]), parse_date(start, "start_date") if start else None,
                      origin, parse_quantity(spacing, "pfault_map_spacing", "m") if spacing else None,
                      parse_quantity(opts.get("pfault_hazard_strain_threshold", "2e-4"), "threshold", ""),
                      fissures.fault_names(run_dir))


# -- rasters --------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PixelMap:
    """Pixels over triangles: centres ``x`` (nx,), ``y`` (ny,) ascending, and for each pixel inside (row-major flat
    index ``pixel``) its triangle and barycentric coordinates."""
    x: np.ndarray
    y: np.ndarray
    pixel: np.ndarray
    triangle: np.ndarray
    lam: np.ndarray

    def fill(self, values: np.ndarray) -> np.ndarray:
        """(ny, nx) map of per-pixel ``values`` (NaN off the triangles)."""
        out = np.full(len(self.y) * len(self.x), np.nan)
        out[self.pixel] = values
        return out.reshape(len(self.y), len(self.x))


def pixel_map(xy: np.ndarray, triangles: np.ndarray, spacing: float | None) -> PixelMap:
    """Pixels aligned on multiples of ``spacing`` (default: the triangles' mean edge) over the triangles (``xy`` the
    points' site x, y); a pixel centre on several triangles takes the first."""
    p = xy[triangles]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    flat = np.flatnonzero(np.abs(area) > 1e-9 * np.abs(area).max())
    p = p[flat]
    if spacing is None:
        spacing = float(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).mean())
    lo, hi = p.min(axis=(0, 1)), p.max(axis=(0, 1))
    first = np.floor(lo / spacing + 1e-9) * spacing
    count = np.maximum(np.ceil((hi - first) / spacing - 1e-9).astype(np.int64), 1)
    pixel, k, lam = _pixels_in_triangles(p, first, spacing, count)
    order = np.lexsort((k, pixel))
    pixel, k, lam = pixel[order], k[order], lam[order]
    one = np.r_[True, pixel[1:] != pixel[:-1]] if len(pixel) else np.zeros(0, bool)
    x = first[0] + spacing * (np.arange(count[0]) + 0.5)
    y = first[1] + spacing * (np.arange(count[1]) + 0.5)
    return PixelMap(x, y, pixel[one], flat[k[one]], lam[one])


def surface_maps(run_dir: str, ctx: GisContext, out: str) -> list[str]:
    """The land surface's maps: surface_maps.nc (every output time) and the GeoTIFFs of the last."""
    points, tris, steps = read_surface_steps(run_dir)
    xy = points[:, :2] + ctx.origin[:2]
    pm = pixel_map(xy, tris, ctx.spacing)
    corners = tris[pm.triangle]
    maps = {name: [] for name, _, _ in MAPS}
    for _, _, u, strain, distortion in steps:
        maps["subsidence"].append(pm.fill(-np.einsum("pk,pk->p", pm.lam, u[corners, 2])))
        maps["horizontal_strain"].append(pm.fill(strain[pm.triangle]))
        maps["angular_distortion"].append(pm.fill(distortion[pm.triangle]))
    times = np.array([s[1] for s in steps])
    written = [write_maps_netcdf(os.path.join(out, "surface_maps.nc"), pm.x, pm.y, times,
                                 np.array([s[0] for s in steps]), {k: np.array(v) for k, v in maps.items()}, ctx)]
    for name, unit, long in MAPS:
        written.append(write_geotiff(os.path.join(out, f"{name}.tif"), pm.x, pm.y, maps[name][-1], ctx.crs,
                                     _tags(long, unit, times[-1], ctx)))
    for name, unit, long, at_points in soil_point_maps(run_dir):
        values = pm.fill(np.einsum("pk,pk->p", pm.lam, at_points[corners]))
        written.append(write_geotiff(os.path.join(out, f"{name}.tif"), pm.x, pm.y, values, ctx.crs,
                                     _tags(long, unit, times[-1], ctx)))
    return written


def soil_point_maps(run_dir: str) -> list[tuple[str, str, str, np.ndarray]]:
    """(file name, unit, long name, values at the land surface's points) of surface.h5's last output time for
    materials that remember: the inelastic and elastic subsidence, and per compressible layer its critical head and
    head margin ([] without them; pfault.soils.columns)."""
    with open_h5(os.path.join(run_dir, "surface.h5"), "r") as f:
        g = f["steps"][sorted(f["steps"])[-1]]
        data = {k: g[k][...] for k in g if k.startswith(("subsidence_", "critical_head_", "head_margin_"))}
    maps = [(name, unit, long, data[name]) for name, unit, long in SOIL_MAPS if name in data]
    layers = sorted(k[len("critical_head_"):] for k in data if k.startswith("critical_head_"))
    return maps + [(f"{kind}_{layer}", unit, long.format(layer), data[f"{kind}_{layer}"])
                   for layer in layers for kind, unit, long in LAYER_MAPS]


def _tags(long: str, unit: str, t: float, ctx: GisContext) -> dict:
    tags = {"long_name": long, "units": unit, "time_s": repr(float(t))}
    if ctx.start is not None:
        tags["date"] = dates(ctx.start, t)[0].isoformat()
    return tags


def write_maps_netcdf(path: str, x: np.ndarray, y: np.ndarray, times: np.ndarray, steps: np.ndarray, maps: dict,
                      ctx: GisContext) -> str:
    """CF-1.8 NetCDF-4 of maps (time, y, x) with the grid mapping ``spatial_ref`` of the run's CRS."""
    import h5netcdf
    tmp = path + ".tmp"
    with h5netcdf.File(tmp, "w") as nc:
        nc.attrs.update({"Conventions": "CF-1.8", "title": "maps of the land surface (pfault)"})
        nc.dimensions = {"time": len(times), "y": len(y), "x": len(x)}
        add_grid_mapping(nc, ctx.crs)
        for name, values, axis in (("x", x, "X"), ("y", y, "Y")):
            v = nc.create_variable(name, (name,), np.float64, data=values)
            v.attrs.update({"standard_name": f"projection_{name}_coordinate", "units": "m", "axis": axis})
        v = nc.create_variable("time", ("time",), np.float64, data=times)
        v.attrs.update({"units": cf_time_units(ctx.start), "standard_name": "time", "axis": "T"})
        if ctx.start is not None:
            v.attrs["calendar"] = "standard"
        nc.create_variable("step", ("time",), np.int64, data=steps)
        for name, unit, long in MAPS:
            v = nc.create_variable(name, ("time", "y", "x"), np.float64, data=maps[name], fillvalue=np.nan,
                                   chunks=(1, len(y), len(x)))
            v.attrs.update({"units": unit, "long_name": long, "grid_mapping": "spatial_ref"})
    os.replace(tmp, path)
    return path


def los_geotiffs(run_dir: str, ctx: GisContext, out: str) -> list[str]:
    """insar_los.tif and insar_los_velocity.tif: the LOS raster's last output time, in the raster's CRS."""
    path = os.path.join(run_dir, "insar_los.nc")
    if not os.path.exists(path):
        return []
    d = read_netcdf(path)
    crs = crs_from_cf(d.get("grid_mapping", {}), path) or ctx.crs
    if not (_regular(d["x"]) and _regular(d["y"])):
        return []
    return [write_geotiff(os.path.join(out, f"{name}.tif"), d["x"], d["y"], d[key][-1], crs,
                          _tags(long, unit, d["time"][-1], ctx))
            for name, key, unit, long in (
                ("insar_los", "los_displacement", "m", "line-of-sight displacement, positive towards the satellite"),
                ("insar_los_velocity", "los_velocity", "m s-1", "line-of-sight velocity since the previous output"))]


def _regular(axis: np.ndarray) -> bool:
    step = np.diff(axis)
    return len(axis) < 2 or bool(np.all(np.abs(step - step[0]) <= 1e-9 * max(abs(step[0]), 1.0)))


# -- vector layers ---------------------------------------------------------------------------------------------------
def trace_layers(run_dir: str, ctx: GisContext) -> list[Layer]:
    """fault_faces, fault_traces and fissure_traces: the fault faces (3-D triangles) and their edges on the land
    surface at the last output time, with their margins to failure."""
    path = os.path.join(run_dir, "fault.h5")
    if not os.path.exists(path):
        return []
    with open_h5(path, "r") as f:
        points, faces = f["mesh/points"][...], f["mesh/cells"][...].astype(np.int64)
        g = f["steps"][sorted(f["steps"])[-1]]
        data = {k: g[k][...] for k in ("fault", "state", "opening", "slip_magnitude", "broken", "break_time",
                                       "margin_drawdown_m", "margin_pore_pressure_pa", "margin_mode") if k in g}
        t = float(g.attrs["time"])
    per_face = face_attributes(data, len(faces), ctx, t)
    site = points + ctx.origin
    layers = [Layer("fault_faces", "POLYGON", [[tri] for tri in site[faces]], per_face,
                    "fault faces (3-D triangles, site coordinates) and their margins to failure", dims=3)]
    on = fissures.on_land_surface(run_dir, points)
    edges, face = fissures.surface_edges(faces, np.ones(len(faces), bool), on)
    xy = site[edges][:, :, :2]
    attrs = {k: np.asarray(v)[face] for k, v in per_face.items()}
    layers.append(Layer("fault_traces", "LINESTRING", list(xy), attrs, "fault faces' edges on the land surface"))
    when = data.get("break_time", np.full(len(faces), np.nan))[face]
    formed = np.isfinite(when)
    sub = {k: np.asarray(v)[formed] for k, v in attrs.items() if k not in ("state", "broken")}
    sub["break_time_s"] = when[formed]
    if ctx.start is not None:
        sub["break_date"] = np.array([d.date().isoformat() for d in dates(ctx.start, when[formed])], dtype=object)
    layers.append(Layer("fissure_traces", "LINESTRING", list(xy[formed]), sub,
                        "edges on the land surface of the fault faces that broke (fissures that reached it)"))
    return layers


def face_attributes(data: dict, n: int, ctx: GisContext, t: float) -> dict:
    """Per fault face of fault.h5's ``data`` at time ``t``: its fault's name, row, state, slip, opening, broken,
    and its margin to failure: ``margin_drawdown_m`` (m of further drawdown; 0 failed now; NULL where no margin was
    computed or no further drawdown fails the face), ``margin_pore_pressure_pa`` and ``margin_mode`` (slip, open,
    break; never: no further drawdown fails it; NULL where no margin was computed)."""
    fault = data.get("fault", np.zeros(n)).astype(np.int64)
    names = np.array([ctx.faults[k] if k < len(ctx.faults) else f"fault {k}" for k in fault], dtype=object)
    state = data.get("state", np.zeros(n)).astype(np.int64)
    margin = data.get("margin_drawdown_m", np.full(n, np.nan)).astype(float)
    code = data.get("margin_mode", np.full(n, -1)).astype(np.int64)
    mode = np.array([MODE_NAMES.get(int(c)) for c in code], dtype=object)
    mode[np.isnan(margin)] = None
    return {"fault": names, "face": np.arange(n), "state": np.array([STATE_NAMES[s] for s in state], dtype=object),
            "slip_m": data.get("slip_magnitude", np.zeros(n)), "opening_m": data.get("opening", np.zeros(n)),
            "broken": data.get("broken", np.ones(n)).astype(np.int64), "margin_drawdown_m": margin,
            "margin_pore_pressure_pa": data.get("margin_pore_pressure_pa", np.full(n, np.nan)).astype(float),
            "margin_mode": mode, "time_s": np.full(n, t)}


def _rings(triangles: np.ndarray, xy: np.ndarray) -> list[np.ndarray]:
    """The boundary of a set of triangles as closed rings (arrays of points), exterior first (largest area)."""
    p = xy[triangles]
    ccw = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) > 0
    tri = np.where(ccw[:, None], triangles, triangles[:, ::-1])
    directed = tri[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    key = np.sort(directed, axis=1)
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = directed[count[inv.ravel()] == 1]
    following = {int(a): int(b) for a, b in boundary}
    rings = []
    while following:
        start = next(iter(following))
        ring, v = [start], following.pop(start)
        while v != start and v in following:
            ring.append(v)
            v = following.pop(v)
        rings.append(xy[ring + [start]])
    area = [abs(0.5 * np.sum(r[:-1, 0] * r[1:, 1] - r[1:, 0] * r[:-1, 1])) for r in rings]
    return [rings[i] for i in np.argsort(area)[::-1]]


def hazard_layer(run_dir: str, ctx: GisContext) -> list[Layer]:
    """hazard_zones: per edge-connected zone of triangles whose horizontal strain exceeds the threshold at the
    last output time, its outline (holes included), area and peak strain."""
    points, tris, steps = read_surface_steps(run_dir)
    _, t, _, strain, _ = steps[-1]
    prone = strain > ctx.threshold
    xy = points[:, :2] + ctx.origin[:2]
    geoms, area, peak = [], [], []
    if prone.any():
        zone = _zones(tris[prone])
        p = xy[tris[prone]]
        tri_area = 0.5 * np.abs(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
        for z in range(zone.max() + 1):
            mine = zone == z
            geoms.append(_rings(tris[prone][mine], xy))
            area.append(float(tri_area[mine].sum()))
            peak.append(float(strain[prone][mine].max()))
    attrs = {"area_m2": np.array(area), "max_horizontal_strain": np.array(peak),
             "threshold": np.full(len(geoms), ctx.threshold), "time_s": np.full(len(geoms), t)}
    return [Layer("hazard_zones", "POLYGON", geoms, attrs,
                  "land surface whose horizontal tensile strain exceeds -pfault_hazard_strain_threshold")]


# -- stations -------------------------------------------------------------------------------------------------------
def station_outputs(run_dir: str, ctx: GisContext, out: str) -> tuple[list[str], list[Layer]]:
    """stations_enu.csv and the stations layer (geodetic east/north/up in mm; pfault.georef.true_east_north)."""
    h5 = os.path.join(run_dir, "station_displacement.h5")
    if not os.path.exists(h5):
        return [], []
    with open_h5(h5, "r") as f:
        names = [s.decode() for s in f["stations"][()]]
        xyz = f["geometry/vertices"][()]
    series = read_station_series(run_dir)
    east, north = true_east_north(ctx.crs, xyz[:, 0], xyz[:, 1])
    lon, lat = Transform(ctx.crs, ctx.crs.geodetic_crs)(xyz[:, 0], xyz[:, 1])
    lines = ["station,date,decimal_year,time_s,east_mm,north_mm,up_mm\n"]
    last = []
    for i, name in enumerate(names):
        t, u = series[name].time, series[name].u
        enu = np.column_stack([u[:, :2] @ east[i], u[:, :2] @ north[i], u[:, 2]]) * 1e3
        when = dates(ctx.start, t) if ctx.start is not None else [None] * len(t)
        lines += [f"{name},{d.date().isoformat() if d else ''},{f'{decimal_year(d):.6f}' if d else ''},"
                  f"{s!r},{e:.4f},{n:.4f},{v:.4f}\n" for d, s, (e, n, v) in zip(when, t.tolist(), enu)]
        last.append(enu[-1])
    path = os.path.join(out, "stations_enu.csv")
    replace_text(path, "".join(lines))
    last = np.array(last).reshape(-1, 3)
    attrs = {"station": np.array(names, dtype=object), "z_m": xyz[:, 2], "longitude": lon, "latitude": lat,
             "east_mm": last[:, 0], "north_mm": last[:, 1], "up_mm": last[:, 2]}
    return [path], [Layer("stations", "POINT", list(xyz[:, :2]), attrs, "stations and their last displacement")]


def write_gis(run_dir: str) -> list[str]:
    """Every GIS file of a run written with a CRS into RUN_DIR/gis (module docstring); [] without a CRS."""
    ctx = read_context(run_dir)
    if ctx is None:
        return []
    out = os.path.join(run_dir, DIR)
    os.makedirs(out, exist_ok=True)
    written = los_geotiffs(run_dir, ctx, out)
    layers: list[Layer] = []
    if os.path.exists(os.path.join(run_dir, "surface.h5")):
        written += surface_maps(run_dir, ctx, out)
        layers += hazard_layer(run_dir, ctx)
    layers += trace_layers(run_dir, ctx)
    files, station_layers = station_outputs(run_dir, ctx, out)
    written += files
    layers += station_layers
    if layers:
        written.append(write_geopackage(os.path.join(out, "pfault.gpkg"), ctx.crs, layers))
    return written


def main(argv: list[str] | None = None) -> int:
    """``python -m pfault.post.gis RUN_DIR``: (re)write the run's GIS layers."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1 or not os.path.isdir(args[0]):
        sys.stderr.write("usage: python -m pfault.post.gis RUN_DIR  (a run written with -pfault_crs)\n")
        return 2
    written = write_gis(args[0])
    if not written:
        sys.stderr.write(f"pfault.post.gis: error: {args[0]}: the run has no CRS (summary.json georef); run the scene "
                         "with -pfault_crs\n")
        return 1
    print(f"pfault.post.gis: {len(written)} files in {os.path.join(args[0], DIR)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

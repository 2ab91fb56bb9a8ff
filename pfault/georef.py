"""Where a scene is on Earth and in the calendar: ``-pfault_crs`` (the coordinate reference system of the site
coordinates) and ``-pfault_start_date`` (the date of the scene's time 0).

Site coordinates are mesh coordinates plus ``-pfault_mesh_origin`` (pfault.io.probes.mesh_to_site), in metres; with
``-pfault_crs`` they are the easting and northing of that CRS, which must therefore be projected with metre axes (a
UTM zone, a national grid). The vertical stays as the scene has it: site z, in metres.

- ``parse_crs``: an authority code (``EPSG:32650``, ``32650``, ``ESRI:102003``), a file holding WKT (a ``.prj`` or
  ``.wkt``; found from the working directory, else beside the scene file), or a WKT / PROJ string, read by pyproj
  (PROJ's database); anything else is an InputError naming the option and the fix.
- ``Transform``: coordinates from one CRS to another (pyproj, always easting/longitude first), the identity when
  either is unknown or both are the same.
- ``cf_grid_mapping`` / ``crs_from_cf``: the CF grid-mapping attributes of a CRS (pyproj's ``to_cf`` with
  ``crs_wkt`` and GDAL's ``spatial_ref``), and the CRS such attributes describe.
- ``true_east_north``: the unit vectors of geodetic east and north in the projected plane at given points: a GNSS
  series is in the local east/north/up frame, which a projected grid meets at the meridian convergence (up to a few
  degrees in a UTM zone).
- dates: ``parse_date`` (ISO 8601 dates and date-times, UTC), ``cf_time_units`` (``seconds since ...``),
  ``decimal_year``.

pyproj is imported when a CRS is used: a scene without ``-pfault_crs`` does not load it.
"""

from __future__ import annotations

import datetime as dt
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError
from .paths import beside_scene, file_problem

OPTION = "-pfault_crs"
EXAMPLE = "EPSG:32650 (WGS 84 / UTM zone 50N)"
UTC = dt.timezone.utc


@dataclass(frozen=True)
class Georef:
    """The scene's CRS (pyproj CRS, or None: site coordinates are not placed on Earth) and the date of its time 0
    (None: times are seconds from the start only)."""
    crs: Any = None
    start: dt.datetime | None = None
    crs_file: str = ""          # the .prj/.wkt file -pfault_crs named ('': a code or a WKT string)

    @property
    def wkt(self) -> str:
        return self.crs.to_wkt() if self.crs is not None else ""

    def summary(self) -> dict:
        """summary.json's ``georef``: the CRS (name, EPSG code or null, WKT) and the start date (ISO, or null)."""
        crs = None if self.crs is None else {"name": self.crs.name, "epsg": self.crs.to_epsg(), "wkt": self.wkt}
        return {"crs": crs, "start_date": None if self.start is None else self.start.isoformat()}


def parse_crs(text: str, where: str = OPTION, scene_file: str = "", projected: bool = True) -> Any:
    """The pyproj CRS ``text`` names (an authority code, a WKT file, a WKT or PROJ string); ``projected``: it must be
    a projected CRS in metres (the horizontal part of a compound CRS is taken)."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError
    value = text.strip()
    path = beside_scene(value, scene_file)
    if os.path.exists(path):
        problem = file_problem(path)
        if problem:
            raise InputError(f"{where} {value}: {problem}; give an EPSG code (e.g. {EXAMPLE}) or a .prj/.wkt file")
        with open(path, encoding="utf-8", errors="replace") as fh:
            value = fh.read().strip()
    elif value.isdigit():
        value = f"EPSG:{value}"
    try:
        crs = CRS.from_user_input(value)
    except CRSError as exc:
        shown = text if len(text) < 60 else text[:57] + "..."
        raise InputError(f"{where} {shown}: not a coordinate reference system PROJ knows ({str(exc).splitlines()[0]});"
                         f" give an EPSG code (e.g. {EXAMPLE}), a .prj/.wkt file or a WKT string") from None
    if crs.is_compound:
        crs = next((c for c in crs.sub_crs_list if c.is_projected or c.is_geographic), crs)
    if projected:
        check_projected_metres(crs, f"{where} {text}")
    return crs


def check_projected_metres(crs: Any, where: str) -> None:
    """Site coordinates are metres east and north: a geographic CRS, or a projected one in feet, is an error."""
    if not crs.is_projected:
        raise InputError(f"{where}: '{crs.name}' is not a projected CRS (site coordinates are metres east and north "
                         f"of a map projection); give the projected CRS of the site, e.g. its UTM zone ({EXAMPLE})")
    units = {a.unit_name for a in crs.axis_info[:2]}
    if not units <= {"metre", "meter", "m"}:
        raise InputError(f"{where}: '{crs.name}' has axes in {', '.join(sorted(units))}, but site coordinates are "
                         "metres; give a projected CRS in metres (e.g. the metric variant of the national grid)")


def parse_date(text: str, where: str) -> dt.datetime:
    """An ISO 8601 date or date-time (``2015-01-01``, ``2015-01-01T12:00:00``, ``...Z``), in UTC."""
    value = text.strip()
    try:
        when = dt.datetime.fromisoformat(value[:-1] + "+00:00" if value.endswith("Z") else value)
    except ValueError:
        raise InputError(f"{where} {text}: not an ISO 8601 date; give the date as YYYY-MM-DD (e.g. 2015-01-01) or a "
                         "date-time YYYY-MM-DDTHH:MM:SS (UTC)") from None
    return when.replace(tzinfo=UTC) if when.tzinfo is None else when.astimezone(UTC)


def read_georef(reader: Any, scene_file: str = "") -> Georef:
    """-pfault_crs and -pfault_start_date (every rank reads and checks them alike)."""
    text = reader.get("pfault_crs")
    start = reader.get("pfault_start_date")
    crs = parse_crs(text, OPTION, scene_file) if text else None
    path = beside_scene(text.strip(), scene_file) if text else ""
    return Georef(crs, parse_date(start, "-pfault_start_date") if start else None,
                  path if path and os.path.isfile(path) else "")


def same_crs(a: Any, b: Any) -> bool:
    """Whether two CRSs (or None) give the same coordinates: None matches anything (coordinates as they are)."""
    return a is None or b is None or a == b or a.equals(b, ignore_axis_order=True)


class Transform:
    """Coordinates from CRS ``src`` to CRS ``dst`` (x, y arrays; easting or longitude first); the identity when they
    are the same or either is None."""

    def __init__(self, src: Any, dst: Any) -> None:
        self.identity = same_crs(src, dst)
        self.src, self.dst = src, dst
        if not self.identity:
            from pyproj import Transformer
            self.transformer = Transformer.from_crs(src, dst, always_xy=True)

    def __call__(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        if self.identity:
            return x, y
        a, b = self.transformer.transform(x, y)
        return np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)


def cf_grid_mapping(crs: Any) -> dict[str, Any]:
    """Attributes of a CF grid-mapping variable for ``crs``: pyproj's CF parameters, ``crs_wkt`` (CF 1.7) and
    ``spatial_ref`` (what GDAL and QGIS read first)."""
    attrs = {k: v for k, v in crs.to_cf().items() if v is not None}
    wkt = crs.to_wkt()
    attrs.update({"crs_wkt": wkt, "spatial_ref": wkt})
    return attrs


def crs_from_cf(attrs: dict, where: str) -> Any:
    """The CRS of a CF grid-mapping variable's attributes (``crs_wkt``, ``spatial_ref``, ``wkt`` as MODFLOW 6's
    mesh files have it, or the CF parameters), None when they hold none."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError
    text = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in attrs.items()}
    for key in ("crs_wkt", "spatial_ref", "wkt", "esri_pe_string"):
        if isinstance(text.get(key), str) and text[key].strip():
            try:
                return CRS.from_wkt(text[key])
            except CRSError as exc:
                raise InputError(f"{where}: its grid mapping's {key} is not a WKT PROJ reads ({exc}); fix the "
                                 "attribute or remove it") from None
    if "grid_mapping_name" in text:
        try:
            return CRS.from_cf(text)
        except CRSError as exc:
            raise InputError(f"{where}: its grid mapping does not describe a CRS ({exc})") from None
    if "epsg_code" in text or "EPSG" in text:
        code = str(text.get("epsg_code", text.get("EPSG"))).split(":")[-1]
        return CRS.from_epsg(int(code))
    return None


def true_east_north(crs: Any, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (n, 2) of geodetic east and north in the plane of the projected ``crs`` at the points (x, y):
    north from a step of 1e-5 degrees of latitude, east a quarter turn clockwise from it (a conformal projection)."""
    geo = crs.geodetic_crs
    to_geo, to_map = Transform(crs, geo), Transform(geo, crs)
    lon, lat = to_geo(x, y)
    xn, yn = to_map(lon, lat + 1e-5)
    north = np.column_stack([xn - np.asarray(x, float), yn - np.asarray(y, float)])
    north /= np.linalg.norm(north, axis=1)[:, None]
    east = np.column_stack([north[:, 1], -north[:, 0]])
    return east, north


def cf_time_units(start: dt.datetime | None) -> str:
    """CF units of times in seconds from the scene's start: ``seconds since <start>`` with a start date (a calendar
    axis GDAL, QGIS's temporal controller and xarray read as dates), else ``s``."""
    return "s" if start is None else f"seconds since {start.strftime('%Y-%m-%dT%H:%M:%S')}"


def dates(start: dt.datetime, seconds: np.ndarray) -> list[dt.datetime]:
    return [start + dt.timedelta(seconds=float(s)) for s in np.atleast_1d(seconds)]


def decimal_year(when: dt.datetime) -> float:
    """The date as a decimal year (2015.5 is mid-2015), as GNSS time series give it."""
    year = dt.datetime(when.year, 1, 1, tzinfo=UTC)
    length = (dt.datetime(when.year + 1, 1, 1, tzinfo=UTC) - year).total_seconds()
    return when.year + (when - year).total_seconds() / length

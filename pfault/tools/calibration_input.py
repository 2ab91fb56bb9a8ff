"""The files of ``python -m pfault.calibrate``: the parameters to fit and the observations to fit them to.

Parameter file (CSV, one parameter a line, ``#`` comments), as PEST's parameter data section holds them::

    name,option,start,lower,upper,transform,value
    E_clay,-pfault_material_clay_young_modulus,10*MPa,1*MPa,100*MPa,log,
    Q,-pfault_flow_well_rate,2*L/s,0.5*L/s,20*L/s,none,"0:{Q},120*day:{Q}"

- ``option``: a numeric ``-pfault_`` option (a real, a quantity, or a material property given as a number), or
  a table or list option with a ``value`` template in which ``{name}`` stands for the parameter (in SI units),
  e.g. a pumping rate;
- ``start``, ``lower``, ``upper``: numbers in SI units, or with a unit as in a scene (``10*MPa``);
- ``transform``: ``log`` (fitted as log10 of the value, as PEST's PARTRANS log; the default for options in
  Pa, the moduli, and for the soils' compressibilities: the compression and recompression indices Cc and Cr and
  CSUB's skeletal specific storages) or ``none``;
- ``value`` (optional): the template above; empty for a plain number.

The bounds of a property of the soils that remember must be values the property admits
(pfault.materials.properties.RANGES): a preconsolidation head at most 0 (m below the initial heads), an index
positive, an overconsolidation ratio at least 1 (a sign slip there would not fail a run at once but fit another
soil). Other properties' bounds are not checked: a run outside their range fails and the fit steps back.

Observation file (CSV): ``name,time,ux,uy,uz,sigma``: a station of the scene's ``-pfault_stations`` file, the
time from the start of the scene (s, or with a unit: ``30*day``), the displacement components relative to the
initial state (m, any of them empty when not measured) and the standard deviation of each given component (m,
> 0; the weight is 1/sigma^2).

Everything wrong is a CalibrationInputError: one line naming the file (or option) and the fix.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..materials.properties import RANGES, property_name
from ..optionsfile import ArgumentError, read_options_file
from ..options import spec_for
from ..paths import beside_scene, file_problem
from ..units import parse_list, parse_quantity, parse_table

NUMERIC_KINDS = ("real", "quantity", "property")    # property: a material property given as a number
TEMPLATE_KINDS = ("table", "list")
KIND_WORDS = {"string": "a text", "choice": "one of a few words", "bool": "true or false", "names": "names",
              "int": "a whole number", "ints": "whole numbers", "table": "a table", "list": "a list"}
PARAMETER_COLUMNS = ("name", "option", "start", "lower", "upper")
OBSERVATION_COLUMNS = ("name", "time", "ux", "uy", "uz", "sigma")
COMPONENTS = ("ux", "uy", "uz")
PARAMETER_FIX = "its first line names the columns name,option,start,lower,upper[,transform][,value]"
OBSERVATION_FIX = "its first line names the columns name,time,ux,uy,uz,sigma"
NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
# material properties fitted as log10 by default besides the moduli (unit Pa): compressibilities, which span decades
LOG_PROPERTIES = ("compression_index", "recompression_index", "inelastic_skeletal_specific_storage",
                  "elastic_skeletal_specific_storage")
MEMORY_PROPERTIES = LOG_PROPERTIES + ("preconsolidation_stress", "overconsolidation_ratio", "preconsolidation_head")


class CalibrationInputError(Exception):
    """Bad input to the calibration: exit 1, nothing written."""


@dataclass(frozen=True)
class Parameter:
    name: str
    option: str             # without the leading '-'
    start: float            # SI
    lower: float
    upper: float
    log: bool               # fitted as log10(value)
    template: str           # the option's value, '{name}' standing for the parameter

    def option_value(self, value: float) -> str:
        return self.template.replace("{" + self.name + "}", repr(float(value)))


@dataclass(frozen=True)
class Observations:
    """One entry per measured component, in file order."""
    station: np.ndarray     # (m,) str
    time: np.ndarray        # (m,) s
    component: np.ndarray   # (m,) int: 0 ux, 1 uy, 2 uz
    value: np.ndarray       # (m,) m
    sigma: np.ndarray       # (m,) m

    @property
    def stations(self) -> list[str]:
        return list(dict.fromkeys(self.station.tolist()))


def _rows(path, what, fix):
    """(line number, header, rows) of a CSV file; '#' lines and blank lines skipped."""
    problem = file_problem(path)
    if problem:
        raise CalibrationInputError(f"{what} file {path}: {problem}; give a CSV file ({fix})")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
        rows = [(i + 1, [c.strip() for c in r]) for i, r in enumerate(csv.reader(lines))
                if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise CalibrationInputError(f"{what} file {path}: not a CSV text file ({exc}); {fix}") from None
    if len(rows) < 2:
        raise CalibrationInputError(f"{what} file {path}: nothing after the header line; {fix}, then one "
                                    f"{what} a line")
    header = [c.lower() for c in rows[0][1]]
    return header, [(n, r + [""] * (len(header) - len(r))) for n, r in rows[1:]]


def _quantity(text, where, column, unit):
    try:
        return parse_quantity(text, column, unit)
    except InputError as exc:
        raise CalibrationInputError(f"{where}: {column}: {str(exc).split(': ', 1)[-1]}") from None


def _columns(header, needed, path, what, fix):
    missing = [c for c in needed if c not in header]
    if missing:
        raise CalibrationInputError(f"{what} file {path}: no column {', '.join(missing)} in its header line "
                                    f"'{','.join(header)}'; {fix}")
    return {c: header.index(c) for c in header}


def read_parameters(path: str) -> list[Parameter]:
    header, rows = _rows(path, "parameter", PARAMETER_FIX)
    col = _columns(header, PARAMETER_COLUMNS, path, "parameter", PARAMETER_FIX)
    params: list[Parameter] = []
    for line, r in rows:
        p = _parameter(path, line, {c: r[i] for c, i in col.items()})
        if p.name in [q.name for q in params]:
            raise CalibrationInputError(f"parameter file {path} line {line}: parameter '{p.name}' appears twice; "
                                        "give each parameter its own name")
        if p.option in [q.option for q in params]:
            raise CalibrationInputError(f"parameter file {path} line {line}: -{p.option} is given by two "
                                        "parameters; fit each option with one parameter")
        params.append(p)
    return params


def _parameter(path, line, cells):
    where = f"parameter file {path} line {line}"
    name, option = cells["name"], cells["option"].lstrip("-").lower()
    if not NAME.match(name):
        raise CalibrationInputError(f"{where}: parameter name '{name}' must be a letter or _ then letters, "
                                    "digits or _ (it names the parameter in the outputs and in value templates)")
    spec = spec_for(option) if option.startswith("pfault_") else None
    template = cells.get("value", "")
    if spec is None:
        raise CalibrationInputError(f"{where}: '{cells['option']}' is not a pfault option; give a numeric "
                                    "-pfault_ option (python -m pfault -help lists them)")
    if spec.kind not in NUMERIC_KINDS + TEMPLATE_KINDS or (spec.kind in TEMPLATE_KINDS and not template):
        raise CalibrationInputError(
            f"{where}: -{option} takes {KIND_WORDS.get(spec.kind, spec.kind)}, not a real number; give a numeric "
            "-pfault_ option (a real or a quantity), or for a table or list option a value column with {" + name
            + "} where the parameter goes (e.g. 0:{" + name + "},10*year:{" + name + "})")
    template = template or "{" + name + "}"
    if "{" + name + "}" not in template:
        raise CalibrationInputError(f"{where}: the value '{template}' has no {{{name}}}; put {{{name}}} where the "
                                    "parameter's value goes")
    unit = spec.unit
    start, lower, upper = (_quantity(cells[c], where, c, unit) for c in ("start", "lower", "upper"))
    log_default = unit == "Pa" or (spec.kind == "property" and property_name(option) in LOG_PROPERTIES)
    transform = (cells.get("transform") or ("log" if log_default else "none")).lower()
    if transform not in ("log", "none"):
        raise CalibrationInputError(f"{where}: transform '{transform}' is not log or none (log: fitted as log10 "
                                    "of the value, for moduli and conductivities)")
    _check_range(where, name, start, lower, upper, transform == "log")
    if spec.kind == "property" and property_name(option) in MEMORY_PROPERTIES:
        _check_admissible(where, name, option, lower, upper)
    p = Parameter(name, option, start, lower, upper, transform == "log", template)
    _check_template(where, p, spec)
    return p


def _check_range(where, name, start, lower, upper, log):
    if lower >= upper:
        raise CalibrationInputError(f"{where}: {name}: lower bound {lower:g} is not below upper bound {upper:g}; "
                                    "give lower < upper")
    if not lower <= start <= upper:
        raise CalibrationInputError(f"{where}: {name}: start {start:g} is outside its bounds [{lower:g}, "
                                    f"{upper:g}]; give a start within them")
    if log and lower <= 0:
        raise CalibrationInputError(f"{where}: {name}: a log transform needs a lower bound > 0, got {lower:g}; "
                                    "give a positive lower bound or transform none")


def _check_admissible(where, name, option, lower, upper):
    """Both bounds of a material property within what the property admits (the runs would fail otherwise)."""
    prop = property_name(option)
    test, words = RANGES[prop]
    bad = [f"{what} bound {v:g}" for what, v in (("lower", lower), ("upper", upper)) if not test(np.float64(v))]
    if bad:
        raise CalibrationInputError(f"{where}: {name}: {' and '.join(bad)} of -{option}: a {prop.replace('_', ' ')} "
                                    f"is {words}; give bounds within that range")


def _check_template(where, p, spec):
    text = p.option_value(p.start)
    try:
        if spec.kind == "table":
            parse_table(text, p.option, spec.unit)
        elif spec.kind == "list":
            parse_list(text, p.option, spec.unit)
        else:
            parse_quantity(text, p.option, spec.unit)
    except InputError as exc:
        raise CalibrationInputError(f"{where}: the value '{p.template}' at the start gives {exc}; write the "
                                    f"option's value with {{{p.name}}} in it") from None


def read_observations(path: str, stations: list[str], station_file: str, time_end: float) -> Observations:
    header, rows = _rows(path, "observation", OBSERVATION_FIX)
    aliases = {"time_s": "time", "ux_m": "ux", "uy_m": "uy", "uz_m": "uz", "sigma_m": "sigma"}
    header = [aliases.get(c, c) for c in header]
    col = _columns(header, OBSERVATION_COLUMNS, path, "observation", OBSERVATION_FIX)
    entries = []
    for line, r in rows:
        where = f"observation file {path} line {line}"
        name = r[col["name"]]
        if name not in stations:
            raise CalibrationInputError(f"{where}: station '{name}' is not in the scene's station file "
                                        f"{station_file}; use a station name of that file or add the station to it")
        t = _quantity(r[col["time"]], where, "time", "s")
        if not 0 <= t <= time_end * (1 + 1e-12):
            raise CalibrationInputError(f"{where}: time {t:g} s is outside the scene's 0 to {time_end:g} s "
                                        "(-pfault_time_end); give times within the run")
        sigma = _quantity(r[col["sigma"]], where, "sigma", "m")
        if not sigma > 0:
            raise CalibrationInputError(f"{where}: sigma {sigma:g} must be > 0 (the standard deviation of the "
                                        "measurement, m)")
        given = [(k, _quantity(r[col[c]], where, c, "m")) for k, c in enumerate(COMPONENTS) if r[col[c]]]
        if not given:
            raise CalibrationInputError(f"{where}: no ux, uy or uz; give at least one component or remove the line")
        entries += [(name, t, k, v, sigma) for k, v in given]
    station, time, comp, value, sig = zip(*entries)
    return Observations(np.array(station), np.array(time, dtype=np.float64), np.array(comp, dtype=np.int64),
                        np.array(value, dtype=np.float64), np.array(sig, dtype=np.float64))


@dataclass(frozen=True)
class SceneFacts:
    station_file: str
    stations: list[str]
    time_end: float         # s
    start_date: str = ""    # -pfault_start_date ('' : none)


def empty_observations() -> Observations:
    """No station observations (an InSAR-only fit)."""
    return Observations(np.array([], dtype=str), np.zeros(0), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))


def scene_facts(scene: str, need_stations: bool = True) -> SceneFacts:
    """The station file, end time and start date of a scene, read from its options file as PETSc will read it;
    ``need_stations``: a scene without -pfault_stations is an error."""
    if not os.path.isfile(scene):
        raise CalibrationInputError(f"scene file '{scene}' not found (give a pfault options file such as "
                                    "config/twin/twin.opts)")
    try:
        entries = {e.name: e.value for e in read_options_file(scene)}
    except ArgumentError as exc:
        raise CalibrationInputError(str(exc)) from None
    station_file = entries.get("pfault_stations") or ""
    if not station_file and need_stations:
        raise CalibrationInputError(f"scene {scene}: no -pfault_stations; add the stations the observations "
                                    "name (a CSV file name,x,y,z) to the scene")
    station_file = beside_scene(station_file, scene)          # as pfault finds it (pfault.paths)
    stations = station_names(station_file, scene) if station_file else []
    try:
        time_end = parse_quantity(entries.get("pfault_time_end") or str(spec_for("pfault_time_end").default),
                                  "pfault_time_end", "s")
    except InputError as exc:
        raise CalibrationInputError(f"scene {scene}: {exc}") from None
    if not math.isfinite(time_end):
        raise CalibrationInputError(f"scene {scene}: -pfault_time_end is not a finite time")
    return SceneFacts(station_file, stations, time_end, entries.get("pfault_start_date") or "")


def station_names(path: str, scene: str) -> list[str]:
    """The names in a station file, read as pfault.io.stations reads it (which pfault checks fully in the
    runs; that module is not imported here: it starts PETSc)."""
    problem = file_problem(path)
    if problem:
        raise CalibrationInputError(f"scene {scene}: -pfault_stations {path}: {problem}; give the scene's "
                                    "station file (a path from the directory pfault runs in, or beside the scene)")
    with open(path, newline="", encoding="utf-8-sig", errors="replace") as fh:
        lines = [line for line in fh.read().splitlines() if line.strip() and not line.lstrip().startswith("#")]
    first = lines[0] if lines else ""
    delimiter = next((d for d in (";", "\t") if d in first and "," not in first), ",")
    rows = list(csv.reader(lines, delimiter=delimiter))
    header = [c.strip().lower() for c in rows[0]] if rows else []
    if "name" not in header:
        raise CalibrationInputError(f"scene {scene}: -pfault_stations {path}: no column name in its header line; "
                                    "its first line names the columns name,x,y,z")
    k = header.index("name")
    return [r[k].strip() for r in rows[1:] if len(r) > k]


FILE_OPTIONS = ("pfault_stations", "pfault_heads_file", "pfault_heads_grid")    # found beside the scene too
FIELD = "field:"                                                        # pfault.materials.properties.FIELD_PREFIX


def scene_files_absolute(scene: str) -> dict[str, str]:
    """The scene's options that name data files (stations, heads, material fields), their paths made absolute as
    pfault finds them (pfault.paths.beside_scene): a file of options that includes the scene from elsewhere
    (fitted.opts) finds them too."""
    try:
        entries = {e.name: e.value for e in read_options_file(scene)}
    except ArgumentError:
        return {}
    out = {}
    for name, value in entries.items():
        if not value:
            continue
        if name in FILE_OPTIONS:
            out[name] = os.path.abspath(beside_scene(value, scene))
        elif value.startswith(FIELD):
            path, _, rest = value[len(FIELD):].partition(",")
            out[name] = FIELD + os.path.abspath(beside_scene(path, scene)) + ("," + rest if rest else "")
    return out

"""Quantities with units in option values: ``10*year``, ``-0.1*MPa``, ``250``, ``20*m``.

Values are converted to SI (angles to degrees). A bare number is taken to be in the option's unit
already. Each option declares its unit (pfault.options.SPECS); a unit of another dimension is an error
(``100*MPa`` as a length), and so is a value that is not finite (``1e999``).
"""

from __future__ import annotations

import math
import re

from .errors import InputError

YEAR = 365.25 * 86400.0

# dimension: exponents of (metre, kilogram, second, angle)
_ONE = (0, 0, 0, 0)
_TIME = (0, 0, 1, 0)
_LENGTH = (1, 0, 0, 0)
_PRESSURE = (-1, 1, -2, 0)
_DENSITY = (-3, 1, 0, 0)
_FLOW_RATE = (3, 0, -1, 0)
_VELOCITY = (1, 0, -1, 0)
_ACCELERATION = (1, 0, -2, 0)
_ANGLE = (0, 0, 0, 1)
_PER_LENGTH = (-1, 0, 0, 0)
_PRESSURE_PER_LENGTH = (-2, 1, -2, 0)

DIMENSION_NAMES = {
    _ONE: "plain number", _TIME: "time", _LENGTH: "length", _PRESSURE: "pressure", _DENSITY: "density",
    _FLOW_RATE: "flow rate", _VELOCITY: "velocity", _ACCELERATION: "acceleration", _ANGLE: "angle",
    _PER_LENGTH: "inverse length", _PRESSURE_PER_LENGTH: "stiffness per area",
}

UNITS = {
    # time
    "s": (1.0, _TIME), "second": (1.0, _TIME), "minute": (60.0, _TIME), "hour": (3600.0, _TIME),
    "day": (86400.0, _TIME), "year": (YEAR, _TIME), "yr": (YEAR, _TIME),
    # length
    "m": (1.0, _LENGTH), "km": (1e3, _LENGTH), "cm": (1e-2, _LENGTH), "mm": (1e-3, _LENGTH),
    # pressure / stress
    "Pa": (1.0, _PRESSURE), "kPa": (1e3, _PRESSURE), "MPa": (1e6, _PRESSURE), "GPa": (1e9, _PRESSURE),
    # density
    "kg/m**3": (1.0, _DENSITY), "kg/m^3": (1.0, _DENSITY),
    # flow rate
    "m**3/s": (1.0, _FLOW_RATE), "m^3/s": (1.0, _FLOW_RATE), "L/s": (1e-3, _FLOW_RATE),
    "l/s": (1e-3, _FLOW_RATE),
    # velocity (hydraulic conductivity)
    "m/s": (1.0, _VELOCITY), "m/day": (1.0 / 86400.0, _VELOCITY), "m/year": (1.0 / YEAR, _VELOCITY),
    # acceleration
    "m/s**2": (1.0, _ACCELERATION), "m/s^2": (1.0, _ACCELERATION),
    # angle (degrees inside the code)
    "degree": (1.0, _ANGLE), "deg": (1.0, _ANGLE), "rad": (180.0 / math.pi, _ANGLE),
    # specific storage, penalty stiffness
    "1/m": (1.0, _PER_LENGTH), "Pa/m": (1.0, _PRESSURE_PER_LENGTH), "MPa/m": (1e6, _PRESSURE_PER_LENGTH),
    "GPa/m": (1e9, _PRESSURE_PER_LENGTH),
}

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_QUANTITY = re.compile(rf"^\s*({_NUMBER})\s*(?:\*\s*([A-Za-z0-9][A-Za-z0-9/*^]*))?\s*$")


def dimension(unit: str) -> tuple[int, int, int, int]:
    """Dimension of a declared unit ('' is a plain number)."""
    if not unit:
        return _ONE
    if unit not in UNITS:
        raise KeyError(f"unit '{unit}' is not in pfault.units.UNITS")
    return UNITS[unit][1]


def _example(unit):
    return {"": "0.25", "s": "10*year", "m": "20*m", "Pa": "-0.1*MPa", "degree": "30"}.get(unit, f"1*{unit}")


def parse_quantity(text: str, option: str = "value", unit: str | None = None) -> float:
    """Parse ``number`` or ``number*unit`` into a finite float in SI units.

    ``unit`` is the option's declared unit: a given unit must have its dimension ('' takes plain numbers
    only); None accepts any known unit.
    """
    m = _QUANTITY.match(str(text))
    if not m:
        raise InputError(f"-{option}: cannot read '{text}' as a number (examples: 250, 10*year, -0.1*MPa)")
    value = float(m.group(1))
    given = m.group(2)
    if given is not None:
        if given not in UNITS:
            known = ", ".join(sorted(UNITS))
            raise InputError(f"-{option}: unknown unit '{given}' in '{text}' (known units: {known})")
        factor, dim = UNITS[given]
        if unit is not None and dim != dimension(unit):
            have = DIMENSION_NAMES.get(dim, given)
            if not unit:
                raise InputError(f"-{option}: '{text}' is a {have}, but this option takes a plain number "
                                 f"without a unit (e.g. {_example(unit)})")
            want = DIMENSION_NAMES.get(dimension(unit), unit)
            raise InputError(f"-{option}: '{text}' is a {have}, but this option takes a {want} in {unit} "
                             f"(e.g. {_example(unit)})")
        value *= factor
    if not math.isfinite(value):
        raise InputError(f"-{option}: '{text}' is not a finite number")
    return value


def quantity_unit(text: str) -> str | None:
    """The unit written in a quantity (``10*year`` -> 'year'), None for a bare number (or text that is not a
    quantity)."""
    m = _QUANTITY.match(str(text))
    return m.group(2) if m else None


TIME_UNITS = ("year", "day", "hour", "minute", "s")


def format_duration(t: float) -> str:
    """``t`` seconds in the largest time unit it holds at least once of, for messages: '10 year', '36.5 day',
    '10 s'."""
    for name in TIME_UNITS:
        if abs(t) >= UNITS[name][0] or name == "s":
            return f"{t / UNITS[name][0]:.4g} {name}"
    raise AssertionError(t)


def format_time(t: float) -> str:
    """``t`` seconds in years, days or seconds, the number 8 characters wide (the progress line's time)."""
    year = 365.25 * 86400.0
    if t >= 0.01 * year:
        return f"{t / year:8.4g} yr"
    if t >= 86400.0:
        return f"{t / 86400.0:8.4g} d"
    return f"{t:8.4g} s"


def parse_list(text: str, option: str = "value", unit: str | None = None) -> list[float]:
    """Comma-separated list of quantities."""
    items = [s for s in str(text).split(",") if s.strip()]
    return [parse_quantity(s, option, unit) for s in items]


def parse_table(text: str, option: str = "value", unit: str | None = None) -> list[tuple[float, float]]:
    """Piecewise-linear table ``t0:v0,t1:v1,...`` with strictly increasing times; values in ``unit``."""
    pairs: list[tuple[float, float]] = []
    for item in str(text).split(","):
        if not item.strip():
            continue
        if ":" not in item:
            raise InputError(f"-{option}: table entries are time:value pairs, got '{item}' "
                             "(example: 0:0,10*year:20)")
        t, v = item.split(":", 1)
        pairs.append((parse_quantity(t, option, None if unit is None else "s"), parse_quantity(v, option, unit)))
    if not pairs:
        raise InputError(f"-{option}: empty table (example: 0:0,10*year:20)")
    times = [p[0] for p in pairs]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise InputError(f"-{option}: times in '{text}' must increase strictly")
    return pairs

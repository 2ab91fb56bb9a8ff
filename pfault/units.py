"""Quantities with units in option values: ``10*year``, ``-0.1*MPa``, ``250``, ``20*m``.

Values are converted to SI. A bare number is taken to be in SI units already.
"""

import re

from .errors import InputError

YEAR = 365.25 * 86400.0

UNITS = {
    # time
    "s": 1.0, "second": 1.0, "minute": 60.0, "hour": 3600.0, "day": 86400.0, "year": YEAR, "yr": YEAR,
    # length
    "m": 1.0, "km": 1e3, "cm": 1e-2, "mm": 1e-3,
    # pressure / stress
    "Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "GPa": 1e9,
    # density
    "kg/m**3": 1.0, "kg/m^3": 1.0,
    # flow rate
    "m**3/s": 1.0, "m^3/s": 1.0, "L/s": 1e-3, "l/s": 1e-3,
    # velocity (hydraulic conductivity)
    "m/s": 1.0, "m/day": 1.0 / 86400.0, "m/year": 1.0 / YEAR,
    # angle
    "degree": 1.0, "deg": 1.0,
}

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_QUANTITY = re.compile(rf"^\s*({_NUMBER})\s*(?:\*\s*([A-Za-z][A-Za-z0-9/*^]*))?\s*$")


def parse_quantity(text, option="value"):
    """Parse ``number`` or ``number*unit`` into a float in SI units."""
    m = _QUANTITY.match(str(text))
    if not m:
        raise InputError(f"-{option}: cannot read '{text}' as a number (examples: 250, 10*year, -0.1*MPa)")
    value = float(m.group(1))
    unit = m.group(2)
    if unit is None:
        return value
    if unit not in UNITS:
        known = ", ".join(sorted(UNITS))
        raise InputError(f"-{option}: unknown unit '{unit}' in '{text}' (known units: {known})")
    return value * UNITS[unit]


def parse_list(text, option="value"):
    """Comma-separated list of quantities."""
    items = [s for s in str(text).split(",") if s.strip()]
    return [parse_quantity(s, option) for s in items]


def parse_table(text, option="value"):
    """Piecewise-linear table ``t0:v0,t1:v1,...`` with strictly increasing times."""
    pairs = []
    for item in str(text).split(","):
        if not item.strip():
            continue
        if ":" not in item:
            raise InputError(f"-{option}: table entries are time:value pairs, got '{item}' "
                             "(example: 0:0,10*year:20)")
        t, v = item.split(":", 1)
        pairs.append((parse_quantity(t, option), parse_quantity(v, option)))
    if not pairs:
        raise InputError(f"-{option}: empty table (example: 0:0,10*year:20)")
    times = [p[0] for p in pairs]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise InputError(f"-{option}: times in '{text}' must increase strictly")
    return pairs

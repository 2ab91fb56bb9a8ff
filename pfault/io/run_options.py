"""The options of a run directory (its ``options.txt``) against those of a run that continues it
(``-pfault_restart``): a continued run equals the uninterrupted one only with the same model and the same
load up to the checkpoint's time.

- Physical options (materials, faults, boundary conditions, mesh, initial state, flow) must be equal.
- Output, solver and time-stepping options may change.
- The loading tables (LOADING) may change after the checkpoint's time only: the checkpoint is the answer to
  the load up to then. What is compared is the load they give (a piecewise-linear function of time in SI),
  not their text, so the same load written another way (``-100*kPa`` for ``-0.1*MPa``, a head drawdown for
  the pore-pressure change it gives, a breakpoint added) is the same.

No PETSc here: the options are {name: value string}, as in options.txt and PETSc.Options().getAll().
"""

from __future__ import annotations

import re

from ..errors import InputError
from ..options import spec_for
from ..physics.loading import Table
from ..units import parse_table
from .output import read_options


# options a continued run may change: output, solver, time stepping, and the loading tables (LOADING) after
# the checkpoint's time (check_loading); every other -pfault_* option must equal that of the run it continues.
# The observations (stations, LOS raster) are output: their own check says whether that run has the same ones
# (pfault.io.observations)
RESTART_MAY_CHANGE = re.compile(r"^pfault_(scene|output_.*|figures|solver|contact_monitor|time_.*|restart|restart_.*|"
                                r"stations|insar_.*|mesh_cache)$")

# the loading tables: (their option names, what they load, its unit in SI, its value when none is given)
LOADING = ((re.compile(r"^pfault_material_(.+)_head_drawdown$"), "pore-pressure change of {}", "Pa", 0.0),
           (re.compile(r"^pfault_material_(.+)_pressure_change$"), "pore-pressure change of {}", "Pa", 0.0),
           (re.compile(r"^pfault_flow_well_rate$"), "pumping rate of each well", "m**3/s", 0.0),
           (re.compile(r"^pfault_bc_(.+)_history$"), "load factor of boundary {}", "", 1.0))


def _physical_options(options):
    return {k.lower(): ("" if v is None else str(v)) for k, v in options.items()
            if k.lower().startswith("pfault_") and not RESTART_MAY_CHANGE.match(k.lower())
            and not any(pattern.match(k.lower()) for pattern, *_ in LOADING)}


def loading_tables(options: dict[str, str], water_density: float,
                   gravity: float) -> dict[str, tuple[str, str, str, float, Table]]:
    """The loads a run's loading tables give, from its options ({name: value string}): {what it loads:
    (option, value string, unit, value when not given, Table in SI)}; a head drawdown as the pore-pressure
    change it gives (dp = -rho_w g h), so that the same load given either way is the same."""
    out = {}
    for name, text in options.items():
        name = name.lower()
        for pattern, what, unit, default in LOADING:
            match = pattern.match(name)
            if match:
                scale = -water_density * gravity if name.endswith("_head_drawdown") else 1.0
                spec = spec_for(name)
                assert spec is not None          # every LOADING pattern is a declared option (SPECS)
                table = Table.from_pairs(parse_table(text, name, spec.unit), scale=scale)
                out[what.format(*match.groups())] = (name, text, unit, default, table)
    return out


def check_loading(run_dir: str, theirs: dict[str, str], mine: dict[str, str], until: float, water_density: float,
                  gravity: float) -> None:
    """InputError naming the first loading table whose load on [0, until] (up to the checkpoint's time)
    differs from that of the run in ``run_dir``: the checkpoint is the answer to that run's load up to then,
    so a continued run may change a table (extend it, alter the future load) only after it. ``theirs``,
    ``mine``: the options of that run and of this one."""
    a = loading_tables(theirs, water_density, gravity)
    b = loading_tables(mine, water_density, gravity)
    for what in sorted(set(a) | set(b)):
        old, new = a.get(what), b.get(what)
        given = new or old
        assert given is not None                 # ``what`` is a key of a or of b
        name, _, unit, default, _ = given
        unloaded = Table((0.0,), (default,))
        diff = (new[4] if new else unloaded).first_difference(old[4] if old else unloaded, until)
        if diff is None:
            continue
        t, now, was = diff
        u = f" {unit}" if unit else ""
        had = f"-{old[0]} {old[1]}" if old else f"no -{name}"
        raise InputError(f"-pfault_restart {run_dir}: -{name} changes the {what} before t = {until:g} s, where "
                         f"that run's checkpoint is (at t = {t:g} s: {now:g}{u}, that run {was:g}{u}); a "
                         f"continued run may change a loading table only after that time: keep the values of "
                         f"that run ({had}) up to it")


def check_options(run_dir: str, options: dict[str, str], until: float, water_density: float,
                  gravity: float) -> None:
    """InputError naming the first physical option (material, fault, boundary condition, mesh, geostatic
    state, flow) that differs from the run in ``run_dir`` or the first loading table that differs from its
    before ``until``, the checkpoint's time: a continued run equals the uninterrupted one only with the same
    model and the same load up to then. ``options``: this run's PETSc options."""
    try:
        run_options = read_options(run_dir)
    except OSError:
        return      # a run directory without options.txt: the checkpoint's own checks stand
    theirs, mine = _physical_options(run_options), _physical_options(options)
    for key in sorted(set(theirs) | set(mine)):
        if theirs.get(key) != mine.get(key):
            was = f"-{key} {theirs[key]}".rstrip() if key in theirs else f"no -{key}"
            now = f"-{key} {mine[key]}".rstrip() if key in mine else f"no -{key}"
            raise InputError(f"-pfault_restart {run_dir}: that run had {was}, this one {now}; a continued run "
                             "keeps the model (materials, faults, boundary conditions, mesh, initial state, "
                             "flow): give the options of that run (only output, solver, time and loading-table "
                             "options may change)")
    check_loading(run_dir, run_options, options, until, water_density, gravity)

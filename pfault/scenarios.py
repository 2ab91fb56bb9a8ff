"""``python -m pfault.scenarios SCENE.opts PLANS.opts [--workers N] [--ranks N] [--output DIR] [--timeout S]
[--figures] [-option value ...]``: one site under several water-management plans, side by side, compared.

A plans file is a PETSc options file cut into named plans::

    # options before the first plan apply to every plan (the baseline included)
    -pfault_mesh_size_factor 6
    [stopped_year5]
    -pfault_flow_well_rate 0:0,5*year:150*L/s,5.001*year:0
    [halved]
    -pfault_flow_well_rate 0:0,10*year:150*L/s

Every plan is the scene with its options on top (then the command line's). The scene as it is, with the common
options, always runs too, as the plan ``baseline``. A plan changes the pumping through the options that define
it: the flow model's well rates (``-pfault_flow_well_rate``, a time:rate table) and positions
(``-pfault_flow_wells``), a groundwater model's heads (``-pfault_heads_file``), or the drawdown tables
(``-pfault_material_<material>_head_drawdown``); any other option may change as well.

Each plan is its own pfault run (pfault.tools.runs) into ``DIR/<plan>/`` (log ``DIR/<plan>.log``), up to
``--workers`` at a time (default: the cores divided by ``--ranks``). The comparison, from each run's
summary.json, is ``DIR/scenarios.csv``, printed as a table, and ``DIR/scenarios.png``. A plan that fails is a row
with its exit code and error line and no values; the other plans complete. With soils that remember the table has
each plan's inelastic subsidence (what stays when the heads recover) and its smallest head margin (the least further
drawdown any cell could still have borne elastically; 0 when some cell compacted on its virgin line): plans that
keep the heads above the critical heads and plans that draw below them differ in kind, not by a factor. Columns
no plan has a value for (the soils' in a scene of linear soils) are left out of the printed table and the figure.

Exit codes: 0 every plan completed; 1 bad input (the scene, the plans file: an unknown option, a plan that
sets nothing, two plans with one name), one line and nothing written; 2 usage; 4 the output directory cannot be
made or written; 7 interrupted (Ctrl-C: the plans under way are stopped, no table); 8 a plan failed (the
table says which and why). This module does not import PETSc.
"""

from __future__ import annotations

import csv
import os
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass

from .errors import EXIT_INPUT, EXIT_INTERRUPTED, EXIT_OUTPUT, EXIT_USAGE, InputError, OutputError
from .options import spec_for
from .optionsfile import ArgumentError, is_option_name, read_options_file
from .post.rundir import read_summary
from .tools.runs import Run, RunResult, run_many
from .units import parse_list, parse_quantity, parse_table

EXIT_PLAN_FAILED = 8
BASELINE = "baseline"
USAGE = ("usage: python -m pfault.scenarios SCENE.opts PLANS.opts [--workers N] [--ranks N] [--output DIR] "
         "[--timeout S] [--figures] [-option value ...]")
# options the command sets for every plan itself
RESERVED = {"pfault_output_dir": "the scenarios command writes each plan into DIR/<plan> (give --output DIR)",
            "pfault_restart": "every plan runs from its own initial state",
            "options_file": "put the options themselves under the plan"}
# (column, summary.json key, printed heading): the figures compared
COLUMNS = (("max_subsidence_m", "max_subsidence_m", "subsidence [m]"),
           ("final_subsidence_m", "final_subsidence_m", "final subs. [m]"),
           ("max_fault_opening_m", "max_fault_opening_m", "opening [m]"),
           ("max_fault_slip_m", "max_fault_slip_m", "slip [m]"),
           ("max_horizontal_strain", "max_horizontal_strain", "strain [-]"),
           ("max_angular_distortion", "max_angular_distortion", "distortion [-]"),
           ("max_fissure_prone_length_m", "max_fissure_prone_length_m", "fissure-prone [m]"),
           ("max_subsidence_inelastic_m", "max_subsidence_inelastic_m", "inelastic subs. [m]"),
           ("min_head_margin_m", "min_head_margin_m", "head margin [m]"))
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*$")


@dataclass(frozen=True)
class Plan:
    name: str
    options: dict[str, str]     # option name without '-' -> value ('' for a bare flag)


def _check_value(name: str, value: str, where: str) -> None:
    """A -pfault_ option must be declared and its value of its kind (PETSc's own are checked by the run)."""
    if name in RESERVED:
        raise InputError(f"{where}: -{name} cannot be set in a plan: {RESERVED[name]}")
    if not name.startswith("pfault_"):
        return
    spec = spec_for(name)
    if spec is None:
        raise InputError(f"{where}: unknown option -{name}; see python -m pfault -help")
    try:
        if spec.kind in ("real", "quantity"):
            parse_quantity(value, name, spec.unit)
        elif spec.kind == "list" and value.strip():
            parse_list(value, name, spec.unit)
        elif spec.kind == "table":
            parse_table(value, name, spec.unit)
        elif spec.kind == "int":
            int(value)
        elif spec.kind == "choice" and value not in spec.choices:
            raise InputError(f"-{name}: '{value}' is not one of {', '.join(spec.choices)}")
        elif spec.kind == "bool" and value.strip().lower() not in ("", "1", "true", "yes", "on", "0", "false",
                                                                     "no", "off"):
            raise InputError(f"-{name}: '{value}' is not true or false")
    except ValueError:
        raise InputError(f"{where}: -{name}: '{value}' is not a whole number") from None
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None


def read_plans(path: str) -> tuple[dict[str, str], list[Plan]]:
    """The common options and the plans of a plans file (module docstring); InputError names the file and line."""
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "not UTF-8 text"
        raise InputError(f"plans file {path}: cannot read it ({reason}); give a text file of [plan] sections "
                         "and options") from None
    common: dict[str, str] = {}
    plans: list[Plan] = []
    current, first_line = common, {}
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        where = f"{path} line {number}"
        if body.startswith("["):
            name = body[1:-1].strip() if body.endswith("]") else ""
            if not NAME.match(name):
                raise InputError(f"{where}: '{body}' is not a plan header; write [name], the name of letters, "
                                 "digits, '_', '.', '+', '-' (it names the plan's output directory)")
            if name.lower() == BASELINE:
                raise InputError(f"{where}: the plan name '{BASELINE}' is the scene as it is, which always runs; "
                                 "give this plan another name")
            if name.lower() in first_line:
                raise InputError(f"{where}: a second plan named '{name}' (the first is at line "
                                 f"{first_line[name.lower()]}); give every plan its own name")
            first_line[name.lower()] = number
            plans.append(Plan(name, {}))
            current = plans[-1].options
            continue
        tokens = body.split()
        if not is_option_name(tokens[0]) or len(tokens) > 2:
            raise InputError(f"{where}: '{body}' is not one option (one '-name value' per line, plans as [name] "
                             "lines, comments after '#')")
        name = tokens[0].lstrip("-").lower()
        value = tokens[1] if len(tokens) == 2 else ""
        if name in current:
            raise InputError(f"{where}: -{name} is set twice in the same {'plan' if plans else 'common part'}")
        _check_value(name, value, where)
        current[name] = value
    if not plans:
        raise InputError(f"plans file {path}: no plan; write one [name] line per plan, each followed by the "
                         "options it changes")
    for plan in plans:
        if not plan.options:
            raise InputError(f"{path} line {first_line[plan.name.lower()]}: plan '{plan.name}' sets no option, "
                             f"so it would repeat the baseline; give it the options it changes, or remove it")
    return common, plans


def parse_arguments(argv: Sequence[str]) -> dict:
    """SCENE, PLANS, the command's flags and the trailing -option value pairs (applied to every plan)."""
    args = {"workers": 0, "ranks": 1, "output": "", "timeout": None, "figures": False, "options": {}}
    positional: list[str] = []
    i, argv = 0, list(argv)
    flags = {"--workers": ("workers", int), "--ranks": ("ranks", int), "--output": ("output", str),
             "--timeout": ("timeout", float)}
    while i < len(argv):
        token = argv[i]
        if token in flags:
            key, kind = flags[token]
            try:
                args[key] = kind(argv[i + 1])
            except (IndexError, ValueError):
                raise ArgumentError(f"{token} needs a {'number' if kind is not str else 'value'}\n{USAGE}",
                                    EXIT_USAGE) from None
            i += 2
        elif token == "--figures":
            args["figures"], i = True, i + 1
        elif token in ("-h", "--help", "-help"):
            raise ArgumentError(__doc__.strip(), 0)
        elif is_option_name(token) and not token.startswith("--"):
            value = argv[i + 1] if i + 1 < len(argv) and not is_option_name(argv[i + 1]) else ""
            name = token.lstrip("-").lower()
            _check_value(name, value, "the command line")
            args["options"][name] = value
            i += 2 if value else 1
        elif len(positional) < 2 and not token.startswith("-"):
            positional.append(token)
            i += 1
        else:
            raise ArgumentError(f"unexpected argument '{token}'\n{USAGE}", EXIT_USAGE)
    if len(positional) != 2:
        raise ArgumentError(USAGE, EXIT_USAGE)
    if args["workers"] < 0 or args["ranks"] < 1 or (args["timeout"] is not None and args["timeout"] <= 0):
        raise ArgumentError(f"--workers must be >= 0 (0: as many as the cores allow), --ranks >= 1, --timeout > 0"
                            f"\n{USAGE}", EXIT_USAGE)
    args["scene"], args["plans"] = positional
    return args


# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Row:
    plan: str
    status: str                 # completed | failed
    code: int
    values: dict[str, float | None]
    wall_s: float
    options: str
    error: str


def row_of(name: str, options: dict[str, str], result: RunResult) -> Row:
    summary = read_summary(result.run.output_dir) if result.ok else None
    done = summary is not None and bool(summary.get("converged")) and not summary.get("interrupted")
    values = {col: (float(summary[key]) if done and summary.get(key) is not None else None)
              for col, key, _ in COLUMNS}
    error = "" if done else (result.error or f"no completed summary.json in {result.run.output_dir}")
    text = " ".join(f"-{k} {v}".strip() for k, v in options.items())
    return Row(name, "completed" if done else "failed", result.code, values, result.wall, text, error)


def write_csv(path: str, rows: Sequence[Row]) -> None:
    """One row per plan: the compared figures at full precision (repr), empty for a failed plan."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["plan", "status", "exit_code", *[c for c, _, _ in COLUMNS], "wall_s", "options", "error"])
        for r in rows:
            w.writerow([r.plan, r.status, r.code, *["" if r.values[c] is None else repr(r.values[c])
                                                    for c, _, _ in COLUMNS], f"{r.wall_s:.2f}", r.options, r.error])


def shown_columns(rows: Sequence[Row]) -> list[tuple[str, str, str]]:
    """The COLUMNS some plan has a value for (every one when no plan completed)."""
    shown = [col for col in COLUMNS if any(r.values[col[0]] is not None for r in rows)]
    return shown or list(COLUMNS)


def format_table(rows: Sequence[Row]) -> str:
    """The table as printed: 4 significant digits, failed plans with their error line."""
    columns = shown_columns(rows)
    head = ["plan", "status", *[h for _, _, h in columns]]
    body = [[r.plan, r.status if r.status == "completed" else f"failed ({r.code})",
             *["-" if r.values[c] is None else f"{r.values[c]:.4g}" for c, _, _ in columns]] for r in rows]
    width = [max(len(x[k]) for x in [head] + body) for k in range(len(head))]
    lines = ["  ".join(x[k].rjust(width[k]) if k > 1 else x[k].ljust(width[k]) for k in range(len(x)))
             for x in [head] + body]
    lines += [f"  {r.plan}: {r.error}" for r in rows if r.status != "completed"]
    return "\n".join(lines)


def write_figure(path: str, rows: Sequence[Row], outdir: str) -> str | None:
    """Bars per plan for every compared figure and the maximum subsidence against time; None without
    matplotlib."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    columns = shown_columns(rows)
    grid = -(-(len(columns) + 1) // 4)
    fig, axes = plt.subplots(grid, 4, figsize=(16, 3.5 * grid), constrained_layout=True, squeeze=False)
    names = [r.plan for r in rows]
    colors = [f"C{k % 10}" for k in range(len(rows))]
    for ax in list(axes.flat)[len(columns) + 1:]:
        ax.set_visible(False)
    for ax, (col, _, head) in zip(axes.flat, columns):
        vals = [r.values[col] for r in rows]
        ax.bar(range(len(rows)), [0.0 if v is None else v for v in vals], color=colors)
        for k, v in enumerate(vals):
            if v is None:
                ax.text(k, 0.0, "failed", rotation=90, ha="center", va="bottom", color="red")
        ax.set_xticks(range(len(rows)), names, rotation=30, ha="right")
        ax.set_title(head)
    ax = axes.flat[len(columns)]
    for r, c in zip(rows, colors):
        summary = read_summary(os.path.join(outdir, r.plan)) if r.status == "completed" else None
        steps = [s for s in (summary or {}).get("steps", []) if "max_subsidence_m" in s]
        if steps:
            ax.plot([s["time_s"] / 31557600.0 for s in steps], [s["max_subsidence_m"] for s in steps], "o-",
                    color=c, label=r.plan, ms=3)
    ax.set_xlabel("time [year]")
    ax.set_title("max subsidence [m]")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_plans(args: dict) -> int:
    scene, plans_path = args["scene"], args["plans"]
    read_options_file(scene)                                       # a bad scene is one line, before any run
    common, plans = read_plans(plans_path)
    command_line = args["options"]
    outdir = args["output"] or os.path.join("runs", os.path.splitext(os.path.basename(plans_path))[0])
    try:
        os.makedirs(outdir, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"--output {outdir}: cannot make the directory ({exc.strerror}); give another") from None
    if not os.access(outdir, os.W_OK):
        raise OutputError(f"--output {outdir}: not writable; give another directory")
    ranks = args["ranks"]
    workers = args["workers"] or max(1, (os.cpu_count() or 1) // ranks)
    # (name, the options it changes, all it is given): a plan's own options over the common ones, the command
    # line's over both
    named = [(BASELINE, {}, {**common, **command_line})]
    named += [(p.name, p.options, {**common, **p.options, **command_line}) for p in plans]
    runs = [Run(scene, os.path.join(outdir, name), opts, ranks=ranks, figures=args["figures"],
                timeout=args["timeout"]) for name, _, opts in named]
    print(f"pfault scenarios: {len(runs)} plans of {scene} into {outdir}, {min(workers, len(runs))} at a time "
          f"on {ranks} rank(s) each", flush=True)
    results = run_many(runs, workers)
    rows = [row_of(name, own, res) for (name, own, _), res in zip(named, results)]
    write_csv(os.path.join(outdir, "scenarios.csv"), rows)
    figure = write_figure(os.path.join(outdir, "scenarios.png"), rows, outdir)
    print(format_table(rows))
    print(f"-> {os.path.join(outdir, 'scenarios.csv')}" + (f", {figure}" if figure else ""))
    return 0 if all(r.status == "completed" for r in rows) else EXIT_PLAN_FAILED


def main(argv: Sequence[str] | None = None) -> int:
    try:
        return run_plans(parse_arguments(sys.argv[1:] if argv is None else argv))
    except ArgumentError as exc:
        stream = sys.stdout if exc.code == 0 else sys.stderr
        stream.write(f"{exc}\n" if exc.code in (0, EXIT_USAGE) else f"pfault: error: {exc}\n")
        return exc.code
    except InputError as exc:
        sys.stderr.write(f"pfault: error: {exc}\n")
        return EXIT_INPUT
    except OutputError as exc:
        sys.stderr.write(f"pfault: error: {exc}\n")
        return EXIT_OUTPUT
    except KeyboardInterrupt:
        sys.stderr.write("pfault: interrupted: the plans under way were stopped; no table written\n")
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python
"""Margins to failure at paper size: what they say, whether the scene run further fails where they say, and what
they cost.

    python benchmarks/margins.py [--ranks 2] [--scenes aquifer,wuxi,fissure] [--aquifer-size 1] [--wuxi-size 1]
                                 [--out runs/margins] [-- -option value ...]

For each scene (config/faulted_aquifer.opts on benchmarks/faulted_aquifer_mesh.py's mesh, config/wuxi.opts,
config/wuxi_fissure.opts):

1. the run with margins (the default) and (--off) the same run with -pfault_margins false, one after the other on
   the same ranks: per output time the step's wall time, Newton iterations and factorisations, the margin's linear solve
   (wall time, Krylov iterations, factorisations) and the smallest margin (m of drawdown, mode, face); the totals of
   both runs (the margins' share of the solve time; the steps' own iterations and factorisations with and without
   them: the margin's solve may change which factors the next step keeps);
2. at the last output time with a face that has not failed (a run to that time, continued from its checkpoint): the
   drawdown of every loaded material raised by the smallest margin plus 2 % and minus 2 %; whether the face reported
   slips, opens or breaks in each (the target: in the first, not in the second).

Options after ``--`` go to every run. Prints the tables and one JSON line; exit code 0 when every run completed.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
from pfault.post import figures as fg  # noqa: E402
from pfault.tools.runs import run_captured, run_logged  # noqa: E402

YEAR = fg.YEAR
# scene: options file, fault, {material: drawdown (m) at the end}, end (years, one step a year)
SCENES = {"aquifer": ("config/faulted_aquifer.opts", "fault", {"sand": 73.0}, 10),
          "wuxi": ("config/wuxi.opts", "fissure", {"sand": 20.0, "clay": 10.0}, 10),
          "fissure": ("config/wuxi_fissure.opts", "fissure", {"sand": 20.0, "clay": 10.0}, 10)}


def scene_options(name: str, args: argparse.Namespace) -> list[str]:
    if name == "aquifer":
        msh = os.path.join(args.out, f"faulted_aquifer_{args.aquifer_size:g}.msh")
        if not os.path.exists(msh):
            made = run_captured(["benchmarks/faulted_aquifer_mesh.py", msh, "--size-factor", f"{args.aquifer_size:g}"],
                                cwd=REPO)
            if made.returncode != 0:
                raise SystemExit(f"faulted_aquifer_mesh.py: exit {made.returncode}\n{made.stderr[-2000:]}")
        return ["-pfault_mesh_file", msh]
    return ["-pfault_mesh_size_factor", f"{args.wuxi_size:g}"]


def run(name: str, tag: str, options: list[str], args: argparse.Namespace) -> dict | None:
    """One run of scene ``name`` into --out/NAME-TAG; its summary (None when it failed)."""
    out = os.path.join(args.out, f"{name}-{tag}")
    cmd = ["-m", "pfault", SCENES[name][0], "-pfault_output_dir", out, *scene_options(name, args), *options,
           *args.extra]
    log = run_logged(cmd, args.ranks, out + ".log", args.timeout, cwd=REPO)
    print(f"{name} {tag}: {log.command}\n  exit {log.code}, {log.wall:.1f} s end to end, load {log.load:.2f}",
          flush=True)
    if log.code != 0:
        print("  " + "\n  ".join(log.output.strip().splitlines()[-5:]))
        return None
    s = fg.read_summary(out)
    s["end_to_end_s"], s["dir"] = log.wall, out
    return s


def steps_table(name: str, s: dict) -> list[dict]:
    fault = SCENES[name][1]
    rows = []
    print(f"\n{name}: | year | step wall (s) | Newton | LU | margin solve (s) | its | LU | smallest margin (m) | mode | "
          "face | failed faces |\n|---|---|---|---|---|---|---|---|---|---|---|")
    for r in s["steps"]:
        ms, m = r.get("margin_solve", {}), r.get("faults", {}).get(fault, {}).get("margin", {})
        rows.append({"year": r["time_s"] / YEAR, "wall_s": r["wall_s"], "newton": r["newton_its"],
                     "lu": r.get("factorizations", 0), "margin_wall_s": ms.get("wall_s", 0.0),
                     "margin_its": ms.get("ksp_its", 0), "margin_lu": ms.get("factorizations", 0),
                     "min_drawdown_m": m.get("min_drawdown_m"), "mode": m.get("min_mode"), "face": m.get("min_face"),
                     "failed": m.get("faces_failed")})
        x = rows[-1]
        shown = "none" if x["min_drawdown_m"] is None else f"{x['min_drawdown_m']:.5g}"
        print(f"| {x['year']:.3g} | {x['wall_s']:.3g} | {x['newton']} | {x['lu']} | {x['margin_wall_s']:.3g} | "
              f"{x['margin_its']} | {x['margin_lu']} | {shown} | {x['mode']} | {x['face']} | {x['failed']} |")
    return rows


def totals(s: dict) -> dict:
    steps = [r for r in s["steps"] if not r.get("initial")]
    return {"solve_s": s["wall_s"]["solve"], "total_s": s["wall_s"]["total"], "end_to_end_s": s["end_to_end_s"],
            "newton": sum(r["newton_its"] for r in steps), "lu": sum(r.get("factorizations", 0) for r in steps),
            "margin_s": sum(r.get("margin_solve", {}).get("wall_s", 0.0) for r in s["steps"]),
            "margin_lu": sum(r.get("margin_solve", {}).get("factorizations", 0) for r in s["steps"]),
            "margin_solves": sum(1 for r in s["steps"] if r.get("margin_solve", {}).get("solved"))}


def table(points: list) -> str:
    return ",".join(f"{t}:{v!r}" for t, v in points)


def plus_minus(name: str, whole: dict, rows: list[dict], args: argparse.Namespace) -> dict | None:
    """The run to the last output time with a face not failed (``whole``, the run with margins, when that is its
    end), continued with the drawdown raised by its smallest margin times 1.02 and 0.98: whether the face reported
    fails in each."""
    opts, fault, final, end = SCENES[name]
    live = [r for r in rows if r["min_drawdown_m"] is not None and r["year"] > 0]
    if not live:
        return None
    k = int(round(live[-1]["year"]))
    base = whole if k == end else run(name, f"to{k}", ["-pfault_time_end", f"{k}*year", "-pfault_time_steps",
                                                       str(k), "-pfault_figures", "false"], args)
    if base is None:
        return None
    m = base["faults"][fault]["margin"]
    out = {"year": k, "margin_m": m["min_drawdown_m"], "mode": m["min_mode"], "face": m["min_face"]}
    for factor in (1.02, 0.98):
        raised = []
        for material, h_end in final.items():
            h = h_end * k / end
            raised += [f"-pfault_material_{material}_head_drawdown",
                       table([(0, 0), (f"{k}*year", h), (f"{k + 1}*year", h + factor * m["min_drawdown_m"])])]
        cont = run(name, f"to{k}x{factor:g}", ["-pfault_restart", base["dir"], "-pfault_time_end", f"{k + 1}*year",
                                               "-pfault_time_steps", str(k + 1), "-pfault_figures", "false",
                                               *raised], args)
        if cont is None:
            return None
        last = fg.read_fault(cont["dir"]).cell_data
        face = m["min_face"]
        failed = bool(last["broken"][face]) if m["min_mode"] == "break" else bool(last["state"][face] != 0)
        out[f"fails_at_{factor:g}"] = failed
    out["target_met"] = out["fails_at_1.02"] and not out["fails_at_0.98"]
    print(f"\n{name}: at year {k} the smallest margin {m['min_drawdown_m']:.5g} m ({m['min_mode']}, face {face}); "
          f"+2 %: {'fails' if out['fails_at_1.02'] else 'holds'}, -2 %: {'fails' if out['fails_at_0.98'] else 'holds'}")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--scenes", default="aquifer,wuxi,fissure")
    ap.add_argument("--aquifer-size", type=float, default=1.0, help="faulted aquifer mesh size factor")
    ap.add_argument("--wuxi-size", type=float, default=1.0, help="Wuxi's -pfault_mesh_size_factor")
    ap.add_argument("--out", default="runs/margins")
    ap.add_argument("--off", default=None, help="the scenes also run with -pfault_margins false (default: all)")
    ap.add_argument("--timeout", type=float, default=7200.0)
    ap.add_argument("extra", nargs="*", help="options for every run (after --)")
    args = ap.parse_args()
    args.out = os.path.abspath(args.out)
    os.makedirs(args.out, exist_ok=True)
    report, ok = {}, True
    offs = args.scenes.split(",") if args.off is None else args.off.split(",")
    for name in args.scenes.split(","):
        on = run(name, "margins", [], args)
        off = run(name, "off", ["-pfault_margins", "false"], args) if name in offs else None
        if on is None or (name in offs and off is None):
            ok = False
            continue
        rows = steps_table(name, on)
        t_on = totals(on)
        print(f"\n{name}: with margins solve {t_on['solve_s']:.2f} s, {t_on['newton']} Newton, {t_on['lu']} LU; "
              f"margin solves {t_on['margin_solves']} x, {t_on['margin_s']:.2f} s "
              f"({100 * t_on['margin_s'] / max(t_on['solve_s'], 1e-300):.1f} % of the steps' solve time), "
              f"{t_on['margin_lu']} LU; end to end {t_on['end_to_end_s']:.1f} s")
        t_off = totals(off) if off is not None else None
        if t_off is not None:
            print(f"{name}: without: solve {t_off['solve_s']:.2f} s, {t_off['newton']} Newton, {t_off['lu']} LU; "
                  f"end to end {t_off['end_to_end_s']:.1f} s")
        check = plus_minus(name, on, rows, args)
        ok = ok and check is not None
        report[name] = {"with": t_on, "without": t_off, "steps": rows, "plus_minus": check,
                        "faces": int(on["mesh"]["fault_faces"]), "dofs": int(on["dofs"])}
    print(json.dumps({"ranks": args.ranks, "scenes": report}, default=lambda v: None if v is np.nan else v))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())

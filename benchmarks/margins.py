#!/usr/bin/env python
"""Margins to failure at paper size: what they say, whether the scene run further fails where they say, and what
they cost.

    python benchmarks/margins.py [--ranks 2] [--scenes aquifer,wuxi,fissure] [--aquifer-size 1] [--wuxi-size 1]
                                 [--pairs 2] [--no-check] [--out runs/margins] [-- -option value ...]

For each scene (config/faulted_aquifer.opts on benchmarks/faulted_aquifer_mesh.py's mesh, config/wuxi.opts,
config/wuxi_fissure.opts):

1. the run with margins (the default) and (--off) the same run with -pfault_margins false, in alternation --pairs
   times on the same ranks (on, off, on, off, ...: the machine's load moves both alike): per output time the step's
   wall time, Newton iterations and factorisations, the margin's linear solve (wall time, Krylov iterations,
   factorisations) and the smallest margin (m of drawdown, mode, face); per pair the end-to-end wall and CPU times
   (all ranks) of both runs, the load average and the margins' own time the run reports; the overhead of the
   margins from the medians (wall and CPU) and whether the steps' Newton and Krylov iterations are the same with and
   without them;
2. (unless --no-check) at the last output time with a face that has not failed (a run to that time, continued from
   its checkpoint): the drawdown of every loaded material raised by the smallest margin plus 2 % and minus 2 %;
   whether the face reported slips, opens or breaks in each (the target: in the first, not in the second).

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
    s["end_to_end_s"], s["cpu_s"], s["load"], s["dir"] = log.wall, log.cpu, log.load, out
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
            "margin_solves": sum(1 for r in s["steps"] if r.get("margin_solve", {}).get("solved")),
            "margin_its": sum(r.get("margin_solve", {}).get("ksp_its", 0) for r in s["steps"]),
            "steps_its": [(r["newton_its"], r.get("ksp_its", 0)) for r in steps],
            "cpu_s": s["cpu_s"], "load": s["load"]}


def overhead(name: str, ons: list[dict], offs: list[dict]) -> dict:
    """The pairs' figures and the margins' overhead from the medians of the runs with and without them."""
    print(f"\n{name}: | pair | with margins: wall / CPU (s) | margins' own (s) | without: wall / CPU (s) | load |\n"
          "|---|---|---|---|---|")
    for k, (a, b) in enumerate(zip(ons, offs)):
        print(f"| {k + 1} | {a['end_to_end_s']:.1f} / {a['cpu_s']:.1f} | {a['margin_s']:.2f} | "
              f"{b['end_to_end_s']:.1f} / {b['cpu_s']:.1f} | {a['load']:.1f}, {b['load']:.1f} |")
    med = {key: (float(np.median([r[key] for r in ons])), float(np.median([r[key] for r in offs])))
           for key in ("end_to_end_s", "cpu_s", "margin_s")}
    same = all(r["steps_its"] == offs[0]["steps_its"] for r in ons + offs)
    out = {"wall_on_s": med["end_to_end_s"][0], "wall_off_s": med["end_to_end_s"][1], "cpu_on_s": med["cpu_s"][0],
           "cpu_off_s": med["cpu_s"][1], "margin_s": med["margin_s"][0], "same_step_iterations": same,
           "load": [r["load"] for r in ons + offs]}
    for key in ("wall", "cpu"):
        on, off = out[f"{key}_on_s"], out[f"{key}_off_s"]
        out[f"{key}_overhead_pct"] = 100.0 * (on - off) / off
    out["margin_pct_of_run"] = 100.0 * out["margin_s"] / out["wall_on_s"]
    print(f"{name}: medians of {len(ons)} pairs: wall {out['wall_on_s']:.1f} s with margins, {out['wall_off_s']:.1f} "
          f"without ({out['wall_overhead_pct']:+.1f} %); CPU {out['cpu_on_s']:.1f} s, {out['cpu_off_s']:.1f} s "
          f"({out['cpu_overhead_pct']:+.1f} %); the margins' own time {out['margin_s']:.2f} s "
          f"({out['margin_pct_of_run']:.1f} % of the run with them); steps' Newton and Krylov iterations "
          f"{'the same' if same else 'DIFFERENT'} with and without")
    return out


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
    ap.add_argument("--pairs", type=int, default=2, help="runs with and without margins, in alternation")
    ap.add_argument("--no-check", action="store_true", help="skip the runs continued past the smallest margin")
    ap.add_argument("--timeout", type=float, default=7200.0)
    ap.add_argument("extra", nargs="*", help="options for every run (after --)")
    args = ap.parse_args()
    args.out = os.path.abspath(args.out)
    os.makedirs(args.out, exist_ok=True)
    report, ok = {}, True
    offs = args.scenes.split(",") if args.off is None else args.off.split(",")
    for name in args.scenes.split(","):
        ons, offs_runs = [], []
        for k in range(args.pairs if name in offs else 1):
            tag = "" if k == 0 else f"-{k + 1}"
            ons.append(run(name, "margins" + tag, [], args))
            if name in offs:
                offs_runs.append(run(name, "off" + tag, ["-pfault_margins", "false"], args))
        if any(r is None for r in ons + offs_runs):
            ok = False
            continue
        on = ons[0]
        rows = steps_table(name, on)
        t_on = totals(on)
        print(f"\n{name}: with margins solve {t_on['solve_s']:.2f} s, {t_on['newton']} Newton, {t_on['lu']} LU; "
              f"margin solves {t_on['margin_solves']} x, {t_on['margin_its']} Krylov iterations, "
              f"{t_on['margin_s']:.2f} s "
              f"({100 * t_on['margin_s'] / max(t_on['solve_s'], 1e-300):.1f} % of the steps' solve time), "
              f"{t_on['margin_lu']} LU; end to end {t_on['end_to_end_s']:.1f} s")
        t_off = totals(offs_runs[0]) if offs_runs else None
        if t_off is not None:
            print(f"{name}: without: solve {t_off['solve_s']:.2f} s, {t_off['newton']} Newton, {t_off['lu']} LU; "
                  f"end to end {t_off['end_to_end_s']:.1f} s")
        pairs = overhead(name, [totals(r) for r in ons], [totals(r) for r in offs_runs]) if offs_runs else None
        check = None if args.no_check else plus_minus(name, on, rows, args)
        ok = ok and (args.no_check or check is not None)
        report[name] = {"with": t_on, "without": t_off, "pairs": pairs, "steps": rows, "plus_minus": check,
                        "faces": int(on["mesh"]["fault_faces"]), "dofs": int(on["dofs"])}
    print(json.dumps({"ranks": args.ranks, "scenes": report}, default=lambda v: None if v is np.nan else v))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())

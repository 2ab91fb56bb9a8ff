#!/usr/bin/env python
"""A candidate surface breaking across a scene against the same scene with a pre-existing fault, and against the
per-pass scheme (each row of the fracture front a solve again of the whole step at the same load), side by side.

    python benchmarks/candidate_surface.py [--reference /work/ref] [--out runs/candidate_surface] [--size 95]
                                           [--scenes basin,layered] [--repeats 1] [--timeout 7200]

Two scenes, each meshed here with benchmarks/basin_fault_mesh.py at --size (m):
- ``basin``: config/basin_fault.opts (a basin-bounding plane dipping 60 degrees, 300 m of sediments in its hanging
  wall over rock, 40 m of drawdown in the sediments over 10 years);
- ``layered``: a plane dipping 50 degrees through three sediment layers (clay, sand, clay: --layers 60,240) over
  rock in its hanging wall, rock in its footwall, drawdown 25, 100 and 50 m in the three layers (``LAYERED``).
Each scene runs as it is (a pre-existing fault, c = 0), then with its plane a candidate surface (``CANDIDATE``:
tensile strength 20 kPa, cohesion 50 kPa, residual cohesion 0), with this checkout on --ranks and on 1 rank, and
with the checkout at --reference (pfault before breaking moved into Newton: main at 526008b, which runs the same
scenes). The runs of a repeat are interleaved (fault, candidate, per-pass; the order turned in every other repeat)
so that the machine's load falls on them alike; Newton iterations, factorisations and the broken set do not
depend on the load.

Printed: per run the wall time end to end and of the solve stage, CPU time, Newton iterations, factorisations,
breaking rounds, broken faces; the candidate's ratios to the pre-existing fault (targets: at most 3 in wall time
and Newton iterations); whether the broken set and the break times of every output step are the same on 1 and
--ranks ranks and as the per-pass scheme's. One JSON line at the end; exit code 1 when a run failed.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import h5py
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
from pfault.post.rundir import read_summary  # noqa: E402
from pfault.tools.runs import environment, run_captured, run_logged  # noqa: E402

CANDIDATE = ["-pfault_fault_fault_tensile_strength", "20*kPa", "-pfault_fault_fault_cohesion", "50*kPa",
             "-pfault_fault_fault_residual_cohesion", "0"]
MAX_RATIO = 3.0
MESHES = {"basin": ["--dip", "60"], "layered": ["--dip", "50", "--layers", "60,240"]}
LAYERED = """# A plane dipping 50 degrees between a basin's layered sediments and the rock of its footwall
-pfault_scene layered_basin
-pfault_ground_surface top
# materials: clay over a sand aquifer over clay, 300 m in all, over rock
-pfault_material_basin1_young_modulus 10*MPa
-pfault_material_basin1_poisson_ratio 0.35
-pfault_material_basin1_density 1900
-pfault_material_basin2_young_modulus 40*MPa
-pfault_material_basin2_poisson_ratio 0.25
-pfault_material_basin2_density 2000
-pfault_material_basin3_young_modulus 15*MPa
-pfault_material_basin3_poisson_ratio 0.35
-pfault_material_basin3_density 1950
-pfault_material_rock_young_modulus 5000*MPa
-pfault_material_rock_poisson_ratio 0.25
-pfault_material_rock_density 2600
# fault
-pfault_faults fault
-pfault_fault_fault_cohesion 0
-pfault_fault_fault_friction_angle 30
# boundary conditions and initial state
-pfault_bc_bottom_type fixed
-pfault_bc_xmin_type roller
-pfault_bc_xmax_type roller
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_geostatic true
-pfault_water_table 0
# loading: the aquifer drawn down 100 m over 10 years, the clay below it half as much, the clay above a quarter
-pfault_material_basin1_head_drawdown 0:0,10*year:25
-pfault_material_basin2_head_drawdown 0:0,10*year:100
-pfault_material_basin3_head_drawdown 0:0,10*year:50
# time
-pfault_time_end 10*year
-pfault_time_steps 10
"""


def make_scene(name: str, out: str, size: float) -> tuple[str, str]:
    """The scene file and mesh of ``name`` under ``out`` (the mesh made once)."""
    mesh = os.path.join(out, f"{name}_{size:g}.msh")
    if not os.path.exists(mesh):
        made = run_captured([os.path.join(REPO, "benchmarks", "basin_fault_mesh.py"), mesh, "--size", str(size),
                             *MESHES[name]], cwd=REPO)
        if made.returncode != 0:
            raise SystemExit(f"basin_fault_mesh.py: exit {made.returncode}\n{made.stderr[-2000:]}")
    if name == "basin":
        return os.path.join(REPO, "config", "basin_fault.opts"), mesh
    scene = os.path.join(out, "layered_basin.opts")
    with open(scene, "w") as fh:
        fh.write(LAYERED)
    return scene, mesh


def run(tree: str, scene: str, mesh: str, out: str, ranks: int, extra: list, timeout: float) -> dict:
    """One pfault run of the checkout ``tree`` into ``out``: its figures (``ok`` False for a failed run)."""
    env = environment()
    env["PYTHONPATH"] = tree
    done = run_logged(["-m", "pfault", scene, "-pfault_mesh_file", mesh, "-pfault_output_dir", out,
                       "-pfault_figures", "false", *extra], ranks, out + ".log", timeout, cwd=tree, env=env)
    s = read_summary(out) if done.code == 0 and not done.timed_out else None
    rec = {"dir": out, "ok": bool(s and s["converged"]), "wall_s": done.wall, "load": done.load, "cpu_s": done.cpu}
    if s is None:
        return rec
    steps = [r for r in s["steps"] if not r.get("initial")]
    rec.update(solve_s=s["wall_s"]["solve"], newton=sum(r["newton_its"] for r in steps),
               lu=sum(r.get("factorizations", 0) for r in steps),
               rounds=sum(r.get("breaking_passes", 0) for r in steps),
               broken=s["faults"]["fault"].get("faces_broken", 0), faces=s["mesh"]["fault_faces"])
    return rec


def breaks(run_dir: str) -> list:
    """(time, broken, break time) of every output step of a run's fault.h5 (faces in the serial order)."""
    with h5py.File(os.path.join(run_dir, "fault.h5"), "r") as f:
        groups = [f["steps"][k] for k in sorted(f["steps"], key=int)]
        return [(float(g.attrs["time"]), g["broken"][()] != 0, g["break_time"][()]) for g in groups]


def same_breaks(a: str, b: str) -> tuple[bool, int]:
    """Whether two runs broke the same faces at the same times at every output step; the most faces that
    differ at a step."""
    x, y = breaks(a), breaks(b)
    if len(x) != len(y):
        return False, -1
    worst = max(int(np.count_nonzero((p[1] != q[1]) | ~np.isclose(p[2], q[2], rtol=0, atol=0, equal_nan=True)))
                for p, q in zip(x, y))
    return worst == 0 and all(p[0] == q[0] for p, q in zip(x, y)), worst


def scene_runs(name: str, args: argparse.Namespace) -> dict:
    """The runs of one scene: ``repeats`` interleaved rounds of (fault, candidate, per-pass), then the candidate
    on 1 rank; the best wall time of each."""
    scene, mesh = make_scene(name, args.out, args.size)
    plan = {"fault": (REPO, []), "candidate": (REPO, CANDIDATE), "per-pass": (args.reference, CANDIDATE)}
    runs: dict = {k: [] for k in plan}
    for rep in range(args.repeats):
        for key in (list(plan) if rep % 2 == 0 else list(plan)[::-1]):
            tree, extra = plan[key]
            r = run(tree, scene, mesh, os.path.join(args.out, f"{name}_{key}_{rep}"), args.ranks, extra,
                    args.timeout)
            print(f"  {name} {key} (repeat {rep}): {'ok' if r['ok'] else 'FAILED'} {r['wall_s']:.1f} s, load "
                  f"{r['load']:.1f}", flush=True)
            runs[key].append(r)
    one = run(REPO, scene, mesh, os.path.join(args.out, f"{name}_candidate_1rank"), 1, CANDIDATE, args.timeout)
    best = {k: min(v, key=lambda r: r["wall_s"]) for k, v in runs.items()}
    best["candidate 1 rank"] = one
    return best


def report(name: str, best: dict, ranks: int) -> dict:
    """Print a scene's table and comparisons; returns its figures."""
    print(f"\n{name}: {best['fault'].get('faces', '?')} fault faces\n\n| run | ranks | wall s | solve s | CPU s | "
          "load | Newton | LU | rounds | broken |\n|---|---|---|---|---|---|---|---|---|---|")
    for key, r in best.items():
        n = 1 if key.endswith("1 rank") else ranks
        if not r["ok"]:
            print(f"| {key} | {n} | FAILED (see {r['dir']}.log) |||||||")
            continue
        print(f"| {key} | {n} | {r['wall_s']:.1f} | {r['solve_s']:.1f} | {r['cpu_s']:.1f} | {r['load']:.1f} | "
              f"{r['newton']} | {r['lu']} | {r['rounds']} | {r['broken']} |")
    if not all(r["ok"] for r in best.values()):
        return {"ok": False}
    f, c, p = best["fault"], best["candidate"], best["per-pass"]
    out = {"ok": True, "wall_ratio": c["wall_s"] / f["wall_s"], "newton_ratio": c["newton"] / f["newton"],
           "cpu_ratio": c["cpu_s"] / f["cpu_s"], "per_pass_wall_ratio": p["wall_s"] / f["wall_s"],
           "per_pass_newton_ratio": p["newton"] / f["newton"]}
    out["same_as_1_rank"], out["faces_differing_1_rank"] = same_breaks(c["dir"], best["candidate 1 rank"]["dir"])
    out["same_as_per_pass"], out["faces_differing_per_pass"] = same_breaks(c["dir"], p["dir"])
    print(f"\ncandidate / pre-existing fault: wall {out['wall_ratio']:.2f}, Newton {out['newton_ratio']:.2f}, CPU "
          f"{out['cpu_ratio']:.2f} (target <= {MAX_RATIO:g}); per-pass / pre-existing: wall "
          f"{out['per_pass_wall_ratio']:.2f}, Newton {out['per_pass_newton_ratio']:.2f}")
    print(f"broken faces and break times at every output step: {ranks} ranks vs 1 rank "
          f"{'the same' if out['same_as_1_rank'] else 'DIFFER'}; vs the per-pass scheme "
          f"{'the same' if out['same_as_per_pass'] else 'DIFFER'} (most faces differing at a step: "
          f"{out['faces_differing_1_rank']}, {out['faces_differing_per_pass']})")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default="/work/ref", help="checkout with the per-pass scheme")
    ap.add_argument("--out", default=os.path.join(REPO, "runs", "candidate_surface"))
    ap.add_argument("--size", type=float, default=95.0, help="element size away from the plane (m)")
    ap.add_argument("--scenes", default="basin,layered")
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=7200.0, help="s per run")
    args = ap.parse_args(argv)
    args.out = os.path.abspath(args.out)
    os.makedirs(args.out, exist_ok=True)
    figures = {}
    for name in args.scenes.split(","):
        figures[name] = report(name, scene_runs(name, args), args.ranks)
    print(json.dumps(figures))
    return 0 if all(f["ok"] for f in figures.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())

"""Newton on penalty faces with full steps (-snes_linesearch_type basic, the Lagrange faces' default) against
backtracking (bt): Newton iterations per step side by side, on the fissure box (config/hard/fissure_box.opts, ten
years of drawdown in ten steps; at h/2 its first year in one step) and the two blocks (config/two_blocks.opts at 8 x 4 x 4 cells), penalty
stiffness k = 1e2, 1e4, 1e6 E/h (E/h of the softer side on the faces, h = sqrt(face area)), and the basin's
normal fault (config/basin_fault.opts on benchmarks/basin_fault_mesh.py's default mesh) with penalty faces at
their default k; the Lagrange faces for reference.

    .venv/bin/python studies/penalty_linesearch.py [--cases NAME,...] [--out DIR]

One run at a time, one rank, into ``--out`` (default runs/penalty_linesearch/); prints one line per run (Newton
iterations per step, their sum, sub-steps, converged) and a JSON line of all.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from pfault.tools.runs import run_captured  # noqa: E402
from studies import REPO  # noqa: E402

SCENES = {
    # clay E = 8 MPa on 12.5 m x 10 m halves
    "fissure_box": ("config/hard/fissure_box.opts", "fissure", 8.0e6 / math.sqrt(62.5), []),
    # at h/2, the first year in one step (the step where full steps on the former penalty law 2-cycled)
    "fissure_box_h2": ("config/hard/fissure_box.opts", "fissure", 8.0e6 / math.sqrt(15.625),
                       ["-pfault_box_cells", "32,16,20", "-pfault_time_end", "1*year", "-pfault_time_steps", "1"]),
    # the basin's normal fault (benchmarks/basin_fault_mesh.py at 95 m, 37k tetrahedra), ten years of drawdown:
    # penalty faces at their default k (E/h of each face's cells) only (None)
    "basin_fault": ("config/basin_fault.opts", "fault", None, []),
    # E = 10 MPa on 0.25 m x 0.25 m halves
    "two_blocks": ("config/two_blocks.opts", "fault", 10.0e6 / math.sqrt(0.03125),
                   ["-pfault_box_cells", "8,4,4"]),
}
MULTIPLES = (1e2, 1e4, 1e6)
SEARCHES = ("basic", "bt")


def cases() -> dict:
    out = {}
    for scene, (_, fault, e_over_h, extra) in SCENES.items():
        for ls in SEARCHES:
            out[f"{scene}-lagrange-{ls}"] = (scene, extra + ["-snes_linesearch_type", ls])
            if e_over_h is None:
                out[f"{scene}-kdefault-{ls}"] = (scene, extra + [
                    f"-pfault_fault_{fault}_method", "penalty", "-snes_linesearch_type", ls])
                continue
            for m in MULTIPLES:
                k = f"{m * e_over_h:.6g}"
                out[f"{scene}-k{m:g}-{ls}"] = (scene, extra + [
                    f"-pfault_fault_{fault}_method", "penalty", f"-pfault_fault_{fault}_penalty_normal", k,
                    f"-pfault_fault_{fault}_penalty_tangential", k, "-snes_linesearch_type", ls])
    return out


def basin_mesh(out: str) -> str:
    """The basin-fault mesh at its default size, made once in ``out``."""
    path = os.path.join(out, "basin_fault.msh")
    if not os.path.exists(path):
        os.makedirs(out, exist_ok=True)
        proc = run_captured([os.path.join("benchmarks", "basin_fault_mesh.py"), path], 1, timeout=600, cwd=REPO)
        if proc.returncode != 0:
            raise SystemExit(f"basin_fault_mesh.py: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=None, help="comma-separated names (default all)")
    ap.add_argument("--out", default=os.path.join(REPO, "runs", "penalty_linesearch"))
    a = ap.parse_args()
    table = cases()
    names = a.cases.split(",") if a.cases else list(table)
    results = {}
    for name in names:
        scene, extra = table[name]
        out = os.path.join(a.out, name)
        if scene == "basin_fault":
            extra = ["-pfault_mesh_file", basin_mesh(a.out)] + extra
        t0 = time.perf_counter()
        proc = run_captured(["-m", "pfault", SCENES[scene][0], "-pfault_output_dir", out, "-pfault_figures",
                             "false", *extra], 1, timeout=1800, cwd=REPO)
        wall = time.perf_counter() - t0
        try:
            s = json.load(open(os.path.join(out, "summary.json")))
        except OSError:
            s = {"steps": [], "converged": False}
        steps = s.get("steps", [])
        r = {"exit": proc.returncode, "converged": bool(s.get("converged")) and proc.returncode == 0,
             "newton": [st["newton_its"] for st in steps], "substeps": sum(st.get("substeps", 1) - 1 for st in steps),
             "wall_s": round(wall, 1)}
        r["total"] = sum(r["newton"])
        results[name] = r
        print(f"{name:32s} newton {r['newton']} total {r['total']} sub-steps {r['substeps']} "
              f"converged {r['converged']} exit {r['exit']} {r['wall_s']} s", flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()

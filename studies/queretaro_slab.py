"""Queretaro's fault in plane strain: does the slip and opening of a cohesionless vertical fault between rock and
drawn-down sediment, under the land surface, converge as the elements at the fault shrink?

    .venv/bin/python benchmarks/queretaro_slab.py [--sizes 8,4,2,1,0.5,0.25] [--drawdown 11.3] [--no-run]

The section of config/queretaro.opts across its fault, as a slab one element thick with rollers on its ends
(benchmarks/faulted_aquifer_mesh.py --slab --dip 90): 2 km across, 50 m deep, rock for x < 1000 m, 20 m of clay over
30 m of sand beside it, Queretaro's materials and fault (c = 0, phi = 30 degrees), fixed bottom, rollers on the
sides, geostatic start with the water table at the land surface. The load is the sand's head drawdown growing to
11.3 m at year 10 (-111 kPa, the pore-pressure change calibrated Queretaro's aquifer has at 50 m from its fault at
year 10; --drawdown changes it); the clay and the rock are not drawn down. Each element size on the fault (m; growing to 40 m 200 m from
it) runs on 1 rank with MUMPS into runs/queretaro_slab/h<size>/; then one table of year 10, per metre of strike:
potency (integral of the slip), open volume, slipping and open lengths down the fault, the deepest slipping and open
faces, the largest slip and opening, and the Richardson rate and extrapolation over the last three sizes.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

import numpy as np

from pfault.tools.runs import run_captured, run_logged

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUNS = os.path.join(ROOT, "runs", "queretaro_slab")
MESHER = os.path.join(ROOT, "benchmarks", "faulted_aquifer_mesh.py")
DRAWDOWN = "11.3"      # m of head in the sand at year 10 (calibrated Queretaro beside its fault)
GEOMETRY = ["--slab", "--dip", "90", "--depth", "50", "--clay", "20", "--fault-x", "1000", "--length", "2000"]
SCENE = """-pfault_scene queretaro_slab
-pfault_ground_surface top
-pfault_mesh_file {mesh}
-pfault_material_sand_young_modulus 15*MPa
-pfault_material_sand_poisson_ratio 0.25
-pfault_material_sand_density 1960
-pfault_material_clay_young_modulus 15*MPa
-pfault_material_clay_poisson_ratio 0.25
-pfault_material_clay_density 1960
-pfault_material_rock_young_modulus 4900*MPa
-pfault_material_rock_poisson_ratio 0.25
-pfault_material_rock_density 2600
-pfault_faults fault
-pfault_fault_fault_cohesion 0
-pfault_fault_fault_friction_angle 30
-pfault_bc_bottom_type fixed
-pfault_bc_xmin_type roller
-pfault_bc_xmax_type roller
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_geostatic true
-pfault_water_table 0
-pfault_material_sand_head_drawdown 0:0,10*year:{drawdown}
-pfault_time_end 10*year
-pfault_time_steps 10
-pfault_solver mumps
-pfault_figures false
"""


def _dir(h, drawdown):
    return os.path.join(RUNS, f"h{h}" if drawdown == DRAWDOWN else f"h{h}-dd{drawdown}")


def make_case(out, h, drawdown=DRAWDOWN):
    """The slab's mesh (element size h on the fault) and scene in directory out; returns the scene's path."""
    os.makedirs(out, exist_ok=True)
    mesh = os.path.join(out, "slab.msh")
    made = run_captured([MESHER, mesh, "--fault-size", str(h), *GEOMETRY], cwd=ROOT)
    if made.returncode != 0:
        raise SystemExit(f"{MESHER}: exit {made.returncode}\n{made.stderr[-2000:]}")
    scene = os.path.join(out, "scene.opts")
    with open(scene, "w") as fh:
        fh.write(SCENE.format(mesh=mesh, drawdown=drawdown))
    return scene


def run(h, drawdown):
    out = _dir(h, drawdown)
    scene = make_case(out, h, drawdown)
    done = run_logged(["-m", "pfault", scene, "-pfault_output_dir", out], 1, os.path.join(out, "stdout.txt"), cwd=ROOT)
    if done.code != 0:
        raise SystemExit(f"{scene}: exit {done.code}; see {done.log}")


def measures(out, h):
    """Year-10 figures of the run in out per metre of strike (the slab is h thick), or None without a run."""
    import h5py
    if not os.path.exists(os.path.join(out, "summary.json")):
        return None
    with open(os.path.join(out, "summary.json")) as fh:
        s = json.load(fh)
    f, w = s["faults"]["fault"], float(h)
    with h5py.File(os.path.join(out, "fault.h5"), "r") as fa:
        pts, cells = fa["mesh/points"][()], fa["mesh/cells"][()]
        state = fa["steps"][sorted(fa["steps"])[-1]]["state"][()].astype(int)
    depth = -pts[cells][:, :, 2].min(axis=1)
    return {"potency": f["slip_potency_m3"] / w, "open_volume": f["open_volume_m3"] / w,
            "slip_length": f["slipping_area_m2"] / w, "open_length": f["open_area_m2"] / w,
            "slip_depth": float(depth[state == 1].max()) if np.any(state == 1) else 0.0,
            "open_depth": float(depth[state == 2].max()) if np.any(state == 2) else 0.0,
            "max_slip": f["max_slip_m"], "max_opening": f["max_opening_m"], "converged": s["converged"],
            "newton": max(r["newton_its"] for r in s["steps"]), "dofs": s.get("dofs")}


def richardson(h, v):
    """Rate and extrapolated value from three sizes h (ratio r each) and values v; None without a monotone range."""
    d1, d2 = v[1] - v[0], v[2] - v[1]
    if d1 == 0 or d2 == 0 or d1 * d2 < 0 or abs(d2) >= abs(d1):
        return None
    r = h[0] / h[1]
    p = math.log(abs(d1 / d2)) / math.log(r)
    return p, v[2] + d2 / (r ** p - 1.0)


COLUMNS = [("potency", "potency m^3/m", "{:.4g}"), ("open_volume", "open volume m^3/m", "{:.4g}"),
           ("slip_length", "slipping length m", "{:.4g}"), ("open_length", "open length m", "{:.4g}"),
           ("slip_depth", "deepest slipping face m", "{:.3g}"), ("open_depth", "deepest open face m", "{:.3g}"),
           ("max_slip", "max slip m", "{:.4g}"), ("max_opening", "max opening m", "{:.4g}"),
           ("newton", "Newton (worst step)", "{:d}"), ("dofs", "unknowns", "{:,}")]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="8,4,2,1,0.5,0.25", help="element sizes on the fault (m), comma-separated")
    ap.add_argument("--drawdown", default=DRAWDOWN, help="the sand's head drawdown at year 10 (m; default 11.3; "
                    "the stated pumping of config/queretaro.opts draws about 7 times as much)")
    ap.add_argument("--no-run", action="store_true", help="only rebuild the table from the runs there")
    a = ap.parse_args()
    sizes = [h for h in a.sizes.split(",") if h]
    if not a.no_run:
        for h in sizes:
            run(h, a.drawdown)
    rows = {h: measures(_dir(h, a.drawdown), h) for h in sizes}
    lines = ["| h m | " + " | ".join(c[1] for c in COLUMNS) + " |", "|" + "---|" * (len(COLUMNS) + 1)]
    for h, m in rows.items():
        cells = ["(no run)"] if m is None else [fmt.format(m[k]) for k, _, fmt in COLUMNS]
        lines.append(f"| {h}{'' if m is None or m['converged'] else ' (NOT CONVERGED)'} | " + " | ".join(cells) + " |")
    done = [h for h in sizes if rows[h] is not None]
    if len(done) >= 3:
        last = done[-3:]
        for key in ("potency", "open_volume", "slip_length", "open_length"):
            fit = richardson([float(h) for h in last], [rows[h][key] for h in last])
            lines.append(f"\n{key} over h = {', '.join(last)}: " + ("no monotone converging range" if fit is None else
                         f"rate {fit[0]:.2f}, extrapolated {fit[1]:.4g} (finest {rows[last[-1]][key]:.4g})"))
    text = "\n".join(lines)
    print(text)
    os.makedirs(RUNS, exist_ok=True)
    name = "table.md" if a.drawdown == DRAWDOWN else f"table-dd{a.drawdown}.md"
    with open(os.path.join(RUNS, name), "w") as fh:
        fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

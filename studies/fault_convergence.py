"""Mesh convergence of the fault answer on the faulted aquifer (config/faulted_aquifer.opts): the 3-D block
against size factor and its plane-strain slab against the fault's element size, and controlled variants.

    .venv/bin/python benchmarks/fault_convergence.py [--cases NAME,...] [--no-run] [--list] [--step N]

Each case makes its mesh (benchmarks/faulted_aquifer_mesh.py) and runs the scene into runs/fault_convergence/<case>/
(one run at a time; 1 rank, 2 for the 3-D size factor 1), then one table of the last step (year 10; --step N: step
N) is printed and written to runs/fault_convergence/table.md. The figures are per metre of strike (the block is 1 km
long along the strike, the slab one element): the slip potency (integral of the slip magnitude over the fault,
m^3/m), that of the slipping and open faces only and that of the faces above 10 m depth, the open volume (integral
of the opening over the open faces), the slipping and open lengths down the dip (area / strike length), the largest
slip and opening over slipping and open faces and over all faces (face averages, the fault output's), and the
largest subsidence. Every run is also checked to converge in every step: the table gives its Newton iterations in
the worst step and its sub-steps.

The variants change one thing, on the slab or the block (the variants of the former traction-jump stabilisation's
share, ``frac<F>``, were measured before the face bubbles replaced it: docs/verification.md keeps their figures):
penalty faces (their default stiffness E/h) instead of Lagrange faces (``penalty``), no cohesion (``c0``), a fault capped 10 m below the land surface with a welded contact
above (``cap10``), an isotropic geostatic start (``k01``: K0 = 1 instead of nu / (1 - nu) of each material), the 3-D
block only 40 m long along the strike (``3d-w40``: the same plane-strain problem, so that its tetrahedra can be
refined to 3.2 m on the fault), the tension cut-off at t_N = 0 instead of the cone's apex (``zero``:
-pfault_fault_fault_tension_cutoff zero), and ``glued`` (cohesion 1e4 MPa: no face slips; the elastic comparison of
the slab with the 3-D block). Every variant is an option of pfault's or of the mesher's, given on the command line.
--no-run rebuilds the table from the run directories already there.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from pfault.tools.runs import run_captured, run_logged  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUNS = os.path.join(ROOT, "runs", "fault_convergence")
SCENE = os.path.join(ROOT, "config", "faulted_aquifer.opts")
MESHER = os.path.join(ROOT, "benchmarks", "faulted_aquifer_mesh.py")
QUIET = ["-pfault_figures", "false"]
ZERO = ["-pfault_fault_fault_tension_cutoff", "zero"]
TIMEOUT = 4 * 3600.0    # s, a run's limit


def _cases():
    """name -> (mesh arguments, ranks, pfault options); a name ending in -zero: the tension cut-off at t_N = 0 (the
    law before the cut-off moved to the cone's apex)."""
    c = {}
    for f in ("2", "1.4", "1"):
        c[f"3d-f{f}"] = (["--size-factor", f], 2 if f == "1" else 1, [])
    c["3d-f2-zero"] = (["--size-factor", "2"], 1, ZERO)
    c["3d-f1.4-zero"] = (["--size-factor", "1.4"], 1, ZERO)
    # the block 40 m long along the strike (the same plane-strain problem), down to 3.2 m on the fault
    for f in ("1", "0.5", "0.35"):
        c[f"3d-w40-f{f}"] = (["--size-factor", f, "--strike-length", "40"], 1, [])
    c["3d-f2-glued"] = (["--size-factor", "2"], 1, ["-pfault_fault_fault_cohesion", "1e4*MPa"])
    c["3d-f2-cap10"] = (["--size-factor", "2", "--fault-top", "10"], 1, [])
    c["3d-f2-penalty"] = (["--size-factor", "2"], 1, ["-pfault_fault_fault_method", "penalty"])
    c["3d-f1.4-penalty"] = (["--size-factor", "1.4"], 1, ["-pfault_fault_fault_method", "penalty"])
    for h in ("8", "4", "2", "1", "0.5"):
        c[f"slab-h{h}"] = (["--slab", "--fault-size", h], 1, [])
    # 52,000 tetrahedra: MUMPS, as the coarser slabs have by -pfault_solver auto (the iterative solver took 62
    # Krylov iterations per Newton iteration on these flat elements)
    c["slab-h0.25"] = (["--slab", "--fault-size", "0.25"], 1, ["-pfault_solver", "mumps"])
    for h in ("8", "2"):
        c[f"slab-h{h}-c0"] = (["--slab", "--fault-size", h], 1, ["-pfault_fault_fault_cohesion", "0"])
    for h in ("4", "1"):
        c[f"slab-h{h}-penalty"] = (["--slab", "--fault-size", h], 1,
                                   ["-pfault_fault_fault_method", "penalty"])
        c[f"slab-h{h}-c0"] = (["--slab", "--fault-size", h], 1, ["-pfault_fault_fault_cohesion", "0"])
        c[f"slab-h{h}-cap10"] = (["--slab", "--fault-size", h, "--fault-top", "10"], 1, [])
    for h in ("8", "4", "2", "1"):
        c[f"slab-h{h}-zero"] = (["--slab", "--fault-size", h], 1, ZERO)
    for h in ("4", "1"):       # the initial state: K0 = 1 (an isotropic geostatic stress) instead of nu/(1-nu)
        c[f"slab-h{h}-k01"] = (["--slab", "--fault-size", h], 1, ["-pfault_geostatic_k0", "1"])
        c[f"slab-h{h}-k01-zero"] = (["--slab", "--fault-size", h], 1, ["-pfault_geostatic_k0", "1", *ZERO])
    c["slab-h4-glued"] = (["--slab", "--fault-size", "4"], 1, ["-pfault_fault_fault_cohesion", "1e4*MPa"])
    return c


CASES = _cases()


def _mesh(args):
    name = "mesh" + "".join(a.replace("--", "_").replace("-", "") for a in args) + ".msh"
    path = os.path.join(RUNS, "meshes", name)
    if not os.path.exists(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        made = run_captured([MESHER, path, *args], cwd=ROOT)
        if made.returncode != 0:
            raise SystemExit(f"{MESHER}: exit {made.returncode}\n{made.stderr[-2000:]}")
    return path


def run(name):
    """The case's run: its mesh, then pfault on the scene with the case's options."""
    mesh_args, ranks, opts = CASES[name]
    out = os.path.join(RUNS, name)
    os.makedirs(out, exist_ok=True)
    mesh = _mesh(mesh_args)
    run_case(name, ["-m", "pfault", SCENE, "-pfault_mesh_file", mesh, "-pfault_output_dir", out, *QUIET, *opts],
             ranks, out)


def run_case(name, args, ranks, out):
    """Run ``python ARGS`` on ``ranks`` ranks from the repository's root (pfault.tools.runs.run_logged) with its output in
    ``out``/stdout.txt; ``out``/case.json records the command, its exit code and wall time."""
    done = run_logged(args, ranks, os.path.join(out, "stdout.txt"), TIMEOUT, cwd=ROOT)
    with open(os.path.join(out, "case.json"), "w") as f:
        json.dump({"command": done.command, "exit_code": done.code, "wall_s": done.wall}, f)
    print(f"{name}: exit {done.code}, {done.wall:.0f} s", flush=True)


def measures(out, step=None):
    """Figures of a run (per metre of strike) at its last output step or at ``step``, or None if it has no fault
    output (or not that step)."""
    import h5py
    path = os.path.join(out, "fault.h5")
    if not os.path.exists(path):
        return None
    with h5py.File(path, "r") as f:
        pts, cells = f["mesh/points"][()], f["mesh/cells"][()]
        last = sorted(f["steps"].keys())[-1] if step is None else f"{step:06d}"
        if last not in f["steps"]:
            return None
        s = f["steps"][last]
        slip, opening, state = s["slip_magnitude"][()], s["opening"][()], s["state"][()].astype(int)
    x = pts[cells]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    strike = np.ptp(pts[:, 1])
    slipping, opn = state == 1, state == 2
    moving = slipping | opn
    depth = -x[:, :, 2].mean(axis=1)

    def mx(v, m):
        return float(v[m].max()) if np.any(m) else 0.0
    with open(os.path.join(out, "summary.json")) as f:
        summary = json.load(f)
    steps = [s for s in summary["steps"] if not s.get("initial") and s["step"] <= int(last)]
    return {
        "faces": len(cells), "step": int(last),
        "converged": all(s.get("converged") for s in steps),
        "newton_worst": max(s["newton_its"] for s in steps),
        "substeps": sum(s.get("substeps", 0) or 0 for s in steps),
        "potency": float(np.sum(area * slip)) / strike,
        "potency_moving": float(np.sum((area * slip)[moving])) / strike,
        "open_volume": float(np.sum((area * opening)[opn])) / strike,
        "slip_length": float(area[slipping].sum()) / strike,
        "open_length": float(area[opn].sum()) / strike,
        "max_slip_moving": mx(slip, moving), "max_slip": float(slip.max()),
        "max_opening_open": mx(opening, opn), "max_opening": float(opening.max()),
        "potency_top10m": float(np.sum((area * slip)[depth < 10.0])) / strike,
        "max_subsidence": max(s.get("max_subsidence_m", 0.0) for s in steps),
    }


COLUMNS = [("faces", "fault faces", "{:d}"), ("newton_worst", "Newton (worst step)", "{:d}"),
           ("substeps", "sub-steps", "{:d}"), ("potency", "potency m^3/m", "{:.4g}"),
           ("potency_moving", "of slipping/open faces", "{:.4g}"), ("potency_top10m", "of faces above 10 m",
                                                                    "{:.3g}"),
           ("open_volume", "open volume m^3/m", "{:.3g}"), ("slip_length", "slipping length m", "{:.4g}"),
           ("open_length", "open length m", "{:.3g}"), ("max_slip_moving", "max slip (slip/open) m", "{:.4g}"),
           ("max_slip", "max slip (all) m", "{:.4g}"), ("max_opening_open", "max opening (open) m", "{:.3g}"),
           ("max_opening", "max opening (all) m", "{:.3g}"), ("max_subsidence", "max subsidence m", "{:.4g}")]


def table(names, step=None):
    head = "| case | " + " | ".join(c[1] for c in COLUMNS) + " |"
    lines = [head, "|" + "---|" * (len(COLUMNS) + 1)]
    for name in names:
        m = measures(os.path.join(RUNS, name), step)
        if m is None:
            lines.append(f"| {name} | (no run) |")
            continue
        status = "" if m["converged"] else " (NOT CONVERGED)"
        lines.append(f"| {name}{status} | " + " | ".join(fmt.format(m[k]) for k, _, fmt in COLUMNS) + " |")
    return "\n".join(lines)


def surface_profiles(slab_case="slab-h4-glued", block_case="3d-f2-glued"):
    """The plane-strain check: the land surface's displacement of the 3-D block against the slab's (linear
    interpolation of the slab's surface profile in x, nodes within 5 m of the fault trace left out), relative L2
    differences of u_z and u_x, the 3-D block's largest |u_y|, and both far-field subsidences against the
    oedometer's 73 m x rho_w g x 70 m / M of the sand (M = E (1 - nu) / ((1 + nu)(1 - 2 nu)))."""
    import h5py

    def load(case):
        with h5py.File(os.path.join(RUNS, case, "fields.h5"), "r") as f:
            s = f["steps"][sorted(f["steps"].keys())[-1]]
            return f["mesh/points"][()], s["displacement"][()]
    ps, us = load(slab_case)
    pb, ub = load(block_case)
    top = (np.abs(ps[:, 2]) < 1e-6) & (np.abs(ps[:, 1]) < 1e-6)
    order = np.argsort(ps[top, 0])
    xs = ps[top, 0][order]
    t = (np.abs(pb[:, 2]) < 1e-6) & (np.abs(pb[:, 0] - 900.0) > 5.0)
    out = {}
    for k, name in ((2, "u_z"), (0, "u_x")):
        ref = np.interp(pb[t, 0], xs, us[top, k][order])
        out[f"{name} rel L2"] = float(np.linalg.norm(ub[t, k] - ref) / np.linalg.norm(ref))
    out["max |u_y| 3-D"] = float(np.abs(ub[:, 1]).max())
    far_s = (np.abs(ps[:, 2]) < 1e-6) & (ps[:, 0] > 1900)
    far_b = (np.abs(pb[:, 2]) < 1e-6) & (pb[:, 0] > 1900)
    modulus = 60e6 * 0.7 / (1.3 * 0.4)
    out["far subsidence slab"] = float(-us[far_s, 2].mean())
    out["far subsidence 3-D"] = float(-ub[far_b, 2].mean())
    out["oedometer"] = 1000.0 * 9.80665 * 73.0 * 70.0 / modulus
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="", help="comma-separated case names (default: all)")
    ap.add_argument("--no-run", action="store_true", help="only rebuild the table from the runs there")
    ap.add_argument("--list", action="store_true", help="list the cases")
    ap.add_argument("--step", type=int, default=None, help="the figures at this output step (default: the last)")
    a = ap.parse_args()
    if a.list:
        print("\n".join(CASES))
        return 0
    names = [n for n in a.cases.split(",") if n] or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"fault_convergence.py: --cases: unknown case(s) {', '.join(unknown)} (--list lists them)")
        return 1
    if not a.no_run:
        for n in names:
            run(n)
    text = table(names, a.step)
    if all(os.path.exists(os.path.join(RUNS, c, "fields.h5")) for c in ("slab-h4-glued", "3d-f2-glued")):
        text += "\n\nplane strain (glued fault, slab-h4-glued against 3d-f2-glued): " + ", ".join(
            f"{k} {v:.4g}" for k, v in surface_profiles().items())
    print(text)
    os.makedirs(RUNS, exist_ok=True)
    with open(os.path.join(RUNS, "table.md" if a.step is None else f"table_step{a.step}.md"), "w") as f:
        f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

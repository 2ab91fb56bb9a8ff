"""Mesh convergence of calibrated Queretaro's fault answer (config/queretaro_calibrated.opts) and controlled variants
that each change one thing, to find why the slip potency shrinks with the mesh.

    .venv/bin/python benchmarks/queretaro_convergence.py [--cases NAME,...] [--no-run] [--list]

Each case (by default those docs/verification.md gives) runs the scene on 2 ranks (one run at a time) into
runs/queretaro_convergence/<case>/ at size factor 6, 4, 3 or 2, the scene itself also at 1 (the paper's mesh, about
70 s) and 0.5 (1.37 million unknowns, 24 min), iso also at 1.5 (9 min) and 1 (the case's name ends in -sf<F>); then
one table of year 10 is printed and written to runs/queretaro_convergence/table.md, with the measures of
studies/fault_convergence.py (fault.h5 and summary.json) as totals over the fault (m^3, m^2; the fault is 30 km
long), the depth of the deepest slipping face, and the median shear traction of the top row of faces (those
touching the land surface, within 5 km along the fault of the wells' middle) and its ratio to their effective
normal traction (above tan 30 = 0.577 in a glued run: the row would slip).

The variants (one change each, applied in the child process where it is not an option):
``base``: the scene as it is. The mesh: ``lat4``: the element size along and across the fault a quarter of the
scene's (-pfault_queretaro_fault_size 13 instead of 52 m at size factor 1; the layers unchanged); ``vert4``: layers
a quarter as thick (pfault.mesh.geometry._QRO_DZ; the lateral sizes unchanged); ``iso``: the size at the fault equal
to the layer thickness (-pfault_queretaro_fault_size 7.142857, 50/7 m: elements about as wide as high beside the
fault); ``iso-vert2``, ``iso-vert4``, ``iso-vert8``: iso's width with layers a half, a quarter and an eighth as thick
(the top row of fault faces thinner at the same width); ``lat13-top0.9``, ``iso-top0.9``, ``lat5-top0.9``: the
layers graded towards the land surface by -pfault_queretaro_surface_size 0.9 (1.8 m top rows at size factor 2,
growing with depth to the layers' height) at widths 13, 50/7, 5, 3.5 and 2.5 m, ``iso-top1.8``, ``iso-top0.45``: iso with 3.6
and 0.9 m top rows at size factor 2 (the scene's options; no patch). The initial state:
``litho``: the initial stress of flat layers (sigma_v = -rho g depth of each cell's own material, the scene's K0
rule) instead of the elastic gravity solve's sigma_v, which beside the fault carries the soft sediment hung on the
rock; ``k01``: K0 = 1. The pore pressure: ``rockdry``: no pore-pressure change in the rock (the flow model's head
is continuous across the fault, so the rock cells touching it take part of the aquifer's drawdown); ``claydry``: none
in the clay; ``dry500``: none within 500 m of the fault (rock and sediment). The contact: ``frac0.1``,
``frac0.001``: the former traction-jump stabilisation at that share of the compliance estimate (measured before the
face bubbles replaced it; their rows in docs/verification.md stay as measured); ``penalty``: penalty faces
at their default stiffness; ``glued``: cohesion 1e4 MPa (no face slips: the shear the fault is asked to carry);
``glued-lat4``: glued and lat4.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUNS = os.path.join(ROOT, "runs", "queretaro_convergence")
SCENE = os.path.join(ROOT, "config", "queretaro_calibrated.opts")
QUIET = ["-pfault_figures", "false"]
FACTORS = ("6", "4", "3", "2")
WELLS_Y = 15000.0       # the wells' mid y (m)
CLAY = 20.0             # the clay's thickness (m)
ROCK_X = 10000.0        # the fault plane; rock for x < ROCK_X (pfault.mesh.geometry.QUERETARO_DEFAULTS)
VARIANTS = {
    "base": ([], {}),
    "litho": ([], {"litho": True}),
    "rockdry": ([], {"rockdry": True}),
    "claydry": ([], {"claydry": True}),
    "dry500": ([], {"dry500": True}),
    "lat4": (["-pfault_queretaro_fault_size", "13"], {}),
    "vert4": ([], {"vertical": 0.25}),
    "iso": (["-pfault_queretaro_fault_size", "7.142857"], {}),
    "iso-vert2": (["-pfault_queretaro_fault_size", "7.142857"], {"vertical": 0.5}),
    "iso-vert4": (["-pfault_queretaro_fault_size", "7.142857"], {"vertical": 0.25}),
    "iso-vert8": (["-pfault_queretaro_fault_size", "7.142857"], {"vertical": 0.125}),
    "lat13-top0.9": (["-pfault_queretaro_fault_size", "13", "-pfault_queretaro_surface_size", "0.9"], {}),
    "iso-top0.9": (["-pfault_queretaro_fault_size", "7.142857", "-pfault_queretaro_surface_size", "0.9"], {}),
    "iso-top1.8": (["-pfault_queretaro_fault_size", "7.142857", "-pfault_queretaro_surface_size", "1.8"], {}),
    "lat5-top0.9": (["-pfault_queretaro_fault_size", "5", "-pfault_queretaro_surface_size", "0.9"], {}),
    "lat3.5-top0.9": (["-pfault_queretaro_fault_size", "3.5", "-pfault_queretaro_surface_size", "0.9"], {}),
    "lat2.5-top0.9": (["-pfault_queretaro_fault_size", "2.5", "-pfault_queretaro_surface_size", "0.9"], {}),
    # width and top rows halved together (28.6 / 14.3 / 7.1 m wide, 3.6 / 1.8 / 0.9 m rows at size factor 2)
    "lat14.3-top1.8": (["-pfault_queretaro_fault_size", "14.285714", "-pfault_queretaro_surface_size", "1.8"], {}),
    "lat3.6-top0.45": (["-pfault_queretaro_fault_size", "3.571429", "-pfault_queretaro_surface_size", "0.45"], {}),
    "iso-top0.45": (["-pfault_queretaro_fault_size", "7.142857", "-pfault_queretaro_surface_size", "0.45"], {}),
    "penalty": (["-pfault_fault_fault_method", "penalty"], {}),
    "k01": (["-pfault_geostatic_k0", "1"], {}),
    "glued": (["-pfault_fault_fault_cohesion", "1e4*MPa"], {}),
    "glued-lat4": (["-pfault_fault_fault_cohesion", "1e4*MPa", "-pfault_queretaro_fault_size", "13"], {}),
}
CASES = {f"{v}-sf{f}": (f, opts, patch) for v, (opts, patch) in VARIANTS.items() for f in FACTORS}
# finer: the scene itself at the size factors of the paper's mesh and half of it, iso down to 7.1 m
CASES.update({f"{v}-sf{f}": (f, *VARIANTS[v]) for v, fs in (("base", ("1", "0.5")), ("iso", ("1.5", "1")))
              for f in fs})
# the cases of docs/verification.md (the default): every variant at the size factors its row gives
STUDY = ([f"{v}-sf{f}" for v in ("base", "litho", "rockdry", "claydry", "dry500", "iso", "glued") for f in FACTORS]
         + [f"{v}-sf{f}" for v in ("lat4", "vert4", "glued-lat4") for f in ("6", "4")]
         + [f"{v}-sf{f}" for v in ("penalty", "k01") for f in ("4", "2")]
         + ["base-sf1", "base-sf0.5", "iso-sf1.5", "iso-vert2-sf2", "iso-vert4-sf2", "iso-vert8-sf2"]
         + [f"{v}-sf2" for v in ("lat13-top0.9", "iso-top1.8", "iso-top0.9", "iso-top0.45", "lat5-top0.9",
                                  "lat3.5-top0.9", "lat2.5-top0.9", "lat14.3-top1.8", "lat3.6-top0.45")])


def run(name):
    f, opts, patch = CASES[name]
    out = os.path.join(RUNS, name)
    os.makedirs(out, exist_ok=True)
    cmd = ["mpirun", "-n", "2", sys.executable, os.path.join(ROOT, "benchmarks", "queretaro_convergence.py"),
           "--child", json.dumps(patch), SCENE, "-pfault_mesh_size_factor", f, "-pfault_output_dir", out,
           *QUIET, *opts]
    from studies.fault_convergence import run_logged
    run_logged(name, cmd, out)


def child(patch, argv):
    """Run pfault in this process with the variant's patches, applied once petsc4py.init has read the options
    (pfault's modules import PETSc)."""
    import petsc4py
    init = petsc4py.init

    def init_then_patch(*args, **kwargs):
        init(*args, **kwargs)
        _patch(patch)
    petsc4py.init = init_then_patch
    from pfault.__main__ import run as pfault_run
    return pfault_run([sys.argv[0], *argv])


def _patch(patch):
    if patch.get("vertical"):
        from pfault.mesh import geometry
        geometry._QRO_DZ *= patch["vertical"]
    if patch.get("rockdry") or patch.get("claydry") or patch.get("dry500"):
        from pfault.solver import flow
        cell_dp = flow.GroundwaterFlow.cell_dp

        def without(self):
            dp = cell_dp(self)
            mesh = self.grid.mesh
            c = mesh.coords[mesh.cells].mean(axis=1)
            if patch.get("rockdry"):
                dry = c[:, 0] < ROCK_X
            elif patch.get("claydry"):
                dry = (c[:, 0] > ROCK_X) & (c[:, 2] > -CLAY)
            else:
                dry = c[:, 0] < ROCK_X + 500.0
            return np.where(dry, 0.0, dp)
        flow.GroundwaterFlow.cell_dp = without
    if patch.get("litho"):
        from pfault.solver import equations
        original = equations.Equations.geostatic_stress

        def flat_layers(self, u_gravity_local):
            sig = original(self, u_gravity_local)
            s = self.settings
            depth = np.maximum(-self.asm.centroids[:, 2], 0.0)
            p0 = s.water_density * s.gravity * np.maximum(s.water_table - self.asm.centroids[:, 2], 0.0)
            alpha = self.asm.alpha
            nu = self.asm.lam / (2 * (self.asm.lam + self.asm.mu))
            k0 = np.full(len(depth), s.k0) if s.k0 >= 0 else nu / (1 - nu)
            sv = -self.asm.density * s.gravity * depth
            sig[:, 2, 2] = sv
            sig[:, 0, 0] = sig[:, 1, 1] = k0 * (sv + alpha * p0) - alpha * p0
            return sig
        equations.Equations.geostatic_stress = flat_layers


def measures(out):
    """Year-10 figures of a run as totals over the fault, or None without fault output."""
    import h5py
    sys.path.insert(0, ROOT)
    from studies.fault_convergence import measures as per_metre
    m = per_metre(out)
    if m is None:
        return None
    with h5py.File(os.path.join(out, "fault.h5"), "r") as f:
        pts, cells = f["mesh/points"][()], f["mesh/cells"][()]
        s = f["steps"][sorted(f["steps"].keys())[-1]]
        state = s["state"][()].astype(int)
        shear = np.linalg.norm(s["traction_shear"][()], axis=1)
        normal = s["traction_normal_effective"][()]
    strike = float(np.ptp(pts[:, 1]))
    for k in ("potency", "potency_moving", "open_volume", "slip_length", "open_length", "potency_top10m"):
        m[k] *= strike
    x = pts[cells]
    m["row_depth"] = float(np.median(np.ptp(x[:, :, 2], axis=1)))
    # the row of faces under the land surface, along the 10 km of fault beside the wells (y = 12..18 km)
    top = (x[:, :, 2].max(axis=1) > -1e-6) & (np.abs(x[:, :, 1].mean(axis=1) - WELLS_Y) < 5000.0)
    m["top_shear"] = float(np.median(shear[top]))
    m["top_ratio"] = float(np.median(shear[top] / np.maximum(np.abs(normal[top]), 1.0)))
    m["slip_depth"] = float(-x[state > 0][:, :, 2].min()) if np.any(state > 0) else 0.0
    return m


COLUMNS = [("faces", "fault faces", "{:d}"), ("row_depth", "face height m", "{:.3g}"),
           ("newton_worst", "Newton (worst step)", "{:d}"), ("potency", "potency m^3", "{:.4g}"),
           ("potency_moving", "of slipping/open faces", "{:.4g}"),
           ("potency_top10m", "of faces above 10 m", "{:.4g}"), ("slip_length", "slipping area m^2", "{:.4g}"),
           ("open_length", "open area m^2", "{:.3g}"),
           ("open_volume", "open volume m^3", "{:.4g}"), ("slip_depth", "deepest slipping face m", "{:.3g}"),
           ("top_shear", "top row shear traction Pa (median)", "{:.3g}"),
           ("top_ratio", "top row shear / effective normal (median)", "{:.3g}"),
           ("max_slip_moving", "max slip m", "{:.4g}"), ("max_opening_open", "max opening m", "{:.3g}"),
           ("max_subsidence", "max subsidence m", "{:.4g}")]


def table(names):
    lines = ["| case | " + " | ".join(c[1] for c in COLUMNS) + " |", "|" + "---|" * (len(COLUMNS) + 1)]
    for name in names:
        m = measures(os.path.join(RUNS, name))
        if m is None:
            lines.append(f"| {name} | (no run) |")
            continue
        status = "" if m["converged"] else " (NOT CONVERGED)"
        lines.append(f"| {name}{status} | " + " | ".join(fmt.format(m[k]) for k, _, fmt in COLUMNS) + " |")
    return "\n".join(lines)


def main():
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        return child(json.loads(sys.argv[2]), sys.argv[3:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="", help="comma-separated case names (default: those of "
                    "docs/verification.md; --list lists them all)")
    ap.add_argument("--no-run", action="store_true", help="only rebuild the table from the runs there")
    ap.add_argument("--list", action="store_true", help="list the cases")
    a = ap.parse_args()
    if a.list:
        print("\n".join(CASES))
        return 0
    names = [n for n in a.cases.split(",") if n] or STUDY
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"queretaro_convergence.py: --cases: unknown case(s) {', '.join(unknown)} (--list lists them)")
        return 1
    if not a.no_run:
        for n in names:
            run(n)
    text = table(names)
    print(text)
    os.makedirs(RUNS, exist_ok=True)
    with open(os.path.join(RUNS, "table.md"), "w") as fh:
        fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, ROOT)
    sys.exit(main())

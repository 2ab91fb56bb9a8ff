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

The variants (one change each, every one an option of pfault's given on the command line):
``base``: the scene as it is. The mesh: ``lat4``: the element size along and across the fault a quarter of the
scene's (-pfault_queretaro_fault_size 13 instead of 52 m at size factor 1; the layers unchanged); ``vert4``: layers
a quarter as thick (-pfault_queretaro_layer_thickness 50/28 m instead of 50/7; the lateral sizes unchanged); ``iso``:
the size at the fault equal to the layer thickness (-pfault_queretaro_fault_size 7.142857, 50/7 m: elements about as
wide as high beside the fault); ``iso-vert2``, ``iso-vert4``, ``iso-vert8``: iso's width with layers a half, a
quarter and an eighth as thick (the top row of fault faces thinner at the same width); ``lat13-top0.9``,
``iso-top0.9``, ``lat5-top0.9``: the layers graded towards the land surface by -pfault_queretaro_surface_size 0.9
(1.8 m top rows at size factor 2, growing with depth to the layers' height) at widths 13, 50/7, 5, 3.5 and 2.5 m,
``iso-top1.8``, ``iso-top0.45``: iso with 3.6 and 0.9 m top rows at size factor 2. The initial state: ``litho``: the
lithostatic initial stress (-pfault_geostatic_stress lithostatic: sigma_v the weight of the column above each cell,
the scene's K0 rule) instead of the elastic gravity solve's sigma_v, which beside the fault carries the soft sediment
hung on the rock (every column of this scene has one density over its depth, rock 2600 or clay and sand 1960
kg/m^3, so this is the -rho g depth of each cell's own material the variant was first measured with); ``k01``:
K0 = 1. The pore pressure: ``rockdry``: no pore-pressure change in the rock (-pfault_pore_pressure_unchanged_materials
rock; the flow model's head is continuous across the fault, so the rock cells touching it take part of the aquifer's
drawdown); ``claydry``: none in the clay (a clay the wells do not drain). The variant without pore-pressure change
within 500 m of the fault (rock and sediment, ``dry500``) is gone: no physical situation a user would choose has the
aquifer drained everywhere but in a band beside the fault, and pfault has no option for it; its row in
docs/verification.md (no face slid at any size) was measured when the study replaced pfault's functions in the run.
The contact: ``frac0.1``, ``frac0.001``: the former traction-jump stabilisation at that share of the compliance
estimate (measured before the face bubbles replaced it; their rows in docs/verification.md stay as measured);
``penalty``: penalty faces at their default stiffness; ``glued``: cohesion 1e4 MPa (no face slips: the shear the
fault is asked to carry); ``glued-lat4``: glued and lat4.
"""

from __future__ import annotations

import argparse
import os
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from studies.fault_convergence import measures as per_metre, run_case  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUNS = os.path.join(ROOT, "runs", "queretaro_convergence")
SCENE = os.path.join(ROOT, "config", "queretaro_calibrated.opts")
QUIET = ["-pfault_figures", "false"]
FACTORS = ("6", "4", "3", "2")
WELLS_Y = 15000.0       # the wells' mid y (m)


def layers(fraction):
    """The mesh's layers ``fraction`` as thick as the scene's 50/7 m (size factor 1)."""
    return ["-pfault_queretaro_layer_thickness", repr(50.0 / 7.0 * fraction)]


ISO = ["-pfault_queretaro_fault_size", "7.142857"]
VARIANTS = {
    "base": [],
    "litho": ["-pfault_geostatic_stress", "lithostatic"],
    "rockdry": ["-pfault_pore_pressure_unchanged_materials", "rock"],
    "claydry": ["-pfault_pore_pressure_unchanged_materials", "clay"],
    "lat4": ["-pfault_queretaro_fault_size", "13"],
    "vert4": layers(0.25),
    "iso": ISO,
    "iso-vert2": ISO + layers(0.5),
    "iso-vert4": ISO + layers(0.25),
    "iso-vert8": ISO + layers(0.125),
    "lat13-top0.9": ["-pfault_queretaro_fault_size", "13", "-pfault_queretaro_surface_size", "0.9"],
    "iso-top0.9": ISO + ["-pfault_queretaro_surface_size", "0.9"],
    "iso-top1.8": ISO + ["-pfault_queretaro_surface_size", "1.8"],
    "lat5-top0.9": ["-pfault_queretaro_fault_size", "5", "-pfault_queretaro_surface_size", "0.9"],
    "lat3.5-top0.9": ["-pfault_queretaro_fault_size", "3.5", "-pfault_queretaro_surface_size", "0.9"],
    "lat2.5-top0.9": ["-pfault_queretaro_fault_size", "2.5", "-pfault_queretaro_surface_size", "0.9"],
    # width and top rows halved together (28.6 / 14.3 / 7.1 m wide, 3.6 / 1.8 / 0.9 m rows at size factor 2)
    "lat14.3-top1.8": ["-pfault_queretaro_fault_size", "14.285714", "-pfault_queretaro_surface_size", "1.8"],
    "lat3.6-top0.45": ["-pfault_queretaro_fault_size", "3.571429", "-pfault_queretaro_surface_size", "0.45"],
    "iso-top0.45": ISO + ["-pfault_queretaro_surface_size", "0.45"],
    "penalty": ["-pfault_fault_fault_method", "penalty"],
    "k01": ["-pfault_geostatic_k0", "1"],
    "glued": ["-pfault_fault_fault_cohesion", "1e4*MPa"],
    "glued-lat4": ["-pfault_fault_fault_cohesion", "1e4*MPa", "-pfault_queretaro_fault_size", "13"],
}
CASES = {f"{v}-sf{f}": (f, opts) for v, opts in VARIANTS.items() for f in FACTORS}
# finer: the scene itself at the size factors of the paper's mesh and half of it, iso down to 7.1 m
CASES.update({f"{v}-sf{f}": (f, VARIANTS[v]) for v, fs in (("base", ("1", "0.5")), ("iso", ("1.5", "1")))
              for f in fs})
# the cases of docs/verification.md (the default): every variant at the size factors its row gives
STUDY = ([f"{v}-sf{f}" for v in ("base", "litho", "rockdry", "claydry", "iso", "glued") for f in FACTORS]
         + [f"{v}-sf{f}" for v in ("lat4", "vert4", "glued-lat4") for f in ("6", "4")]
         + [f"{v}-sf{f}" for v in ("penalty", "k01") for f in ("4", "2")]
         + ["base-sf1", "base-sf0.5", "iso-sf1.5", "iso-vert2-sf2", "iso-vert4-sf2", "iso-vert8-sf2"]
         + [f"{v}-sf2" for v in ("lat13-top0.9", "iso-top1.8", "iso-top0.9", "iso-top0.45", "lat5-top0.9",
                                  "lat3.5-top0.9", "lat2.5-top0.9", "lat14.3-top1.8", "lat3.6-top0.45")])


def run(name):
    """The case's run on 2 ranks: the scene at its size factor with its variant's options."""
    f, opts = CASES[name]
    out = os.path.join(RUNS, name)
    os.makedirs(out, exist_ok=True)
    run_case(name, ["-m", "pfault", SCENE, "-pfault_mesh_size_factor", f, "-pfault_output_dir", out, *QUIET, *opts],
             2, out)


def measures(out):
    """Year-10 figures of a run as totals over the fault, or None without fault output."""
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
    sys.exit(main())

"""The stress of the cells beside a fault with and without the face bubbles' strain: a fault held closed and stuck
(cohesion 1e12 Pa, "glued") against the same mesh without the fault.

    .venv/bin/python studies/bubble_stress.py [--cases NAME,...] [--baseline DIR] [--out DIR]

Each case runs its scene twice, one rank each, into ``--out`` (default runs/bubble_stress/): with the fault glued
and with the fault's options dropped (the box mesher puts the same tetrahedra on both sides of a fault plane
that lies on its grid), and prints for the last output step, over the cells with a face on the fault, the largest
difference of the written stress (fields.h5) between the two runs, absolute and relative to the largest stress of
those cells, and the same over all other cells. ``--baseline DIR``: the same runs with the pfault package found in
DIR (a checkout, e.g. ``git archive`` of an earlier commit) for the faulted run, to set the stress of the P1 part
alone beside the stress with the bubbles' strain. One JSON line per case at the end. ``--wuxi F``: Wuxi at size
factor F with this pfault and with ``--baseline``'s, and the largest change of the written stress (initial and
last output step, beside the fault and elsewhere) with both runs' Newton iterations and fault maxima.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from pfault.tools.runs import environment, run_captured  # noqa: E402
from studies import REPO  # noqa: E402

GLUE = "1e12"       # Pa of cohesion: no face slips or opens
CASES = {
    # the two blocks pressed and sheared: a uniform stress state, which P1 represents exactly
    "two_blocks": ("config/two_blocks.opts", "fault", []),
    # the fissure box in one year of drawdown: stress that varies in every cell
    "fissure_box": ("config/hard/fissure_box.opts", "fissure", ["-pfault_time_end", "1*year",
                                                                "-pfault_time_steps", "1"]),
    "fissure_box_h2": ("config/hard/fissure_box.opts", "fissure", ["-pfault_time_end", "1*year",
                                                                   "-pfault_time_steps", "1",
                                                                   "-pfault_box_cells", "32,16,20"]),
}


def unfaulted(scene: str, out: str) -> str:
    """The scene without its fault: its lines of -pfault_box_fault_planes, -pfault_faults, -pfault_fault_* dropped
    (written into ``out``)."""
    keep = [line for line in open(os.path.join(REPO, scene)).read().splitlines()
            if not line.split("#")[0].strip().startswith(("-pfault_box_fault_planes", "-pfault_faults",
                                                          "-pfault_fault_"))]
    path = os.path.join(out, "unfaulted.opts")
    with open(path, "w") as f:
        f.write("\n".join(keep) + "\n")
    return path


def run(scene: str, outdir: str, extra: list, pythonpath: str | None = None) -> None:
    args = ["-m", "pfault", os.path.join(REPO, scene), "-pfault_output_dir", outdir, "-pfault_figures", "false",
            *extra]
    if pythonpath:
        # python -m puts the working directory first on the import path: run from the other checkout
        env = environment()
        env["PYTHONPATH"] = os.pathsep.join([pythonpath, env["PYTHONPATH"]])
        proc = run_captured(args, 1, cwd=pythonpath, env=env, timeout=1200)
    else:
        proc = run_captured(args, 1, timeout=1200, cwd=REPO)
    if proc.returncode != 0:
        raise SystemExit(f"{scene} {' '.join(extra)}: exit {proc.returncode}\n{proc.stdout[-2000:]}"
                         f"{proc.stderr[-2000:]}")


def last_stress(outdir: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cell centroids, stress (n, 9), cell vertex coordinates (n, 4, 3)) of the last output step."""
    import h5py
    with h5py.File(os.path.join(outdir, "fields.h5"), "r") as f:
        pts, cells = f["mesh/points"][...], f["mesh/cells"][...]
        sig = f["steps"][sorted(f["steps"])[-1]]["stress"][...]
    x = pts[cells]
    return x.mean(axis=1), sig, x


def fault_cells(outdir: str, x: np.ndarray) -> np.ndarray:
    """Mask of the cells (vertex coordinates x (n, 4, 3)) with a face on a fault face of fault.h5."""
    import h5py
    with h5py.File(os.path.join(outdir, "fault.h5"), "r") as f:
        tri = f["mesh/points"][...][f["mesh/cells"][...]]
    key = lambda p: tuple(np.round(np.sort(p.reshape(-1, 3), axis=0).ravel(), 6))  # noqa: E731
    faces = {key(t) for t in tri}
    out = np.zeros(len(x), bool)
    for i, c in enumerate(x):
        out[i] = any(key(c[[a for a in range(4) if a != k]]) in faces for k in range(4))
    return out


def compare(faulted: str, plain: str) -> dict:
    cf, sf, xf = last_stress(faulted)
    cp, sp, _ = last_stress(plain)
    order_f, order_p = np.lexsort(cf.T[::-1]), np.lexsort(cp.T[::-1])
    if len(cf) != len(cp) or np.abs(cf[order_f] - cp[order_p]).max() > 1e-9 * np.abs(cf).max():
        raise SystemExit(f"{faulted} and {plain}: not the same cells")
    sf, sp, beside = sf[order_f], sp[order_p], fault_cells(faulted, xf)[order_f]
    d = np.abs(sf - sp).max(axis=1)
    scale = np.abs(sp[beside]).max()
    return {"cells_beside": int(beside.sum()), "max_stress_beside_Pa": float(scale),
            "max_diff_beside_Pa": float(d[beside].max()), "rel_diff_beside": float(d[beside].max() / scale),
            "max_diff_elsewhere_Pa": float(d[~beside].max()) if np.any(~beside) else 0.0}


def change(new: str, old: str) -> dict:
    """The largest change of the written stress from run ``old`` to run ``new`` (the same scene and mesh), at the
    initial output step (the geostatic initial stress) and at the last, beside the fault and elsewhere; and the
    summaries' Newton iterations and fault maxima."""
    import h5py
    out = {}
    for label, pick in (("initial", lambda k: k[0]), ("last", lambda k: k[-1])):
        sig, beside = [], None
        for d in (new, old):
            with h5py.File(os.path.join(d, "fields.h5"), "r") as f:
                pts, cells = f["mesh/points"][...], f["mesh/cells"][...]
                sig.append(f["steps"][pick(sorted(f["steps"]))]["stress"][...])
            if beside is None:
                beside = fault_cells(d, pts[cells])
        d = np.abs(sig[0] - sig[1]).max(axis=1)
        out[label] = {"max_change_beside_Pa": float(d[beside].max()),
                      "max_stress_beside_Pa": float(np.abs(sig[1][beside]).max()),
                      "max_change_elsewhere_Pa": float(d[~beside].max()), "cells_beside": int(beside.sum())}
    for tag, d in (("new", new), ("old", old)):
        s = json.load(open(os.path.join(d, "summary.json")))
        out[tag] = {"newton": [st["newton_its"] for st in s["steps"]],
                    **{k: s.get(k) for k in ("max_fault_opening_m", "max_fault_slip_m", "max_subsidence_m")}}
    return out


def wuxi(out: str, baseline: str, size_factor: str) -> dict:
    """Wuxi at ``size_factor`` with this pfault and with the one in ``baseline``, one rank each."""
    extra = ["-pfault_mesh_size_factor", size_factor]
    run("config/wuxi.opts", os.path.join(out, "new"), extra)
    run("config/wuxi.opts", os.path.join(out, "old"), extra, pythonpath=baseline)
    return change(os.path.join(out, "new"), os.path.join(out, "old"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="two_blocks,fissure_box")
    ap.add_argument("--baseline", default=None)
    ap.add_argument("--out", default=os.path.join(REPO, "runs", "bubble_stress"))
    ap.add_argument("--wuxi", default=None, metavar="SIZE_FACTOR", help="Wuxi at this size factor against "
                    "--baseline (the change of the written stress) instead of the cases")
    a = ap.parse_args()
    if a.wuxi:
        if not a.baseline:
            raise SystemExit("--wuxi needs --baseline DIR")
        print(json.dumps(wuxi(os.path.join(a.out, f"wuxi_sf{a.wuxi}"), a.baseline, a.wuxi)))
        return
    results = {}
    for name in a.cases.split(","):
        scene, fault, extra = CASES[name]
        out = os.path.join(a.out, name)
        os.makedirs(out, exist_ok=True)
        glued = extra + [f"-pfault_fault_{fault}_cohesion", GLUE]
        run(scene, os.path.join(out, "glued"), glued)
        run(unfaulted(scene, out), os.path.join(out, "plain"), extra)
        r = {"bubbles": compare(os.path.join(out, "glued"), os.path.join(out, "plain"))}
        if a.baseline:
            run(scene, os.path.join(out, "glued-baseline"), glued, pythonpath=a.baseline)
            r["baseline"] = compare(os.path.join(out, "glued-baseline"), os.path.join(out, "plain"))
            # what the bubbles' strain adds to the glued run's stress
            r["bubble_part"] = change(os.path.join(out, "glued"), os.path.join(out, "glued-baseline"))["last"]
        results[name] = r
        print(name, json.dumps(r), flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()

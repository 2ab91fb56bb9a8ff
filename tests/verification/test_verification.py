"""Verification: manufactured-solution convergence rates and a patch test on an unstructured gmsh mesh."""

import numpy as np
import pytest

from conftest import read_last_step, run_scene, run_script


@pytest.mark.parametrize("ranks", [1, 2])
def test_mms_convergence_rates(ranks):
    res = run_script("mms.py", ranks=ranks, args=["6", "12", "24"])
    h, l2, h1 = map(np.array, (res["h"], res["l2"], res["h1"]))
    rate_l2 = np.log(l2[:-1] / l2[1:]) / np.log(h[:-1] / h[1:])
    rate_h1 = np.log(h1[:-1] / h1[1:]) / np.log(h[:-1] / h[1:])
    # P1: second order in L2, first in H1 (two-sided: too good a rate is a bug as well)
    assert 1.85 < rate_l2[-1] < 2.15, rate_l2
    assert 0.9 < rate_h1[-1] < 1.1, rate_h1
    # absolute bound: amplitude |c| ~ 1e-2 m; measured 4.26e-5 m at h = 1/24
    assert 3e-5 < l2[-1] < 5e-5


def test_mms_same_on_two_ranks():
    a = run_script("mms.py", ranks=1, args=["4", "8"])
    b = run_script("mms.py", ranks=2, args=["4", "8"])
    assert np.allclose(a["l2"], b["l2"], rtol=1e-10)


def make_patch_mesh(path):
    """Unstructured tetrahedral box 0..3 x 0..2 x -1..0 with named physical volume and surfaces."""
    import gmsh
    gmsh.initialize(["pfault-test"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("patch")
    gmsh.model.occ.addBox(0, 0, -1, 3, 2, 1)
    gmsh.model.occ.synchronize()
    gmsh.model.addPhysicalGroup(3, [1], name="soil")
    for s in gmsh.model.getEntities(2):
        c = gmsh.model.occ.getCenterOfMass(*s)
        name = ("xmin" if abs(c[0]) < 1e-9 else "xmax" if abs(c[0] - 3) < 1e-9 else
                "ymin" if abs(c[1]) < 1e-9 else "ymax" if abs(c[1] - 2) < 1e-9 else
                "bottom" if abs(c[2] + 1) < 1e-9 else "top")
        gmsh.model.addPhysicalGroup(2, [s[1]], name=name)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.45)
    gmsh.model.mesh.generate(3)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.write(str(path))
    gmsh.finalize()


PATCH = {"E": 10e6, "nu": 0.25, "alpha": 0.8, "dp": -5e4, "sx": -2e4, "sy": 1e4, "sz": -3e4}


def patch_options(mesh):
    p = PATCH
    return ["-pfault_mesh_file", str(mesh), "-pfault_material_soil_young_modulus", str(p["E"]),
            "-pfault_material_soil_poisson_ratio", str(p["nu"]),
            "-pfault_material_soil_biot_coefficient", str(p["alpha"]),
            "-pfault_material_soil_pressure_change", f"0:0,1:{p['dp']}",
            "-pfault_bc_xmin_type", "roller", "-pfault_bc_ymin_type", "roller", "-pfault_bc_bottom_type", "roller",
            "-pfault_bc_xmax_type", "traction", "-pfault_bc_xmax_traction", f"{p['sx']},0,0",
            "-pfault_bc_ymax_type", "traction", "-pfault_bc_ymax_traction", f"0,{p['sy']},0",
            "-pfault_bc_top_type", "traction", "-pfault_bc_top_traction", f"0,0,{p['sz']}",
            "-pfault_time_end", "1", "-pfault_time_steps", "1", "-pfault_solver", "mumps"]


def patch_exact(points):
    p = PATCH
    lam = p["E"] * p["nu"] / ((1 + p["nu"]) * (1 - 2 * p["nu"]))
    mu = p["E"] / (2 * (1 + p["nu"]))
    s_eff = np.array([p["sx"], p["sy"], p["sz"]]) + p["alpha"] * p["dp"]
    # invert sigma = lam tr(eps) I + 2 mu eps for a diagonal state
    tr = s_eff.sum() / (3 * lam + 2 * mu)
    eps = (s_eff - lam * tr) / (2 * mu)
    return np.column_stack([eps[0] * points[:, 0], eps[1] * points[:, 1], eps[2] * (points[:, 2] + 1.0)])


@pytest.fixture(scope="module")
def patch_mesh(tmp_path_factory):
    path = tmp_path_factory.mktemp("patch") / "box.msh"
    make_patch_mesh(path)
    return path


@pytest.mark.parametrize("ranks", [1, 2])
def test_patch_test_unstructured(tmp_path, patch_mesh, ranks):
    """Uniform stress (tractions + pore pressure) on an unstructured mesh: P1 is exact to round-off."""
    _, summary = run_scene_plain(tmp_path, patch_mesh, ranks)
    assert summary["converged"]
    points, _, pd, cd = read_last_step(tmp_path / "out")
    u = pd["displacement"]
    exact = patch_exact(points)
    assert np.max(np.abs(u - exact)) < 1e-10 * np.max(np.abs(exact))
    # total stress is the applied one in every cell
    stress = cd["stress"][0].reshape(-1, 3, 3)
    expected = np.diag([PATCH["sx"], PATCH["sy"], PATCH["sz"]])
    assert np.max(np.abs(stress - expected)) < 1e-8 * 3e4


def run_scene_plain(tmp_path, mesh, ranks):
    scene = tmp_path / "patch.opts"
    scene.write_text("# patch test scene\n-pfault_scene patch\n")
    return run_scene(str(scene), tmp_path / "out", ranks=ranks, extra=patch_options(mesh))

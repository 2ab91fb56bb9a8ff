"""Material properties from spatial fields: the oedometer column with a modulus that varies with depth.

Under a uniform drawdown dp a laterally confined column settles by |dp| alpha int_0^H dz / M(z), with M = E
(1-nu)/((1+nu)(1-2nu)) the oedometric modulus.
- Layers whose interfaces are element layers (a 1-D grid in z, a 3-D grid in x, y, z): sum_i |dp| h_i / M_i,
  which P1 reproduces to round-off (the exact displacement is piecewise linear in z).
- A modulus linear in depth: |dp| H ln(M_b/M_t) / (M_b - M_t). Each cell takes the modulus at its centroid, so the
  six tetrahedra of a hexahedron layer differ by O(h): the mean settlement of the top converges at rate 2, its
  largest value at rate 1 (the top tilts by O(h) in a one-cell-wide column).
"""

import math

import h5py
import numpy as np
import pytest

from conftest import OEDOMETER, TWO_BLOCKS, compare_runs, read_last_step, run_scene, write_flow_box
from pfault.materials.field_files import read_field

SITE = "config/site_example/site.opts"

NU, DP, H = 0.25, 0.1e6, 100.0
OED_FACTOR = (1 - NU) / ((1 + NU) * (1 - 2 * NU))          # M / E = 1.2
LAYERS = [(0.0, -40.0, 5e6), (-40.0, -70.0, 20e6), (-70.0, -100.0, 10e6)]   # top, bottom, E
LAYERED = DP * sum((top - bottom) / (OED_FACTOR * e) for top, bottom, e in LAYERS)
E_TOP, E_BOTTOM = 5e6, 25e6
LINEAR = DP * H * math.log(E_BOTTOM / E_TOP) / (OED_FACTOR * (E_BOTTOM - E_TOP))


def layered_profile():
    """z and E (MPa) of a 1-D grid constant within each layer: nodes 1 m on either side of each interface, where
    no cell centroid of a 10 m element layer falls (centroids lie 2.5 m or more from the layer's faces)."""
    z = [-100.0, -71.0, -69.0, -41.0, -39.0, 0.0]
    e = [10.0, 10.0, 20.0, 20.0, 5.0, 5.0]
    return z, e


def test_analytic_values():
    assert LAYERED == pytest.approx(1e5 * (40 / 6e6 + 30 / 24e6 + 30 / 12e6), rel=1e-14)   # 1.041667 m
    assert LINEAR == pytest.approx(0.670599, rel=1e-6)


def test_layered_column_from_a_depth_profile(tmp_path):
    z, e = layered_profile()
    path = tmp_path / "profile.csv"
    path.write_text("z,young_modulus [MPa]\n" + "".join(f"{a},{b}\n" for a, b in zip(z, e)))
    _, summary = run_scene(OEDOMETER, tmp_path / "out", extra=["-pfault_material_soil_young_modulus",
                                                               f"field:{path}", "-pfault_time_steps", "2"])
    assert abs(summary["max_subsidence_m"] - LAYERED) / LAYERED < 1e-9
    points, _, pd, _ = read_last_step(tmp_path / "out")
    uz = pd["displacement"][:, 2]
    zz = points[:, 2]
    exact = -DP * np.array([sum(max(min(top, zv) - bottom, 0.0) / (OED_FACTOR * em) for top, bottom, em in LAYERS)
                            for zv in zz])
    assert np.allclose(uz, exact, atol=1e-9 * LAYERED)


def write_cube(path):
    """The layered modulus as a 3-D grid (z, y, x), x fastest, in kPa."""
    z, e = layered_profile()
    with h5py.File(path, "w") as h5:
        h5["x"], h5["y"], h5["z"] = [-5.0, 15.0], [-5.0, 5.0, 15.0], z
        h5["E"] = np.array(e)[:, None, None] * 1e3 * np.ones((len(z), 3, 2))
        h5["E"].attrs["units"] = "kPa"
    return path


@pytest.mark.mpi
def test_layered_column_from_a_3d_grid_at_2_ranks(tmp_path):
    path = write_cube(tmp_path / "cube.h5")
    _, summary = run_scene(OEDOMETER, tmp_path / "out", ranks=2, extra=[
        "-pfault_material_soil_young_modulus", f"field:{path},variable=E", "-pfault_box_cells", "2,2,10",
        "-pfault_time_steps", "2"])
    assert summary["ranks"] == 2
    assert abs(summary["max_subsidence_m"] - LAYERED) / LAYERED < 1e-9


MAP_SCENE = """# a clay plate whose modulus follows a map E(x, y), its Poisson ratio scattered points, under a drawdown
-pfault_box_size 300,200,30
-pfault_box_cells 6,4,3
-pfault_box_materials clay
-pfault_material_clay_young_modulus field:{map}
-pfault_material_clay_poisson_ratio field:{nu},outside=nearest
-pfault_material_clay_density field:{rho}
-pfault_material_clay_pressure_change 0:0,1:-0.1*MPa
-pfault_bc_xmin_type roller
-pfault_bc_xmax_type roller
-pfault_bc_ymin_type roller
-pfault_bc_ymax_type roller
-pfault_bc_bottom_type fixed
-pfault_geostatic true
-pfault_time_end 1
-pfault_time_steps 2
-pfault_solver mumps
"""


@pytest.mark.mpi
def test_map_fields_agree_at_1_and_2_ranks(tmp_path):
    """Moduli that vary laterally move the plate sideways: every output (displacements, stresses, surface
    strains and distortion) agrees between 1 and 2 ranks to round-off, and differs from the uniform plate."""
    (tmp_path / "map.csv").write_text("x,y,E [MPa]\n" + "".join(
        f"{x},{y},{4 + 0.04 * x + 0.03 * y + 1e-4 * x * y}\n" for x in (0, 100, 300) for y in (0, 200)))
    (tmp_path / "nu.csv").write_text("x,y,nu\n0,0,0.3\n300,0,0.25\n0,200,0.35\n300,200,0.3\n150,100,0.28\n")
    (tmp_path / "rho.csv").write_text("z,density [kg/m^3]\n-30,2100\n0,1900\n")
    scene = tmp_path / "plate.opts"
    scene.write_text(MAP_SCENE.format(map=tmp_path / "map.csv", nu=tmp_path / "nu.csv", rho=tmp_path / "rho.csv"))
    runs = {}
    for ranks in (1, 2):
        _, runs[ranks] = run_scene(str(scene), tmp_path / f"r{ranks}", ranks=ranks)
    assert compare_runs(tmp_path / "r1", tmp_path / "r2", rtol=1e-9) < 1e-9
    assert runs[1]["max_horizontal_displacement_m"] > 1e-3 * runs[1]["max_subsidence_m"] > 0


def test_modulus_linear_in_depth_converges_at_rate_2(tmp_path):
    """Two-point depth profile, 10/20/40 element layers. Measured: mean top settlement error 3.7e-3, 9.7e-4,
    2.5e-4 (rates 1.93, 1.98); largest settlement 1.2e-2, 7.5e-3, 4.0e-3 (rate 0.7-0.9)."""
    path = tmp_path / "linear.csv"
    path.write_text(f"z,young_modulus\n{-H},{E_BOTTOM}\n0,{E_TOP}\n")
    errors = []
    for n in (10, 20, 40):
        out = tmp_path / f"n{n}"
        run_scene(OEDOMETER, out, extra=["-pfault_material_soil_young_modulus", f"field:{path}",
                                         "-pfault_box_cells", f"1,1,{n}", "-pfault_time_steps", "1"])
        points, _, pd, _ = read_last_step(out)
        top = np.abs(points[:, 2]) < 1e-9
        errors.append(abs(-pd["displacement"][top, 2].mean() - LINEAR) / LINEAR)
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert errors[0] < 4e-3 and errors[-1] < 3e-4, errors
    assert np.all((rates > 1.8) & (rates < 2.2)), rates


def test_uniform_fields_give_the_numbers_results(tmp_path):
    """A field that holds one value everywhere gives the run of that number: the flow model's conductivity and
    default storage (from a modulus field, per cell), and the fault's stiffness estimates (two blocks)."""
    (tmp_path / "e.csv").write_text("z,E [MPa]\n-200,10\n0,10\n")
    (tmp_path / "k.csv").write_text("x,y,K [m/day]\n-1,-1,1\n11,-1,1\n-1,11,1\n11,11,1\n")
    for name, young, k in (("numbers", "10*MPa", "1*m/day"), ("fields", f"field:{tmp_path / 'e.csv'}",
                                                               f"field:{tmp_path / 'k.csv'}")):
        run_scene(write_flow_box(tmp_path), tmp_path / f"flow_{name}",
                  extra=["-pfault_time_end", "1*day", "-pfault_time_steps", "2",
                         "-pfault_material_soil_young_modulus", young,
                         "-pfault_material_soil_hydraulic_conductivity", k])
    assert compare_runs(tmp_path / "flow_numbers", tmp_path / "flow_fields", rtol=1e-12) < 1e-12
    run_scene(TWO_BLOCKS, tmp_path / "blocks_numbers")
    (tmp_path / "e2.csv").write_text("z,E [MPa]\n-1,10\n0,10\n")
    _, summary = run_scene(TWO_BLOCKS, tmp_path / "blocks_fields",
                           extra=["-pfault_material_rock_young_modulus", f"field:{tmp_path / 'e2.csv'}"])
    # (the opening of the stuck-and-slipping faces is round-off, 2e-16 m: not compared)
    for name, keys in (("fields", ("displacement", "stress")), ("fault", ("slip", "traction_normal", "traction_shear",
                                                                          "state"))):
        with h5py.File(tmp_path / "blocks_numbers" / f"{name}.h5") as a, \
                h5py.File(tmp_path / "blocks_fields" / f"{name}.h5") as b:
            for key in keys:
                x, y = a["steps/000001"][key][()], b["steps/000001"][key][()]
                assert np.max(np.abs(x - y)) <= 1e-12 * np.max(np.abs(x)), (name, key)
    assert summary["max_fault_slip_m"] > 0.1


def test_site_example_clay_map(tmp_path):
    """config/site_example/site.opts: the clay's modulus from a map in site coordinates (4.2-7 MPa at its nodes, the
    mesh placed by -pfault_mesh_origin). Every station's settlement lies between those of the same site with the clay uniformly at
    the map's smallest and largest value, and strictly inside where the map is not at either bound."""
    field = read_field("config/site_example/site_clay_modulus.csv", "pfault_material_clay_young_modulus", "Pa")
    lo_e, hi_e = field.values.min(), field.values.max()
    assert field.is_grid and 4e6 <= lo_e < 4.5e6 and 6.8e6 < hi_e <= 7e6
    one_step = ["-pfault_time_end", "2*year", "-pfault_time_steps", "1", "-pfault_insar_los", "0,0,1"]
    settle = {}
    for name, modulus in (("map", None), ("soft", f"{lo_e:.17g}"), ("stiff", f"{hi_e:.17g}")):
        extra = one_step + ([] if modulus is None else ["-pfault_material_clay_young_modulus", modulus])
        _, summary = run_scene(SITE, tmp_path / name, extra=extra)
        assert summary["converged"]
        rows = [line.split(",") for line in (tmp_path / name / "station_displacement.csv").read_text().splitlines()[1:]]
        settle[name] = {r[0]: -float(r[4]) for r in rows if float(r[1]) > 0}
    assert set(settle["map"]) == {"WELL_BM", "GNSS_N", "GNSS_W", "EXT_30"}
    for station, w in settle["map"].items():
        assert settle["stiff"][station] < w < settle["soft"][station], (station, settle)
    # beside the well the clay is at the soft bound: much closer to the soft run than to the stiff one
    w, lo, hi = settle["map"]["WELL_BM"], settle["stiff"]["WELL_BM"], settle["soft"]["WELL_BM"]
    assert (hi - w) < 0.5 * (w - lo), (lo, w, hi)


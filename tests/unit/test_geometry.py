"""Built-in case-study meshes (pfault.mesh.geometry): materials, named surfaces, conforming faults, volumes.

Coarse size factors keep each mesh to about a second; the paper's counts at size factor 1 are checked by
benchmarks/mesh_sizes.py.
"""

import numpy as np
import pytest

from pfault.errors import InputError
from pfault.mesh import geometry
from pfault.mesh.serial import locate_faces, signed_volumes
from pfault.options import spec_for
from pfault.units import parse_list

OUTER = {"xmin", "xmax", "ymin", "ymax", "bottom", "top"}
WUXI_VOLUME = 2000.0 * 5000.0 * 250.0
QRO_VOLUME = 30000.0 * 30000.0 * 50.0


@pytest.fixture(scope="module")
def wuxi():
    return geometry.wuxi_mesh(3.0)


@pytest.fixture(scope="module")
def queretaro():
    return geometry.queretaro_mesh(3.0)


def material_volumes(mesh):
    vol = signed_volumes(mesh.points, mesh.tets)
    assert np.all(vol > 0)
    return {name: float(vol[mesh.cell_material == i].sum()) for i, name in enumerate(mesh.material_names)}


def fault_neighbours(mesh, name):
    """The two cells of every fault triangle (asserting there are exactly two)."""
    tri = mesh.surfaces[name]
    assert len(tri) > 0
    t, cell, _ = locate_faces(mesh.tets, len(mesh.points), tri)
    counts = np.bincount(t, minlength=len(tri))
    assert np.all(counts == 2), f"{np.sum(counts != 2)} fault triangles are not shared by exactly two tets"
    order = np.argsort(t, kind="stable")
    return cell[order].reshape(-1, 2)


def test_wuxi_names(wuxi):
    assert set(wuxi.material_names) == {"sand", "clay", "rock"}
    assert set(wuxi.surfaces) == OUTER | {"fissure"}
    assert all(len(tri) > 0 for tri in wuxi.surfaces.values())


def test_wuxi_fissure_is_conforming_on_its_plane(wuxi):
    cells = fault_neighbours(wuxi, "fissure")
    clay = wuxi.material_names.index("clay")
    assert np.all(wuxi.cell_material[cells] == clay)        # the crest is covered by the top clay only
    x = wuxi.points[np.unique(wuxi.surfaces["fissure"])]
    assert np.max(np.abs(x[:, 0] - 1000.0)) < 1e-6
    assert np.max(x[:, 2]) == pytest.approx(0.0, abs=1e-6)
    assert np.min(x[:, 2]) == pytest.approx(-5.0, abs=1e-6)
    assert np.min(x[:, 1]) == pytest.approx(0.0, abs=1e-6) and np.max(x[:, 1]) == pytest.approx(5000.0, abs=1e-6)
    # its bottom edge lies on the bedrock
    bottom = np.unique(wuxi.surfaces["fissure"])[x[:, 2] < -5.0 + 1e-6]
    rock_vertices = np.unique(wuxi.tets[wuxi.cell_material == wuxi.material_names.index("rock")])
    assert np.all(np.isin(bottom, rock_vertices))


def test_wuxi_volumes(wuxi):
    vols = material_volumes(wuxi)
    assert sum(vols.values()) == pytest.approx(WUXI_VOLUME, rel=1e-9)
    # rock: 150 m slab plus the triangular ridge (base 200 m, height 95 m) along 5 km
    assert vols["rock"] == pytest.approx((2000.0 * 150.0 + 0.5 * 200.0 * 95.0) * 5000.0, rel=1e-9)
    # the profile is the one documented
    rock = wuxi.tets[wuxi.cell_material == wuxi.material_names.index("rock")]
    c = wuxi.points[rock].mean(axis=1)
    assert np.all(c[:, 2] < geometry.wuxi_bedrock_top(c[:, 0]) + 1e-9)


def test_wuxi_outer_surfaces_on_their_planes(wuxi):
    for name, axis, value in (("xmin", 0, 0.0), ("xmax", 0, 2000.0), ("ymin", 1, 0.0), ("ymax", 1, 5000.0),
                              ("bottom", 2, -250.0), ("top", 2, 0.0)):
        x = wuxi.points[np.unique(wuxi.surfaces[name])]
        assert np.max(np.abs(x[:, axis] - value)) < 1e-6, name
    # top + bottom triangles cover the full plan area (the fissure does not cut the top in two)
    for name in ("top", "bottom"):
        tri = wuxi.points[wuxi.surfaces[name]]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
        assert area == pytest.approx(2000.0 * 5000.0, rel=1e-9)


def test_wuxi_parameters():
    m = geometry.wuxi_mesh(4.0, ridge_x=800.0, crest_depth=8.0, interfaces=[30.0, 60.0])
    fault_neighbours(m, "fissure")
    x = m.points[np.unique(m.surfaces["fissure"])]
    assert np.max(np.abs(x[:, 0] - 800.0)) < 1e-6
    assert np.min(x[:, 2]) == pytest.approx(-8.0, abs=1e-6)
    assert sum(material_volumes(m).values()) == pytest.approx(WUXI_VOLUME, rel=1e-9)


def test_queretaro_names(queretaro):
    assert set(queretaro.material_names) == {"sand", "clay", "rock"}
    assert set(queretaro.surfaces) == OUTER | {"fault"}
    assert all(len(tri) > 0 for tri in queretaro.surfaces.values())


def test_queretaro_fault_is_conforming_on_its_plane(queretaro):
    cells = fault_neighbours(queretaro, "fault")
    rock = queretaro.material_names.index("rock")
    assert np.all(np.sum(queretaro.cell_material[cells] == rock, axis=1) == 1)   # rock on one side only
    x = queretaro.points[np.unique(queretaro.surfaces["fault"])]
    assert np.max(np.abs(x[:, 0] - 10000.0)) < 1e-6
    assert np.max(x[:, 2]) == pytest.approx(0.0, abs=1e-6) and np.min(x[:, 2]) == pytest.approx(-50.0, abs=1e-6)
    assert np.min(x[:, 1]) == pytest.approx(0.0, abs=1e-6)
    assert np.max(x[:, 1]) == pytest.approx(30000.0, abs=1e-6)
    tri = queretaro.points[queretaro.surfaces["fault"]]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    assert area == pytest.approx(30000.0 * 50.0, rel=1e-9)


def test_queretaro_volumes(queretaro):
    vols = material_volumes(queretaro)
    total = sum(vols.values())
    assert total == pytest.approx(QRO_VOLUME, rel=1e-9)
    assert vols["rock"] == pytest.approx(total / 3.0, rel=0.01)
    assert vols["clay"] == pytest.approx(20000.0 * 30000.0 * 20.0, rel=1e-9)
    assert vols["sand"] == pytest.approx(20000.0 * 30000.0 * 30.0, rel=1e-9)


def _local_size(mesh, x, y, radius):
    """Mean edge length of the top-surface triangles within radius of (x, y)."""
    tri = mesh.surfaces["top"]
    p = mesh.points[tri]
    c = p.mean(axis=1)
    sel = np.hypot(c[:, 0] - x, c[:, 1] - y) < radius
    assert np.any(sel)
    return np.mean(np.linalg.norm(p[sel] - np.roll(p[sel], 1, axis=1), axis=2))


def test_queretaro_refined_at_fault_and_wells(queretaro):
    far = _local_size(queretaro, 25000.0, 5000.0, 3000.0)
    for x, y in geometry.QUERETARO_WELLS:
        assert _local_size(queretaro, x, y, 300.0) < 0.25 * far
    assert _local_size(queretaro, 10000.0, 25000.0, 300.0) < 0.25 * far
    m = geometry.queretaro_mesh(3.0, wells=[20000.0, 25000.0])
    assert _local_size(m, 20000.0, 25000.0, 300.0) < 0.25 * far
    assert _local_size(m, 12000.0, 15000.0, 300.0) > 2.0 * _local_size(queretaro, 12000.0, 15000.0, 300.0)


def test_size_factor_coarsens(wuxi):
    # Queretaro: 2-D sizes double (4x fewer triangles), layers go from 3 to 2 (1 in the clay, 1 in the sand)
    fine, coarse = geometry.queretaro_mesh(2.0), geometry.queretaro_mesh(4.0)
    assert len(fine.tets) / 8 < len(coarse.tets) < len(fine.tets) / 4
    # Wuxi: the layers bound the element height away from the ridge (about 3-4x fewer cells)
    assert len(geometry.wuxi_mesh(6.0).tets) < len(wuxi.tets) / 2.5


def test_deterministic_and_leaves_callers_gmsh_alone():
    import gmsh
    a = geometry.wuxi_mesh(4.0)
    assert not gmsh.isInitialized()
    gmsh.initialize(["test"], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 4)
        gmsh.model.add("mine")
        gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        b = geometry.wuxi_mesh(4.0)
        assert gmsh.isInitialized()
        assert gmsh.model.getCurrent() == "mine" and gmsh.model.getEntities(3) == [(3, 1)]
        assert gmsh.option.getNumber("Mesh.Algorithm3D") == 4
    finally:
        gmsh.finalize()
    assert np.array_equal(a.points, b.points) and np.array_equal(a.tets, b.tets)
    assert np.array_equal(a.cell_material, b.cell_material)


def _fault_rows(mesh):
    """Depths (m) of the boundaries of the rows of fault faces, from the land surface down."""
    return np.unique(np.round(-mesh.points[np.unique(mesh.surfaces["fault"])][:, 2], 6))


@pytest.mark.parametrize("surface_size", [0.6, 1.2])
def test_queretaro_surface_size_grades_the_rows_beside_the_fault(queretaro, surface_size):
    f = 3.0
    m = geometry.queretaro_mesh(f, surface_size=surface_size)
    rows = _fault_rows(m)
    heights = np.diff(rows)
    assert heights[0] == pytest.approx(f * surface_size, rel=1e-9, abs=1e-6)   # the top row: the option
    assert np.all(heights[1:] <= f * 50.0 / 7.0 * 1.1)                         # growing to the layers' height
    assert np.all(heights[1:] >= heights[0] * (1.0 - 1e-9))
    assert np.all(heights[1:] / heights[:-1] <= 2.0)                           # graded: no row twice the last
    assert np.any(np.isclose(rows, 20.0)) and rows[-1] == pytest.approx(50.0)  # the clay's base: a layer face
    assert np.isclose(material_volumes(m)["clay"], 20000.0 * 30000.0 * 20.0, rtol=1e-9)
    # the default: the uniform layers, untouched by the grading code
    assert np.allclose(np.diff(_fault_rows(queretaro)), [20.0, 30.0])


def test_queretaro_layer_thickness_sets_the_rows(queretaro):
    """Layers a quarter as thick (50/28 m at size factor 3: 5.36 m) give 4 rows of 5 m in the clay and 6 of 5 m in
    the sand; the default (50/7 m: 21.4 m) one row in each."""
    m = geometry.queretaro_mesh(3.0, layer_thickness=50.0 / 28.0)
    assert np.allclose(_fault_rows(m), np.concatenate([np.linspace(0.0, 20.0, 5), np.linspace(20.0, 50.0, 7)[1:]]))
    assert np.allclose(_fault_rows(queretaro), [0.0, 20.0, 50.0])
    assert len(m.tets) > 4 * len(queretaro.tets)


@pytest.mark.parametrize("build,kwargs,option", [
    (geometry.wuxi_mesh, {"size_factor": 0.0}, "-pfault_mesh_size_factor"),
    (geometry.wuxi_mesh, {"size_factor": "x"}, "-pfault_mesh_size_factor"),
    (geometry.wuxi_mesh, {"ridge_x": 100.0}, "-pfault_wuxi_ridge_x"),
    (geometry.wuxi_mesh, {"crest_depth": 0.0}, "-pfault_wuxi_crest_depth"),
    (geometry.wuxi_mesh, {"bedrock_depth": 2.0}, "-pfault_wuxi_bedrock_depth"),
    (geometry.wuxi_mesh, {"ridge_half_width": -1.0}, "-pfault_wuxi_ridge_half_width"),
    (geometry.wuxi_mesh, {"interfaces": [50.0, 20.0]}, "-pfault_wuxi_interfaces"),
    (geometry.wuxi_mesh, {"interfaces": [20.0, 120.0]}, "-pfault_wuxi_interfaces"),
    (geometry.wuxi_mesh, {"ridge": 1.0}, "-pfault_wuxi_ridge"),
    (geometry.queretaro_mesh, {"size_factor": -2.0}, "-pfault_mesh_size_factor"),
    (geometry.queretaro_mesh, {"fault_x": 40000.0}, "-pfault_queretaro_fault_x"),
    (geometry.queretaro_mesh, {"clay_thickness": 50.0}, "-pfault_queretaro_clay_thickness"),
    (geometry.queretaro_mesh, {"fault_size": 0.5}, "-pfault_queretaro_fault_size"),
    (geometry.queretaro_mesh, {"fault_size": "x"}, "-pfault_queretaro_fault_size"),
    (geometry.queretaro_mesh, {"surface_size": 0.0}, "-pfault_queretaro_surface_size"),
    (geometry.queretaro_mesh, {"surface_size": -1.0}, "-pfault_queretaro_surface_size"),
    (geometry.queretaro_mesh, {"surface_size": 8.0}, "-pfault_queretaro_surface_size"),
    (geometry.queretaro_mesh, {"surface_size": 3.0, "clay_thickness": 2.0}, "-pfault_queretaro_surface_size"),
    (geometry.queretaro_mesh, {"surface_size": 7.0, "size_factor": 3.0}, "-pfault_queretaro_surface_size"),
    (geometry.queretaro_mesh, {"surface_size": "x"}, "-pfault_queretaro_surface_size"),
    (geometry.queretaro_mesh, {"surface_size": 2.0, "layer_thickness": 1.5}, "-pfault_queretaro_surface_size"),
    (geometry.queretaro_mesh, {"layer_thickness": 0.05}, "-pfault_queretaro_layer_thickness"),
    (geometry.queretaro_mesh, {"layer_thickness": 60.0}, "-pfault_queretaro_layer_thickness"),
    (geometry.queretaro_mesh, {"layer_thickness": "x"}, "-pfault_queretaro_layer_thickness"),
    (geometry.queretaro_mesh, {"wells": [12000.0, 12000.0, 13000.0]}, "-pfault_queretaro_wells"),
    (geometry.queretaro_mesh, {"wells": [5000.0, 12000.0]}, "-pfault_queretaro_wells"),
])
def test_bad_parameters(build, kwargs, option):
    with pytest.raises(InputError) as err:
        build(**kwargs)
    message = str(err.value)
    assert message.startswith(option) and "\n" not in message


class _Reader:
    """Stands in for OptionReader: option values from a dict, else the declared defaults."""

    def __init__(self, values):
        self.values = values

    def has(self, name):
        return name in self.values

    def get(self, name):
        spec = spec_for(name)
        assert spec is not None, name
        value = self.values.get(name, spec.default)
        if spec.kind == "list" and isinstance(value, str):
            return parse_list(value, name)
        return value


def test_queretaro_fault_size():
    """-pfault_queretaro_fault_size sets the element size along and across the fault (times the size factor),
    the layers unchanged: a quarter of the default gives four times the fault triangles, each a quarter as long."""
    from types import SimpleNamespace

    from pfault.scene import generator_options
    settings = SimpleNamespace(mesh_file="", mesh_generator="queretaro")
    meshes = [generator_options(_Reader({"pfault_mesh_size_factor": 4.0, "pfault_queretaro_fault_size": h}),
                                settings)() for h in (52.0, 13.0)]
    faces = [len(m.surfaces["fault"]) for m in meshes]
    assert 3.6 < faces[1] / faces[0] < 4.4
    along = [np.median(np.ptp(m.points[m.surfaces["fault"]][:, :, 1], axis=1)) for m in meshes]
    assert along[0] == pytest.approx(4 * 52.0, rel=0.1) and along[1] == pytest.approx(4 * 13.0, rel=0.1)
    assert [np.unique(np.round(m.points[:, 2], 6)).size for m in meshes] == [3, 3]


def test_scene_generators():
    from types import SimpleNamespace

    from pfault.scene import generator_options
    settings = SimpleNamespace(mesh_file="", mesh_generator="queretaro")
    build = generator_options(_Reader({"pfault_mesh_size_factor": 4.0, "pfault_queretaro_fault_x": 12000.0,
                                       "pfault_queretaro_wells": "20000,20000"}), settings)
    m = build()
    x = m.points[np.unique(m.surfaces["fault"])]
    assert np.max(np.abs(x[:, 0] - 12000.0)) < 1e-6
    # without -pfault_queretaro_wells the mesh is refined where the flow model pumps (-pfault_flow_wells)
    far = _local_size(m, 25000.0, 5000.0, 3000.0)
    assert _local_size(m, 20000.0, 20000.0, 300.0) < 0.25 * far
    m = generator_options(_Reader({"pfault_mesh_size_factor": 4.0, "pfault_flow_wells": "20000,20000"}),
                          settings)()
    assert _local_size(m, 20000.0, 20000.0, 300.0) < 0.25 * far
    assert _local_size(m, 12000.0, 15000.0, 1500.0) > 2.0 * _local_size(m, 20000.0, 20000.0, 300.0)
    settings = SimpleNamespace(mesh_file="", mesh_generator="wuxi")
    m = generator_options(_Reader({"pfault_mesh_size_factor": 5.0, "pfault_wuxi_crest_depth": 7.0}), settings)()
    assert np.min(m.points[np.unique(m.surfaces["fissure"]), 2]) == pytest.approx(-7.0, abs=1e-6)

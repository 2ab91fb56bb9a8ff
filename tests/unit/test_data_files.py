"""The data files a run reads, in-process on one rank: every option that names a file says 'is a directory' of a
directory (not 'no such file'), and the record of the files (pfault.provenance: size, SHA-256) and its comparison
with a continued run's own, with the line that ends a continued run whose files changed."""

import hashlib
from types import SimpleNamespace

import pytest
from pyproj import CRS

from pfault import provenance
from pfault.errors import InputError
from pfault.georef import read_georef
from pfault.io.stations import read_stations
from pfault.materials.field_files import read_field
from pfault.mesh.gmsh_io import read_msh
from pfault.model import _check_restart_dir
from pfault.options import SPECS
from pfault.optionsfile import ArgumentError, read_options_file
from pfault.sources.head_files import read_mf6_grid
from pfault.sources.heads import HeadsSettings, check_heads_files
from pfault.tools.calibration_input import CalibrationInputError, read_parameters

# the options of kind string that name no data file, each with what it names
NOT_DATA = {"pfault_scene": "a name", "pfault_output_dir": "the output directory",
            "pfault_ground_surface": "a surface of the mesh", "pfault_heads_time_unit": "a unit",
            "pfault_solver": "an options file (its options are in options.txt)",
            "pfault_restart": "a run directory (checked by its checkpoint)",
            "pfault_start_date": "a calendar date",
            "pfault_mesh_cache": "a directory of meshes pfault wrote (keyed by their options and code version)"}


def test_every_option_that_names_a_data_file_is_recorded():
    """A new option of kind string must be put in provenance.FILE_OPTIONS (its file is recorded and checked on a
    restart) or here, in NOT_DATA, with what it names."""
    strings = {s.name for s in SPECS if s.kind == "string"}
    assert strings == set(provenance.FILE_OPTIONS) | set(NOT_DATA)


def test_a_directory_is_not_a_file_for_any_option(tmp_path):
    d = tmp_path / "data.hds"
    d.mkdir()
    heads = HeadsSettings(file=str(d), grid=str(d), time_unit=86400.0, time_unit_given=False, length_unit=1.0,
                          reference_time=None, outside="error", origin=(0.0, 0.0, 0.0), water_density=1000.0,
                          gravity=9.80665)
    expected = [
        (lambda: check_heads_files(heads, 1.0), f"-pfault_heads_grid {d}: is a directory, not a file; give the "
         "model's binary grid file (MODEL.dis.grb or MODEL.disv.grb)"),
        (lambda: check_heads_files(HeadsSettings(**{**heads.__dict__, "grid": ""}), 1.0),
         f"-pfault_heads_file {d}: is a directory, not a file; give the head file the model saved (MODFLOW's HEAD "
         "FILEOUT, e.g. model.hds) or an HDF5/NetCDF file in the layout of README"),
        (lambda: read_mf6_grid(str(d)), f"-pfault_heads_grid {d}: is a directory, not a file"),
        (lambda: read_msh(str(d)), f"-pfault_mesh_file {d}: is a directory, not a file; give a gmsh MSH 4.1 file"),
        (lambda: read_field(str(d), "pfault_material_clay_young_modulus", "Pa"),
         f"-pfault_material_clay_young_modulus field:{d}: is a directory, not a file; give the path of a CSV"),
        (lambda: read_stations(str(d)), f"-pfault_stations {d}: is a directory, not a file; give a CSV file"),
        (lambda: _check_restart_dir(str(tmp_path / "f.txt")), f"-pfault_restart {tmp_path / 'f.txt'}: is a file, "
         "not a run directory; give the output directory of the run to continue"),
    ]
    (tmp_path / "f.txt").write_text("x")
    for call, message in expected:
        with pytest.raises(InputError) as err:
            call()
        assert str(err.value).startswith(message), str(err.value)
    scene = tmp_path / "scene.opts"
    scene.write_text(f"-options_file {d}\n")
    with pytest.raises(ArgumentError, match=f"-options_file {d}: is a directory, not a file; give a PETSc options"):
        read_options_file(str(scene))
    with pytest.raises(CalibrationInputError, match=f"{d}: is a directory, not a file; give a CSV file"):
        read_parameters(str(d))


def entry(option, path, size, sha):
    return {"option": option, "path": path, "size_bytes": size, "sha256": sha}


def test_describe_and_record(tmp_path, monkeypatch):
    data = b"name,x,y,z\na,1,2,3\n"
    (tmp_path / "s.csv").write_bytes(data)
    monkeypatch.chdir(tmp_path)
    assert provenance.describe("pfault_stations", "s.csv") == entry(
        "pfault_stations", str(tmp_path / "s.csv"), len(data), hashlib.sha256(data).hexdigest())


def test_differences_and_the_line_that_names_them():
    """Files are compared by size and hash: one moved with the same content is the same; one changed in place,
    another file under the option, a file read by only one of the runs differ; stations left out may be."""
    then = [entry("pfault_mesh_file", "/a/m.msh", 10, "aa" * 32), entry("pfault_heads_file", "/a/h.hds", 20,
                                                                          "bb" * 32),
            entry("pfault_heads_grid", "/a/h.grb", 30, "cc" * 32), entry("pfault_stations", "/a/s.csv", 5, "dd" * 32)]
    moved = [dict(e, path=e["path"].replace("/a/", "/b/")) for e in then[:3]]
    assert provenance.differences(then, moved) == []
    now = [then[0], dict(then[1], sha256="ee" * 32), dict(then[2], path="/a/other.grb", size_bytes=31),
           entry("pfault_material_clay_young_modulus", "/a/E.csv", 7, "ff" * 32)]
    diffs = provenance.differences(then, now)
    assert [d["option"] for d in diffs] == ["pfault_heads_file", "pfault_heads_grid",
                                            "pfault_material_clay_young_modulus"]
    assert diffs[0]["then"] == {"path": "/a/h.hds", "size_bytes": 20, "sha256": "bb" * 32}
    assert diffs[2]["then"] is None
    assert provenance.changed_message("run", diffs) == (
        "-pfault_restart run: -pfault_heads_file /a/h.hds has changed since that run read it (now 20 bytes, SHA-256 "
        "eeeeeeeeeeee...; then 20 bytes, bbbbbbbbbbbb...) (and -pfault_heads_grid, "
        "-pfault_material_clay_young_modulus); the checkpoint is the answer to the files that run read: give those "
        "files to continue it as it was, or -pfault_restart_changed_inputs "
        "pfault_heads_file,pfault_heads_grid,pfault_material_clay_young_modulus to continue with the files as they "
        "are now (the steps up to the checkpoint stay those of the old files)")
    assert provenance.changed_message("run", diffs[1:2]).startswith(
        "-pfault_restart run: -pfault_heads_grid now reads /a/other.grb, which differs from the file that run read, "
        "/a/h.grb (now 31 bytes")
    assert provenance.changed_message("run", diffs[2:]).startswith(
        "-pfault_restart run: -pfault_material_clay_young_modulus /a/E.csv is a file that run did not read;")
    gone = provenance.differences(then[:2], then[1:2])
    assert provenance.changed_message("run", gone).startswith(
        "-pfault_restart run: that run read -pfault_mesh_file /a/m.msh, this one reads no file for it;")


def test_a_crs_file_is_a_data_file(tmp_path):
    """-pfault_crs given as a .prj file (beside the scene) is recorded like the other data files: heads in another
    CRS are reprojected by it, so a restart with it changed must not go on quietly; an EPSG code names no file."""
    (tmp_path / "site.prj").write_text(CRS.from_epsg(32650).to_wkt())
    scene_file = str(tmp_path / "scene.opts")

    class Reader:
        def __init__(self, crs):
            self.values = {"pfault_crs": crs, "pfault_start_date": ""}

        def get(self, name):
            return self.values[name]

    by_file = read_georef(Reader("site.prj"), scene_file)
    assert by_file.crs.to_epsg() == 32650 and by_file.crs_file == str(tmp_path / "site.prj")
    assert read_georef(Reader("EPSG:32650"), scene_file).crs_file == ""
    scene = SimpleNamespace(settings=SimpleNamespace(mesh_file=""), heads_settings=None, materials={},
                            flow_settings=None, soils=(), georef=by_file)
    assert provenance.scene_files(scene, "", scene_file) == [("pfault_crs", str(tmp_path / "site.prj"))]

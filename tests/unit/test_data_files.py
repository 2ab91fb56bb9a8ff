"""The data files a run reads, in-process on one rank: every option that names a file says 'is a directory' of a
directory (not 'no such file')."""

import pytest

from pfault.errors import InputError
from pfault.io.field_files import read_field
from pfault.io.head_files import read_mf6_grid
from pfault.io.stations import read_stations
from pfault.mesh.gmsh_io import read_msh
from pfault.model import _check_restart_dir
from pfault.optionsfile import ArgumentError, read_options_file
from pfault.sources.heads import HeadsSettings, check_heads_files
from pfault.tools.calibration_input import CalibrationInputError, read_parameters


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

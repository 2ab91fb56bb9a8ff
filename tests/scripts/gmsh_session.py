"""The gmsh session of the test meshes written by these scripts (penny_mesh.py, frictional_crack_mesh.py)."""
from __future__ import annotations

import contextlib


@contextlib.contextmanager
def gmsh_session(name):
    """gmsh, initialised under ``name`` unless the caller already did, quiet, with an empty model; cleared
    afterwards, and finalised if it was initialised here."""
    import gmsh
    initialized = gmsh.isInitialized()
    if not initialized:
        gmsh.initialize([name], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.clear()
        yield gmsh
    finally:
        gmsh.clear()
        if not initialized:
            gmsh.finalize()


def write_msh41(gmsh, path):
    """Write the current model as an ASCII MSH 4.1 file (what pfault's -pfault_mesh_file reads)."""
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.write(str(path))

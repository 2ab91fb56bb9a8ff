"""Read a gmsh mesh (MSH 4.1 file or the current gmsh model) into a SerialMesh.

Physical volumes become materials and physical surfaces become named surfaces (boundaries or
faults), all addressed by their physical names.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import InputError
from ..paths import file_problem
from .serial import SerialMesh, orient_positive

TET4, TRI3 = 4, 2


def read_msh(path: str) -> SerialMesh:
    """The mesh of a gmsh file (MSH 4.1), its physical volumes the materials, its physical surfaces named."""
    problem = file_problem(path)
    if problem:
        raise InputError(f"-pfault_mesh_file {path}: {problem}; give a gmsh MSH 4.1 file of linear tetrahedra")
    import gmsh
    initialized = gmsh.isInitialized()
    if not initialized:
        gmsh.initialize(["pfault"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.clear()
        try:
            gmsh.open(path)
        except Exception as exc:  # gmsh raises plain Exception with its own message
            raise InputError(f"-pfault_mesh_file: gmsh cannot read '{path}': {exc}") from None
        mesh = from_gmsh_model(source=path)
    finally:
        gmsh.clear()
        if not initialized:
            gmsh.finalize()
    return mesh


def _elements(gmsh: Any, lookup: np.ndarray, dim: int, tag: int, wanted: int, what: str, source: str) -> np.ndarray:
    """The elements (as node indices) of physical group ``tag`` of dimension ``dim``, all of gmsh type ``wanted``."""
    blocks = []
    for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
        types, _, nodes = gmsh.model.mesh.getElements(dim, ent)
        for t, n in zip(types, nodes):
            if t != wanted:
                name = gmsh.model.mesh.getElementProperties(t)[0]
                raise InputError(f"mesh {source}: {what} holds '{name}' elements; pfault needs linear "
                                 f"{'tetrahedra' if dim == 3 else 'triangles'} (set Mesh.ElementOrder 1)")
            blocks.append(lookup[np.asarray(n, dtype=np.int64)].reshape(-1, 4 if dim == 3 else 3))
    return np.concatenate(blocks) if blocks else np.zeros((0, 4 if dim == 3 else 3), np.int64)


def _volumes(gmsh: Any, lookup: np.ndarray, source: str) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The named physical volumes: their names (the materials, in tag order), tetrahedra and material index."""
    names: list[str] = []
    tet_blocks: list[np.ndarray] = []
    mat_blocks: list[np.ndarray] = []
    for dim, tag in sorted(gmsh.model.getPhysicalGroups(3), key=lambda x: x[1]):
        name = gmsh.model.getPhysicalName(dim, tag)
        if not name:
            raise InputError(f"mesh {source}: physical volume {tag} has no name; name it (materials are "
                             "addressed by physical name)")
        if name in names:
            raise InputError(f"mesh {source}: two physical volumes are named '{name}'")
        t = _elements(gmsh, lookup, dim, tag, TET4, f"physical volume '{name}'", source)
        tet_blocks.append(t)
        mat_blocks.append(np.full(len(t), len(names), dtype=np.int64))
        names.append(name)
    if not tet_blocks:
        raise InputError(f"mesh {source}: no physical volumes; tag the volumes with named physical groups")
    tets = np.concatenate(tet_blocks)
    if np.any(tets < 0):
        raise InputError(f"mesh {source}: elements refer to unknown nodes")
    return names, tets, np.concatenate(mat_blocks)


def from_gmsh_model(source: str = "gmsh model") -> SerialMesh:
    """SerialMesh from the mesh of the current gmsh model."""
    import gmsh
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    if len(node_tags) == 0:
        raise InputError(f"mesh {source}: no nodes (is the mesh generated and saved?)")
    node_tags = np.asarray(node_tags, dtype=np.int64)
    coords = np.asarray(coords, dtype=float).reshape(-1, 3)
    lookup = np.full(node_tags.max() + 1, -1, dtype=np.int64)
    lookup[node_tags] = np.arange(len(node_tags))
    names, tets, mats = _volumes(gmsh, lookup, source)
    surfaces = {}
    for dim, tag in gmsh.model.getPhysicalGroups(2):
        name = gmsh.model.getPhysicalName(dim, tag)
        if not name:
            raise InputError(f"mesh {source}: physical surface {tag} has no name; name it")
        surfaces[name] = _elements(gmsh, lookup, dim, tag, TRI3, f"physical surface '{name}'", source)
    # keep only the nodes used by tetrahedra
    used = np.unique(tets)
    renum = np.full(len(coords), -1, dtype=np.int64)
    renum[used] = np.arange(len(used))
    points = coords[used]
    tets = orient_positive(points, renum[tets])
    for name, tri in surfaces.items():
        tri = renum[tri]
        if np.any(tri < 0):
            raise InputError(f"mesh {source}: physical surface '{name}' has nodes that are on no tetrahedron")
        surfaces[name] = tri
    return SerialMesh(points=points, tets=tets, cell_material=mats, material_names=names, surfaces=surfaces,
                      source=source).check()

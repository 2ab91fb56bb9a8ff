"""Meshes: built-in generators, gmsh input, fault splitting and DMPlex distribution."""

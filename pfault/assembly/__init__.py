"""Vectorised element kernels -> PETSc Vec/Mat."""

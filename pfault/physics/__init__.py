"""Pure NumPy kernels: no PETSc here."""

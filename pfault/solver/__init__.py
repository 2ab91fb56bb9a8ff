"""Nonlinear and linear solvers: SNES set up once per run, near-null spaces, constraints."""

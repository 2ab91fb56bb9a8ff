"""Faults: split interface faces with contact and Mohr-Coulomb friction.

- ``settings``: what a scene asks of each fault (friction, method) and of the contact law;
- ``contact``: the contact laws per face, pure NumPy (semismooth Lagrange rows, penalty);
- ``breaking``: the strength of candidate surfaces' faces, intact and broken, and which faces break (NumPy);
- ``bubbles``: the face bubbles of the fault faces' cells and their static condensation (NumPy kernels);
- ``faces``: the faces on the distributed mesh, their cells and dofs on both sides;
- ``interface``: the laws on the faces, their residual rows and Jacobian blocks, each face's history.
"""

"""Faults: split interface faces with contact and Mohr-Coulomb friction.

- ``settings``: what a scene asks of each fault (friction, method) and of the contact law;
- ``contact``: the contact laws per face, pure NumPy (semismooth Lagrange rows, penalty);
- ``stabilization``: the traction-jump stabilisation of the P1-P0 multipliers;
- ``interface``: the faces on the distributed mesh, their dofs, residual rows and Jacobian blocks.
"""

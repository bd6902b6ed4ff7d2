"""Rotations, rigid transforms and rigid registration: pure numerics, batched over leading axes.

Conventions (MODEL §1, §5): lengths in mm, angles in rad; ``rpy = (r, p, y)`` means
``R = Rz(y) · Ry(p) · Rx(r)``; rotation vectors are axis × angle; homogeneous transforms
are (..., 4, 4).
"""

"""The robot model: conventions, batched forward kinematics, Jacobians, the parameter space.

- :mod:`.robot` — :class:`Robot`: geometry, limits, base and tool frames.
- :mod:`.dh` — the DH family (``dh``, ``hayati``, ``craig``): joint transforms, batched
  FK and the twist Jacobian.  A new convention is a sibling module with the same
  three functions, registered in :mod:`.kinematics`.
- :mod:`.kinematics` — the convention-independent entry points (``chain_pose``, …).
- :mod:`.parameters` — :class:`ParameterSpace`: named deviations ↔ robots, batched poses,
  the exact identification Jacobian.
- :mod:`.candidates` — which deviations a calibration offers by default.
- :mod:`.measurements`, :mod:`.metrics` — measured poses, and a model's errors on them.
"""

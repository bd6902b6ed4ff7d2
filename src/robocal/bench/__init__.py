"""Benchmarks of robocal's speed targets (``robocal bench``): the workloads W1–W8 and their timing.

Peers (pyswarms, pybotics, Robotics Toolbox) are not part of the package: they live in the
source tree's ``benchmarks/peers.py`` and run when that file and the ``bench`` extra are there.
"""

"""The robot cell: one frame algebra (world, robot base, flange, TCP, the program's user frame)
for everything that hands a calibrated model's result to a robot (:mod:`.frames`)."""

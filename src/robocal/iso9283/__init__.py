"""ISO 9283 pose and distance accuracy and repeatability: the test cube's poses for a robot
(:mod:`.cube`), the command and measurement files (:mod:`.files`) and the characteristics
(:mod:`.characteristics`)."""

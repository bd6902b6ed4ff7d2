"""One inverse kinematics for nominal and calibrated models: every solution of a batch of goals
(closed forms where the chain allows, else multi-start), each with its configuration data and a
typed status (:mod:`.solve`); the damped least-squares polish they share (:mod:`.local`)."""

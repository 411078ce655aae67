"""Pose trajectories as a LeRobot dataset (codebase v3.0), written and read through LeRobot."""

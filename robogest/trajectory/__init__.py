"""Command trajectories and their file format."""

from robogest.trajectory.types import Trajectory, check_matches

__all__ = ["Trajectory", "check_matches"]

"""The retargeting seam: canonical human motion in, robot joint angles out."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from robogest.motion.human_motion import HumanMotion
from robogest.robot.config import RobotConfig

#: Human (canonical: x left, y up, z forward) -> robot world (x forward, y left, z up).
HUMAN_TO_ROBOT = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class RetargetResult:
    """Robot joint angles for every motion frame.

    Attributes
    ----------
    q_rad : ndarray [shape=(T, J)], radians
        In the robot YAML's joint order, inside the joint limits.
    fps : float
    direction_error_rad : ndarray [shape=(T, K)], radians
        Angle between each human bone direction and its robot link, per retarget vector.
    collision_frames : ndarray [shape=(T,)], bool
        Frames whose IK solution would have put the robot into contact and was held back.
    """

    q_rad: np.ndarray
    fps: float
    direction_error_rad: np.ndarray
    collision_frames: np.ndarray | None = None


class Retargeter(ABC):
    """Maps human motion onto one robot."""

    def __init__(self, robot: RobotConfig) -> None:
        self.robot = robot

    @abstractmethod
    def retarget(self, motion: HumanMotion, q0: np.ndarray | None = None) -> RetargetResult:
        """Joint angles for ``motion``; ``q0 (J,)`` warm-starts the first frame (default rest)."""

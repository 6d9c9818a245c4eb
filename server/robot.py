"""The robot and its sensors as the simulator models them: a Pioneer 3DX-like differential-drive
robot (``ROBOT``), its laser (``LASER``) and its fiducial finder (``FIDUCIAL``); poses and angles.

Conventions (docs/protocol.md): SI units, x forward, y left, angles counter-clockwise, yaw in
(-pi, pi]. ``server.world`` simulates them; ``server.worldfile`` reads the worlds they move in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from protocol.messages import MAX_VA, MAX_VX

__all__ = ["FIDUCIAL", "LASER", "ROBOT", "FiducialSpec", "LaserSpec", "Pose", "RobotSpec",
           "wrap_angle"]


def wrap_angle(a: float) -> float:
    """Wrap an angle in radians into (-pi, pi]."""
    a = math.fmod(a, 2.0 * math.pi)
    if a <= -math.pi:
        a += 2.0 * math.pi
    elif a > math.pi:
        a -= 2.0 * math.pi
    return a


class Pose(NamedTuple):
    """A planar pose: metres and radians (a tuple, so ``(x, y, yaw)`` compares equal)."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class RobotSpec:
    """Pioneer 3DX-like differential-drive robot (collision shape: a circle of ``radius``)."""

    length: float = 0.511
    width: float = 0.4
    radius: float = 0.25
    max_vx: float = MAX_VX  # m/s (the protocol's limits: docs/protocol.md section 2)
    max_va: float = MAX_VA  # rad/s (100 deg/s)
    mass: float = 9.0  # kg (only matters robot against robot)


@dataclass(frozen=True)
class LaserSpec:
    """SICK-like laser at the robot's centre, facing forward: 360 beams over 180 degrees."""

    count: int = 360
    min_angle: float = -math.pi / 2.0
    max_angle: float = math.pi / 2.0
    max_range: float = 8.0
    offset: float = 0.0  # m ahead of the robot's centre (0: at the centre)

    @property
    def resolution(self) -> float:
        return (self.max_angle - self.min_angle) / (self.count - 1)

    def bearings(self) -> np.ndarray:
        """Bearing of each beam in the robot frame (rad), ``min_angle + i * resolution``."""
        return self.min_angle + np.arange(self.count, dtype=np.float64) * self.resolution


@dataclass(frozen=True)
class FiducialSpec:
    """The fiducial finder (Player's ``fiducial`` interface, Stage's fiducial finder model) at
    the robot's centre, facing forward: a beacon is seen when its centre is within
    ``max_range`` of the sensor, within ``fov`` (centred on the heading) and no wall crosses the
    line from the sensor to its centre first; its id is reported within ``max_range_id``, 0
    (seen, not identified) beyond it. Other robots do not hide a beacon."""

    min_range: float = 0.0  # m: a beacon nearer is reported at this range (as Stage does)
    max_range: float = 8.0  # m (the laser's range)
    max_range_id: float = 8.0  # m (Stage's default is 5 m; here a room's width)
    fov: float = math.pi  # rad (180 degrees, the laser's field of view)
    offset: float = 0.0  # m ahead of the robot's centre
    size: tuple[float, float] = (0.1, 0.1)  # m, the sensor's footprint (length, width)


ROBOT = RobotSpec()
LASER = LaserSpec()
FIDUCIAL = FiducialSpec()

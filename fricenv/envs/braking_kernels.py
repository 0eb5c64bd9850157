"""Moved: the fast ROS2 substep kernels live in :mod:`fricenv.plants.quarter_car_fast` (physics belongs to the
plants). This module re-exports them for existing imports."""

from fricenv.plants.quarter_car_fast import (
    ROS2_GAMMA,
    Ros2Batch,
    make_scalar_substep,
    ros2_substep_scalar,
    scalar_road,
)

__all__ = ["ROS2_GAMMA", "Ros2Batch", "make_scalar_substep", "ros2_substep_scalar", "scalar_road"]

"""Batched Lie groups: SO2, SE2, SO3, SE3, Sim3, and the matrix groups Aff2 and SL3."""

from .base import LieGroup
from .matrix_group import SL3, Aff2
from .se2 import SE2
from .se3 import SE3
from .sim3 import Sim3
from .so2 import SO2
from .so3 import SO3

__all__ = ["SE2", "SE3", "SL3", "SO2", "SO3", "Aff2", "LieGroup", "Sim3"]

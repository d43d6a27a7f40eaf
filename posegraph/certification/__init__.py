"""Certified global optimality of SE2 and SE3 pose graphs: SE-Sync's verification and
Riemannian staircase (Rosen, Carlone, Bandeira and Leonard, IJRR 2019)."""

from .data import require_certifiable
from .staircase import Certificate, certify

__all__ = ["Certificate", "certify", "require_certifiable"]

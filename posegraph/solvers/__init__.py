"""Nonlinear least-squares solvers: Gauss-Newton and Levenberg-Marquardt."""

from .optimize import STOPPED, TIME_LIMIT, Callback, optimize
from .options import SolverOptions
from .summary import IterationRecord, Result, Summary

__all__ = [
    "STOPPED",
    "TIME_LIMIT",
    "Callback",
    "IterationRecord",
    "Result",
    "SolverOptions",
    "Summary",
    "optimize",
]

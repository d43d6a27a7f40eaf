"""Nonlinear least-squares solvers: Gauss-Newton, Levenberg-Marquardt and Powell's dogleg."""

from .loop import GRADIENT_BELOW_TOLERANCE, MAX_ITERATIONS, STOPPED, TIME_LIMIT, Callback, solve
from .options import SolverOptions
from .summary import PHASES, IterationRecord, Result, Summary

__all__ = [
    "GRADIENT_BELOW_TOLERANCE",
    "MAX_ITERATIONS",
    "PHASES",
    "STOPPED",
    "TIME_LIMIT",
    "Callback",
    "IterationRecord",
    "Result",
    "SolverOptions",
    "Summary",
    "solve",
]

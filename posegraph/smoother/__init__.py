"""The back end: ``Smoother`` owns a pose graph and what a later call reuses (the last solution,
the normal equations, GNC's decisions), with its warm-start policy."""

from .smoother import Smoother
from .solution import GncProblem, Solution
from .warm_start import COMPOSED, RESTART, SKIPPED

__all__ = ["COMPOSED", "RESTART", "SKIPPED", "GncProblem", "Smoother", "Solution"]

"""posegraph: pose-graph optimisation on Lie groups (SE2, SE3, Sim3)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("posegraph")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

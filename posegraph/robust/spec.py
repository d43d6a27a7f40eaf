"""The robust option, parsed once at the edge (``RobustSpec``), and its resolution for one graph
(``Kernel``): a width per measurement, by the rank of its information."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..graph import PoseGraph, information_ranks, measurement_mask, odometry_mask
from .kernels import KERNELS, default_width

GNC = "gnc"
"""Graduated non-convexity with the truncated least-squares kernel ("tls" names it too)."""
ROBUST_EDGE_CLASSES = ("loops", "all")
GNC_QUANTILE = 0.999
"""Default TLS threshold: of all the inliers under the kernel, one's s = rᵀΩr exceeds its width
once in a thousand graphs (``gnc_quantile``)."""
KERNEL_QUANTILE = 0.95
"""Default width of the IRLS kernels (Huber, Cauchy, …): √χ²_dof(0.95), Huber's usual choice."""


@dataclasses.dataclass(frozen=True, eq=False)
class RobustSpec:
    """A robust estimation request: ``kernel`` ("gnc" or an IRLS kernel of
    ``kernels.KERNELS``), its ``width`` c in Mahalanobis units (None: per measurement,
    √χ²_k(q) for the k directions its information weighs), the between ``edges`` it covers
    ("loops": not between consecutive nodes; "all"; or the caller's class, a boolean mask over
    the between edges or their indices), and whether it covers the ``priors`` too."""

    kernel: str
    width: float | None = None
    edges: str | np.ndarray = "loops"
    priors: bool = False

    @classmethod
    def parse(
        cls, text: str, edges: str | np.ndarray = "loops", priors: bool = False
    ) -> RobustSpec:
        """The spec of "NAME[:WIDTH]" (as ``--robust`` takes it); ``ValueError`` names what is
        wrong: an unknown kernel, a width that is not a positive finite number, an unknown edge
        class."""
        name, _, width_text = text.partition(":")
        name = name.strip().lower()
        name = GNC if name == "tls" else name
        if name != GNC and name not in KERNELS:
            raise ValueError(
                f"unknown robust kernel {name!r}; choose from gnc, {', '.join(KERNELS)}"
            )
        width = None
        if width_text:
            try:
                width = float(width_text)
            except ValueError:
                raise ValueError(
                    f"a robust kernel's width is a number (as in {name}:2.5), not {width_text!r}"
                ) from None
            if not (math.isfinite(width) and width > 0):
                raise ValueError(
                    f"a robust kernel's width must be positive and finite, not {width_text}"
                )
        if isinstance(edges, str):
            _check_edge_class(edges)
        return cls(name, width, edges, bool(priors))

    @property
    def gnc(self) -> bool:
        return self.kernel == GNC

    def same_kernel(self, other: RobustSpec) -> bool:
        """Whether ``other`` asks for the same kernel and width (the class may differ)."""
        return self.kernel == other.kernel and self.width == other.width

    def measured(self, graph: PoseGraph) -> np.ndarray:
        """Which edges of the robust problem the kernel covers (``robust_problem``): the class
        over the between edges, then, with ``priors``, every prior."""
        mask = robust_mask(graph, self.edges)
        if not (self.priors and len(graph.priors) > 0):
            return mask
        return np.concatenate([mask, np.ones(len(graph.priors), dtype=bool)])


def robust_mask(graph: PoseGraph, edges: str | np.ndarray) -> np.ndarray:
    """Which between edges a robust kernel applies to: "loops" (not between consecutive nodes),
    "all", or the caller's own class, as a boolean mask over the graph's between edges or as
    their indices (negative ones count from the end). The edges outside it are trusted (gtsam's
    GNC calls them known inliers)."""
    if isinstance(edges, str):
        _check_edge_class(edges)
        return ~odometry_mask(graph) if edges == "loops" else np.ones(graph.num_edges, dtype=bool)
    return measurement_mask(edges, graph.num_edges, "edge", "robust edges")


def _check_edge_class(edges: str) -> None:
    if edges not in ROBUST_EDGE_CLASSES:
        raise ValueError(
            f"robust edges are {' or '.join(ROBUST_EDGE_CLASSES)}, a boolean mask or edge "
            f"indices, not {edges!r}"
        )


@dataclasses.dataclass(frozen=True, eq=False)
class Kernel:
    """A ``RobustSpec`` resolved for one graph."""

    spec: RobustSpec
    measured: np.ndarray
    """Which edges of the robust problem it covers (``RobustSpec.measured``)."""
    widths: np.ndarray
    """Each edge's width c, over the robust problem's edges (the between edges, then with
    ``priors`` the priors)."""
    label: str
    """The spec as the summary reports it: the width of full-rank measurements, and those of
    other ranks in the class ("gnc:4.73896 (rank 3: 4.03314)")."""

    @property
    def name(self) -> str:
        return self.spec.kernel


def gnc_quantile(count: int) -> float:
    """The quantile of each of ``count`` measurements' width under GNC, such that one of them
    exceeds its width with probability 1 − ``GNC_QUANTILE`` (Bonferroni): 0.999 for one,
    1 − 10⁻⁶ for a thousand. A per-measurement 0.999 would reject true loops in every graph of
    a few thousand, and with them pull the map away from the outlier-free optimum."""
    return 1.0 - (1.0 - GNC_QUANTILE) / max(count, 1)


def resolve(spec: RobustSpec, graph: PoseGraph) -> Kernel:
    """The kernel of ``spec`` for ``graph``. Without a width, each measurement's is √χ²_k(q) for
    the k directions its information weighs (its rank: 3 for an SE3 position-only fix, not 6),
    as gtsam's GNC sets one threshold per factor dimension; q is ``gnc_quantile`` of the
    measurements under the kernel, or ``KERNEL_QUANTILE``."""
    measured = spec.measured(graph)
    name = spec.kernel
    if spec.width is not None:
        widths = np.full(len(measured), spec.width)
        return Kernel(spec, measured, widths, f"{name}:{spec.width:.6g}")
    quantile = gnc_quantile(int(measured.sum())) if spec.gnc else KERNEL_QUANTILE
    information = graph.edges.information
    if len(measured) > graph.num_edges:  # the priors, as edges
        information = np.concatenate([information, graph.priors.information])
    ranks = information_ranks(information)
    dof = graph.group.dof
    by_rank = np.array([default_width(k, quantile) for k in range(1, dof + 1)])  # rank 1, 2, …
    others = ", ".join(
        f"rank {k}: {by_rank[k - 1]:.6g}" for k in np.unique(ranks[measured]).tolist() if k != dof
    )
    label = f"{name}:{by_rank[-1]:.6g}" + (f" ({others})" if others else "")
    return Kernel(spec, measured, by_rank[ranks - 1], label)

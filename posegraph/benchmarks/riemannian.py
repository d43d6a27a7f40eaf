"""posegraph's Riemannian trust region against pymanopt's on SE-Sync's problem.

Usage: ``python -m posegraph.benchmarks.riemannian [--graphs intel sphere2500 ...]`` (needs
``pip install pymanopt``). From the rotations of posegraph's optimum, both minimise
F(Y) = tr(Y Q Yᵀ) on SO(d)ⁿ's Stiefel embedding to the gradient norm ``certify`` asks for,
with the same Q products, Euclidean gradient and Hessian and the same preconditioner (Newton's
system over poses, ``certification.poses``, factorised at each new point), so that the table
compares the two solvers' machinery: time, iterations, F.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from posegraph_datasets.paths import benchmark_graph

from ..api import optimize
from ..certification.data import SESyncData, sesync_data
from ..certification.poses import PosePreconditioner
from ..certification.staircase import GRADIENT_TOLERANCE, RELATIVE_TOLERANCE
from ..certification.stiefel import blocks, joined, sym_block_products
from ..certification.trust_region import minimize
from ..io import read_graph
from .table import MarkdownTable


def pymanopt_minimum(data: SESyncData, y: np.ndarray, tolerance: float):
    """pymanopt's ``TrustRegions`` from ``y`` on Stiefel(d, d, k=n): (F, iterations)."""
    import pymanopt
    from pymanopt.manifolds import Stiefel
    from pymanopt.optimizers import TrustRegions

    d = data.d
    manifold = Stiefel(d, d, k=data.n)

    @pymanopt.function.numpy(manifold)
    def cost(x):
        return data.objective(joined(x))

    @pymanopt.function.numpy(manifold)
    def gradient(x):
        return blocks(2.0 * data.product(joined(x)), d)

    @pymanopt.function.numpy(manifold)
    def hessian(x, v):
        return blocks(2.0 * data.product(joined(v)), d)

    poses, factorized_at = PosePreconditioner(data), [None]

    def precondition(x, u):
        y = joined(x)
        if factorized_at[0] is None or not np.array_equal(factorized_at[0], y):
            poses.factorize(y, sym_block_products(y, data.product(y), d))
            factorized_at[0] = y
        return blocks(poses(joined(u)), d)

    problem = pymanopt.Problem(
        manifold,
        cost,
        euclidean_gradient=gradient,
        euclidean_hessian=hessian,
        preconditioner=precondition,
    )
    optimizer = TrustRegions(min_gradient_norm=tolerance, verbosity=0, max_iterations=500)
    result = optimizer.run(problem, initial_point=blocks(y, d))
    return result.cost, result.iterations


def row(name: str) -> str | None:
    """One table row, or None where the graph is not on this machine."""
    path = benchmark_graph(name)
    if path is None:
        return None
    graph = read_graph(path).graph
    optimize(graph)
    data = sesync_data(graph)
    d = data.d
    y = graph.values.as_matrix()[:, :d, :d].transpose(1, 0, 2).reshape(d, -1)
    tolerance = GRADIENT_TOLERANCE * RELATIVE_TOLERANCE * data.scale
    began = time.perf_counter()
    ours = minimize(data, y, tolerance)
    own_time = time.perf_counter() - began
    began = time.perf_counter()
    value, iterations = pymanopt_minimum(data, y, tolerance)
    peer_time = time.perf_counter() - began
    cells = [name, f"{own_time:.2f} s", f"{peer_time:.2f} s", f"{peer_time / own_time:.1f}"]
    cells += [f"{ours.iterations} / {iterations}", f"{ours.objective:.10g} / {value:.10g}"]
    return " | ".join(cells)


def main(arguments: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graphs", nargs="+", default=["intel.g2o", "sphere2500.g2o",
                        "parking-garage.g2o", "torus3D.g2o"])  # fmt: skip
    args = parser.parse_args(arguments)
    try:
        import pymanopt  # noqa: F401
    except ImportError:
        sys.exit("this benchmark needs pymanopt: pip install pymanopt")
    table = MarkdownTable(
        "graph | posegraph | pymanopt | pymanopt / posegraph | iterations | F", echo=True
    )
    table.add_present(row(name) for name in args.graphs)


if __name__ == "__main__":
    main()

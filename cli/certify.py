"""``posegraph certify``: optimise a graph, then certify the result with SE-Sync's check
(``posegraph.certify``), climbing the Riemannian staircase where the check fails."""

from __future__ import annotations

import argparse
import os

import posegraph

from .common import Inputs, about, cost_label, emit, solving_options, talks
from .errors import EXIT_NOT_CONVERGED
from .progress import Progress

EXIT_CERTIFIED = 0


def certify(args: argparse.Namespace) -> int:
    """Exit 0 when the estimate is certified globally optimal for SE-Sync's problem, else 1."""
    from posegraph.certify import certify as certified

    inputs = Inputs(args)
    progress = Progress(talks(args), args.solver, args.max_iterations, cost_label(args))
    with progress:
        with progress.stage(f"reading {os.path.basename(args.input)}"):
            graph = inputs.graph(args.input).graph
        progress.begin("optimising")
        with progress.interruptible(), about(args.input):
            result = posegraph.Smoother(graph).optimize(callback=progress, **solving_options(args))
        progress.end()
        with progress.stage("certifying (SE-Sync)"):
            certificate = certified(graph)
        with progress.stage("refining the certified estimate"):
            refined = graph.copy()
            refined.set_values(certificate.values)
            after = posegraph.optimize(refined, init="file").summary.final_error
    record = {
        "command": "certify",
        "input": args.input,
        "posegraph_error": result.summary.final_error,
        "certificate": certificate.as_dict(),
        "error_after_refining_certified": after,
    }
    emit(args, record, _text(args.input, result.summary.final_error, certificate, after))
    return EXIT_CERTIFIED if certificate.certified else EXIT_NOT_CONVERGED


def _text(source: str, error: float, certificate, after: float) -> str:
    verdict = (
        "certified globally optimal for SE-Sync's isotropic problem"
        if certificate.certified
        else f"not certified (the staircase stopped at rank {certificate.rank})"
    )
    climbed = " → ".join(
        f"rank {s['rank']}: λ_min {s['smallest_eigenvalue']:.3g}" for s in certificate.steps
    )
    return "\n".join(
        [
            f"{source}: {verdict}",
            f"  SE-Sync objective  {certificate.objective:.10g} (lower bound {certificate.lower_bound:.10g})",
            f"  λ_min(Q − Λ)       {certificate.smallest_eigenvalue:.3g} (tolerance −{certificate.tolerance:.3g})",
            f"  checks             {climbed}",
            f"  posegraph's error  {error:.10g}; from the certified estimate {after:.10g}"
            f" ({'the same optimum' if abs(after - error) <= 1e-6 * max(1.0, error) else 'another point'})",
            f"  time               {certificate.time:.2f} s",
        ]
    )

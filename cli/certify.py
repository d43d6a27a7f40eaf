"""``posegraph certify``: optimise a graph, then certify the result with SE-Sync's check
(``posegraph.certify``), climbing the Riemannian staircase where the check fails."""

from __future__ import annotations

import argparse
import os

import posegraph
from posegraph.certification import require_certifiable
from posegraph.io.atomic import output_batch
from posegraph.io.conversion import convert as convert_graph
from posegraph.io.conversion import output_format

from .common import (
    Inputs,
    about,
    check_output,
    check_paths,
    check_writable,
    cost_label,
    emit,
    set_aside_rejected,
    solving_options,
    talks,
)
from .errors import EXIT_NOT_CONVERGED, EXIT_OK
from .progress import Progress


def certify(args: argparse.Namespace) -> int:
    """Exit 0 when the estimate is certified globally optimal for SE-Sync's problem, else 1.
    After a robust run (``--robust``), the problem of the measurements it kept; the lines a
    file marks rejected are set aside unless ``--readmit-rejected``."""
    check_paths([args.input], {"-o": args.output}, args.overwrite)
    check_output(args.output, args.to)
    inputs = Inputs(args)
    progress = Progress(talks(args), args.solver, args.max_iterations, cost_label(args))
    with progress:
        with progress.stage(f"reading {os.path.basename(args.input)}"):
            graph, _ = set_aside_rejected(inputs.graph(args.input), args.readmit_rejected)
        require_certifiable(graph)  # before any work
        check_writable(args.input, graph, args.output, to=args.to)
        smoother = posegraph.Smoother(graph)
        progress.begin("optimising")
        with progress.interruptible(), about(args.input):
            result = smoother.optimize(callback=progress, **solving_options(args))
        progress.end()
        kept = smoother.without_rejected()  # a robust run's inliers; all in least squares
        with progress.stage("certifying (SE-Sync)"):
            certificate = posegraph.certify(kept)
        with progress.stage("refining the certified estimate"):
            refined = kept.copy()
            refined.set_values(certificate.values)
            after = posegraph.optimize(refined, init="file").summary.final_error
        if args.output:
            with progress.stage("writing"), output_batch():
                convert_graph(
                    refined,
                    args.output,
                    output_format(args.output, args.to),
                    g2o_rotation_information=args.g2o_rotation_information,
                )
    record = {
        "command": "certify",
        "input": args.input,
        "output": args.output,
        "posegraph_error": result.summary.final_error,
        "certificate": certificate.as_dict(),
        "error_after_refining_certified": after,
    }
    text = _text(args.input, result.summary.final_error, certificate, after)
    emit(args, record, text + (f"\nwrote {args.output}" if args.output else ""), inputs.warnings)
    return EXIT_OK if certificate.certified else EXIT_NOT_CONVERGED


def _text(source: str, error: float, certificate, after: float) -> str:
    same = abs(after - error) <= 1e-6 * max(1.0, error)
    return "\n".join(
        [
            f"{source}: {verdict(certificate)}",
            *certificate_lines(certificate),
            f"  posegraph's error  {error:.10g}; from the certified estimate {after:.10g}"
            f" ({'the same optimum' if same else 'another point'})",
        ]
    )


def certified_if_asked(args: argparse.Namespace, smoother: posegraph.Smoother, progress: Progress):
    """``optimize --certify``: the certificate of the smoother's solution (of the measurements a
    robust run kept), or None unasked."""
    if not args.certify:
        return None
    with progress.stage("certifying (SE-Sync)"):
        return posegraph.certify(smoother.without_rejected())


def info_certificate(args: argparse.Namespace, graph: posegraph.PoseGraph, record: dict, text: str):
    """``info --certify``: optimise a copy of the graph (defaults) and certify it, adding the
    certificate to the record and text; a graph the check cannot take gets a line saying why
    (``info`` refuses nothing it could read)."""
    if not args.certify:
        return text
    try:
        require_certifiable(graph)
    except ValueError as reason:
        record["certificate"] = None
        return f"{text}\ncertificate: not checked: {reason}"
    solved = graph.copy()
    posegraph.optimize(solved)
    return with_certificate(record, text, posegraph.certify(solved))


def with_certificate(record: dict, text: str, certificate) -> str:
    """``optimize``'s record (in place) and text with the certificate, where there is one."""
    if certificate is None:
        return text
    record["certificate"] = certificate.as_dict()
    return "\n".join(
        [text, f"certificate: {verdict(certificate)}", *certificate_lines(certificate)]
    )


def verdict(certificate) -> str:
    """The certificate's verdict in words."""
    if certificate.certified:
        return "certified globally optimal for SE-Sync's isotropic problem"
    return f"not certified (the staircase stopped at rank {certificate.rank})"


def certificate_lines(certificate) -> list[str]:
    """The summary's lines on a certificate: objective, λ_min, the checks, time; and where it
    is not certified, the relaxation's lower bound on the objective (where it is, the objective
    is the optimum, and the bound, weakened by the tolerance, says less)."""
    checks = " → ".join(
        f"rank {step['rank']}: {'passed' if step['certified'] else 'failed'}"
        for step in certificate.steps
    )
    bound = "" if certificate.certified else f" (lower bound {certificate.lower_bound:.10g})"
    return [
        f"  SE-Sync objective  {certificate.objective:.10g}{bound}",
        f"  λ_min(Q − Λ)       {certificate.smallest_eigenvalue:.3g}"
        f" (certified if ≥ −{certificate.tolerance:.3g})",
        f"  checks             {checks}",
        f"  certify time       {certificate.time:.2f} s",
    ]

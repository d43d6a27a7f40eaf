"""The trust region's preconditioner at rank d against the Hessian it inverts: for a tangent
V = Rᵢ kᵢ^ that holds pose 0, the pose system applied to Hess F[V] (SE-Sync eq. 44, written out
here) gives back 2V: it is the Riemannian Hessian in pose coordinates, sparse because the
translations stay unknowns."""

from __future__ import annotations

import numpy as np
import pytest
from posegraph_datasets.generators import grid, manhattan_world

import posegraph
from posegraph.certification.data import sesync_data
from posegraph.certification.poses import PosePreconditioner
from posegraph.certification.stiefel import blocks, joined, project, sym_block_products


@pytest.mark.parametrize(
    "graph",
    [manhattan_world(num_poses=40, grid_size=4, seed=2)[0], grid(size=3, seed=3)[0]],
    ids=["SE2", "SE3"],
)
def test_the_pose_system_inverts_the_riemannian_hessian(graph):
    graph.priors = graph.priors.subset(np.zeros(len(graph.priors), dtype=bool))
    certificate = posegraph.certify(graph)
    assert certificate.certified
    data = sesync_data(graph)
    d = data.d
    y = certificate.values.as_matrix()[:, :d, :d].transpose(1, 0, 2).reshape(d, -1)
    curvature = sym_block_products(y, 2.0 * data.product(y), d)  # SymBlockDiag(Yᵀ 2 Y Q)
    preconditioner = PosePreconditioner(data)
    preconditioner.factorize(y, 0.5 * curvature)
    coordinates = np.random.default_rng(0).normal(size=(data.n, preconditioner.skew.shape[0]))
    coordinates[0] = 0.0  # pose 0 held
    skew = np.einsum("np,pab->nab", coordinates, preconditioner.skew)
    tangent = joined(blocks(y, d) @ skew)
    hessian = project(y, 2.0 * data.product(tangent) - joined(blocks(tangent, d) @ curvature), d)
    np.testing.assert_allclose(preconditioner(hessian), 2.0 * tangent, atol=1e-9)

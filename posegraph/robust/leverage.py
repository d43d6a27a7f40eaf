"""What leaving an edge out, or adding one, does to a least-squares solution, to first order.

Whiten each edge with a Wₑ such that Wₑᵀ Wₑ = Ωₑ: residual r̃ₑ = Wₑ rₑ and Jacobian rows
Aₑ = Wₑ [∂r/∂δᵢ, ∂r/∂δⱼ]. H = AᵀA is the information matrix of the linearised problem (priors
included).

* An edge of the graph, with Mₑₑ = Aₑ H⁻¹ Aₑᵀ its block of the hat matrix: at the solution
  fitted without it, its whitened residual is (I − Mₑₑ)⁻¹ r̃ₑ, and its innovation against that
  solution is d²ₑ = r̃ₑᵀ (I − Mₑₑ)⁻¹ r̃ₑ (deleted residuals: Cook & Weisberg 1982, "Residuals
  and Influence in Regression", §2.2; Baarda's data snooping in geodesy). Leaving the edge out
  lowers the least-squares cost by d²ₑ (χ² units). A false loop that the solution bent to fit
  has a small residual but Mₑₑ near I, hence a large d².
* An edge not in the graph: its innovation χ², r̃ₑᵀ (I + Pₑ)⁻¹ r̃ₑ with Pₑ = Aₑ H⁻¹ Aₑᵀ, the
  Mahalanobis size of its residual under the covariance Ωₑ⁻¹ + Jₑ Σ Jₑᵀ that the solution
  predicts for it (the χ² gate of Kalman filtering). Adding the edge raises the cost by that
  much (Sherman–Morrison–Woodbury). A true loop that a distorted solution fits badly has a
  large residual but a large Pₑ, hence a small innovation.
* Several edges not in the graph, added together: their joint innovation, the same form over
  their stacked rows, with the cross terms Aₑ H⁻¹ A_fᵀ. Edges that each alone disagree with
  the solution can agree with each other, and then raise the cost by far less than the sum of
  their innovations.

Mₑₑ is exact, from the joint covariance of each edge's two nodes (``posegraph.analysis.marginals``):
their blocks of H⁻¹ lie in the pattern of H's factor, so CHOLMOD gives every edge's at once by
selected inversion, at about the cost of a factorisation; SuperLU needs a solve per edge
there. Pₑ and the cross terms lie outside
H's pattern: for m candidates they take one solve of m·d columns, H⁻¹ Aᵀ, and are exact. With
CHOLMOD, Pₑ of more candidates (up to ``SELECTED_COLUMNS`` columns) comes from selected
inversion too, of H factorised on its pattern with the candidates' node pairs added.

Beyond that, estimates: from K Rademacher probes z over the whitened rows and the one K-column
solve w = H⁻¹ Aᵀ z, SuperLU's Mₑₑ of every edge, and Pₑ of candidates whose m·d columns exceed
K. Mₑₑ from E[(A w)ₑ zₑᵀ] = Mₑₑ (Bekas, Kokiopoulou & Saad 2007, "An estimator for the diagonal
of a matrix"), whose variance per entry is (Mₑₑ − Mₑₑ²)/K; Pₑ from E[(Aₑ w)(Aₑ w)ᵀ] =
Aₑ H⁻¹ (AᵀA) H⁻¹ Aₑᵀ = Pₑ, within ≈ √(2/K) relative. Where Mₑₑ is near I, the estimate's error
in I − Mₑₑ, squared in the deleted residual's s, can reach an order of magnitude.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Protocol

import numpy as np

from ..graph import EdgeSet, PoseGraph
from ..graph.checks import definite_beyond, positive_definite
from ..lie import LieGroup
from ..problem.backends import inverts_selectively
from ..problem.covariance import joint_covariances
from ..problem.factors import Linearization, information_root, linearize_between, linearize_priors
from ..problem.information import factorize_information, factorized_information
from ..problem.linear import NormalEquations
from ..problem.linearization import Linearized


class Solved(Protocol):
    """What a least-squares solve lends at its solution (``solvers.Result``): its normal
    equations and its linearisation there."""

    system: NormalEquations | None
    linearization: Linearized | None


PROBES = 256
"""Probes of the estimates, and the widest solve for exact innovations. At 32 a leverage of 0.7
is off by ±0.08, and d² by up to two orders of magnitude where I − Mₑₑ is small (824 for a true
5.3 on a generated graph); at 256 it is within ≈ 30% there (sphere2500's worst: 190%)."""
SELECTED_COLUMNS = 2048
"""Innovations of candidates of up to this many columns in all (m·d) are exact, by selected
inversion (CHOLMOD), beyond the probes' width; beyond this, the fill of so many node pairs
added to H's pattern costs more than the probes' solve (docs/benchmarks.md)."""
SMALLEST_COMPLEMENT = 1e-3
"""Eigenvalues of I − Mₑₑ are clipped here: the estimate can reach 0 or below where Mₑₑ ≈ I."""


@dataclasses.dataclass(frozen=True)
class _Factored:
    """H factorised at the graph's values, and the whitened rows of its edges and priors."""

    system: NormalEquations
    whitened: np.ndarray
    """r̃ of every between edge."""
    rows: np.ndarray
    """Its rows Aₑ = Ω^½ [Jᵢ Jⱼ] (m, d, 2d)."""
    prior_rows: np.ndarray

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """H⁻¹ rhs for a (size, K) right-hand side, as (num_nodes, d, K), zero on held nodes."""
        return self.system.scatter(self.system.solve(rhs))

    def cross_terms(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """A H⁻¹ Aᵀ over the stacked rows A (m, d, 2d) of m edges i → j, as (m, d, m·d), from
        the factor of H (``inverse_form``: sparse solves with CHOLMOD)."""
        count, d = len(i), self.system.dof
        if self.system.size == 0:
            return np.zeros((count, d, count * d))
        form = self.system.cholesky.inverse_form(*self.transposed_entries(i, j, rows), count * d)
        return form.reshape(count, d, count * d)

    def transposed_entries(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray) -> tuple:
        """Aᵀ of m edges' rows (m, d, 2d) at their nodes i and j, (size, m·d), as its entries
        (rows, columns, values): column e·d + b is row b of edge e."""
        system, d = self.system, self.system.dof
        columns = np.arange(len(i) * d).reshape(-1, d, 1)
        parts = []
        for nodes, part in ((i, rows[..., :d]), (j, rows[..., d:])):
            block = system.block_of[nodes]
            free = block >= 0  # held nodes have no columns in H
            places = (block[free, None] * d + np.arange(d))[:, None, :]
            places, at = np.broadcast_arrays(places, columns[free])
            parts.append((places.ravel(), at.ravel(), part[free].ravel()))
        return tuple(np.concatenate(pieces) for pieces in zip(*parts, strict=True))

    def rademacher(self, probes: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """Rademacher probes z of the between rows (K, m, d) and w = H⁻¹ Aᵀ z, the priors'
        rows probed too."""
        rng = np.random.default_rng(seed)
        d = self.system.dof
        z = rng.choice([-1.0, 1.0], size=(probes, len(self.whitened), d))
        z_priors = rng.choice([-1.0, 1.0], size=(probes, len(self.prior_rows), d))

        def transposed_times(rows: np.ndarray, probe: np.ndarray) -> np.ndarray:
            return np.einsum("mba,mb->ma", rows, probe)

        rhs = np.stack(
            [
                self.system.vector(
                    np.concatenate(
                        [
                            transposed_times(self.rows, z[k]).ravel(),
                            transposed_times(self.prior_rows, z_priors[k]).ravel(),
                        ]
                    )
                )
                for k in range(probes)
            ],
            axis=1,
        )
        return z, self.solve(rhs)


def _whitened(between: Linearization, information: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r̃ₑ and the rows Aₑ = Wₑ [Jᵢ Jⱼ] (m, d, 2d) of every between edge (``_whitening``)."""
    root = _whitening(information)
    return np.einsum("mab,mb->ma", root, between.residuals), root @ between.jacobians


def _whitening(information: np.ndarray) -> np.ndarray:
    """Wₑ with Wₑᵀ Wₑ = Ωₑ for each information matrix: Lᵀ of its Cholesky factor where it is
    definite beyond 1e-12 of its trace (clear of rounding, so that LAPACK's Cholesky succeeds),
    its symmetric root elsewhere (``information_root``). Every quantity here is the same for
    any such Wₑ: they change by an orthogonal Qₑ, r̃ₑ → Qₑ r̃ₑ, Aₑ → Qₑ Aₑ."""
    definite = definite_beyond(information, 1e-12)
    roots = np.empty_like(information)
    roots[definite] = np.swapaxes(np.linalg.cholesky(information[definite]), 1, 2)
    roots[~definite] = information_root(information[~definite])
    return roots


def _rows_times(rows: np.ndarray, i: np.ndarray, j: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Aₑ w of edges i → j with rows (m, d, 2d), for w (num_nodes, d, K): (m, d, K)."""
    d = rows.shape[1]
    return rows[..., :d] @ w[i] + rows[..., d:] @ w[j]


def _factorize(
    graph: PoseGraph,
    values: LieGroup,
    linear_solver: str,
    covariance_of: np.ndarray | None = None,
    solved: Solved | None = None,
) -> _Factored:
    """H factorised at ``values``. ``solved``, a least-squares solve of this graph ending at
    ``values``, lends its pattern (where ``covariance_of`` lies within it: the groups are
    edges' ends) and its linearisation there: H and the Jacobians."""
    held = graph.gauge_nodes()
    lent = solved is not None and solved.system is not None and solved.system.describes(graph, held)
    if lent:
        system = solved.system.for_covariance(linear_solver)
        data = solved.linearization.normal_matrix_for(graph, values, system)
    else:
        system, data = NormalEquations(graph, held, linear_solver, covariance_of), None
    if data is None:
        between = factorized_information(graph, values, system, regularize=True)
    else:
        factorize_information(system, data, regularize=True)
        between = solved.linearization.between
    prior_rows = _whitening(graph.priors.information) @ linearize_priors(values, graph.priors).jac_j
    return _Factored(system, *_whitened(between, graph.edges.information), prior_rows)


def _quadratic_forms(
    whitened: np.ndarray, matrices: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r̃ₑᵀ Bₑ⁻¹ r̃ₑ, ‖Bₑ⁻¹ r̃ₑ‖² and the sum of Bₑ's eigenvalues above ``SMALLEST_COMPLEMENT``,
    for the symmetrised Bₑ with its eigenvalues below ``SMALLEST_COMPLEMENT`` raised to it.
    Where none is below (Bₑ − ``SMALLEST_COMPLEMENT`` I is positive definite), by a solve, the
    sum being the trace; elsewhere from the eigenvalues. An edge whose residual or Bₑ overflowed
    gets ∞, ∞ and d."""
    count, d = whitened.shape
    finite = np.isfinite(whitened).all(axis=1) & np.isfinite(matrices).all(axis=(1, 2))
    symmetric = 0.5 * (matrices + np.swapaxes(matrices, 1, 2))
    symmetric[~finite] = np.eye(d)
    solved = finite & positive_definite(symmetric - SMALLEST_COMPLEMENT * np.eye(d))
    inverse, squares = np.full(count, np.inf), np.full(count, np.inf)
    eigenvalue_sum = np.full(count, float(d))
    x = np.linalg.solve(symmetric[solved], whitened[solved][..., None])[..., 0]  # B⁻¹ r̃
    inverse[solved] = np.einsum("ma,ma->m", whitened[solved], x)
    squares[solved] = np.einsum("ma,ma->m", x, x)
    eigenvalue_sum[solved] = np.trace(symmetric[solved], axis1=1, axis2=2)
    rest = finite & ~solved
    eigenvalues, eigenvectors = np.linalg.eigh(symmetric[rest])
    projected = np.einsum("mba,mb->ma", eigenvectors, whitened[rest])
    clipped = eigenvalues.clip(min=SMALLEST_COMPLEMENT)
    inverse[rest] = (projected**2 / clipped).sum(axis=1)
    squares[rest] = (projected**2 / clipped**2).sum(axis=1)
    eigenvalue_sum[rest] = (clipped * (clipped > SMALLEST_COMPLEMENT)).sum(axis=1)
    return inverse, squares, eigenvalue_sum


@dataclasses.dataclass(frozen=True)
class DeletedResiduals:
    """Of between edges, against the solution fitted without each (first order)."""

    innovation: np.ndarray
    """d²ₑ = r̃ₑᵀ (I − Mₑₑ)⁻¹ r̃ₑ: what leaving the edge out saves."""
    squares: np.ndarray
    """‖(I − Mₑₑ)⁻¹ r̃ₑ‖²: the edge's s = rᵀΩr at that solution (at least d²ₑ where Mₑₑ
    is exact: its eigenvalues lie in [0, 1])."""
    exact: bool
    """Whether Mₑₑ was exact, or estimated from probes."""
    redundancy: np.ndarray
    """tr(I − Mₑₑ), the edge's redundancy number: the expected s = rᵀΩr at the solution when
    the information states the noise right (0 for an edge that nothing else measures)."""


_MEASUREMENT_PARTS = (
    lambda edges: edges.i,
    lambda edges: edges.j,
    lambda edges: edges.information,
    lambda edges: edges.measurements.as_matrix(),
)
"""What makes measurements the same ones (``Leverage.serves``, ``Leverage.innovations``)."""


class Leverage:
    """Deleted residuals and innovations at one least-squares solution ``values`` of
    ``graph``, exact or from K Rademacher probes (module docstring): H is factorised, and the
    probes solved for, once, on first use, and shared by every call. ``solved``, the solve that
    ended at ``values``, lends its normal equations (``_factorize``)."""

    def __init__(
        self,
        graph: PoseGraph,
        values: LieGroup,
        probes: int = PROBES,
        seed: int = 0,
        linear_solver: str = "auto",
        solved: Solved | None = None,
    ) -> None:
        self.graph, self.values, self.solved = graph, values, solved
        self.probes, self.seed, self.linear_solver = probes, seed, linear_solver
        self._innovations: dict[bytes, np.ndarray] = {}

    @staticmethod
    def lent_by(solved: object, graph: PoseGraph, values: LieGroup) -> Leverage | None:
        """The leverages that a solve carries (``Result.leverage``), where they serve ``graph``
        at ``values``; else None."""
        lent = getattr(solved, "leverage", None)
        return lent if lent is not None and lent.serves(graph, values) else None

    def serves(self, graph: PoseGraph, values: LieGroup) -> bool:
        """Whether these are the leverages of ``graph``'s measurements at ``values``: the same
        edges, priors and information, and the same values."""
        mine, theirs = (self.graph.edges, self.graph.priors), (graph.edges, graph.priors)
        return np.array_equal(self.values.as_matrix(), values.as_matrix()) and all(
            np.array_equal(part(a), part(b))
            for a, b in zip(mine, theirs, strict=True)
            for part in _MEASUREMENT_PARTS
        )

    @functools.cached_property
    def _factored(self) -> _Factored:
        """H factorised at the values, shared by the probes and the exact innovations."""
        return _factorize(self.graph, self.values, self.linear_solver, solved=self.solved)

    @functools.cached_property
    def _probed(self) -> tuple[_Factored, np.ndarray, np.ndarray]:
        """H factorised, the probes z (K, m, d) and w = H⁻¹ Aᵀ z (num_nodes, d, K)."""
        return self._factored, *self._factored.rademacher(self.probes, self.seed)

    @functools.cached_property
    def deleted_residuals(self) -> DeletedResiduals:
        """Deleted residuals of every between edge of the graph: exact where the backend inverts
        selectively (CHOLMOD), else estimated from the probes (module docstring); computed on
        first use."""
        if inverts_selectively(self.linear_solver):
            return deleted_residuals(
                self.graph, self.values, linear_solver=self.linear_solver, solved=self.solved
            )
        factored, z, w = self._probed
        i, j = self.graph.edges.i, self.graph.edges.j
        hat_z = _rows_times(factored.rows, i, j, w)  # (m, d, K): (A w)ₑ
        hat = hat_z @ np.moveaxis(z, 0, 2).swapaxes(1, 2) / self.probes  # Σₖ (A w)ₑ zₑᵀ / K
        return _deleted(factored.whitened, hat, exact=False)

    def innovations(self, candidates: EdgeSet) -> np.ndarray:
        """Innovation χ² of each edge of ``candidates`` (edges over the graph's nodes that it
        does not hold) against the solution: exact while their d columns in all are no more
        than the probes (a solve as wide as the probes'), or with CHOLMOD no more than
        ``SELECTED_COLUMNS`` (selected inversion), else estimated from the probes. Kept for
        the next call with the same candidates."""
        key = b"".join(
            np.ascontiguousarray(part(candidates)).tobytes() for part in _MEASUREMENT_PARTS
        )
        if key not in self._innovations:
            self._innovations[key] = self._computed_innovations(candidates)
        return self._innovations[key].copy()

    def _computed_innovations(self, candidates: EdgeSet) -> np.ndarray:
        whitened, rows = _whitened(
            linearize_between(self.values, candidates), candidates.information
        )
        count, d = whitened.shape
        if count * d <= self.probes:
            cross = self._factored.cross_terms(candidates.i, candidates.j, rows)
            every = np.arange(count)
            predicted = cross.reshape(count, d, count, d)[every, :, every]  # Aₑ H⁻¹ Aₑᵀ
        elif count * d <= SELECTED_COLUMNS and inverts_selectively(self.linear_solver):
            ends = np.stack([candidates.i, candidates.j], axis=1)
            system = _factorize(self.graph, self.values, self.linear_solver, ends).system
            predicted = rows @ joint_covariances(system, ends) @ np.swapaxes(rows, 1, 2)
        else:
            samples = _rows_times(rows, candidates.i, candidates.j, self._probed[2])  # (m, d, K)
            predicted = samples @ np.swapaxes(samples, 1, 2) / self.probes
        return _quadratic_forms(whitened, np.eye(d) + predicted)[0]

    def sequential_innovations(self, candidates: EdgeSet) -> np.ndarray:
        """Exact innovation χ² of each edge of ``candidates`` against the solution with the
        edges before it added (to first order): their running sums are the joint innovations
        of the leading edges, r̃ᵀ (I + A H⁻¹ Aᵀ)⁻¹ r̃ over their stacked rows A and whitened
        residuals r̃ (the joint compatibility test of Neira & Tardós 2001, "Data Association
        in Stochastic Mapping Using the Joint Compatibility Test"). With C = I + A H⁻¹ Aᵀ =
        L Lᵀ, the k-th is ‖(L⁻¹ r̃)ₖ‖², one solve with H's factor of d columns per edge. All
        are ∞ where C or r̃ is not finite, or C not numerically positive definite."""
        import scipy.linalg  # on use: the noise check of a summary does without scipy

        whitened, rows = _whitened(
            linearize_between(self.values, candidates), candidates.information
        )
        predicted = self._factored.cross_terms(candidates.i, candidates.j, rows)
        predicted = predicted.reshape(whitened.size, whitened.size)
        covariance = np.eye(len(predicted)) + 0.5 * (predicted + predicted.T)
        try:
            factor = np.linalg.cholesky(covariance)
            standardized = scipy.linalg.solve_triangular(factor, whitened.reshape(-1), lower=True)
        except (np.linalg.LinAlgError, ValueError):  # not positive definite, or not finite
            return np.full(len(whitened), np.inf)
        return (standardized.reshape(whitened.shape) ** 2).sum(axis=1)


def _deleted(whitened: np.ndarray, hat: np.ndarray, exact: bool) -> DeletedResiduals:
    """Deleted residuals from r̃ₑ and the hat matrix's blocks Mₑₑ (``exact`` or estimated)."""
    innovation, squares, redundancy = _quadratic_forms(whitened, np.eye(hat.shape[-1]) - hat)
    return DeletedResiduals(innovation, squares, exact, redundancy)


def deleted_residuals(
    graph: PoseGraph,
    values: LieGroup,
    edges: np.ndarray | None = None,
    linear_solver: str = "auto",
    solved: Solved | None = None,
) -> DeletedResiduals:
    """Exact deleted residuals at ``values`` (see the module docstring) of the between edges
    indexed by ``edges``, by default all; ``solved``, the least-squares solve that ended at
    ``values``, lends its normal equations (``_factorize``)."""
    edges = np.arange(graph.num_edges) if edges is None else np.asarray(edges, dtype=np.int64)
    ends = np.stack([graph.edges.i[edges], graph.edges.j[edges]], axis=1)
    factored = _factorize(graph, values, linear_solver, ends, solved)
    covariances = joint_covariances(factored.system, ends)
    rows = factored.rows[edges]
    hat = rows @ covariances @ np.swapaxes(rows, 1, 2)  # Aₑ H⁻¹ Aₑᵀ
    return _deleted(factored.whitened[edges], hat, exact=True)


def innovations(
    graph: PoseGraph,
    values: LieGroup,
    candidates: EdgeSet,
    probes: int = PROBES,
    seed: int = 0,
    linear_solver: str = "auto",
) -> np.ndarray:
    """Innovation χ² of each edge of ``candidates`` (edges over ``graph``'s nodes that it does
    not hold) against ``graph``'s solution ``values``: exact, or estimated from ``probes``
    probes where the candidates' columns are more (``Leverage.innovations``)."""
    return Leverage(graph, values, probes, seed, linear_solver).innovations(candidates)

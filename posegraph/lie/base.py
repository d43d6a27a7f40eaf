"""The contract every Lie group in posegraph follows, and the routines shared by all of them.

Conventions (``CONVENTIONS.md``, binding):

* Elements are immutable and batched: every stored array has leading batch axes that broadcast
  like numpy, so one call acts on many elements at once.
* Perturbations are on the right: ``X.retract(δ) = X · Exp(δ)`` and ``X.local(Y) = Log(X⁻¹ Y)``.
  Every Jacobian is with respect to δ in ``X · Exp(δ)`` and is expressed in the tangent of the
  output at its value, ``∂ Log(f(X)⁻¹ f(X · Exp(δ))) / ∂δ``.
* ``jr`` is the right Jacobian: ``Exp(ξ + dξ) ≈ Exp(ξ) · Exp(jr(ξ) dξ)``; ``jl(ξ) = jr(−ξ)``.

A group subclass supplies its storage, ``exp``, ``log``, ``compose``, ``inverse``, ``as_matrix``,
``from_matrix``, ``identity``, ``sample`` and the basis of its Lie algebra (``generators``). The
base class derives the rest from the matrix representation, which any subclass may override
with a closed form for speed (each override is tested against the generic routine).
"""

from __future__ import annotations

import dataclasses
import functools
from abc import ABC, abstractmethod
from math import factorial
from typing import ClassVar, TypeVar

import numpy as np

from ._coeffs import series_terms
from .equality import same_entries

G = TypeVar("G", bound="LieGroup")

SCALED_NORM = 0.5
"""``integral_of_exp`` scales each matrix by a power of two to ‖B‖₁ ≤ ``SCALED_NORM``."""
TRUNCATION = 1e-18
"""``integral_of_exp`` sums the Taylor series until the first term left out is below this,
relative: ‖B‖₁ᴷ⁺¹/(K + 2)! for K terms."""
_MOST_TERMS = series_terms(lambda k: SCALED_NORM ** (k + 1) / factorial(k + 2), TRUNCATION, 100)


def _taylor_terms(norm: float) -> int:
    """The fewest terms K of φ₁'s Taylor series (k ≤ K) for ‖B‖₁ ≤ ``norm`` (≤
    ``SCALED_NORM``): the first left out, ‖B‖₁ᴷ⁺¹/(K + 2)!, is below ``TRUNCATION``."""
    return series_terms(lambda k: norm ** (k + 1) / factorial(k + 2), TRUNCATION, _MOST_TERMS)


def _taylor_phi1(b: np.ndarray, terms: int) -> np.ndarray:
    """Σₖ Bᵏ/(k+1)!, k ≤ ``terms``, for (m, n, n) B, by Paterson & Stockmeyer (1973): the powers
    B, …, Bᵖ, then Horner in Bᵖ over chunks of p terms, about 2√terms products in all."""
    n = b.shape[-1]
    p = max(1, int(np.ceil(np.sqrt(terms + 1))))
    powers = [np.broadcast_to(np.eye(n), b.shape), b]
    while len(powers) <= p:
        powers.append(powers[-1] @ b)
    top = powers.pop()  # Bᵖ
    phi = None
    for start in reversed(range(0, terms + 1, p)):
        chunk = sum(powers[i] / factorial(start + i + 1) for i in range(min(p, terms + 1 - start)))
        phi = chunk if phi is None else chunk + top @ phi
    return phi


def integral_of_exp(a: np.ndarray) -> np.ndarray:
    """φ₁(A) = ∫₀¹ exp(sA) ds = Σₖ Aᵏ/(k+1)! for a batch (…, n, n) of matrices; NaN where A
    is not finite.

    Scaling and squaring (Skaflestad & Wright 2009, "The scaling and modified squaring method
    for matrix functions related to the exponential"): the Taylor series of φ₁ and exp at
    B = A/2ˢ, with s per matrix so that ‖B‖₁ ≤ ``SCALED_NORM``, to as many terms as the largest
    ‖B‖₁ of the batch needs (``_taylor_terms``: 6 at 0.01, 15 at most), then s doublings
    φ₁(2B) = ½ φ₁(B)(e^B + I), e^{2B} = (e^B)², on the matrices that were scaled. Against
    40-digit references on Sim3's −ad_ξ, within 2.3e-14 relative for ‖A‖₁ up to 175, 1e-15 at
    1 and 4e-16 below 0.1; scipy's expm of Van Loan's block [[A, I], [0, 0]] (1978) was within
    9e-13.
    """
    a = np.asarray(a, float)
    shape, n = a.shape, a.shape[-1]
    a = a.reshape(-1, n, n)
    identity = np.eye(n)
    norm = np.abs(a).sum(axis=-2).max(axis=-1)
    finite = np.isfinite(norm)
    norm = np.where(finite, norm, 0.0)
    steps = np.ceil(np.log2(np.maximum(norm, 1e-300) / SCALED_NORM)).clip(min=0).astype(np.int64)
    b = a / np.exp2(steps)[:, None, None]
    terms = _taylor_terms(float((norm / np.exp2(steps)).max(initial=0.0)))
    phi = _taylor_phi1(b, terms)
    scaled = np.flatnonzero(steps)
    if scaled.size:
        sub_phi, sub_b, sub_steps = phi[scaled], b[scaled], steps[scaled]
        exp = identity + sub_b @ sub_phi
        for step in range(int(sub_steps.max())):
            doubling = (sub_steps > step)[:, None, None]
            sub_phi = np.where(doubling, 0.5 * sub_phi @ (exp + identity), sub_phi)
            exp = np.where(doubling, exp @ exp, exp)
        phi[scaled] = sub_phi
    return np.where(finite[:, None, None], phi, np.nan).reshape(shape)


@dataclasses.dataclass(frozen=True, eq=False)
class LieGroup(ABC):
    """Base of all groups. Subclasses are frozen dataclasses whose fields are numpy arrays."""

    dof: ClassVar[int]
    """Dimension of the tangent space."""
    matrix_size: ClassVar[int]
    """Side of the square matrix representation."""
    point_dim: ClassVar[int]
    """Dimension of the points the group acts on."""
    _event_ndims: ClassVar[dict[str, int]]
    """Number of trailing (non-batch) axes of each stored field."""

    def __post_init__(self) -> None:
        for name in self._event_ndims:
            object.__setattr__(self, name, np.asarray(getattr(self, name), float))

    # ----------------------------------------------------------------------------- storage
    def _batch_shapes(self) -> list[tuple[int, ...]]:
        """The leading batch axes of each stored field."""
        shapes = []
        for name, ndim in self._event_ndims.items():
            shape = getattr(self, name).shape
            shapes.append(shape[: len(shape) - ndim])
        return shapes

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The broadcast shape of the leading batch axes."""
        shapes = self._batch_shapes()
        if all(shape == shapes[0] for shape in shapes):
            return shapes[0]
        return np.broadcast_shapes(*shapes)

    def __len__(self) -> int:
        return self.batch_shape[0]

    def __getitem__(self: G, index) -> G:
        """Index the batch axes, like indexing an array of elements."""
        shapes = self._batch_shapes()
        if all(shape == shapes[0] for shape in shapes):  # no broadcasting needed
            return type(self)(**{name: getattr(self, name)[index] for name in self._event_ndims})
        batch = np.broadcast_shapes(*shapes)
        fields = {}
        for name, ndim in self._event_ndims.items():
            value = getattr(self, name)
            event = value.shape[value.ndim - ndim :]
            fields[name] = np.broadcast_to(value, batch + event)[index]
        return type(self)(**fields)

    def broadcast_to(self: G, batch_shape: tuple[int, ...]) -> G:
        """The same elements, repeated to ``batch_shape``."""
        fields = {}
        for name, ndim in self._event_ndims.items():
            value = getattr(self, name)
            fields[name] = np.broadcast_to(value, batch_shape + value.shape[value.ndim - ndim :])
        return type(self)(**fields)

    def set_at(self: G, index, values: G) -> G:
        """A copy with the elements at ``index`` (of the batch axes) replaced by ``values``."""
        batch = self.batch_shape
        fields = {}
        for name, ndim in self._event_ndims.items():
            current = getattr(self, name)
            out = np.broadcast_to(current, batch + current.shape[current.ndim - ndim :]).copy()
            out[index] = np.broadcast_to(getattr(values, name), out[index].shape)
            fields[name] = out
        return type(self)(**fields)

    @classmethod
    def stack(cls: type[G], elements: list[G], axis: int = 0) -> G:
        """Stack elements of equal batch shape along a new batch axis."""
        return cls(
            **{n: np.stack([getattr(e, n) for e in elements], axis) for n in cls._event_ndims}
        )

    @classmethod
    def concatenate(cls: type[G], elements: list[G]) -> G:
        """Join elements with one batch axis end to end."""
        batches = [e.broadcast_to(e.batch_shape) for e in elements]
        return cls(
            **{n: np.concatenate([getattr(e, n) for e in batches]) for n in cls._event_ndims}
        )

    def __repr__(self) -> str:
        return f"{type(self).__name__}(batch_shape={self.batch_shape})"

    def same_as(self, other: LieGroup) -> bool:
        """Whether ``other`` stores exactly the same elements (bit for bit)."""
        return type(other) is type(self) and all(
            same_entries(getattr(self, n), getattr(other, n)) for n in self._event_ndims
        )

    # ------------------------------------------------------------------ group-specific API
    @classmethod
    @abstractmethod
    def identity(cls: type[G], batch_shape: tuple[int, ...] = ()) -> G:
        """The identity element, repeated to ``batch_shape``."""

    @classmethod
    @abstractmethod
    def exp(cls: type[G], tangent: np.ndarray) -> G:
        """The exponential map of a (…, dof) tangent array."""

    @abstractmethod
    def log(self) -> np.ndarray:
        """The logarithm, a (…, dof) tangent array; ``exp(log(X)) = X``."""

    @abstractmethod
    def compose(self: G, other: G) -> G:
        """The product ``self · other``."""

    @abstractmethod
    def inverse(self: G) -> G:
        """The inverse element."""

    @abstractmethod
    def as_matrix(self) -> np.ndarray:
        """The (…, n, n) matrix representation."""

    @classmethod
    @abstractmethod
    def from_matrix(cls: type[G], matrix: np.ndarray) -> G:
        """The element of a (…, n, n) matrix representation."""

    @classmethod
    @abstractmethod
    def sample(cls: type[G], rng: np.random.Generator, batch_shape: tuple[int, ...] = ()) -> G:
        """Random elements (uniform rotations where the group has them)."""

    @classmethod
    @abstractmethod
    def generators(cls) -> np.ndarray:
        """The (dof, n, n) basis of the Lie algebra, in tangent order."""

    def normalize(self: G) -> G:
        """Project stored values back onto the group (rounding drift). Default: unchanged."""
        return self

    # ------------------------------------------------------------------ algebra (generic)
    @classmethod
    @functools.cache
    def _dual_basis(cls) -> np.ndarray:
        """(n·n, dof) matrix mapping a flattened algebra element to its coordinates."""
        flat = cls.generators().reshape(cls.dof, -1)
        return np.linalg.pinv(flat)

    @classmethod
    def hat(cls, tangent: np.ndarray) -> np.ndarray:
        """The algebra matrix Σ ξ_k G_k of a (…, dof) tangent array."""
        return np.einsum("...k,kij->...ij", np.asarray(tangent, float), cls.generators())

    @classmethod
    def vee(cls, algebra: np.ndarray) -> np.ndarray:
        """Coordinates of a (…, n, n) algebra matrix; the inverse of :meth:`hat`."""
        algebra = np.asarray(algebra, float)
        flat = algebra.reshape(algebra.shape[:-2] + (-1,))
        return flat @ cls._dual_basis()

    @classmethod
    def ad(cls, tangent: np.ndarray) -> np.ndarray:
        """The small adjoint: ``ad_ξ η = vee([hat ξ, hat η])``, a (…, dof, dof) array."""
        a = cls.hat(tangent)[..., None, :, :]
        generators = cls.generators()
        return np.swapaxes(cls.vee(a @ generators - generators @ a), -1, -2)

    def adjoint(self) -> np.ndarray:
        """Ad_X with ``X · Exp(δ) · X⁻¹ = Exp(Ad_X δ)``, a (…, dof, dof) array."""
        m = self.as_matrix()[..., None, :, :]
        m_inv = self.inverse().as_matrix()[..., None, :, :]
        return np.swapaxes(self.vee(m @ self.generators() @ m_inv), -1, -2)

    @classmethod
    def jr(cls, tangent: np.ndarray) -> np.ndarray:
        """Right Jacobian ``jr(ξ) = ∫₀¹ exp(−s ad_ξ) ds`` (Chirikjian, vol. 2, §10.2)."""
        return integral_of_exp(-cls.ad(tangent))

    @classmethod
    def jr_inv(cls, tangent: np.ndarray) -> np.ndarray:
        """Inverse of the right Jacobian."""
        return np.linalg.inv(cls.jr(tangent))

    @classmethod
    def jl(cls, tangent: np.ndarray) -> np.ndarray:
        """Left Jacobian: ``Exp(ξ + dξ) ≈ Exp(jl(ξ) dξ) · Exp(ξ)``; equals ``jr(−ξ)``."""
        return cls.jr(-np.asarray(tangent, float))

    @classmethod
    def jl_inv(cls, tangent: np.ndarray) -> np.ndarray:
        """Inverse of the left Jacobian; equals ``jr_inv(−ξ)``."""
        return cls.jr_inv(-np.asarray(tangent, float))

    # ------------------------------------------------------------------- derived operations
    def act(self, points: np.ndarray) -> np.ndarray:
        """Apply the elements to (…, point_dim) points."""
        m = self.as_matrix()
        points = np.asarray(points, float)
        linear = m[..., : self.point_dim, : self.point_dim]
        moved = np.einsum("...ij,...j->...i", linear, points)
        if self.matrix_size > self.point_dim:
            moved = moved + m[..., : self.point_dim, self.point_dim]
        return moved

    def __matmul__(self, other):
        """``X @ Y`` composes; ``X @ points`` acts on a (…, point_dim) array."""
        if isinstance(other, LieGroup):
            return self.compose(other)
        return self.act(other)

    def between(self: G, other: G) -> G:
        """``self⁻¹ · other``: ``other`` expressed in the frame of ``self``."""
        return self.inverse().compose(other)

    def retract(self: G, delta: np.ndarray) -> G:
        """``self · Exp(δ)`` (right perturbation)."""
        return self.compose(self.exp(delta))

    def local(self: G, other: G) -> np.ndarray:
        """``Log(self⁻¹ · other)``, so that ``self.retract(self.local(other)) = other``."""
        return self.between(other).log()

    def interpolate(self: G, other: G, alpha) -> G:
        """The geodesic ``self · Exp(α · Log(self⁻¹ · other))`` (Eade §7); α = 0 → self."""
        alpha = np.asarray(alpha, float)[..., None]
        return self.retract(alpha * self.local(other))

    # ------------------------------------------------------------- operations with Jacobians
    def compose_with_jacobians(self: G, other: G) -> tuple[G, np.ndarray, np.ndarray]:
        """``(X · Y, ∂/∂δ_X, ∂/∂δ_Y) = (X · Y, Ad(Y⁻¹), I)`` (Solà et al. 2018, eqs. 170–171)."""
        value = self.compose(other)
        eye = np.broadcast_to(np.eye(self.dof), value.batch_shape + (self.dof, self.dof))
        return value, other.inverse().adjoint(), eye

    def inverse_with_jacobians(self: G) -> tuple[G, np.ndarray]:
        """``(X⁻¹, −Ad_X)`` (Solà et al. 2018, eq. 160)."""
        return self.inverse(), -self.adjoint()

    def between_with_jacobians(self: G, other: G) -> tuple[G, np.ndarray, np.ndarray]:
        """``(Z = X⁻¹ Y, −Ad(Z⁻¹), I)``: Jacobians with respect to δ_X and δ_Y."""
        value = self.between(other)
        eye = np.broadcast_to(np.eye(self.dof), value.batch_shape + (self.dof, self.dof))
        return value, -value.inverse().adjoint(), eye

    @classmethod
    def exp_with_jacobians(cls: type[G], tangent: np.ndarray) -> tuple[G, np.ndarray]:
        """``(Exp ξ, ∂/∂ξ = jr(ξ))``: Exp(ξ + dξ) ≈ Exp(ξ) · Exp(jr(ξ) dξ)."""
        return cls.exp(tangent), cls.jr(tangent)

    def retract_with_jacobians(self: G, delta: np.ndarray) -> tuple[G, np.ndarray, np.ndarray]:
        """``(X · Exp(δ), ∂/∂δ_X = Ad(Exp(δ)⁻¹), ∂/∂δ = jr(δ))``: compose and Exp chained."""
        step, j_delta = self.exp_with_jacobians(delta)
        value, j_x, _ = self.compose_with_jacobians(step)
        return value, j_x, j_delta

    def local_with_jacobians(self: G, other: G) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ξ = Log(X⁻¹ Y), ∂ξ/∂δ_X = −jr⁻¹(ξ) Ad(Exp(−ξ)), ∂ξ/∂δ_Y = jr⁻¹(ξ))``: between and
        Log chained; the first equals −jl⁻¹(ξ)."""
        between, j_x, _ = self.between_with_jacobians(other)
        tangent, j_log = between.log_with_jacobians()
        return tangent, j_log @ j_x, j_log

    def interpolate_with_jacobians(self: G, other: G, alpha) -> tuple[G, np.ndarray, np.ndarray]:
        """``(X · Exp(α Log(X⁻¹ Y)), ∂/∂δ_X, ∂/∂δ_Y)``: ``local`` and ``retract`` chained."""
        alpha = np.asarray(alpha, float)[..., None, None]
        tangent, local_x, local_y = self.local_with_jacobians(other)
        value, j_x, j_step = self.retract_with_jacobians(alpha[..., 0] * tangent)
        j_step = alpha * j_step
        return value, j_x + j_step @ local_x, j_step @ local_y

    @classmethod
    def bch(cls, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The Baker–Campbell–Hausdorff series to third order: Log(Exp(x) Exp(y)) ≈ x + y +
        ½[x, y] + (1/12)([x, [x, y]] + [y, [y, x]]), with [a, b] = ad_a b, exact to O(|x|⁴ +
        |y|⁴) (Dellaert, "Lie groups for beginners", §2.3; Solà et al. 2018, eq. 143)."""
        x, y = np.asarray(x, float), np.asarray(y, float)

        def bracket(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return np.einsum("...ij,...j->...i", cls.ad(a), b)

        xy = bracket(x, y)
        return x + y + xy / 2 + (bracket(x, xy) - bracket(y, xy)) / 12

    def log_with_jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """``(ξ = Log X, ∂ξ/∂δ = jr⁻¹(ξ))``; the Jacobian is an ordinary (Euclidean) one."""
        tangent = self.log()
        return tangent, self.jr_inv(tangent)

    def act_with_jacobians(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(X p, ∂/∂δ_X, ∂/∂p)``; ``∂(X Exp(δ) p)/∂δ_k = X G_k p̃``, with p̃ homogeneous."""
        points = np.asarray(points, float)
        value = self.act(points)
        m = self.as_matrix()
        n = self.point_dim
        if self.matrix_size > n:
            ones = np.ones(points.shape[:-1] + (self.matrix_size - n,))
            lifted = np.concatenate([points, ones], axis=-1)
        else:
            lifted = points
        generated = np.einsum("kij,...j->...ik", self.generators(), lifted)
        jac_element = (m @ generated)[..., :n, :]
        jac_points = np.broadcast_to(m[..., :n, :n], value.shape[:-1] + (n, n))
        return value, jac_element, jac_points

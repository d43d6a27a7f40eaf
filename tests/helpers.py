"""Shared test helpers: the groups under test, random tangents, and central differences."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from posegraph.lie import SE2, SE3, SL3, SO2, SO3, Aff2, LieGroup, Sim3

POSE_GROUPS = [SO2, SE2, SO3, SE3, Sim3]
ALL_GROUPS = POSE_GROUPS + [Aff2, SL3]
BATCH_SHAPES = [(), (1,), (5,), (2, 3)]


def random_tangent(group: type[LieGroup], rng: np.random.Generator, shape=()) -> np.ndarray:
    """Tangents inside the injectivity domain (rotation angle < π) of every group."""
    scale = 0.5 if group in (Aff2, SL3) else 1.0
    return scale * rng.uniform(-1.0, 1.0, size=tuple(shape) + (group.dof,))


def numerical_jacobian(
    function: Callable,
    at,
    dof: int,
    input_on_group: bool,
    output_on_group: bool,
    step: float = 1e-6,
) -> np.ndarray:
    """Central differences on the manifold, perturbing every batch element at once.

    Input perturbation: ``X · Exp(h e_k)`` on a group, ``x + h e_k`` otherwise. Output difference:
    ``Log(f(x)⁻¹ f(x'))`` on a group, ``f(x') − f(x)`` otherwise. Returns (…, out, dof).
    """
    reference = function(at)
    batch = at.batch_shape if input_on_group else np.shape(at)[:-1]
    columns = []
    for k in range(dof):
        delta = np.zeros(tuple(batch) + (dof,))
        delta[..., k] = step
        moved = [at.retract(d) if input_on_group else at + d for d in (delta, -delta)]
        outputs = [function(m) for m in moved]
        if output_on_group:
            plus, minus = (reference.local(o) for o in outputs)
        else:
            plus, minus = outputs[0] - reference, outputs[1] - reference
        columns.append((plus - minus) / (2.0 * step))
    return np.stack(columns, axis=-1)


def assert_same_element(x: LieGroup, y: LieGroup, atol: float = 1e-10) -> None:
    np.testing.assert_allclose(x.as_matrix(), y.as_matrix(), atol=atol, rtol=0)

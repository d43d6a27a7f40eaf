"""An independent symbolic model of the groups in casadi SX, for checking Jacobians.

Exp and Log are written from the seed formulas directly on matrices (Eade §2–§6; the matrix
groups by a scaled Taylor series of the matrix exponential). Every Jacobian is then casadi's
automatic derivative of a matrix expression at δ = 0, read in the tangent through the linear
``vee`` of the algebra basis: ``∂ vee(A⁻¹ f(δ)) / ∂δ`` with A = f(0). That is exact, because
``A⁻¹ f(δ) = I + hat(J δ) + O(δ²)``. Nothing here calls posegraph's own formulas; only the
algebra basis (``generators``) is shared, as the definition of the tangent coordinates.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from ..lie import SE2, SE3, SL3, SO2, SO3, Aff2, LieGroup, Sim3


def _skew(v) -> ca.SX:
    return ca.vertcat(
        ca.horzcat(0, -v[2], v[1]), ca.horzcat(v[2], 0, -v[0]), ca.horzcat(-v[1], v[0], 0)
    )


def _unskew(m) -> ca.SX:
    return 0.5 * ca.vertcat(m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1])


def _homogeneous(linear, translation) -> ca.SX:
    n = linear.shape[0]
    return ca.vertcat(ca.horzcat(linear, translation), ca.horzcat(ca.DM.zeros(1, n), 1))


def _so3_exp(phi) -> ca.SX:
    theta = ca.norm_2(phi)
    k = _skew(phi)
    return ca.SX.eye(3) + ca.sin(theta) / theta * k + (1 - ca.cos(theta)) / theta**2 * (k @ k)


def _so3_log(r) -> ca.SX:
    """φ = θ v/|v| with v = vee(R − Rᵀ)/2 = sin θ · axis and θ = atan2(|v|, (tr R − 1)/2)."""
    v = 0.5 * _unskew(r - r.T)
    sin = ca.norm_2(v)
    return ca.atan2(sin, (ca.trace(r) - 1) / 2) / sin * v


def _so3_v(phi) -> ca.SX:
    theta = ca.norm_2(phi)
    k = _skew(phi)
    return (
        ca.SX.eye(3)
        + (1 - ca.cos(theta)) / theta**2 * k
        + (theta - ca.sin(theta)) / theta**3 * (k @ k)
    )


def _rot2(theta) -> ca.SX:
    return ca.vertcat(
        ca.horzcat(ca.cos(theta), -ca.sin(theta)), ca.horzcat(ca.sin(theta), ca.cos(theta))
    )


def _se2_v(theta) -> ca.SX:
    a, b = ca.sin(theta) / theta, (1 - ca.cos(theta)) / theta
    return ca.vertcat(ca.horzcat(a, -b), ca.horzcat(b, a))


def _sim3_w(sigma, phi) -> ca.SX:
    """W = ∫₀¹ e^{σu} Exp(uφ) du, integrated in closed form (Eade §6.2)."""
    theta = ca.norm_2(phi)
    e = ca.exp(sigma)
    d = sigma**2 + theta**2
    a = (e - 1) / sigma
    integral_sin = (e * (sigma * ca.sin(theta) - theta * ca.cos(theta)) + theta) / d
    integral_cos = (e * (sigma * ca.cos(theta) + theta * ca.sin(theta)) - sigma) / d
    k = _skew(phi)
    return a * ca.SX.eye(3) + integral_sin / theta * k + (a - integral_cos) / theta**2 * (k @ k)


def _exp(group: type[LieGroup], xi) -> ca.SX:
    if group is SO2:
        return _rot2(xi[0])
    if group is SE2:
        return _homogeneous(_rot2(xi[2]), _se2_v(xi[2]) @ xi[:2])
    if group is SO3:
        return _so3_exp(xi)
    if group is SE3:
        return _homogeneous(_so3_exp(xi[3:]), _so3_v(xi[3:]) @ xi[:3])
    if group is Sim3:
        linear = ca.exp(xi[6]) * _so3_exp(xi[3:6])
        return _homogeneous(linear, _sim3_w(xi[6], xi[3:6]) @ xi[:3])
    return series_exp(group, xi)


def series_exp(group: type[LieGroup], xi) -> ca.SX:
    """exp(hat ξ) = (Σ_k (hat ξ / 2⁸)^k / k!)^(2⁸): smooth everywhere, including at ξ = 0."""
    a = _hat(group, xi) / 2**8
    term, total = ca.SX.eye(group.matrix_size), ca.SX.eye(group.matrix_size)
    for k in range(1, 14):
        term = term @ a / k
        total = total + term
    for _ in range(8):
        total = total @ total
    return total


def _log(group: type[LieGroup], m) -> ca.SX | None:
    if group is SO2:
        return ca.atan2(m[1, 0], m[0, 0])
    if group is SE2:
        theta = ca.atan2(m[1, 0], m[0, 0])
        return ca.vertcat(ca.solve(_se2_v(theta), m[:2, 2]), theta)
    if group is SO3:
        return _so3_log(m)
    if group is SE3:
        phi = _so3_log(m[:3, :3])
        return ca.vertcat(ca.solve(_so3_v(phi), m[:3, 3]), phi)
    if group is Sim3:
        scale = ca.det(m[:3, :3]) ** (1 / 3)
        phi = _so3_log(m[:3, :3] / scale)
        sigma = ca.log(scale)
        return ca.vertcat(ca.solve(_sim3_w(sigma, phi), m[:3, 3]), phi, sigma)
    return None


def _hat(group: type[LieGroup], xi) -> ca.SX:
    generators = group.generators()
    return sum(
        (xi[k] * ca.DM(generators[k]) for k in range(group.dof)),
        ca.SX.zeros(group.matrix_size, group.matrix_size),
    )


def _vee(group: type[LieGroup], m) -> ca.SX:
    """Linear read-off of algebra coordinates (row-major flatten, then the dual basis)."""
    dual = np.linalg.pinv(group.generators().reshape(group.dof, -1))
    return ca.DM(dual.T) @ ca.reshape(m.T, -1, 1)


def between_residual(group: type[LieGroup], x_i, x_j, z) -> ca.SX:
    """r = Log(Z⁻¹ Xᵢ⁻¹ Xⱼ) on matrices (CONVENTIONS.md), with the model's closed-form Log."""
    return _log(group, ca.inv(z) @ ca.inv(x_i) @ x_j)


def between_jacobians(group: type[LieGroup], x_i, x_j, z) -> tuple[np.ndarray, np.ndarray]:
    """casadi's derivatives of r(Xᵢ·Exp(δᵢ), Xⱼ·Exp(δⱼ)) at δ = 0, for numeric 4×4 / 3×3 inputs."""
    n = group.dof
    d_i, d_j = ca.SX.sym("di", n), ca.SX.sym("dj", n)
    r = between_residual(
        group, ca.DM(x_i) @ series_exp(group, d_i), ca.DM(x_j) @ series_exp(group, d_j), ca.DM(z)
    )
    function = ca.Function("J", [d_i, d_j], [ca.jacobian(r, d_i), ca.jacobian(r, d_j)])
    jac_i, jac_j = function(np.zeros(n), np.zeros(n))
    return np.asarray(jac_i), np.asarray(jac_j)


def graph_cost(graph, held: np.ndarray):
    """The graph's ½ Σ rᵀΩr as a casadi function of the free nodes' perturbations δ.

    Node k is Xₖ·Exp(δₖ) around its current value; held nodes stay at theirs. Returns
    (δ symbol, cost expression, a function mapping a numeric δ to the node matrices).
    """
    group, n = graph.group, graph.group.dof
    free = np.setdiff1d(np.arange(graph.num_nodes), held)
    delta = ca.SX.sym("delta", free.size * n)
    base = graph.values.as_matrix()
    nodes = [ca.DM(m) for m in base]
    for slot, k in enumerate(free):
        nodes[k] = ca.DM(base[k]) @ series_exp(group, delta[slot * n : (slot + 1) * n])
    cost = 0
    edges = graph.edges
    measurements = edges.measurements.as_matrix()
    for e in range(len(edges)):
        r = between_residual(group, nodes[edges.i[e]], nodes[edges.j[e]], ca.DM(measurements[e]))
        cost += 0.5 * r.T @ ca.DM(edges.information[e]) @ r
    priors = graph.priors
    prior_measurements = priors.measurements.as_matrix()
    for e in range(len(priors)):
        r = _log(group, ca.inv(ca.DM(prior_measurements[e])) @ nodes[priors.i[e]])
        cost += 0.5 * r.T @ ca.DM(priors.information[e]) @ r
    node_function = ca.Function("nodes", [delta], [ca.vertcat(*[ca.vec(m) for m in nodes])])

    def node_matrices(delta_value: np.ndarray) -> np.ndarray:
        size = group.matrix_size
        flat = np.asarray(node_function(delta_value)).reshape(graph.num_nodes, size, size)
        return np.swapaxes(flat, 1, 2)  # casadi's vec is column-major

    return delta, cost, node_matrices


def has_log(group: type[LieGroup]) -> bool:
    """Whether the model has a closed-form Log for ``group`` (not for Aff2 and SL3)."""
    return group not in (Aff2, SL3)


INTERPOLATION_WEIGHT = 0.3
"""The α at which ``jacobian_functions`` differentiates ``interpolate``."""


def _chained(group: type[LieGroup], a, b, d, e) -> dict[str, ca.SX]:
    """``jacobian_functions``' perturbed expressions of Exp, retract, and where the model has
    a Log, of Log, local and interpolate, at X = Exp(a), Y = Exp(b), δ = d, Exp(δ) ≈ e."""
    x, y, step = _exp(group, a), _exp(group, b), _exp(group, b)
    expressions = {
        "exp": _vee(group, _exp(group, -a) @ _exp(group, a + d)),
        "retract_a": _vee(group, ca.inv(x @ step) @ x @ e @ step),
        "retract_b": _vee(group, ca.inv(step) @ _exp(group, b + d)),
    }
    if not has_log(group):
        return expressions
    expressions["jr_inv"] = _log(group, x @ e)
    expressions["jl_inv"] = _log(group, e @ x)
    expressions["log"] = _log(group, x @ e)
    expressions["local_a"] = _log(group, ca.inv(x @ e) @ y)
    expressions["local_b"] = _log(group, ca.inv(x) @ y @ e)
    middle = x @ _exp(group, INTERPOLATION_WEIGHT * _log(group, ca.inv(x) @ y))
    for name, moved_x, moved_y in (("interpolate_a", x @ e, y), ("interpolate_b", x, y @ e)):
        weighted = INTERPOLATION_WEIGHT * _log(group, ca.inv(moved_x) @ moved_y)
        expressions[name] = _vee(group, ca.inv(middle) @ moved_x @ _exp(group, weighted))
    return expressions


def jacobian_functions(group: type[LieGroup]) -> dict[str, Callable[..., np.ndarray]]:
    """Casadi Jacobians of ``group`` at X = Exp(a), Y = Exp(b) and point p.

    Each value takes arrays ``a`` (N, dof), ``b`` (N, dof), ``p`` (N, point_dim) and returns
    the (N, rows, cols) Jacobians, with the same meaning as posegraph's:
    ``jr``, ``jl``, ``jr_inv``, ``jl_inv`` (at ξ = a), ``compose_a``, ``compose_b``,
    ``inverse``, ``between_a``, ``between_b``, ``log``, ``act_element``, ``act_point``,
    ``exp`` (at a), ``retract_a``, ``retract_b`` (X.retract(b)), and where the model has a Log,
    ``local_a``, ``local_b`` (X.local(Y)), ``interpolate_a``, ``interpolate_b`` (at α =
    ``INTERPOLATION_WEIGHT``).
    """
    n = group.dof
    a, b, d = ca.SX.sym("a", n), ca.SX.sym("b", n), ca.SX.sym("d", n)
    p = ca.SX.sym("p", group.point_dim)
    exp = lambda xi: _exp(group, xi)  # noqa: E731
    x, y = exp(a), exp(b)
    # The perturbation is only differentiated at δ = 0, where Exp(δ) = I + hat(δ) + O(δ²); the
    # closed forms divide by |δ| there.
    e = ca.SX.eye(group.matrix_size) + _hat(group, d)
    z = ca.inv(x) @ y
    expressions = {
        "jr": _vee(group, exp(-a) @ exp(a + d)),
        "jl": _vee(group, exp(a + d) @ exp(-a)),
        "compose_a": _vee(group, ca.inv(x @ y) @ x @ e @ y),
        "compose_b": _vee(group, ca.inv(x @ y) @ x @ y @ e),
        "inverse": _vee(group, x @ ca.inv(x @ e)),
        "between_a": _vee(group, ca.inv(z) @ ca.inv(x @ e) @ y),
        "between_b": _vee(group, ca.inv(z) @ ca.inv(x) @ y @ e),
    }
    expressions.update(_chained(group, a, b, d, e))
    lifted = p if group.matrix_size == group.point_dim else ca.vertcat(p, 1)
    moved = (x @ e @ lifted)[: group.point_dim]
    jacobians = {name: ca.jacobian(expr, d) for name, expr in expressions.items()}
    jacobians["act_element"] = ca.jacobian(moved, d)
    jacobians["act_point"] = ca.jacobian(moved, p)

    def evaluator(expr) -> Callable[..., np.ndarray]:
        function = ca.Function("f", [a, b, p, d], [expr])

        def evaluate(
            a_values: np.ndarray, b_values: np.ndarray, p_values: np.ndarray
        ) -> np.ndarray:
            count = a_values.shape[0]
            batched = function.map(count)
            out = batched(a_values.T, b_values.T, p_values.T, np.zeros((n, count)))
            rows = expr.shape[0]
            return np.asarray(out).reshape(rows, count, expr.shape[1]).transpose(1, 0, 2)

        return evaluate

    return {name: evaluator(expr) for name, expr in jacobians.items()}

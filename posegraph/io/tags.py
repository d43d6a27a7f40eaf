"""The tags of the g2o and TORO formats: how each line becomes graph records, and back.

Conventions (CONVENTIONS.md, "g2o and TORO files"):

* information is given as the row-major upper triangle over the tag's own tangent order;
* SE3 information is taken as-is over (ρ, φ), unless the g2o-faithful reading is asked for
  (g2o's rotation error is the quaternion vector part ≈ φ/2): Λ_φφ = Λ_qq/4, Λ_ρφ = Λ_ρq/2;
* g2o's EDGE_SE3_PRIOR measures the node's pose times the offset of a PARAMS_SE3OFFSET line
  (``prior_without_offset`` moves it onto the node); written priors use offset 0, the identity;
* g2o's Sim3 tangent is (ω, υ, σ), permuted here to (ρ, φ, σ). A g2o Sim3 vertex stores the
  world → camera Sᵢ, so our Xᵢ = Sᵢ⁻¹; an edge measurement Z becomes ours as Z⁻¹.
  Dialect (a) writes the element (q, t, s); dialect (b) writes log(S⁻¹) = log(Xᵢ) (vertex,
  followed by fx fy cx cy) and log(Z⁻¹) (edge), in g2o's tangent order;
* TORO's EDGE2 information order is I11 I12 I22 I33 I13 I23 (some files, e.g. those gtsam's
  ``readG2o`` reads, use g2o's upper triangle instead: ``ReadOptions.edge2_order``);
  VERTEX3/EDGE3 rotations are roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll), information
  as-is over (x, y, z, roll, pitch, yaw), as gtsam's ``load3D`` reads it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from ..lie import SE2, SE3, LieGroup, Sim3
from ..lie.so3 import exp_matrix
from .parsing import symmetric_from_upper, upper_from_symmetric

SIM3_G2O_ORDER = np.array([3, 4, 5, 0, 1, 2, 6])
"""g2o's Sim3 tangent (ω, υ, σ): its component k is our component SIM3_G2O_ORDER[k]."""
EDGE2_ORDERS = {
    "toro": [(0, 0), (0, 1), (1, 1), (2, 2), (0, 2), (1, 2)],
    "g2o": [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)],
}
"""Entries (row, column) of the six information values of an EDGE2 line, by order name."""


@dataclasses.dataclass(frozen=True)
class TagFormat:
    """One line type.

    ``kind`` is vertex, edge, prior, parameter, fix or equiv. ``widths`` are the accepted counts
    of numbers after the tag (one per dialect), ``id_columns`` the columns holding node ids, and
    ``quaternion`` the columns of a quaternion to check. ``parse(numbers, options)`` returns
    the values (vertex, parameter) or the measurements and information (edge, prior).
    """

    kind: str
    group: type[LieGroup] | None
    widths: tuple[int, ...]
    id_columns: tuple[int, ...]
    parse: Callable | None = None
    quaternion: dict[int, slice] = dataclasses.field(default_factory=dict)

    @property
    def information_values(self) -> int:
        """How many numbers at the end of an edge or prior line are its information."""
        if self.kind not in ("edge", "prior"):
            return 0
        return self.group.dof * (self.group.dof + 1) // 2

    @property
    def widths_without_information(self) -> frozenset[int]:
        """The counts of numbers of a line that leaves out exactly its information."""
        missing = self.information_values
        return frozenset(w - missing for w in self.widths) if missing else frozenset()


# ------------------------------------------------------------------- information transforms
def _g2o_faithful_scaling() -> np.ndarray:
    """S with Ω_ours = S Ω_file S: halves the rotation rows and columns (Λ_qq/4, Λ_ρq/2)."""
    return np.diag([1.0, 1.0, 1.0, 0.5, 0.5, 0.5])


def se3_information(upper: np.ndarray, g2o_rotation_information: bool) -> np.ndarray:
    information = symmetric_from_upper(upper, 6)
    if g2o_rotation_information:
        s = _g2o_faithful_scaling()
        information = s @ information @ s
    return information


def se3_information_to_file(information: np.ndarray, g2o_rotation_information: bool) -> np.ndarray:
    if g2o_rotation_information:
        s_inv = np.linalg.inv(_g2o_faithful_scaling())
        information = s_inv @ information @ s_inv
    return upper_from_symmetric(information)


def sim3_information(upper: np.ndarray) -> np.ndarray:
    g2o_order = symmetric_from_upper(upper, 7)
    ours = np.empty_like(g2o_order)
    ours[:, SIM3_G2O_ORDER[:, None], SIM3_G2O_ORDER[None, :]] = g2o_order
    return ours


def sim3_information_to_file(information: np.ndarray) -> np.ndarray:
    return upper_from_symmetric(information[:, SIM3_G2O_ORDER[:, None], SIM3_G2O_ORDER[None, :]])


def edge2_information(values: np.ndarray, order: str) -> np.ndarray:
    """The (n, 3, 3) information of EDGE2 lines from their six values in ``order``."""
    out = np.zeros((values.shape[0], 3, 3))
    for k, (r, c) in enumerate(EDGE2_ORDERS[order]):
        out[:, r, c] = out[:, c, r] = values[:, k]
    return out


def edge2_order_text(order: str) -> str:
    """The order's entries as a file lists them, e.g. "I11 I12 I22 I33 I13 I23"."""
    return " ".join(f"I{r + 1}{c + 1}" for r, c in EDGE2_ORDERS[order])


def toro2_information_to_file(information: np.ndarray) -> np.ndarray:
    return np.stack([information[:, r, c] for r, c in EDGE2_ORDERS["toro"]], axis=1)


def prior_without_offset(
    measurements: SE3, information: np.ndarray, offsets: SE3
) -> tuple[SE3, np.ndarray]:
    """g2o's EDGE_SE3_PRIOR measures the node's pose times its PARAMS_SE3OFFSET O (g2o
    ``EdgeSE3Prior``: Z⁻¹ X O). As Log(Z⁻¹ X O) = Log(O⁻¹ (Z O⁻¹)⁻¹ X O) = Ad(O⁻¹) Log((Z O⁻¹)⁻¹ X),
    the same prior on X itself has measurement Z O⁻¹ and information Ad(O⁻¹)ᵀ Ω Ad(O⁻¹)."""
    inverse = offsets.inverse()
    adjoint = inverse.adjoint()
    moved = np.swapaxes(adjoint, -1, -2) @ information @ adjoint
    return measurements.compose(inverse), 0.5 * (moved + np.swapaxes(moved, -1, -2))


# ------------------------------------------------------------------------- element parsing
def _sim3_from_g2o_tangent(tangent: np.ndarray) -> Sim3:
    ours = np.empty_like(tangent)
    ours[:, SIM3_G2O_ORDER] = tangent
    return Sim3.exp(ours)


def sim3_to_g2o_tangent(element: Sim3) -> np.ndarray:
    return element.log()[:, SIM3_G2O_ORDER]


def _sim3_element(numbers: np.ndarray) -> Sim3:
    """From (qx qy qz qw tx ty tz s) columns: the stored (world → camera) g2o element."""
    return Sim3.from_quaternion_translation_scale(numbers[:, 0:4], numbers[:, 4:7], numbers[:, 7])


def _sim3_vertex(numbers: np.ndarray, options) -> Sim3:
    if numbers.shape[1] == 9:  # dialect (a): id q t s
        return _sim3_element(numbers[:, 1:9]).inverse()
    return _sim3_from_g2o_tangent(numbers[:, 1:8])  # dialect (b): id log(S⁻¹) fx fy cx cy


def _sim3_edge(numbers: np.ndarray, options) -> tuple[Sim3, np.ndarray]:
    if numbers.shape[1] == 38:  # dialect (a): i j q t s info
        return _sim3_element(numbers[:, 2:10]).inverse(), sim3_information(numbers[:, 10:38])
    return _sim3_from_g2o_tangent(numbers[:, 2:9]), sim3_information(numbers[:, 9:37])


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll)."""
    axes = np.eye(3)
    rz = exp_matrix(rpy[:, 2:3] * axes[2])
    ry = exp_matrix(rpy[:, 1:2] * axes[1])
    rx = exp_matrix(rpy[:, 0:1] * axes[0])
    return rz @ ry @ rx


def matrix_to_rpy(rotation: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix` (pitch in [−π/2, π/2])."""
    roll = np.arctan2(rotation[:, 2, 1], rotation[:, 2, 2])
    pitch = np.arcsin(np.clip(-rotation[:, 2, 0], -1.0, 1.0))
    yaw = np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0])
    return np.stack([roll, pitch, yaw], axis=1)


def _quaternion_pose(numbers: np.ndarray, start: int) -> SE3:
    """SE3 from columns x y z qx qy qz qw starting at ``start``."""
    return SE3.from_quaternion_translation(
        numbers[:, start + 3 : start + 7], numbers[:, start : start + 3]
    )


def _rpy_pose(numbers: np.ndarray, start: int) -> SE3:
    return SE3(rpy_to_matrix(numbers[:, start + 3 : start + 6]), numbers[:, start : start + 3])


G2O_TAGS: dict[str, TagFormat] = {
    "VERTEX_SE2": TagFormat("vertex", SE2, (4,), (0,), lambda n, o: SE2.from_xytheta(n[:, 1:4])),
    "EDGE_SE2": TagFormat(
        "edge",
        SE2,
        (11,),
        (0, 1),
        lambda n, o: (SE2.from_xytheta(n[:, 2:5]), symmetric_from_upper(n[:, 5:11], 3)),
    ),
    "EDGE_PRIOR_SE2": TagFormat(
        "prior",
        SE2,
        (10,),
        (0,),
        lambda n, o: (SE2.from_xytheta(n[:, 1:4]), symmetric_from_upper(n[:, 4:10], 3)),
    ),
    "VERTEX_SE3:QUAT": TagFormat(
        "vertex", SE3, (8,), (0,), lambda n, o: _quaternion_pose(n, 1), quaternion={8: slice(4, 8)}
    ),
    "EDGE_SE3:QUAT": TagFormat(
        "edge",
        SE3,
        (30,),
        (0, 1),
        lambda n, o: (
            _quaternion_pose(n, 2),
            se3_information(n[:, 9:30], o.g2o_rotation_information),
        ),
        quaternion={30: slice(5, 9)},
    ),
    "PARAMS_SE3OFFSET": TagFormat(  # parameter id, x y z qx qy qz qw
        "parameter",
        None,
        (8,),
        (),
        lambda n, o: _quaternion_pose(n, 1),
        quaternion={8: slice(4, 8)},
    ),
    "EDGE_SE3_PRIOR": TagFormat(  # id, offset parameter id, pose, info (see prior_without_offset)
        "prior",
        SE3,
        (30,),
        (0,),
        lambda n, o: (
            _quaternion_pose(n, 2),
            se3_information(n[:, 9:30], o.g2o_rotation_information),
        ),
        quaternion={30: slice(5, 9)},
    ),
    "VERTEX_SIM3:EXPMAP": TagFormat(
        "vertex", Sim3, (9, 12), (0,), _sim3_vertex, quaternion={9: slice(1, 5)}
    ),
    "EDGE_SIM3:EXPMAP": TagFormat(
        "edge", Sim3, (38, 37), (0, 1), _sim3_edge, quaternion={38: slice(2, 6)}
    ),
    "FIX": TagFormat("fix", None, (), (0,)),
}
"""g2o tags. Widths count the numbers after the tag, ids included."""

TORO_TAGS: dict[str, TagFormat] = {
    "VERTEX2": TagFormat("vertex", SE2, (4,), (0,), lambda n, o: SE2.from_xytheta(n[:, 1:4])),
    "EDGE2": TagFormat(
        "edge",
        SE2,
        (11,),
        (0, 1),
        lambda n, o: (SE2.from_xytheta(n[:, 2:5]), edge2_information(n[:, 5:11], o.edge2_order)),
    ),
    "VERTEX3": TagFormat("vertex", SE3, (7,), (0,), lambda n, o: _rpy_pose(n, 1)),
    "EDGE3": TagFormat(
        "edge",
        SE3,
        (29,),
        (0, 1),
        lambda n, o: (_rpy_pose(n, 2), symmetric_from_upper(n[:, 8:29], 6)),
    ),
    "EQUIV": TagFormat("equiv", None, (2,), (0, 1)),
}
"""TORO tags (2D and 3D)."""

LANDMARK_TAGS = frozenset(
    {
        "VERTEX_XY",
        "VERTEX_TRACKXYZ",
        "EDGE_SE2_XY",
        "EDGE_BEARING_SE2_XY",
        "EDGE_SE2_XY_CALIB",
        "EDGE_SE2_POINTXY_OFFSET",
        "EDGE_SE2_TWOPOINTSXY",
        "EDGE_SE2_LOTSOFXY",
        "EDGE_POINTXY",
        "EDGE_PRIOR_XY",
        "EDGE_SE3_TRACKXYZ",
        "EDGE_SE3_LOTSOF_XYZ",
        "EDGE_POINTXYZ",
        "EDGE_POINTXYZ_PRIOR",
        "EDGE_PROJECT_DEPTH",
        "EDGE_PROJECT_DISPARITY",
        "LANDMARK2",
        "BR",
    }
)
"""Tags of landmark (point) vertices and of measurements of points: g2o's (types_slam2d and
types_slam3d), and LANDMARK2 and the bearing-range BR of gtsam's example files. Not read, as
posegraph optimises poses only."""

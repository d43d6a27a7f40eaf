"""How a g2o or TORO file is read (``ReadOptions``)."""

from __future__ import annotations

import dataclasses

from ..graph.repair import REPAIRS
from ..sim3.lifting import check_scale_information
from .tags import EDGE2_ORDERS


@dataclasses.dataclass(frozen=True)
class ReadOptions:
    """How to read a file.

    Attributes:
        lenient: skip bad lines and unknown tags (reported in ``ReadResult.skipped``) instead of
            stopping at the first.
        g2o_rotation_information: read SE3 information the way g2o itself weighs it
            (Λ_φφ = Λ_qq/4, Λ_ρφ = Λ_ρq/2) instead of as-is over (ρ, φ) like gtsam.
        identity_information: weigh every edge and prior by the identity, ignoring the file's
            information (TORO's -ic, for files whose information is missing or not trusted);
            lines may then omit their information values.
        edge2_order: the order of the six information values of TORO's EDGE2 lines: "toro"
            (I11 I12 I22 I33 I13 I23, TORO's own) or "g2o" (the upper triangle, row-major, as
            gtsam's ``readG2o`` reads them).
        repair_information: None (refuse a matrix that is not positive semi-definite), "psd"
            (clip its eigenvalues at a small floor: ``posegraph.graph.repair``) or "isotropic"
            (every matrix becomes SE-Sync's model: one translation and one rotation precision
            per measurement). ``ReadResult.repaired_information`` counts the matrices changed.
        scale_information: see below.
    """

    lenient: bool = False
    g2o_rotation_information: bool = False
    identity_information: bool = False
    edge2_order: str = "toro"
    repair_information: str | None = None
    scale_information: float | None = None
    """For files mixing SE3 and Sim3 lines (monocular odometry plus Sim3 loop closures):
    ``load_graph`` lifts the SE3 lines to Sim3 with scale 1 and this information on log-scale
    (``read_graph`` leaves it out: the file gives none) (None:
    ``posegraph.sim3.lifting.default_scale_information`` of the SE3 edges and of the scale change per
    edge that the Sim3 edges call for, ``posegraph.sim3.lifting.loop_scale_sigma``)."""

    def __post_init__(self) -> None:
        if self.edge2_order not in EDGE2_ORDERS:
            raise ValueError(
                f"edge2_order must be one of {', '.join(EDGE2_ORDERS)}, not {self.edge2_order!r}"
            )
        if self.repair_information not in (None, *REPAIRS):
            raise ValueError(
                f"repair_information must be one of {', '.join(REPAIRS)} or None, not"
                f" {self.repair_information!r}"
            )
        check_scale_information(self.scale_information)

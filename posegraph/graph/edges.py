"""``EdgeSet``: stacked measurements of one kind (between edges or priors), and the selections of
measurements by index or mask."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..lie import LieGroup
from ..lie.equality import same_entries


@dataclasses.dataclass(frozen=True, eq=False)
class EdgeSet:
    """Stacked edges of one kind. For priors, ``j`` is unused and equals ``i``."""

    i: np.ndarray
    j: np.ndarray
    measurements: LieGroup
    information: np.ndarray

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @classmethod
    def empty(cls, group: type[LieGroup]) -> EdgeSet:
        d = group.dof
        empty_index = np.zeros(0, dtype=np.int64)
        return cls(empty_index, empty_index, group.identity((0,)), np.zeros((0, d, d)))

    @staticmethod
    def joined(sets: list[EdgeSet]) -> EdgeSet:
        """The edge sets end to end, in order."""
        group = type(sets[0].measurements)
        return EdgeSet(
            np.concatenate([edges.i for edges in sets]),
            np.concatenate([edges.j for edges in sets]),
            group.concatenate([edges.measurements for edges in sets]),
            np.concatenate([edges.information for edges in sets]),
        )

    def extended(self, other: EdgeSet) -> EdgeSet:
        return EdgeSet.joined([self, other])

    def starts_with(self, other: EdgeSet) -> bool:
        """Whether the first ``len(other)`` edges are exactly ``other``'s."""
        count = len(other)
        return (
            count <= len(self)
            and same_entries(self.i[:count], other.i)
            and same_entries(self.j[:count], other.j)
            and same_entries(self.information[:count], other.information)
            and self.measurements[:count].same_as(other.measurements)
        )

    def subset(self, keep: np.ndarray) -> EdgeSet:
        return EdgeSet(self.i[keep], self.j[keep], self.measurements[keep], self.information[keep])

    def reindexed(self, index: np.ndarray) -> EdgeSet:
        """The same measurements on nodes renumbered by ``index`` (old index → new)."""
        return dataclasses.replace(self, i=index[self.i], j=index[self.j])

    def weighted(self, weights: np.ndarray) -> EdgeSet:
        """The edges of positive weight, each information matrix times its weight."""
        kept = weights > 0
        kept_edges = self.subset(kept)
        return dataclasses.replace(
            kept_edges, information=kept_edges.information * weights[kept, None, None]
        )


def renumbered(kept: np.ndarray) -> np.ndarray:
    """Per entry of a sequence, its index among the ``kept`` ones (a mask), or −1."""
    index = np.full(kept.size, -1, dtype=np.int64)
    index[kept] = np.arange(np.count_nonzero(kept))
    return index


def measurement_mask(given, count: int, noun: str, what: str) -> np.ndarray:
    """A new boolean mask over ``count`` measurements (``noun``: "edge" or "prior") from their
    indices (negative ones count from the end, as in Python) or from a boolean mask with one
    entry per measurement. Anything else is a ``ValueError`` that names ``what`` was chosen
    ("edges to remove", "robust edges") and what is wrong."""
    given = np.asarray(given)
    if given.dtype == bool:
        if given.shape != (count,):
            raise ValueError(
                f"{what} given as a mask have one entry per {noun} ({count}), not shape "
                f"{given.shape}"
            )
        return given.copy()
    indices = np.atleast_1d(given)
    if indices.ndim != 1 or (indices.size and indices.dtype.kind not in "iu"):
        raise ValueError(
            f"{what} are given by integer indices or a boolean mask, not by {given.dtype} of "
            f"shape {given.shape}"
        )
    outside = (indices < -count) | (indices >= count)
    if outside.any():
        raise ValueError(
            f"{noun} index {indices[outside][0]} is out of range ({what}): the graph has "
            f"{count} {noun}s"
        )
    mask = np.zeros(count, dtype=bool)
    mask[indices.astype(np.int64)] = True
    return mask

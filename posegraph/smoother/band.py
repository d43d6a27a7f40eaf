"""Symmetric band matrices, held by the rows of their band: a fixed-lag window's H, whose nodes
are in time order and whose measurements reach a few poses back, costs n·b to store, multiply
and factorise (LAPACK's ``dpbtrf``) where a dense H costs n² and n³/3."""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import as_strided, sliding_window_view


class BandMatrix:
    """A symmetric n × n matrix A zero more than ``bandwidth`` b entries off its diagonal,
    stored as ``rows`` (n, 2b + 1) with ``rows[i, b + j − i] = A[i, j]`` for |i − j| ≤ b
    (entries outside the matrix are zero), followed in memory by b rows of zeros."""

    def __init__(self, padded: np.ndarray, size: int) -> None:
        self._padded = padded
        self.rows = padded[:size]
        self.size = size
        self.bandwidth = (padded.shape[1] - 1) // 2

    @classmethod
    def of_blocks(
        cls, rows: np.ndarray, columns: np.ndarray, blocks: np.ndarray, size: int, bandwidth: int
    ) -> BandMatrix:
        """The size × size matrix of (d, d) ``blocks`` summed at block ``rows`` and ``columns``,
        each within ``bandwidth`` of the diagonal (both triangles given). Entry (R d + a, C d + c)
        lies at R d (w − 1) + C d + b + a (w − 1) + c of the rows, w = 2b + 1 their width."""
        d, width = blocks.shape[-1], 2 * bandwidth + 1
        within = np.arange(d)[:, None] * (width - 1) + np.arange(d)
        start = (rows * (width - 1) + columns) * d + bandwidth
        flat = (start[:, None, None] + within).ravel()
        padded = np.bincount(flat, blocks.ravel(), (size + bandwidth) * width)
        return cls(padded.reshape(size + bandwidth, width), size)

    def add(self, at: np.ndarray, block: np.ndarray) -> None:
        """A += ``block`` at rows and columns ``at`` (distinct, within the band of each other)."""
        self.rows[at[:, None], self.bandwidth + at[None, :] - at[:, None]] += block

    def __matmul__(self, vector: np.ndarray) -> np.ndarray:
        """A x for a vector x (n,)."""
        b = self.bandwidth
        padded = np.zeros(self.size + 2 * b)
        padded[b : b + self.size] = vector
        return np.einsum("it,it->i", self.rows, sliding_window_view(padded, 2 * b + 1))

    def lower(self) -> np.ndarray:
        """LAPACK's lower band storage (b + 1, n), a new array: ``band[k, j] = A[j + k, j]``,
        row j + k's entry b − k, at b + j w + k (w − 1) of the rows; the zero rows after them
        give the entries past the matrix."""
        b, n = self.bandwidth, self.size
        flat = self._padded.reshape(-1)[b:]
        step = flat.strides[0]
        width = self._padded.shape[1]
        return as_strided(flat, (b + 1, n), ((width - 1) * step, width * step)).copy()

    def toarray(self) -> np.ndarray:
        """A as a dense n × n array."""
        b, n = self.bandwidth, self.size
        i, t = np.indices(self.rows.shape)
        j = i - b + t
        inside = (j >= 0) & (j < n)
        dense = np.zeros((n, n))
        dense[i[inside], j[inside]] = self.rows[inside]
        return dense

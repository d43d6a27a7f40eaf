"""Bit-for-bit equality of stored arrays, cheap where they are views of one memory."""

from __future__ import annotations

import numpy as np


def same_entries(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two arrays hold the same entries, bit for bit: views of one memory with one
    shape and layout (a stream's stacks, which grow in a buffer with room, are read so at every
    call), else compared entry by entry."""
    if a.shape == b.shape and a.strides == b.strides and a.dtype == b.dtype:
        if a.__array_interface__["data"][0] == b.__array_interface__["data"][0]:
            return True
    return np.array_equal(a, b)

"""Bit-for-bit equality of stored arrays: views of one memory, and copies compared entry by
entry."""

from __future__ import annotations

import numpy as np

from posegraph.lie.equality import same_entries


def test_views_of_one_memory_are_the_same_and_copies_are_compared():
    buffer = np.arange(12.0).reshape(6, 2)
    assert same_entries(buffer[:4], buffer[:4])
    assert same_entries(buffer[:4], buffer[:4].copy())
    changed = buffer[:4].copy()
    changed[3, 1] = -1.0
    assert not same_entries(buffer[:4], changed)
    assert not same_entries(buffer[:4], buffer[1:5])  # one memory, other rows
    assert not same_entries(buffer[:4], buffer[:3])
    assert not same_entries(buffer[:, 0], buffer[:, 1])  # other columns, same shape

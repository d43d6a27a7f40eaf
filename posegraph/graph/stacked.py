"""``Stacked``: a growing stack of rows (node ids, values, edges) that a graph appends to and
reads between appends, in amortised O(1) a step."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..lie import LieGroup


class Stacked:
    """A stacked value (an array, group elements or an ``EdgeSet``) at the front of a buffer
    with room to grow. Appending writes into the room, and a full buffer is reallocated at
    twice the size, so that a loop that adds a node and an edge and reads the graph after each
    costs O(1) a step, not O(n). A read gives views of the filled part (the same object until
    the next change)."""

    __slots__ = ("_buffer", "_view", "length")

    def __init__(self, value) -> None:
        self.set(value)

    def set(self, value) -> None:
        self._buffer = self._view = value
        self.length = len(value)

    def append(self, part) -> None:
        count = len(part)
        end = self.length + count
        if end > len(self._buffer):
            self._buffer = _with_room(self.get(), max(end, 2 * self.length))
        _write(self._buffer, self.length, count, part)
        self._view, self.length = None, end

    def get(self):
        if self._view is None:
            self._view = _prefix(self._buffer, self.length)
        return self._view


def _with_room(value, capacity: int):
    """A copy of ``value`` (an array, or a dataclass of them) at the front of ``capacity`` rows."""
    if isinstance(value, LieGroup):
        value = value[:]  # every field at the full batch shape
    if isinstance(value, np.ndarray):
        room = np.empty((capacity,) + value.shape[1:], dtype=value.dtype)
        room[: len(value)] = value
        return room
    return _fields_mapped(value, lambda field: _with_room(field, capacity))


def _write(buffer, start: int, count: int, part) -> None:
    """``part`` (``count`` rows) into ``buffer`` from row ``start``, in place."""
    if isinstance(buffer, np.ndarray):
        buffer[start : start + count] = part
        return
    for field in dataclasses.fields(buffer):
        _write(getattr(buffer, field.name), start, count, getattr(part, field.name))


def _prefix(buffer, length: int):
    """Views of the first ``length`` rows of ``buffer``."""
    if isinstance(buffer, np.ndarray):
        return buffer[:length]
    return _fields_mapped(buffer, lambda field: _prefix(field, length))


def _fields_mapped(value, function):
    """A dataclass like ``value``, each field mapped by ``function``."""
    return type(value)(
        **{field.name: function(getattr(value, field.name)) for field in dataclasses.fields(value)}
    )

"""The size of the Cholesky factor that CHOLMOD's symbolic analysis predicts, read back from the
factor that cvxopt returns: the column counts cⱼ of L, so that nnz(L) = Σ cⱼ and the numeric
factorisation takes about Σ cⱼ² flops (Davis 2006, "Direct Methods for Sparse Linear Systems",
§4.2). cvxopt does not expose them; they are the leading fields of CHOLMOD's ``cholmod_factor``
(``n``, ``minor``, ``Perm``, ``ColCount``; cholmod.h), unchanged from CHOLMOD 1 to 5. What is
read is checked against the matrix's size and the bounds of a column count, and where it does
not fit, nothing is predicted."""

from __future__ import annotations

import ctypes

import numpy as np

_CAPSULE = b"CHOLMOD FACTOR D L"
"""The name that cvxopt gives the capsule of a real factor."""
_ITYPE_OFFSET = 192
"""Byte offset of ``itype`` (after 22 size_t or pointer fields and 4 ints, on 64-bit)."""
_LONG = 2
"""``CHOLMOD_LONG``: 64-bit integers."""


class _Leading(ctypes.Structure):
    _fields_ = [
        ("n", ctypes.c_size_t),
        ("minor", ctypes.c_size_t),
        ("perm", ctypes.c_void_p),
        ("column_counts", ctypes.c_void_p),
    ]


def predicted_column_counts(factor: object, size: int) -> np.ndarray | None:
    """cⱼ of the factor that ``factor`` (cvxopt's symbolic factorisation of a ``size`` × ``size``
    matrix) predicts, each between 1 and size − j; None where they cannot be read."""
    if ctypes.sizeof(ctypes.c_void_p) != 8 or size == 0:
        return None
    get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
    get_pointer.restype, get_pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    try:
        address = get_pointer(factor, _CAPSULE)
    except ValueError:  # not a capsule of that name
        return None
    leading = _Leading.from_address(address)
    itype = ctypes.c_int.from_address(address + _ITYPE_OFFSET).value
    if leading.n != size or not leading.column_counts:
        return None
    integer = ctypes.c_int64 if itype == _LONG else ctypes.c_int32
    counts = np.ctypeslib.as_array((integer * size).from_address(leading.column_counts)).copy()
    if np.any(counts < 1) or np.any(counts > size - np.arange(size)):
        return None
    return counts.astype(np.int64)


def predicted_flops(factor: object, size: int) -> float | None:
    """Σ cⱼ², about the flops of the numeric factorisation, or None (``predicted_column_counts``)."""
    counts = predicted_column_counts(factor, size)
    return None if counts is None else float(np.square(counts, dtype=float).sum())

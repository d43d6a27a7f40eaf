"""The product of n Stiefel manifolds St(d, r)ⁿ as r × dn matrices Y = [Y₁ … Yₙ], Yᵢᵀ Yᵢ = I_d,
with the Euclidean metric (Absil, Mahony and Sepulchre 2008, §3.6; SE-Sync eqs. 41–44)."""

from __future__ import annotations

import numpy as np


def blocks(y: np.ndarray, d: int) -> np.ndarray:
    """The n blocks (n, r, d) of an r × dn matrix."""
    r = y.shape[0]
    return y.reshape(r, -1, d).transpose(1, 0, 2)


def joined(parts: np.ndarray) -> np.ndarray:
    """The r × dn matrix of n blocks (n, r, d)."""
    n, r, d = parts.shape
    return parts.transpose(1, 0, 2).reshape(r, n * d)


def sym_block_products(y: np.ndarray, g: np.ndarray, d: int) -> np.ndarray:
    """Sym(Yᵢᵀ Gᵢ) of each block (n, d, d)."""
    product = np.swapaxes(blocks(y, d), 1, 2) @ blocks(g, d)
    return 0.5 * (product + np.swapaxes(product, 1, 2))


def project(y: np.ndarray, v: np.ndarray, d: int) -> np.ndarray:
    """The tangent part of V at Y: Vᵢ − Yᵢ Sym(Yᵢᵀ Vᵢ)."""
    return v - joined(blocks(y, d) @ sym_block_products(y, v, d))


def retract(y: np.ndarray, v: np.ndarray, d: int) -> np.ndarray:
    """Y + V moved onto the manifold block by block by the Q factor of its QR decomposition,
    signed so that R has a positive diagonal."""
    q, r = np.linalg.qr(blocks(y + v, d))
    signs = np.sign(np.diagonal(r, axis1=1, axis2=2))
    signs[signs == 0] = 1.0
    return joined(q * signs[:, None, :])


def lifted(y: np.ndarray) -> np.ndarray:
    """Y in St(d, r + 1)ⁿ: a row of zeros below."""
    return np.vstack([y, np.zeros((1, y.shape[1]))])

"""Small batched linear algebra that gives the same answer on every CPU.

``numpy.matmul`` and ``numpy.linalg.solve`` hand small matrices to the BLAS
and LAPACK of the machine, whose kernels (chosen per CPU, e.g. by
``OPENBLAS_CORETYPE``) round differently.  The hot loops of registration use
these instead: plain element-wise arithmetic and reductions, whose rounding
does not depend on the kernel.  And where a ranked list is cut, the order
comes from :func:`stable_order`, which does not let the last bits of a score
decide between near-equal entries.
"""

from __future__ import annotations

import numpy as np

__all__ = ["transform", "rotate", "compose", "solve_spd", "gram", "stable_order", "stable_prefix", "clearly_less",
           "QUANTUM"]

#: relative size of the score bands within which :func:`stable_order` breaks ties by index
QUANTUM = 1e-9


def rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R @ v`` for rotations ``R (..., 3, 3)`` and vectors ``v (..., 3)`` (broadcast)."""
    return R[..., 0] * v[..., 0, None] + R[..., 1] * v[..., 1, None] + R[..., 2] * v[..., 2, None]


def transform(R: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Points ``x (m, 3)`` under each pose ``R (h, 3, 3), t (h, 3)``: ``(h, m, 3)``."""
    Rh = R[:, None]                                                       # (h, 1, 3, 3)
    return (Rh[..., 0] * x[None, :, 0, None] + Rh[..., 1] * x[None, :, 1, None]
            + Rh[..., 2] * x[None, :, 2, None] + t[:, None, :])


def compose(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B`` for stacks of 3 x 3 matrices (broadcast over the leading axes)."""
    A, B = np.broadcast_arrays(A, B)
    out = np.empty(A.shape)
    for j in range(3):
        out[..., :, j] = A[..., :, 0] * B[..., 0, j, None] + A[..., :, 1] * B[..., 1, j, None] \
            + A[..., :, 2] * B[..., 2, j, None]
    return out


def gram(J: np.ndarray, r: np.ndarray | None = None):
    """``J^T J (h, k, k)`` and, with ``r (h, m)``, ``J^T r (h, k)`` for ``J (h, m, k)``."""
    k = J.shape[-1]
    G = np.empty(J.shape[:-2] + (k, k))
    for i in range(k):
        for j in range(i, k):
            G[..., i, j] = G[..., j, i] = np.sum(J[..., i] * J[..., j], axis=-1)
    if r is None:
        return G
    return G, np.sum(J * r[..., None], axis=-2)


def solve_spd(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve ``A x = b`` for symmetric positive definite ``A (h, k, k)``, ``b (h, k)`` (Cholesky)."""
    k = A.shape[-1]
    L = np.zeros_like(A)
    for j in range(k):
        s = A[..., j, j] - np.sum(L[..., j, :j] ** 2, axis=-1)
        L[..., j, j] = np.sqrt(np.maximum(s, 1e-300))
        for i in range(j + 1, k):
            L[..., i, j] = (A[..., i, j] - np.sum(L[..., i, :j] * L[..., j, :j], axis=-1)) / L[..., j, j]
    y = np.empty_like(b)
    for i in range(k):
        y[..., i] = (b[..., i] - np.sum(L[..., i, :i] * y[..., :i], axis=-1)) / L[..., i, i]
    x = np.empty_like(b)
    for i in reversed(range(k)):
        x[..., i] = (y[..., i] - np.sum(L[..., i + 1:, i] * x[..., i + 1:], axis=-1)) / L[..., i, i]
    return x


def _bands(values: np.ndarray, quantum: float) -> np.ndarray:
    """Each of ``values (n,)`` as its band of width ``1 + quantum`` (inf where not finite)."""
    v = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(v)
    with np.errstate(divide="ignore"):
        band = np.floor(np.log(np.maximum(np.where(finite, v, 1.0), 1e-300)) / np.log1p(quantum))
    return np.where(finite, band, np.inf)


def stable_order(values: np.ndarray, *, quantum: float = QUANTUM) -> np.ndarray:
    """Indices sorting ``values (n,)`` (non-negative scores) ascending, with values within a
    factor ``1 + quantum`` of each other ordered by index (non-finite values last, by index).

    A cut ``stable_order(v)[:k]`` then keeps the same entries whatever the last bits of ``v``:
    rounding can only reorder values that fall in one band, and there the index decides.
    """
    return np.argsort(_bands(values, quantum), kind="stable")                # equal bands keep the index order


def stable_prefix(values: np.ndarray, count: int, *, quantum: float = QUANTUM) -> np.ndarray:
    """The start of :func:`stable_order` ``(values)``: its first ``count`` indices (``count >= 1``)
    and the rest of the last one's band (all of them where there are fewer), without sorting the
    others."""
    if count < 1:
        raise ValueError(f"a prefix of at least one index, not {count!r}")
    key = _bands(values, quantum)
    if count >= len(key):
        return np.argsort(key, kind="stable")
    last = np.partition(key, count - 1)[count - 1]
    head = np.flatnonzero(key <= last)                  # in index order: a stable sort keeps it in a band
    return head[np.argsort(key[head], kind="stable")]


def clearly_less(a: float, b: float, *, quantum: float = QUANTUM) -> bool:
    """Whether score ``a`` is below ``b`` by more than a factor ``1 + quantum``: a later pose replaces
    a kept one only then, so two poses that fit equally (a symmetric model's mirror images) are not
    swapped by the last bits of their scores."""
    return bool(a * (1.0 + quantum) < b)

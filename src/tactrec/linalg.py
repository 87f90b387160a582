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

import math

import numpy as np

__all__ = ["transform", "rotate", "tangents", "compose", "solve_spd", "gram", "stable_order", "stable_prefix",
           "clearly_less", "QUANTUM", "cross", "dot3", "norm3", "det3", "times", "eigh", "eigvalsh", "lstsq",
           "inverse_spd", "RANK_TOL"]

#: relative size of the score bands within which :func:`stable_order` breaks ties by index
QUANTUM = 1e-9
#: a column counts as dependent in :func:`lstsq` where its squared sine to the others' span is below this
RANK_TOL = 1e-12


def dot3(a, b) -> np.ndarray:
    """``a . b`` along the last axis of 3-vectors ``a (..., 3)``, ``b (..., 3)`` (broadcast): ``rows @ v``,
    ``v @ v`` without the BLAS."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over the last axis (``(..., 3)``; :func:`numpy.cross` without its overhead on small arrays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def norm3(v) -> np.ndarray:
    """Euclidean length along the last axis of 3-vectors ``v (..., 3)``."""
    return np.sqrt(dot3(v, v))


def det3(M) -> float:
    """The determinant of a 3 x 3 matrix (its rows' triple product)."""
    M = np.asarray(M, dtype=np.float64)
    return float(dot3(M[0], np.cross(M[1], M[2])))


def times(X, M) -> np.ndarray:
    """``X @ M`` for rows ``X (..., k)`` and one small matrix ``M (k, m)``: a sum of ``k`` scaled rows of
    ``M``, in index order (``X @ L.T`` is ``times(X, L.T)``)."""
    X, M = np.asarray(X, dtype=np.float64), np.asarray(M, dtype=np.float64)
    out = X[..., 0, None] * M[0]
    for i in range(1, M.shape[0]):
        out = out + X[..., i, None] * M[i]
    return out


def eigh(A) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues ``(k,)`` (ascending) and eigenvectors (columns of ``(k, k)``) of a small symmetric
    matrix ``A (k, k)``, by cyclic Jacobi rotations in Python floats.

    The eigenvalues are accurate to a few units in the last place of the largest; equal ones keep
    their order on the diagonal.  Each eigenvector's sign makes its largest component (the first of
    equal ones) positive, so the answer is the same wherever it is computed."""
    k = len(A)
    a = [[float(A[i][j]) for j in range(k)] for i in range(k)]
    v = [[1.0 if i == j else 0.0 for j in range(k)] for i in range(k)]
    for _ in range(100):
        rotated = False
        for p in range(k - 1):
            for q in range(p + 1, k):
                apq = a[p][q]
                if apq == 0.0:
                    continue
                if abs(apq) <= 1e-18 * (abs(a[p][p]) + abs(a[q][q])):     # below every rounding of the diagonal
                    a[p][q] = a[q][p] = 0.0
                    continue
                rotated = True
                theta = (a[q][q] - a[p][p]) / (2.0 * apq)
                t = math.copysign(1.0, theta) / (abs(theta) + math.hypot(theta, 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                a[p][p] -= t * apq
                a[q][q] += t * apq
                a[p][q] = a[q][p] = 0.0
                for r in range(k):
                    if r != p and r != q:
                        arp, arq = a[r][p], a[r][q]
                        a[r][p] = a[p][r] = c * arp - s * arq
                        a[r][q] = a[q][r] = s * arp + c * arq
                for r in range(k):
                    vrp, vrq = v[r][p], v[r][q]
                    v[r][p], v[r][q] = c * vrp - s * vrq, s * vrp + c * vrq
        if not rotated:
            break
    order = sorted(range(k), key=lambda i: (a[i][i], i))
    w = np.array([a[i][i] for i in order])
    V = np.array([[v[r][i] for i in order] for r in range(k)])
    for j in range(k):
        if V[int(np.argmax(np.abs(V[:, j]))), j] < 0:
            V[:, j] = -V[:, j]
    return w, V


def eigvalsh(A) -> np.ndarray:
    """The eigenvalues ``(k,)`` of a small symmetric matrix, ascending (:func:`eigh`)."""
    return eigh(A)[0]


def inverse_spd(A) -> np.ndarray:
    """The inverse of one symmetric positive definite matrix ``A (k, k)`` (:func:`solve_spd`)."""
    A = np.asarray(A, dtype=np.float64)
    k = len(A)
    return solve_spd(np.broadcast_to(A, (k, k, k)), np.eye(k))               # row i: A^-1 e_i


def lstsq(A, y, *, tol: float = RANK_TOL) -> tuple[np.ndarray, int]:
    """Least-squares ``x`` minimising ``|A x - y|`` for a tall ``A (m, k)`` and ``y (m,)`` or
    ``(m, n)``, by the normal equations (:func:`gram`, :func:`solve_spd`), and the rank of ``A``.

    A column whose squared sine to the span of the ones before it is below ``tol`` counts as
    dependent: the rank drops and its coefficient is 0 (the fit is as good, though ``x`` is not
    the shortest one).  Meant for well-conditioned bases (polynomials on ``[-1, 1]``), where the
    normal equations lose nothing that matters."""
    A, y = np.asarray(A, dtype=np.float64), np.asarray(y, dtype=np.float64)
    G = gram(A[None])[0]
    k = G.shape[0]
    d = [math.sqrt(G[j, j]) for j in range(k)]
    L = [[0.0] * k for _ in range(k)]           # Cholesky of the unit-diagonal G over the kept columns
    keep: list[int] = []
    for j in range(k):
        if not d[j] > 0:
            continue
        row = [0.0] * k
        for n, i in enumerate(keep):
            s = G[j, i] / (d[j] * d[i]) - math.fsum(row[p] * L[i][p] for p in keep[:n])
            row[i] = s / L[i][i]
        pivot = 1.0 - math.fsum(row[i] * row[i] for i in keep)
        if pivot > tol:
            row[j] = math.sqrt(pivot)
            L[j] = row
            keep.append(j)
    Y = y.reshape(len(y), -1)
    x = np.zeros((k, Y.shape[1]))
    if keep:
        Gk = np.broadcast_to(G[np.ix_(keep, keep)], (Y.shape[1], len(keep), len(keep)))
        b = np.stack([np.sum(A[:, keep] * Y[:, i, None], axis=0) for i in range(Y.shape[1])])
        x[keep] = solve_spd(Gk, b).T
    return (x[:, 0] if y.ndim == 1 else x), len(keep)


def rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R @ v`` for rotations ``R (..., 3, 3)`` and vectors ``v (..., 3)`` (broadcast)."""
    return R[..., 0] * v[..., 0, None] + R[..., 1] * v[..., 1, None] + R[..., 2] * v[..., 2, None]


def transform(R: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Points ``x (m, 3)`` under each pose ``R (h, 3, 3), t (h, 3)``: ``(h, m, 3)``."""
    Rh = R[:, None]                                                       # (h, 1, 3, 3)
    return (Rh[..., 0] * x[None, :, 0, None] + Rh[..., 1] * x[None, :, 1, None]
            + Rh[..., 2] * x[None, :, 2, None] + t[:, None, :])


def tangents(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit directions ``(n, 3)`` across each of the unit ``normals (n, 3)``, at right angles to each
    other: the first across the normal and its smallest axis, the second across both (no BLAS)."""
    d1 = np.cross(normals, np.eye(3)[np.argmin(np.abs(normals), axis=1)])
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    return d1, np.cross(normals, d1)


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

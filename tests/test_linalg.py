"""The small linear algebra of the hot loops: the same results as numpy's BLAS-backed calls."""

import numpy as np

from tactrec.linalg import (clearly_less, compose, det3, dot3, eigh, eigvalsh, gram, inverse_spd, lstsq, norm3, rotate,
                            solve_spd, stable_order, times, transform)


def test_solve_spd_matches_numpy():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(50, 30, 6))
    A = np.einsum("hmi,hmj->hij", J, J) + 1e-3 * np.eye(6)
    b = rng.normal(size=(50, 6))
    assert np.allclose(solve_spd(A, b), np.linalg.solve(A, b[..., None])[..., 0], rtol=1e-9, atol=1e-12)


def test_gram_transform_rotate_compose_match_numpy():
    rng = np.random.default_rng(1)
    J, r = rng.normal(size=(7, 20, 6)), rng.normal(size=(7, 20))
    G, g = gram(J, r)
    assert np.allclose(G, np.swapaxes(J, 1, 2) @ J) and np.allclose(g, np.einsum("hmi,hm->hi", J, r))
    R, t, x = rng.normal(size=(7, 3, 3)), rng.normal(size=(7, 3)), rng.normal(size=(20, 3))
    assert np.allclose(transform(R, t, x), x @ np.swapaxes(R, 1, 2) + t[:, None])
    assert np.allclose(rotate(R, t), np.einsum("hij,hj->hi", R, t))
    assert np.allclose(compose(R, R[::-1]), R @ R[::-1])


def test_stable_order_breaks_near_ties_by_index_and_keeps_real_differences():
    v = np.array([3.0, 1.0 + 1e-13, 1.0, 2.0, np.inf, np.nan, 0.5])
    assert list(stable_order(v)) == [6, 1, 2, 3, 0, 4, 5]      # 1 + 1e-13 and 1 tie: index order
    w = v.copy()
    w[1], w[2] = 1.0, 1.0 + 1e-13                              # rounding swapped them: the same order
    assert list(stable_order(w)) == list(stable_order(v))
    assert list(stable_order(np.array([1.0, 1.0 + 1e-6]))) == [0, 1]
    assert list(stable_order(np.array([1.0 + 1e-6, 1.0]))) == [1, 0]   # a real difference still counts


def test_clearly_less_ignores_the_last_bits_and_keeps_real_differences():
    # two equal fits (a symmetric model's mirror poses) rounded either way: neither replaces the other
    assert not clearly_less(0.0152305661997318, 0.0152305661997303)
    assert not clearly_less(0.0152305661997282, 0.0152305661997305)
    assert clearly_less(0.0152, 0.0153) and not clearly_less(0.0153, 0.0152)
    assert clearly_less(1.0, np.inf) and not clearly_less(np.inf, np.inf)


def _symmetric(rng, w):
    Q = np.linalg.qr(rng.normal(size=(len(w), len(w))))[0]
    return (Q * np.asarray(w, dtype=float)) @ Q.T


def test_dot3_norm3_det3_times_match_numpy():
    rng = np.random.default_rng(2)
    a, b, M = rng.normal(size=(40, 3)), rng.normal(size=3), rng.normal(size=(3, 5))
    assert np.allclose(dot3(a, b), a @ b, rtol=0, atol=1e-12)
    assert np.allclose(norm3(a), np.linalg.norm(a, axis=1), rtol=0, atol=1e-12)
    assert abs(norm3(b) - np.linalg.norm(b)) < 1e-12
    assert np.allclose(times(a, M), a @ M, rtol=0, atol=1e-12) and np.allclose(times(b, M[:, :3]), b @ M[:, :3])
    R = rng.normal(size=(3, 3))
    assert abs(det3(R) - np.linalg.det(R)) < 1e-12 and det3(np.eye(3)) == 1.0


def _check_eigh(A, tol=1e-12):
    w, V = eigh(A)
    scale = max(1.0, float(np.max(np.abs(A))))
    assert np.allclose(w, np.linalg.eigvalsh(A), rtol=0, atol=tol * scale)
    assert np.all(np.diff(w) >= 0)
    assert np.allclose(V.T @ V, np.eye(len(A)), rtol=0, atol=tol)           # orthonormal
    assert np.allclose(A @ V, V * w, rtol=0, atol=tol * scale)               # eigenvectors
    for j in range(len(A)):                                                 # the sign rule
        assert V[np.argmax(np.abs(V[:, j])), j] > 0
    assert np.array_equal(eigvalsh(A), w)
    return w, V


def test_eigh_matches_numpy_on_random_and_degenerate_matrices():
    rng = np.random.default_rng(3)
    for k in (2, 3, 6):
        for _ in range(20):
            _check_eigh(_symmetric(rng, rng.normal(size=k) * 10.0 ** rng.uniform(-3, 3)))
    _check_eigh(_symmetric(rng, [1.0, 1.0, 2.0]))                # a repeated eigenvalue
    _check_eigh(_symmetric(rng, [5.0, 5.0, 5.0]))                # all three equal
    _check_eigh(_symmetric(rng, [0.0, 0.0, 3.0]))                # rank one: points along a line
    _check_eigh(np.zeros((3, 3)))
    w, V = _check_eigh(np.diag([3.0, 1.0, 2.0]))
    assert np.array_equal(V, np.eye(3)[:, [1, 2, 0]])
    # the scatter of collinear points: the line is the last eigenvector, up to the sign rule
    x = np.linspace(-1.0, 1.0, 9)[:, None] * np.array([1.0, -2.0, 0.5])
    x = x - x.mean(axis=0)
    w, V = _check_eigh(x.T @ x)
    assert abs(abs(V[:, 2] @ np.array([1.0, -2.0, 0.5])) / np.linalg.norm([1.0, -2.0, 0.5]) - 1.0) < 1e-12
    # the same matrix gives the same bits, its eigenvectors' signs included, whatever numpy's kernel
    A = _symmetric(rng, [1.0, 2.0, 3.0])
    assert all(np.array_equal(eigh(A)[1], eigh(A.copy())[1]) for _ in range(3))


def test_lstsq_matches_numpy_and_reports_the_rank():
    rng = np.random.default_rng(4)
    for _ in range(20):
        X = rng.uniform(-1.0, 1.0, size=30)
        A = np.vander(X, 4, increasing=True)
        y = rng.normal(size=30)
        x, rank = lstsq(A, y)
        assert rank == 4 and np.allclose(x, np.linalg.lstsq(A, y, rcond=None)[0], rtol=0, atol=1e-12)
        Y = rng.normal(size=(30, 3))
        X2, rank = lstsq(A, Y)
        assert X2.shape == (4, 3) and np.allclose(X2, np.linalg.lstsq(A, Y, rcond=None)[0], rtol=0, atol=1e-12)
    # rank-deficient: three distinct abscissae for a cubic, a repeated column, a zero column
    X = np.repeat([-1.0, 0.2, 1.0], 5)
    for A in (np.vander(X, 4, increasing=True),
              np.column_stack([np.ones(15), X, 2.0 * X]),
              np.column_stack([np.ones(15), np.zeros(15), X])):
        y = rng.normal(size=15)
        x, rank = lstsq(A, y)
        ref, _, ref_rank, _ = np.linalg.lstsq(A, y, rcond=None)
        assert rank == ref_rank < A.shape[1]
        assert np.allclose(A @ x, A @ ref, rtol=0, atol=1e-12)               # as good a fit
    x, rank = lstsq(np.zeros((5, 2)), np.ones(5))
    assert rank == 0 and np.array_equal(x, np.zeros(2))


def test_inverse_spd_matches_numpy():
    rng = np.random.default_rng(5)
    A = _symmetric(rng, [0.5, 1.0, 4.0, 9.0])
    assert np.allclose(inverse_spd(A), np.linalg.inv(A), rtol=0, atol=1e-12)

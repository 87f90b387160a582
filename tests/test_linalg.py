"""The small linear algebra of the hot loops: the same results as numpy's BLAS-backed calls."""

import numpy as np

from tactrec.linalg import clearly_less, compose, gram, rotate, solve_spd, stable_order, transform


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

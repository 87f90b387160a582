"""Probabilities of a recognition (tactrec.probability): the rule, its scale, its calibration."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import special

from tactrec.bench.calibration import expected_calibration_error, reliability
from tactrec.probability import bootstrap_probabilities, evidence
from tactrec.recognition import Recognizer
from tactrec.simulation import simulate_random_touch


def _seeded_results(entries, *, seed: int, per_model: int, noise: float):
    """``(model name, Recognition)`` of ``per_model`` seeded noisy touches on each entry (41 points a
    curve every 0.3 mm, planes 60 degrees apart, Gaussian noise, no outward side)."""
    out = []
    with Recognizer(entries) as recognizer:
        for m_index, entry in enumerate(entries):
            for i in range(per_model):
                touch = simulate_random_touch(entry.model, rng=np.random.default_rng((seed, m_index, i)),
                                              points=41, spacing=0.3,
                                              angle=60.0, noise=noise, noise_kind="gaussian", outward=False)
                out.append((entry.name, recognizer.recognize(touch)))
    return out


def test_the_bootstrap_agrees_with_the_normal_theory_on_white_residuals():
    """Two models' distances to 123 points, white, each resampled on its own: the share of
    replicates the first wins matches Phi(difference of the means / the standard error of that
    difference, sqrt(se1^2 + se2^2)) to 0.03, for three sizes of difference."""
    rng = np.random.default_rng(7)
    base = np.abs(rng.normal(0.0, 0.05, 123))
    other = np.abs(rng.normal(0.0, 0.05, 123))
    for shift in (0.002, 0.005, 0.01):
        d = np.stack([base, other - other.mean() + base.mean() + shift])
        se = np.hypot(*(np.std(r, ddof=1) / np.sqrt(123) for r in d))
        expected = special.ndtr((d[1].mean() - d[0].mean()) / se)
        p = bootstrap_probabilities(d, [41, 41, 41])
        assert abs(p[0] - expected) < 0.03 and abs(p.sum() - 1.0) < 1e-12


def test_bootstrap_limits_and_determinism():
    """Equal rows share about equally; a row below the others by far takes it all; the same
    input gives the same probabilities; a lone model has probability 1."""
    d = np.abs(np.random.default_rng(1).normal(0.0, 0.05, (1, 60)))
    assert np.allclose(bootstrap_probabilities(np.repeat(d, 3, axis=0), [20, 20, 20]), 1 / 3, atol=0.03)
    assert bootstrap_probabilities(np.concatenate([d, d + 0.05]), [30, 30]).tolist() == [1.0, 0.0]
    e = np.concatenate([d, d[:, ::-1]])
    assert bootstrap_probabilities(e, [30, 30]).tolist() == bootstrap_probabilities(e, [30, 30]).tolist()
    assert bootstrap_probabilities(d, [60]).tolist() == [1.0]


def test_a_smooth_misfit_is_resampled_in_blocks_and_decides_less():
    """White residuals are drawn a point at a time; a smooth bow along each curve in long blocks,
    so the same smoothly varying difference between two models is told apart less sharply."""
    rng = np.random.default_rng(3)
    sizes = [41, 41, 41]
    white = rng.normal(0.0, 0.05, 123)
    s = np.linspace(-1, 1, 41)
    bow = np.tile(0.08 * (s * s - 1 / 3), 3) + rng.normal(0.0, 0.002, 123)
    step = 0.012 + 0.03 * np.sin(np.pi * np.concatenate([s, s + 0.4, s - 0.7]))
    a = evidence(["a", "b"], [white, np.abs(white) + step], sizes)
    b = evidence(["a", "b"], [bow, np.abs(bow) + step], sizes)
    assert a.block == 1 and b.block >= 10
    assert a.probabilities()[0] > b.probabilities()[0] > 0.5


def test_calibration_measures():
    """ECE and the reliability bins on a hand-made set: two bins, gaps 0.05 and 0.35."""
    conf = [0.95] * 10 + [0.55] * 10
    ok = [True] * 10 + [True] * 2 + [False] * 8
    bins = reliability(conf, ok)
    assert [b["count"] for b in bins] == [10, 10]
    assert expected_calibration_error(conf, ok) == pytest.approx(0.5 * 0.05 + 0.5 * 0.35)


def test_confident_results_on_noisy_touches_are_right(small):
    """24 seeded noisy touches (Gaussian 0.03 mm, no outward side) on four small meshes of distinct
    shapes: every result with confidence >= 0.95 is right, at least 16 are that sure, and the
    accepted models' probabilities and unknown's sum to 1."""
    sure = right = 0
    for name, result in _seeded_results(small, seed=31, per_model=6, noise=0.03):
        assert abs(sum(result.probabilities.values()) + result.unknown - 1.0) < 1e-9
        if result.confidence >= 0.95:
            sure += 1
            right += result.best == name
    assert sure >= 16 and right == sure


def test_confidence_on_twin_spheres_is_calibrated():
    """Spheres of radius 30 and 31 mm, 40 seeded touches with Gaussian noise of 0.05 mm (no outward
    side), where one touch often cannot tell them apart: the confidence does not overstate the
    share recognised (mean confidence at most 0.05 above it, and within 0.25 below: the rule
    resamples each model on its own, which on two shapes this alike understates how surely the
    data tell them apart), and every result with confidence >= 0.95 is right."""
    import trimesh

    from tactrec.recognition import ModelEntry
    from tactrec.surfaces.mesh import MeshModel
    from tactrec.tables import CurvatureTable

    entries = []
    for name, r in (("r30", 30.0), ("r31", 31.0)):
        mesh = trimesh.creation.icosphere(subdivisions=5, radius=r)
        model = MeshModel(mesh.vertices, mesh.faces, name=name, units="mm")
        entries.append(ModelEntry(model, CurvatureTable(model.table_samples())))
    rows = [(result.best == name, result.confidence)
            for name, result in _seeded_results(entries, seed=41, per_model=20, noise=0.05)]
    right = np.array([r[0] for r in rows])
    conf = np.array([r[1] for r in rows])
    assert 0.55 <= right.mean() <= 0.95                                  # the touches do leave doubt
    assert -0.25 <= conf.mean() - right.mean() <= 0.05
    assert right[conf >= 0.95].all()


def test_the_ece_floor_of_a_calibrated_predictor_shrinks_with_the_touches():
    """Answers drawn right with exactly their confidence: the ECE floor is about 0.1 on 50 touches
    and below 0.02 on 20,000 (it is a property of the sample size, not of the probabilities)."""
    from tactrec.bench.calibration import ece_if_calibrated

    conf = np.random.default_rng(4).uniform(0.2, 1.0, 20_000)
    assert 0.05 < ece_if_calibrated(conf[:50], draws=50) < 0.2
    assert ece_if_calibrated(conf, draws=5) < 0.02


def test_fits_closer_than_the_resolution_are_equal():
    """No distance is read closer than the resolution: two models fitting within it (here 3.5e-7
    against 4e-7, a noise-free touch's fits on two equal surfaces) share the replicates, however
    their last digits fall; a fit with points beyond it still loses to one within it."""
    rng = np.random.default_rng(2)
    sizes = [41, 41, 41]
    a = 3.5e-7 * (1.0 + 0.1 * rng.random(123))
    assert evidence(["a", "b"], [a, a * 4.0 / 3.5], sizes).probabilities().tolist() == [1.0, 0.0]   # without it
    assert np.allclose(evidence(["a", "b"], [a, a * 4.0 / 3.5], sizes, resolution=0.012).probabilities(), 0.5)
    off = a + np.where(np.arange(123) % 10 == 0, 0.05, 0.0)                 # a few points well off
    assert evidence(["a", "b"], [a, off], sizes, resolution=0.012).probabilities()[0] > 0.99


def test_a_noise_free_touch_of_a_face_two_parts_share_is_never_sure():
    """20 seeded noise-free touches (outward known) on the flat top of a box, whose 12 mm curves stay
    on the face: a second box of another size has the same face, and both fit each touch to the
    last digits.  None comes back sure (>= 0.95); each is about even between the two boxes."""
    import trimesh

    from tactrec.recognition import ModelEntry
    from tactrec.simulation import simulate_touch
    from tactrec.surfaces.mesh import MeshModel
    from tactrec.tables import CurvatureTable

    entries = []
    for name, extents in (("tall", (60.0, 60.0, 40.0)), ("wide", (80.0, 50.0, 30.0))):
        v, f = trimesh.remesh.subdivide_to_size(*(lambda b: (b.vertices, b.faces))(trimesh.creation.box(extents)),
                                                max_edge=2.0)
        model = MeshModel(np.asarray(v), np.asarray(f), name=name, units="mm")
        entries.append(ModelEntry(model, CurvatureTable(model.table_samples())))
    model = entries[0].model
    top = np.flatnonzero((model.vertices[:, 2] > 19.9) & (np.abs(model.vertices[:, :2]).max(axis=1) < 12.0))
    rng = np.random.default_rng(11)
    with Recognizer(entries) as recognizer:
        for site in rng.choice(top, 20, replace=False):
            touch = simulate_touch(model, [int(site)], points=41, spacing=0.3, rng=rng)
            result = recognizer.recognize(touch)
            assert result.best in ("tall", "wide") and result.confidence < 0.95
            assert abs(result.probabilities["tall"] - result.probabilities["wide"]) < 0.1


def test_evidence_keeps_its_resolution_through_json():
    """Evidence written to JSON and read back gives the same probabilities, its resolution kept;
    evidence saved before there was one reads as none."""
    from tactrec.probability import Evidence

    a = np.full(123, 3.5e-7)
    found = evidence(["a", "b"], [a, a * 2.0], [41, 41, 41], limits=(0.012,), resolution=0.012)
    back = Evidence.from_json(found.to_json())
    assert back.resolution == 0.012 and back.probabilities().tolist() == found.probabilities().tolist()
    old = found.to_json()
    del old["resolution"]
    assert Evidence.from_json(old).resolution == 0.0


def test_models_an_unsettled_search_could_not_tell_apart_share_its_best_fit():
    """An unsettled search's errors only bound each model's fit: two models read as tied share the
    replicates and the fit test evenly, where read as fits the lower bound takes nearly all; a model
    beyond the tie keeps its own reading; the tie is kept through JSON."""
    from tactrec.probability import Evidence

    rng = np.random.default_rng(5)
    sizes = [41, 41, 41]
    best = 0.0128 * (1.0 + 0.05 * rng.random(123))
    twin, far = best * 0.0158 / 0.0128, best * 10.0
    limits = (0.012,)
    apart = evidence(["d", "c", "x"], [best, twin, far], sizes, limits=limits, resolution=0.012)
    tied = evidence(["d", "c", "x"], [best, twin, far], sizes, limits=limits, resolution=0.012, tied=2)
    assert apart.probabilities()[0] > 0.95
    p = tied.probabilities()
    assert p[0] == p[1] and p[0] < 0.5 and p[2] < 1e-6
    back = Evidence.from_json(tied.to_json())
    assert back.tied == 2 and np.allclose(back.probabilities(), p, atol=0.01)         # distances kept to 7 digits


def test_a_search_cut_short_is_never_sure_between_models_within_its_ratio(scans):
    """Hard touches on two scans, each search cut to its first round: of those that end unsettled,
    their best beyond a plausible fit (a miss somewhere), with the other model's error within the
    search's ratio (3) of the best, none comes back sure; the answer is still the lowest error.
    Those whose best is a plausible fit are read as they are."""
    from tactrec.bench.common import simulate
    from tactrec.features import Touch
    from tactrec.probability import fit_limit, plausible_fit

    close = 0
    with Recognizer(scans.entries[:2], budget=1) as recognizer:
        for m_index, entry in enumerate(scans.entries[:2]):
            for i in range(10):
                _, touch = simulate(entry, m_index, i, 11, "hard")
                r = recognizer.recognize(touch)
                ok = [x for x in r.ranking if x.ok]
                if r.settled or len(ok) < 2 or ok[1].error / ok[1].scale > 3.0 * ok[0].error / ok[0].scale:
                    continue
                t = Touch.from_data(touch)
                if ok[0].error / ok[0].scale <= plausible_fit(fit_limit(t, 1e-3), t.noise, len(t.joint_points), 3.0):
                    assert r.evidence.tied == 1
                    continue
                close += 1
                assert r.ambiguous and r.best == ok[0].model
    assert close >= 3

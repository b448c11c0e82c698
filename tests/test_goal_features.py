"""Tests for drake_skill.perception.features (per-skill PCA of PCAE codes, docs/method.md 3)."""

import numpy as np
import pytest

from drake_skill.fileio import atomic_save_npz, load_npz
from drake_skill.perception.features import GoalFeatures, GoalFeaturesConfig


def _codes(seed=0, t=60, d=128, rank=5):
    """Codes with a dominant rank-``rank`` structure plus small noise."""
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(t, rank)) * np.linspace(3.0, 1.0, rank)
    basis = rng.normal(size=(rank, d))
    return z @ basis + 0.01 * rng.normal(size=(t, d)) + rng.uniform(0, 2, size=d)


def test_fit_transform_shapes_and_variance():
    x = _codes()
    gf = GoalFeatures(8).fit(x)
    assert gf.mean_.shape == (128,)
    assert gf.components_.shape == (8, 128)
    assert gf.explained_variance_.shape == (8,)
    assert gf.n_samples_ == 60
    # Orthonormal components.
    np.testing.assert_allclose(gf.components_ @ gf.components_.T, np.eye(8), atol=1e-10)
    # Rank-5 signal: 5 components explain almost all variance, the rest little.
    assert gf.total_explained_variance_ratio > 0.999
    assert gf.explained_variance_ratio_[:5].sum() > 0.999
    assert np.all(np.diff(gf.explained_variance_) <= 1e-12)
    g = gf.transform(x)
    assert g.shape == (60, 8)
    assert gf.transform(x[3]).shape == (8,)
    np.testing.assert_allclose(gf.transform(x[3]), g[3])
    # Projections are centred and their variances are the explained variances.
    np.testing.assert_allclose(g.mean(axis=0), 0.0, atol=1e-9)
    np.testing.assert_allclose(g.var(axis=0, ddof=1), gf.explained_variance_, rtol=1e-9)
    # Reconstruction from 8 components is near exact for rank-5 data.
    np.testing.assert_allclose(gf.inverse_transform(g), x, atol=0.1)


def _numpy_pca(x, k):
    """The hand-written PCA GoalFeatures used before scikit-learn (thin SVD, largest entry positive)."""
    mean = x.mean(axis=0)
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    comps = vt[:k]
    signs = np.sign(comps[np.arange(k), np.argmax(np.abs(comps), axis=1)])
    signs[signs == 0] = 1.0
    var_all = s**2 / (x.shape[0] - 1)
    return mean, comps * signs[:, None], var_all[:k], var_all[:k] / var_all.sum()


#: How far the scikit-learn fit may be from the hand-written one: both are the same
#: thin SVD (LAPACK via scipy vs numpy), so only rounding separates them.
PCA_TOLERANCE = 1e-9


# (4, 600, 30): over 500 codes, where scikit-learn's default solver would be the randomized one.
@pytest.mark.parametrize("seed, t, rank", [(3, 60, 12), (4, 120, 30), (4, 600, 30)])
def test_same_goal_data_as_the_hand_written_pca(seed, t, rank):
    x = _codes(seed=seed, t=t, rank=rank)
    gf = GoalFeatures(8).fit(x)
    mean, comps, var, ratio = _numpy_pca(x, 8)
    np.testing.assert_allclose(gf.mean_, mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(gf.components_, comps, rtol=0, atol=PCA_TOLERANCE)
    np.testing.assert_allclose(gf.explained_variance_, var, rtol=PCA_TOLERANCE)
    np.testing.assert_allclose(gf.explained_variance_ratio_, ratio, rtol=PCA_TOLERANCE)
    # The goal data, signs included (scikit-learn's own svd_flip signs are not used).
    g_old = (x - mean) @ comps.T
    np.testing.assert_allclose(gf.transform(x), g_old, rtol=0, atol=PCA_TOLERANCE * np.abs(g_old).max())


def test_sign_convention_is_fixed_whatever_scikit_learns_signs():
    from sklearn.decomposition import PCA

    from drake_skill.perception.features import largest_entry_signs

    x = _codes(seed=3, rank=12)
    gf = GoalFeatures(8).fit(x)
    sk = PCA(8, svd_solver="full").fit(x)
    np.testing.assert_allclose(np.abs(gf.components_), np.abs(sk.components_), atol=1e-12)
    assert np.all(gf.components_[np.arange(8), np.argmax(np.abs(gf.components_), axis=1)] > 0)
    # scikit-learn 1.3-1.4 flipped by U's columns (other signs); any signs come out the same.
    flips = np.array([1, -1, 1, -1, -1, 1, 1, -1], dtype=float)
    arbitrary = sk.components_ * flips[:, None]
    np.testing.assert_array_equal(arbitrary * largest_entry_signs(arbitrary)[:, None],
                                  sk.components_ * largest_entry_signs(sk.components_)[:, None])
    np.testing.assert_array_equal(largest_entry_signs(np.zeros((2, 4))), [1.0, 1.0])


def test_skill_arrays_written_by_the_hand_written_pca_still_load():
    x = _codes(seed=5)
    mean, comps, var, ratio = _numpy_pca(x, 8)
    # What skills saved before the switch hold in arrays.npz (goal_features_* keys).
    old = {"mean": mean, "components": comps, "explained_variance": var,
           "explained_variance_ratio": ratio, "n_samples": np.array(60, dtype=np.int64)}
    loaded = GoalFeatures.from_arrays(old)
    np.testing.assert_array_equal(loaded.transform(x), (x - mean) @ comps.T)


def test_list_of_demonstrations_and_sign_convention():
    x = _codes(seed=1, t=90)
    a = GoalFeatures().fit([x[:30], x[30:55], x[55:]], lengths=[30, 25, 35])
    b = GoalFeatures().fit(x)
    np.testing.assert_array_equal(a.components_, b.components_)
    # Sign fixed: the largest-magnitude entry of each component is positive.
    idx = np.argmax(np.abs(a.components_), axis=1)
    assert np.all(a.components_[np.arange(8), idx] > 0)
    # Same fit after flipping the data's sign pattern -> same components (deterministic).
    c = GoalFeatures().fit(x[::-1])
    np.testing.assert_allclose(c.components_, b.components_, atol=1e-10)


def test_round_trip_via_arrays_and_npz(tmp_path):
    x = _codes(seed=2)
    gf = GoalFeatures().fit(x)
    arrays = gf.to_arrays()
    assert set(arrays) == set(GoalFeatures.ARRAY_KEYS)
    back = GoalFeatures.from_arrays(arrays)
    np.testing.assert_array_equal(back.transform(x), gf.transform(x))
    # One memory layout for fitted and loaded: BLAS may round a product with a transposed
    # operand differently (an AVX-512 CPU did, in the last bit, for the fitted Close skill).
    assert gf.components_.flags.c_contiguous and back.components_.flags.c_contiguous
    atomic_save_npz(tmp_path / "pca.npz", arrays)
    again = GoalFeatures.from_arrays(load_npz(tmp_path / "pca.npz"))
    np.testing.assert_array_equal(again.transform(x), gf.transform(x))
    assert again.n_samples_ == 60
    assert again.total_explained_variance_ratio == pytest.approx(gf.total_explained_variance_ratio)


def test_config_yaml():
    from pydrake.common.yaml import yaml_load_typed

    cfg = yaml_load_typed(schema=GoalFeaturesConfig, data="n_components: 6\n")
    assert GoalFeatures.from_config(cfg).n_components == 6


@pytest.mark.parametrize(
    "codes, match",
    [
        (np.zeros((20, 127)), r"codes: expected shape \(T, 128\), got \(20, 127\)"),
        (np.zeros(128), r"codes: expected shape \(T, 128\), got \(128,\)"),
        (np.zeros((8, 128)), r"need more than n_components=8 samples to fit, got 8"),
        (np.full((20, 128), np.nan), r"codes: contains NaN"),
        ([], r"at least one demonstration"),
        ([np.zeros((10, 128)), np.zeros((10, 3))], r"codes\[1\]: expected shape"),
    ],
)
def test_fit_errors(codes, match):
    with pytest.raises(ValueError, match=match):
        GoalFeatures().fit(codes)


def test_other_errors():
    with pytest.raises(ValueError, match="n_components"):
        GoalFeatures(0)
    with pytest.raises(ValueError, match="not fitted"):
        GoalFeatures().transform(np.zeros((3, 128)))
    gf = GoalFeatures().fit(_codes())
    with pytest.raises(ValueError, match=r"codes: expected shape \(T, 128\), got \(3, 64\)"):
        gf.transform(np.zeros((3, 64)))
    with pytest.raises(ValueError, match=r"lengths: sum 10"):
        GoalFeatures().fit(_codes(), lengths=[5, 5])
    arrays = gf.to_arrays()
    with pytest.raises(ValueError, match=r"missing \['mean'\]"):
        GoalFeatures.from_arrays({k: v for k, v in arrays.items() if k != "mean"})
    bad = dict(arrays, mean=np.zeros(100))
    with pytest.raises(ValueError, match=r"arrays\['mean'\]: expected shape \(128,\), got \(100,\)"):
        GoalFeatures.from_arrays(bad)
    bad = dict(arrays, components=np.zeros((8,)))
    with pytest.raises(ValueError, match=r"arrays\['components'\]"):
        GoalFeatures.from_arrays(bad)


# ------------------------------------------------------------------ mutation testing (docs/mutation.md)


def test_constructor_bounds_are_inclusive():
    assert GoalFeatures(1).n_components == 1  # one component is valid
    assert GoalFeatures(3, 3).n_features == 3  # as many components as features
    for args in [(8, 7), (2, 4.5)]:
        with pytest.raises(ValueError, match=r"^n_features: expected an integer >= n_components="):
            GoalFeatures(*args)


def test_integer_codes_are_fitted_and_non_numeric_codes_refused():
    x = np.round(_codes(seed=6, d=16) * 10).astype(np.int64)
    a = GoalFeatures(3, 16).fit(x)
    b = GoalFeatures(3, 16).fit(x.astype(float))
    np.testing.assert_array_equal(a.components_, b.components_)
    with pytest.raises(ValueError, match=r"^codes: expected a numeric array of shape \(T, 16\), got dtype <U1"):
        GoalFeatures(3, 16).fit(np.full((20, 16), "a"))


def test_error_messages_start_with_the_argument():
    with pytest.raises(ValueError, match=r"^codes: expected at least one demonstration, got an empty list$"):
        GoalFeatures().fit([])
    with pytest.raises(ValueError, match=r"^lengths: sum 10 does not match the 60 codes$"):
        GoalFeatures().fit(_codes(), lengths=[5, 5])
    with pytest.raises(ValueError, match=r"^GoalFeatures: not fitted; call fit\(codes\) or from_arrays"):
        GoalFeatures().inverse_transform(np.zeros(8))


def test_constant_codes_explain_no_variance():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # scikit-learn's 0 / 0 for the ratios
        gf = GoalFeatures(2, 16).fit(np.ones((20, 16)))
    np.testing.assert_array_equal(gf.explained_variance_ratio_, [0.0, 0.0])
    assert gf.total_explained_variance_ratio == 0.0


def test_fit_transform_equals_fit_then_transform():
    x = _codes(seed=7, t=40, d=16)
    g = GoalFeatures(3, 16).fit(x).transform(x)
    np.testing.assert_allclose(GoalFeatures(3, 16).fit_transform(x), g, atol=1e-12)
    np.testing.assert_allclose(GoalFeatures(3, 16).fit_transform([x[:15], x[15:]], lengths=[15, 25]), g,
                               atol=1e-12)
    with pytest.raises(ValueError, match=r"^lengths: sum 10 does not match the 40 codes$"):
        GoalFeatures(3, 16).fit_transform(x, lengths=[10])


def test_inverse_transform_shapes():
    x = _codes(seed=8, t=40, d=16)
    gf = GoalFeatures(3, 16).fit(x)
    g = gf.transform(x)
    np.testing.assert_allclose(gf.inverse_transform(g[5]), gf.inverse_transform(g)[5], atol=1e-12)
    assert gf.inverse_transform([1, 0, 0]).shape == (16,)
    for bad in [np.zeros((4, 5)), np.zeros(5), np.zeros((2, 4, 3))]:
        with pytest.raises(ValueError, match=r"^goal: expected shape \(T, 3\) or \(3,\), got"):
            gf.inverse_transform(bad)


def test_from_arrays_other_sizes_and_float64_attributes():
    x = _codes(seed=9, t=40, d=16)
    gf = GoalFeatures(1, 16).fit(x)  # k = 1, D = 16 (not the PCAE's 128)
    arrays = {k: (v.astype(np.float32) if v.dtype == np.float64 else v) for k, v in gf.to_arrays().items()}
    back = GoalFeatures.from_arrays(arrays)
    assert (back.n_components, back.n_features) == (1, 16)
    for name in ("mean_", "components_", "explained_variance_", "explained_variance_ratio_"):
        assert getattr(back, name).dtype == np.float64, name
        np.testing.assert_allclose(getattr(back, name), getattr(gf, name), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(back.transform(x), gf.transform(x), rtol=1e-5, atol=1e-5)
    square = GoalFeatures.from_arrays(dict(gf.to_arrays(), components=np.eye(16)[:16],
                                           explained_variance=np.ones(16), explained_variance_ratio=np.ones(16)))
    assert square.components_.shape == (16, 16)  # D == k is valid


@pytest.mark.parametrize("components", [np.zeros((3, 2)), np.zeros((0, 5))])
def test_from_arrays_refuses_more_components_than_features_or_none(components):
    arrays = {"mean": np.zeros(components.shape[1]), "components": components,
              "explained_variance": np.zeros(components.shape[0]),
              "explained_variance_ratio": np.zeros(components.shape[0]), "n_samples": np.array(10)}
    with pytest.raises(ValueError, match=r"^arrays\['components'\]: expected shape \(k, D\) with D >= k >= 1"):
        GoalFeatures.from_arrays(arrays)


def test_from_arrays_refuses_non_finite_values():
    arrays = GoalFeatures(2, 16).fit(_codes(seed=10, t=30, d=16)).to_arrays()
    for key in ("components", "mean", "explained_variance", "explained_variance_ratio"):
        bad = {k: v.copy() for k, v in arrays.items()}
        bad[key].flat[0] = np.nan
        with pytest.raises(ValueError, match=rf"^arrays\['{key}'\]: contains NaN or infinite values$"):
            GoalFeatures.from_arrays(bad)

"""Goal features: per-skill PCA of PCAE codes, 128-D -> 8-D goal data g_t.

docs/method.md section 3 (last item); thesis 6.4 (PCA on the PCAE codes of the
demonstrations, > 90 % explained variance reported with 8 components).

    fit:        codes X (T, D) stacked over all demonstrations of a skill
                mean mu = mean_t X_t                              (D,)
                X - mu = U S V^T (thin SVD), components = V^T[:k]  (k, D)
                explained variance_i = S_i^2 / (T - 1)             (k,)
    transform:  g = (x - mu) @ components^T                        (T, k) or (k,)

The fit is scikit-learn's ``PCA(svd_solver="full")``. Sign convention (the
project's, kept from its first hand-written PCA): each component is flipped
so that its largest-magnitude entry is positive, so a fit does not depend on
the SVD's arbitrary signs. scikit-learn >= 1.5's ``svd_flip`` happens to pick
the same signs, 1.3-1.4 (allowed by pyproject.toml) flip by ``U`` instead, so
the signs are fixed here explicitly.

No Drake, scikit-learn habits: hyper-parameters in the constructor, fitted
attributes end in ``_``. The fitted state is stored as the five plain arrays
of :meth:`GoalFeatures.to_arrays` (not a pickled estimator), so skills saved
before the switch to scikit-learn load unchanged.
"""


from dataclasses import dataclass

import numpy as np

from drake_skill.perception.pcae import CODE_SIZE


def largest_entry_signs(components: np.ndarray) -> np.ndarray:
    """``(k,)`` signs of each row's largest-magnitude entry (+1 for an all-zero row).

    Multiplying row i of ``components (k, D)`` by sign i makes that entry
    positive: the goal features' sign convention (see the module docstring).
    """
    rows = np.arange(components.shape[0])
    signs = np.sign(components[rows, np.argmax(np.abs(components), axis=1)])
    signs[signs == 0] = 1.0
    return signs


@dataclass
class GoalFeaturesConfig:
    """Configuration of the goal-feature PCA (loadable with ``yaml_load_typed``)."""

    n_components: int = 8
    """Size of the goal data g_t (thesis 6.4: 8)."""


class GoalFeatures:
    """PCA from PCAE codes (D = 128) to goal data (k = 8).

    Fitted attributes: ``mean_`` (D,), ``components_`` (k, D),
    ``explained_variance_`` (k,), ``explained_variance_ratio_`` (k,),
    ``n_samples_`` (int).
    """

    ARRAY_KEYS = ("mean", "components", "explained_variance", "explained_variance_ratio", "n_samples")

    def __init__(self, n_components: int = 8, n_features: int = CODE_SIZE):
        if int(n_components) != n_components or n_components < 1:
            raise ValueError(f"n_components: expected a positive integer, got {n_components!r}")
        if int(n_features) != n_features or n_features < n_components:
            raise ValueError(f"n_features: expected an integer >= n_components={n_components}, got {n_features!r}")
        self.n_components = int(n_components)
        self.n_features = int(n_features)

    @classmethod
    def from_config(cls, config: GoalFeaturesConfig) -> "GoalFeatures":
        return cls(config.n_components)

    # ------------------------------------------------------------------ fit

    def _check_codes(self, codes, name: str = "codes") -> np.ndarray:
        x = np.asarray(codes)
        if x.dtype == object or not np.issubdtype(x.dtype, np.number):
            raise ValueError(f"{name}: expected a numeric array of shape (T, {self.n_features}), got dtype {x.dtype}")
        if x.ndim != 2 or x.shape[1] != self.n_features:
            raise ValueError(f"{name}: expected shape (T, {self.n_features}), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name}: contains NaN or infinite values (shape {x.shape})")
        return x.astype(np.float64)

    def fit(self, codes, lengths=None) -> "GoalFeatures":
        """Fits the PCA on codes (T, D), or on a list of per-demonstration arrays (T_i, D).

        ``lengths`` (as hmmlearn) is accepted for symmetry and only checked to
        sum to T. Needs T > n_components samples.
        """
        if isinstance(codes, (list, tuple)):
            if len(codes) == 0:
                raise ValueError("codes: expected at least one demonstration, got an empty list")
            x = np.concatenate([self._check_codes(c, f"codes[{i}]") for i, c in enumerate(codes)])
        else:
            x = self._check_codes(codes)
        if lengths is not None and int(np.sum(lengths)) != x.shape[0]:
            raise ValueError(f"lengths: sum {int(np.sum(lengths))} does not match the {x.shape[0]} codes")
        t = x.shape[0]
        if t <= self.n_components:
            raise ValueError(f"codes: need more than n_components={self.n_components} samples to fit, got {t}")
        from sklearn.decomposition import PCA

        pca = PCA(n_components=self.n_components, svd_solver="full").fit(x)
        comps = np.array(pca.components_, dtype=np.float64)
        self.mean_ = np.array(pca.mean_, dtype=np.float64)
        # C order, as from_arrays loads it: BLAS rounds a product differently for a
        # transposed operand on some CPUs (AVX-512), so a fitted and a loaded skill
        # would give goal data that differ in the last bits.
        self.components_ = np.ascontiguousarray(comps * largest_entry_signs(comps)[:, None])
        self.explained_variance_ = np.array(pca.explained_variance_, dtype=np.float64)
        # scikit-learn gives NaN ratios for constant data (0 / 0); the project's are 0 there.
        ratio = np.array(pca.explained_variance_ratio_, dtype=np.float64)
        self.explained_variance_ratio_ = np.where(np.isfinite(ratio), ratio, 0.0)
        self.n_samples_ = t
        return self

    @property
    def total_explained_variance_ratio(self) -> float:
        """Sum of ``explained_variance_ratio_`` (thesis 6.4 reports > 0.9)."""
        self._check_fitted()
        return float(np.sum(self.explained_variance_ratio_))

    def _check_fitted(self) -> None:
        if not hasattr(self, "components_"):
            raise ValueError("GoalFeatures: not fitted; call fit(codes) or from_arrays(...) first")

    # ------------------------------------------------------------------ use

    def transform(self, codes) -> np.ndarray:
        """Codes (T, D) -> goal data (T, k); a single code (D,) -> (k,)."""
        self._check_fitted()
        x = np.asarray(codes)
        if x.ndim == 1:
            return self.transform(x[None])[0]
        x = self._check_codes(x)
        return (x - self.mean_) @ self.components_.T

    def fit_transform(self, codes, lengths=None) -> np.ndarray:
        self.fit(codes, lengths)
        if isinstance(codes, (list, tuple)):
            return self.transform(np.concatenate([np.asarray(c) for c in codes]))
        return self.transform(codes)

    def inverse_transform(self, goal) -> np.ndarray:
        """Goal data (T, k) or (k,) -> codes (T, D) or (D,) in the span of the components."""
        self._check_fitted()
        g = np.asarray(goal, dtype=np.float64)
        if g.shape[-1] != self.n_components or g.ndim not in (1, 2):
            raise ValueError(f"goal: expected shape (T, {self.n_components}) or ({self.n_components},), got {g.shape}")
        return g @ self.components_ + self.mean_

    # ------------------------------------------------------------------ arrays

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Fitted state as plain numeric arrays (for ``fileio.atomic_save_npz``)."""
        self._check_fitted()
        return {
            "mean": self.mean_.copy(),
            "components": self.components_.copy(),
            "explained_variance": self.explained_variance_.copy(),
            "explained_variance_ratio": self.explained_variance_ratio_.copy(),
            "n_samples": np.array(self.n_samples_, dtype=np.int64),
        }

    @classmethod
    def from_arrays(cls, arrays) -> "GoalFeatures":
        """Inverse of :meth:`to_arrays`; checks names and shapes, raising ValueError."""
        missing = [k for k in cls.ARRAY_KEYS if k not in arrays]
        if missing:
            raise ValueError(f"arrays: missing {missing}; expected keys {list(cls.ARRAY_KEYS)}")
        comps = np.asarray(arrays["components"], dtype=np.float64)
        if comps.ndim != 2 or comps.shape[0] < 1 or comps.shape[1] < comps.shape[0]:
            raise ValueError(f"arrays['components']: expected shape (k, D) with D >= k >= 1, got {comps.shape}")
        k, d = comps.shape
        expect = {"mean": (d,), "explained_variance": (k,), "explained_variance_ratio": (k,), "n_samples": ()}
        out = cls(k, d)
        vals = {}
        for key, shape in expect.items():
            v = np.asarray(arrays[key])
            if v.shape != shape:
                raise ValueError(f"arrays['{key}']: expected shape {shape}, got {v.shape}")
            vals[key] = v
        for key in ("components", "mean", "explained_variance", "explained_variance_ratio"):
            v = comps if key == "components" else vals[key]
            if not np.all(np.isfinite(v)):
                raise ValueError(f"arrays['{key}']: contains NaN or infinite values")
        out.mean_ = vals["mean"].astype(np.float64)
        out.components_ = comps
        out.explained_variance_ = vals["explained_variance"].astype(np.float64)
        out.explained_variance_ratio_ = vals["explained_variance_ratio"].astype(np.float64)
        out.n_samples_ = int(vals["n_samples"])
        return out

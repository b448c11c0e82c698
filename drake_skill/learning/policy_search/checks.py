"""Argument checks and the plain encoding of random-generator state shared by the methods
(no pickling)."""

from __future__ import annotations

import json
import numbers
from collections.abc import Mapping
from typing import Any

import numpy as np


#: Version of :meth:`PolicySearch.state_dict`'s layout.
_STATE_FORMAT = 1
#: Prefix of a method's options in a state dict.
_OPTION_PREFIX = "option_"


def _check_int(name: str, value, *, minimum: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer >= {minimum}; got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value}")
    return int(value)


def _check_float(name: str, value, *, positive: bool = False,
                 non_negative: bool = False) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number; got {value!r}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite; got {value}")
    if positive and value <= 0:
        raise ValueError(f"{name} must be > 0; got {value}")
    if non_negative and value < 0:
        raise ValueError(f"{name} must be >= 0; got {value}")
    return value


def _check_mean(mean) -> np.ndarray:
    mean = np.array(mean, dtype=float)
    if mean.ndim != 2 or 0 in mean.shape:
        raise ValueError(
            f"mean must be the DMP weights W of shape (B, D) (B bases, D "
            f"dimensions, both >= 1); got shape {mean.shape}")
    if not np.isfinite(mean).all():
        raise ValueError("mean contains NaN or inf")
    return mean


def _check_covariances(covariances, mean_shape, *, name: str):
    """Validate ``(B, D, D)`` SPD covariances; return them and their Cholesky."""
    covariances = np.array(covariances, dtype=float)
    b, d = mean_shape
    if covariances.shape != (b, d, d):
        raise ValueError(
            f"{name} must have shape (B, D, D) = ({b}, {d}, {d}), one D x D "
            f"covariance per basis of the mean; got {covariances.shape}")
    if not np.isfinite(covariances).all():
        raise ValueError(f"{name} contains NaN or inf")
    asymmetry = np.abs(covariances - np.swapaxes(covariances, 1, 2)).max(axis=(1, 2))
    scale = np.abs(covariances).max(axis=(1, 2))
    bad = asymmetry > 1e-8 * scale
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name}[{i}] is not symmetric (max |S - S^T| = {asymmetry[i]:.3g}); "
            "pass 0.5 * (S + S^T)")
    covariances = _symmetrise(covariances)
    try:
        cholesky = np.linalg.cholesky(covariances)
    except np.linalg.LinAlgError:
        smallest = np.linalg.eigvalsh(covariances).min(axis=1)
        i = int(np.argmin(smallest))
        raise ValueError(
            f"{name}[{i}] is not positive definite (smallest eigenvalue "
            f"{smallest[i]:.3g}); regularise it, e.g. S + eps * I") from None
    return covariances, cholesky


def _symmetrise(matrices: np.ndarray) -> np.ndarray:
    return 0.5 * (matrices + np.swapaxes(matrices, -1, -2))


def _make_rng(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None or (isinstance(seed, numbers.Integral)
                        and not isinstance(seed, (bool, np.bool_))):
        return np.random.default_rng(seed)
    raise TypeError(
        f"seed must be an int, None or a numpy.random.Generator; got {seed!r}")


def _rng_state_json(rng: np.random.Generator) -> str:
    def encode(value):
        if isinstance(value, np.ndarray):
            return {"__ndarray__": value.tolist(), "dtype": str(value.dtype)}
        if isinstance(value, np.generic):
            return value.item()
        raise TypeError(f"cannot encode {type(value).__name__}")

    return json.dumps(rng.bit_generator.state, default=encode, sort_keys=True)


def _rng_from_json(text) -> np.random.Generator:
    def decode(obj):
        if "__ndarray__" in obj:
            return np.array(obj["__ndarray__"], dtype=obj["dtype"])
        return obj

    state = json.loads(str(text), object_hook=decode)
    name = state.get("bit_generator")
    bit_generator_type = getattr(np.random, str(name), None)
    if not (isinstance(bit_generator_type, type)
            and issubclass(bit_generator_type, np.random.BitGenerator)):
        raise ValueError(f"rng_state names unknown bit generator {name!r}")
    bit_generator = bit_generator_type()
    bit_generator.state = state
    return np.random.Generator(bit_generator)


def _plain_state(state: Mapping[str, Any]) -> dict[str, Any]:
    """0-d arrays (as ``np.load`` gives them) to Python scalars/strings."""
    if not isinstance(state, Mapping):
        raise TypeError(f"state must be a mapping; got {type(state).__name__}")
    plain = {}
    for key, value in state.items():
        if isinstance(value, np.ndarray) and value.ndim == 0:
            value = value.item()
        elif isinstance(value, np.generic):
            value = value.item()
        plain[str(key)] = value
    return plain

"""Action model: Dynamical Movement Primitive for a 7-D end-effector pose.

Plain numpy/scipy, no Drake import (the Drake wrapper is
``drake_skill.action.systems``). docs/method.md section 2 / thesis section 3.1 and 6.3.

Pose layout: ``y = (x, y, z, qw, qx, qy, qz)``: position in m, unit
quaternion scalar-first, both in the object frame O.

Equations (one controlled dimension; all dimensions share the phase):

- transformation system (thesis Eq. 3.3 in docs/method.md's form)::

      tau * dz/dt = K (g - y) - D z + f(x),     tau * dy/dt = z

  K = 100, D = 2 sqrt(K) = 20 (critically damped), start at rest
  (y(0) = y0, z(0) = 0);
- canonical system (thesis Eq. 3.5): ``tau dx/dt = -alpha_x x``, x(0) = 1,
  so ``x(t) = exp(-alpha_x t / tau)``. The default ``alpha_x = ln(100)`` puts
  ``x(tau) = 0.01``: the forcing term has decayed to 1 % when the
  demonstrated duration is over;
- forcing term (thesis Eq. 3.4 and 3.6)::

      f(x) = (sum_b psi_b(x) w_b / sum_b psi_b(x)) * x * a,
      psi_b(x) = exp(-h_b (x - c_b)^2)           (h_b = 1 / (2 sigma_b^2))

  centres ``c_b = exp(-alpha_x * linspace(0, 1, B))`` (equally spaced in
  time over [0, tau]) and widths ``h_b = width_scale / (c_{b+1} - c_b)^2``;
  the last basis reuses the previous width. ``psi_b`` at a neighbour's centre
  is ``exp(-width_scale)``. With per-basis LWR (``regression="lwr"``)
  ``width_scale = 4`` (0.018 there) suits better than the common 1 (0.37):
  wider bases smooth the forcing term twice (in the regression and in the
  normalised mixture). The default global least-squares fit uses 1
  (docs/method.md section 2 has the measured errors);
- amplitude ``a`` (docs/method.md section 2, "Amplitude"). Default
  (``scale_by_amplitude=False``): per weight column, ``a = g - y0`` (no
  floor) in the columns of ``DmpConfig.scaled_dims`` and ``a = 1`` (no
  scaling, as movement_primitives and others do) in the others.
  :func:`fit_demonstrations` fills ``scaled_dims`` with the columns where
  every demonstration moves by at least ``DmpConfig.scale_threshold``
  (5 cm / 0.05), whose path stays within its start-goal span
  (``scale_rule = "span"``, :func:`scale_choice`) and that
  ``DmpConfig.unscaled_dims`` does not exclude:
  those keep the thesis's spatial scaling toward a new start, the
  nearly-still ones (a lift that returns to its height, a quaternion
  component) are not scaled. Both are continuous in ``y0``: an unscaled
  column changes by ``dy0 (1 - K s(t))``, at most ``|dy0|``; a scaled
  column's shape scales by ``(g - y0) / (g - y0_demo)``, which changes sign
  only if the start moves past the goal by more than the threshold.
  Option ``scale_by_amplitude=True`` is the thesis's form (Eq. 3.4) in every column,
  ``a = g - y0`` per dimension, with ``|a|`` floored at
  ``DmpConfig.amplitude_floor`` keeping its sign (sign(0) = +1) so the fit
  stays finite where start and goal coincide (w = f / 0 otherwise). That form
  is discontinuous where ``g - y0`` changes sign: a 10 cm lift that returns
  to its height becomes a 10 cm dip when the start moves 5 mm up (the sign
  of ``a`` flips); in a rollout the start comes from the measured hand pose
  in the perceived object frame, so perception noise alone can flip it;
- fitting from one demonstration (thesis Eq. 3.7-3.9)::

      f_target(t) = tau^2 ddy - K (g - y) + D tau dy
      w_b = (s^T Gamma_b f_target) / (s^T Gamma_b s),  s_t = x_t a,
      Gamma_b = diag(psi_b(x_t))

  (locally weighted regression per basis, ``regression="lwr"``, the
  thesis's form); derivatives are numerical (``numpy.gradient``, second
  order, non-uniform times allowed). The default,
  ``regression="least_squares"``, instead solves the global least squares
  problem ``min_W sum_t |phi(x_t) (W * a) - f_target(t)|^2`` for the
  normalised basis mixture (docs/method.md section 2, a decision: it
  reproduces the demonstrated path several times more closely with the
  thesis's B, and recovers weights exactly when the data come from the DMP
  itself).

Quaternion handling (``DmpConfig.quaternion``):

- ``"vector"`` (thesis, footnote of section 5.1): the quaternion is a 4-D
  vector like the position; signs are made continuous before fitting and the
  integrated quaternion is normalised for execution. W is ``(B, 7)``.
- ``"ude"``: orientation DMP on the unit sphere of Ude et al. 2014 (ICRA,
  "Orientation in Cartesian space dynamic movement primitives")::

      tau d(eta)/dt = K 2 log(g * conj(q)) - D eta + f_o(x),
      tau dq/dt = 1/2 eta * q,       f_o = (sum psi w / sum psi) x a_o,
      a_o = 2 log(g * conj(q0))  (3-D, floored like a),

  eta = tau omega (spatial angular velocity, rad). W is ``(B, 6)``: three
  position columns then three orientation columns.

Integration:

- vector formulation: the system is linear in W for fixed (y0, g, tau), and
  the phase does not depend on the state, so ``y(t) = y0 + K s(t) (g - y0) +
  G(t) (W * a)`` where ``s`` is the zero-state step response and ``G`` the
  zero-state response to each basis feature ``phi_b(t) = psi_b x / sum psi``.
  ``G`` and ``s`` are computed once per (B, alpha_x, K, D, tau, step, length)
  and cached; a batch of S weight samples is then one matmul. The linear
  dynamics are discretised exactly (zero-order hold, matrix exponential); the
  forcing input is held over each step at its value at the step's midpoint,
  which makes the scheme second order in the step (``DmpConfig.dt``, 1 ms by
  default). Requested times off the internal grid are linearly interpolated.
- Ude formulation: the orientation is nonlinear, integrated step by step with
  semi-implicit Euler at ``DmpConfig.dt`` (first order), vectorised over the
  batch.
"""

# No ``from __future__ import annotations``: pydrake's yaml_load_typed reads the
# dataclass field types, which must be real types rather than strings.
import cmath
import dataclasses
import functools
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.signal

from drake_skill.action.quaternion import (
    UNIT_NORM_TOLERANCE,
    as_quaternions,
    make_quaternions_continuous,
    quat_conjugate,
    quat_exp,
    quat_log,
    quat_multiply,
)

__all__ = [
    "POSE_DIM",
    "DmpConfig",
    "Dmp",
    "DemonstrationFit",
    "validate_demonstration",
    "basis_centres_widths",
    "phase",
    "basis_features",
    "forcing_amplitude",
    "fit_weights",
    "fit_dmp",
    "fit_demonstrations",
    "scale_choice",
    "initial_weights",
    "exploration_covariance",
    "default_times",
    "integrate",
    "clear_operator_cache",
]

#: Width of a pose: xyz (m) + quaternion (w, x, y, z).
POSE_DIM = 7
#: Longest DMP duration tau accepted, s (an hour; the skills last seconds).
MAX_DURATION_S = 3600.0
#: Most internal integration steps one call may allocate (2e6: 2000 s at the
#: default 1 ms step; the cached operators take steps * B * 8 bytes).
MAX_INTEGRATION_STEPS = 2_000_000
_QUATERNION_MODES = ("vector", "ude")
_REGRESSIONS = ("lwr", "least_squares")
_SCALE_RULES = ("span", "amplitude", "joined")
#: A path may leave its start-goal span by this fraction of the span (and at
#: least SPAN_MARGIN_MIN) and still count as within it (scale_rule "span").
SPAN_MARGIN_FRACTION = 0.1
SPAN_MARGIN_MIN = 0.01


@dataclass
class DmpConfig:
    """Hyper-parameters of the action model (docs/method.md section 2, thesis Table 6.1).

    Loadable with ``yaml_load_typed(schema=DmpConfig, data=...)``.
    """

    #: Number of basis functions B shared by all dimensions (>= 2).
    n_basis: int = 20
    #: Spring constant K (1/s^2 after time scaling by tau).
    K: float = 100.0
    #: Damping D; 2 sqrt(K) is critically damped.
    D: float = 20.0
    #: Canonical-system decay; ln(100) gives x(tau) = 0.01.
    alpha_x: float = math.log(100.0)
    #: Basis widths h_b = width_scale / (c_{b+1} - c_b)^2 (see module docstring);
    #: 1 for the default least-squares fit, 4 suits "lwr" (docs/method.md section 2).
    width_scale: float = 1.0
    #: Internal integration step, s.
    dt: float = 0.001
    #: Orientation formulation: "vector" (thesis) or "ude" (Ude et al. 2014).
    quaternion: str = "vector"
    #: Weight regression: "least_squares" (default, docs/method.md section 2) or
    #: "lwr" (per-basis locally weighted regression, thesis Eq. 3.9).
    regression: str = "least_squares"
    #: Scale the forcing term by the amplitude a = g - y0 (thesis Eq. 3.4). Off by
    #: default: that form flips the motion where g - y0 changes sign (module docstring).
    scale_by_amplitude: bool = False
    #: Floor on |a| per dimension (m for xyz, unitless for quaternion/rad); only
    #: used with ``scale_by_amplitude``.
    amplitude_floor: float = 1e-2
    #: Weight columns scaled by a = g - y0 when ``scale_by_amplitude`` is False
    #: (filled by fit_demonstrations when ``scale_threshold`` > 0).
    scaled_dims: list[int] = field(default_factory=list)
    #: fit_demonstrations scales a column when every demonstration's |g - y0|
    #: there is at least this (m for xyz, unitless for quaternion components,
    #: rad for "ude" rotations); <= 0 keeps ``scaled_dims`` as given.
    scale_threshold: float = 0.05
    #: Weight columns fit_demonstrations never scales, whatever they move: a
    #: motion whose via point along a column is not between start and goal
    #: (Draw's hook behind the handle, docs/method.md section 2) keeps its
    #: place in the object frame instead of stretching with g - y0.
    unscaled_dims: list[int] = field(default_factory=list)
    #: How fit_demonstrations picks ``scaled_dims`` (docs/method.md section 2.1):
    #: "span" scales a column only where every demonstration moves by at least
    #: ``scale_threshold`` *and* its path stays within its start-goal span (a
    #: via point outside the span stays put in the object frame); "amplitude"
    #: looks at the amplitude alone (skills fitted before 2026-12-06);
    #: "joined" scales none: with ``start_join`` the path joins the
    #: demonstrated one before contact, and stretching would move the contact
    #: (drake-skill fit chooses it when the demonstrations touch the object).
    scale_rule: str = "span"
    #: Fraction of tau in which an unscaled column's start offset ``y0 - y0_demo``
    #: fades out (minimum jerk), so that the path joins the demonstrated one
    #: before contact (docs/method.md section 2.1); a fraction, so that it
    #: scales with tau as the rest of the DMP does. 0: the spring's own
    #: transient ``(y0 - y0_demo)(1 - K s(t))``, which lasts about tau / 2.
    #: ``drake-skill fit`` sets it from the demonstrations' first contact.
    start_join: float = 0.0

    def validate(self) -> "DmpConfig":
        """Raises ValueError naming the first bad field; returns self."""
        if not isinstance(self.n_basis, (int, np.integer)) or isinstance(self.n_basis, bool) or self.n_basis < 2:
            raise ValueError(f"DmpConfig.n_basis: expected an integer >= 2, got {self.n_basis!r}")
        for name in ("K", "alpha_x", "width_scale", "dt", "amplitude_floor"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
                raise ValueError(f"DmpConfig.{name}: expected a finite value > 0, got {v!r}")
        if not (math.isfinite(self.D) and self.D >= 0):
            raise ValueError(f"DmpConfig.D: expected a finite value >= 0, got {self.D!r}")
        if self.quaternion not in _QUATERNION_MODES:
            raise ValueError(f"DmpConfig.quaternion: expected one of {_QUATERNION_MODES}, got {self.quaternion!r}")
        if self.regression not in _REGRESSIONS:
            raise ValueError(f"DmpConfig.regression: expected one of {_REGRESSIONS}, got {self.regression!r}")
        for name in ("scaled_dims", "unscaled_dims"):
            dims = list(getattr(self, name))
            if any(not isinstance(i, (int, np.integer)) or isinstance(i, bool) or not 0 <= i < self.weight_dim
                   for i in dims) or len(set(dims)) != len(dims):
                raise ValueError(f"DmpConfig.{name}: expected distinct weight columns in [0, {self.weight_dim}), "
                                 f"got {dims!r}")
        if self.scale_rule not in _SCALE_RULES:
            raise ValueError(f"DmpConfig.scale_rule: expected one of {_SCALE_RULES}, got {self.scale_rule!r}")
        if not (isinstance(self.start_join, (int, float)) and math.isfinite(self.start_join)
                and 0 <= self.start_join <= 1):
            raise ValueError(f"DmpConfig.start_join: expected a fraction of tau in [0, 1], got {self.start_join!r}")
        if not math.isfinite(self.scale_threshold):
            raise ValueError(f"DmpConfig.scale_threshold: expected a finite value, got {self.scale_threshold!r}")
        return self

    @property
    def weight_dim(self) -> int:
        """Columns of W: 7 for "vector", 6 for "ude"."""
        return POSE_DIM if self.quaternion == "vector" else 6


@dataclass
class Dmp:
    """Parameters of one fitted DMP, all in the object frame.

    ``weights``: (B, 7) for "vector", (B, 6) for "ude" (row b is w_b);
    ``y0``, ``goal``: (7,) poses (xyz m + unit quaternion wxyz); ``tau``: s.
    """

    weights: np.ndarray
    y0: np.ndarray
    goal: np.ndarray
    tau: float
    #: The demonstrated start (7,) the weights were fitted from; None: ``y0``.
    #: With ``DmpConfig.start_join`` the unscaled columns join the demonstrated
    #: path from a start that differs from it (docs/method.md section 2.1).
    y0_demo: np.ndarray | None = None

    def __post_init__(self):
        self.weights = np.array(self.weights, dtype=float)
        self.y0 = np.array(self.y0, dtype=float)
        self.goal = np.array(self.goal, dtype=float)
        self.tau = float(self.tau)
        if self.y0_demo is not None:
            self.y0_demo = np.array(self.y0_demo, dtype=float)
            if self.y0_demo.shape != (POSE_DIM,) or not np.all(np.isfinite(self.y0_demo)):
                raise ValueError(f"Dmp.y0_demo: expected a finite pose of shape (7,), got {self.y0_demo.shape}")
        if self.weights.ndim != 2 or self.weights.shape[1] not in (6, 7) or self.weights.shape[0] < 2:
            raise ValueError(f"Dmp.weights: expected shape (B >= 2, 7 or 6), got {self.weights.shape}")
        for name in ("y0", "goal"):
            v = getattr(self, name)
            if v.shape != (POSE_DIM,):
                raise ValueError(f"Dmp.{name}: expected shape (7,), got {v.shape}")
            if not np.all(np.isfinite(v)):
                raise ValueError(f"Dmp.{name}: contains NaN or inf: {v}")
        if not np.all(np.isfinite(self.weights)):
            raise ValueError(f"Dmp.weights: contains NaN or inf (shape {self.weights.shape})")
        if not (math.isfinite(self.tau) and self.tau > 0):
            raise ValueError(f"Dmp.tau: expected a finite duration > 0 s, got {self.tau!r}")
        if self.tau > MAX_DURATION_S:
            raise ValueError(f"Dmp.tau: {self.tau!r} s is longer than the {MAX_DURATION_S:.0f} s accepted; "
                             "expected the duration of one skill execution in seconds")
        for name in ("y0", "goal"):
            norm = float(np.linalg.norm(getattr(self, name)[3:]))
            if abs(norm - 1.0) > UNIT_NORM_TOLERANCE:
                raise ValueError(f"Dmp.{name}: quaternion {getattr(self, name)[3:]} has norm {norm:.6g}; "
                                 f"expected a unit quaternion (w, x, y, z) within {UNIT_NORM_TOLERANCE}")

    @property
    def n_basis(self) -> int:
        return self.weights.shape[0]

    @property
    def demonstrated_start(self) -> np.ndarray:
        """``y0_demo``, or ``y0`` when the DMP carries none."""
        return self.y0 if self.y0_demo is None else self.y0_demo

    def with_start(self, y0) -> "Dmp":
        """The same DMP started from ``y0`` (7,), keeping its demonstrated start."""
        return Dmp(weights=self.weights, y0=y0, goal=self.goal, tau=self.tau, y0_demo=self.demonstrated_start)

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Numeric arrays for ``fileio.atomic_save_npz``."""
        out = {
            f"{prefix}weights": self.weights,
            f"{prefix}y0": self.y0,
            f"{prefix}goal": self.goal,
            f"{prefix}tau": np.array(self.tau),
        }
        if self.y0_demo is not None:
            out[f"{prefix}y0_demo"] = self.y0_demo
        return out

    @classmethod
    def from_arrays(cls, arrays, prefix: str = "") -> "Dmp":
        """Inverse of :meth:`to_arrays`."""
        try:
            return cls(
                weights=arrays[f"{prefix}weights"],
                y0=arrays[f"{prefix}y0"],
                goal=arrays[f"{prefix}goal"],
                tau=float(np.asarray(arrays[f"{prefix}tau"])),
                y0_demo=arrays[f"{prefix}y0_demo"] if f"{prefix}y0_demo" in arrays else None,
            )
        except KeyError as e:
            raise ValueError(f"arrays: missing DMP entry {e.args[0]!r}") from e


# --------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------


def validate_demonstration(times, poses, name: str = "demonstration") -> tuple[np.ndarray, np.ndarray]:
    """Checks one demonstration and returns float copies ``(times (T,), poses (T, 7))``.

    Requirements: T >= 3 samples, ``poses`` of width 7, everything finite,
    ``times`` strictly increasing (s), quaternions within 1e-2 of unit norm
    (they are then normalised exactly). Raises ValueError naming ``name``.
    """
    t = np.array(times, dtype=float)
    y = np.array(poses, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"{name} times: expected shape (T,), got {t.shape}")
    if y.ndim != 2 or y.shape[1] != POSE_DIM:
        raise ValueError(f"{name} poses: expected shape (T, 7) (xyz + quaternion wxyz), got {y.shape}")
    if y.shape[0] != t.shape[0]:
        raise ValueError(f"{name}: times has {t.shape[0]} samples but poses has {y.shape[0]}")
    if t.shape[0] < 3:
        raise ValueError(f"{name}: expected at least 3 samples, got {t.shape[0]}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name} times: contains NaN or inf")
    if not np.all(np.isfinite(y)):
        bad = np.argwhere(~np.isfinite(y))[0]
        raise ValueError(f"{name} poses: contains NaN or inf (first at sample {bad[0]}, column {bad[1]})")
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.argmax(dt <= 0))
        raise ValueError(
            f"{name} times: expected strictly increasing timestamps, "
            f"got t[{k}]={float(t[k])!r} >= t[{k + 1}]={float(t[k + 1])!r}"
        )
    y[:, 3:] = as_quaternions(y[:, 3:], name=f"{name} poses[:, 3:7]", tol=UNIT_NORM_TOLERANCE)
    return t, y


def _validate_times(times, name: str = "times") -> np.ndarray:
    t = np.array(times, dtype=float).reshape(-1) if np.ndim(times) <= 1 else None
    if t is None:
        raise ValueError(f"{name}: expected shape (T,), got {np.shape(times)}")
    if t.size == 0:
        raise ValueError(f"{name}: expected at least one time, got none")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name}: contains NaN or inf")
    if np.any(t < 0):
        raise ValueError(f"{name}: expected times >= 0 s from the start of the movement, min is {float(t.min())!r}")
    if np.any(np.diff(t) < 0):
        raise ValueError(f"{name}: expected non-decreasing times")
    return t


# --------------------------------------------------------------------------
# Phase, bases, amplitude
# --------------------------------------------------------------------------


def basis_centres_widths(n_basis: int, alpha_x: float, width_scale: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """Basis centres ``c`` (B,) in phase and widths ``h`` (B,), docs/method.md section 2.

    ``c_b = exp(-alpha_x * b / (B - 1))``,
    ``h_b = width_scale / (c_{b+1} - c_b)^2``, ``h_{B-1} = h_{B-2}``.
    """
    if int(n_basis) != n_basis or n_basis < 2:
        raise ValueError(f"n_basis: expected an integer >= 2, got {n_basis!r}")
    c = np.exp(-alpha_x * np.linspace(0.0, 1.0, int(n_basis)))
    h = np.empty_like(c)
    h[:-1] = width_scale / np.diff(c) ** 2
    h[-1] = h[-2]
    return c, h


def phase(t, tau: float, alpha_x: float) -> np.ndarray:
    """Canonical system solution ``x(t) = exp(-alpha_x t / tau)`` (thesis Eq. 3.5)."""
    return np.exp(-alpha_x * np.asarray(t, dtype=float) / tau)


def basis_features(x, centres: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Normalised, phase-gated features ``phi_b(x) = psi_b(x) x / sum psi``, (T,) -> (T, B).

    ``f(x) = phi(x) @ (W * a)`` is the forcing term of thesis Eq. 3.4.
    """
    x = np.asarray(x, dtype=float)
    psi = np.exp(-widths * (x[:, None] - centres) ** 2)
    return psi * (x / np.maximum(psi.sum(axis=1), 1e-300))[:, None]


def _floor_amplitude(a: np.ndarray, config: DmpConfig) -> np.ndarray:
    if not config.scale_by_amplitude:
        out = np.ones_like(a)
        if config.scaled_dims:
            dims = list(config.scaled_dims)
            out[..., dims] = a[..., dims]
        return out
    sign = np.where(a < 0.0, -1.0, 1.0)
    return sign * np.maximum(np.abs(a), config.amplitude_floor)


def forcing_amplitude(y0, goal, config: DmpConfig) -> np.ndarray:
    """Amplitude ``a`` multiplying the forcing term, shape (..., weight_dim).

    "vector": ``a = g - y0`` (7). "ude": position ``g - y0`` (3) then
    ``2 log(g_q * conj(q0))`` (3, rad). With ``scale_by_amplitude`` floored
    as described in the module docstring; otherwise that value in the
    ``scaled_dims`` columns and 1 elsewhere. ``y0``/``goal`` may carry
    leading batch axes.
    """
    y0 = np.asarray(y0, dtype=float)
    goal = np.asarray(goal, dtype=float)
    if config.quaternion == "vector":
        a = goal - y0
    else:
        rot = 2.0 * quat_log(quat_multiply(goal[..., 3:], quat_conjugate(y0[..., 3:])))
        a = np.concatenate([goal[..., :3] - y0[..., :3], rot], axis=-1)
    return _floor_amplitude(a, config)


# --------------------------------------------------------------------------
# Fitting
# --------------------------------------------------------------------------


def _regress(t: np.ndarray, f_target: np.ndarray, a: np.ndarray, tau: float, config: DmpConfig) -> np.ndarray:
    """Weights (B, n) such that ``phi(x_t) @ (W * a) ~= f_target`` (T, n)."""
    if config.n_basis > t.shape[0]:
        raise ValueError(f"DmpConfig.n_basis: {config.n_basis} bases but the demonstration has only "
                         f"{t.shape[0]} samples; use at most {t.shape[0]} bases or a longer demonstration")
    c, h = basis_centres_widths(config.n_basis, config.alpha_x, config.width_scale)
    x = phase(t, tau, config.alpha_x)
    if config.regression == "lwr":
        # Thesis Eq. 3.9 per basis and dimension, with s_t = x_t a_d:
        # w_bd = sum_t psi_tb x_t a_d f_td / sum_t psi_tb x_t^2 a_d^2.
        psi = np.exp(-h * (x[:, None] - c) ** 2)  # (T, B)
        num = psi.T @ (x[:, None] * f_target)  # (B, n)
        den = psi.T @ (x * x)  # (B,)
        if np.any(den <= 1e-300):
            b = int(np.argmax(den <= 1e-300))
            raise ValueError(f"demonstration: basis {b} (centre x={c[b]:.3g}) receives no samples; use fewer bases")
        return num / (den[:, None] * a[None, :])
    phi = basis_features(x, c, h)
    w, *_ = np.linalg.lstsq(phi, f_target / a[None, :], rcond=None)
    return w


def _f_target(t: np.ndarray, y: np.ndarray, goal: np.ndarray, tau: float, config: DmpConfig) -> np.ndarray:
    """Thesis Eq. 3.7 in docs/method.md's form: ``tau^2 ddy - K (g - y) + D tau dy``, (T, n)."""
    dy = np.gradient(y, t, axis=0, edge_order=2)
    ddy = np.gradient(dy, t, axis=0, edge_order=2)
    return tau * tau * ddy - config.K * (goal - y) + config.D * tau * dy


def fit_weights(times, values, config: DmpConfig, y0=None, goal=None) -> np.ndarray:
    """Fits the vector DMP to arbitrary (T, n) data; returns W (B, n).

    No quaternion handling: this is the per-dimension fit of thesis Eq.
    3.7-3.9 on raw values (used by :func:`fit_dmp` and to check weight
    recovery on DMP-generated data). ``y0``/``goal`` default to the first
    and last samples; amplitude ``a = g - y0`` is floored as configured.
    """
    config.validate()
    t = np.array(times, dtype=float)
    y = np.array(values, dtype=float)
    if t.ndim != 1 or y.ndim != 2 or y.shape[0] != t.shape[0]:
        raise ValueError(f"times/values: expected shapes (T,) and (T, n), got {t.shape} and {y.shape}")
    if t.shape[0] < 3:
        raise ValueError(f"times: expected at least 3 samples, got {t.shape[0]}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise ValueError("times/values: contain NaN or inf")
    if np.any(np.diff(t) <= 0):
        raise ValueError("times: expected strictly increasing timestamps")
    t = t - t[0]
    tau = float(t[-1])
    y0 = y[0] if y0 is None else np.asarray(y0, dtype=float)
    goal = y[-1] if goal is None else np.asarray(goal, dtype=float)
    a = _floor_amplitude(goal - y0, config)
    return _regress(t, _f_target(t, y, goal, tau, config), a, tau, config)


def _angular_velocity(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Spatial angular velocity (T, 3) rad/s of a continuous unit-quaternion path: ``2 dq/dt * conj(q)``."""
    dq = np.gradient(q, t, axis=0, edge_order=2)
    return 2.0 * quat_multiply(dq, quat_conjugate(q))[:, 1:]


def fit_dmp(times, poses, config: DmpConfig | None = None, *, quaternion_reference=None) -> Dmp:
    """Fits one DMP to one demonstration (docs/method.md section 2, thesis Eq. 3.7-3.9).

    ``times``: (T,) s, strictly increasing; ``poses``: (T, 7) xyz (m) +
    quaternion (wxyz) in the object frame. Quaternion signs are made
    continuous along the demonstration (and put on the hemisphere of
    ``quaternion_reference`` (4,) if given). tau = duration, y0 = first pose,
    g = last pose. Returns :class:`Dmp` with W (B, 7) or (B, 6) ("ude").
    """
    config = (config or DmpConfig()).validate()
    t, y = validate_demonstration(times, poses)
    y[:, 3:] = make_quaternions_continuous(y[:, 3:], reference=quaternion_reference)
    t = t - t[0]
    tau = float(t[-1])
    y0, goal = y[0].copy(), y[-1].copy()
    if config.quaternion == "vector":
        w = _regress(t, _f_target(t, y, goal, tau, config), forcing_amplitude(y0, goal, config), tau, config)
        return Dmp(weights=w, y0=y0, goal=goal, tau=tau, y0_demo=y0)
    a = forcing_amplitude(y0, goal, config)
    w_pos = _regress(t, _f_target(t, y[:, :3], goal[:3], tau, config), a[:3], tau, config)
    # Ude et al. 2014, Eq. 24-25: f_o = tau^2 domega - K 2 log(g * conj(q)) + D tau omega.
    q = y[:, 3:]
    omega = _angular_velocity(t, q)
    domega = np.gradient(omega, t, axis=0, edge_order=2)
    err = 2.0 * quat_log(quat_multiply(goal[3:], quat_conjugate(q)))
    f_rot = tau * tau * domega - config.K * err + config.D * tau * omega
    w_rot = _regress(t, f_rot, a[3:], tau, config)
    return Dmp(weights=np.concatenate([w_pos, w_rot], axis=1), y0=y0, goal=goal, tau=tau, y0_demo=y0)


@dataclass
class DemonstrationFit:
    """Result of :func:`fit_demonstrations`.

    ``dmps``: one per demonstration; ``initial_index``: the one whose weights
    start policy search (drawn by seed); ``sigma0``: (B, d, d) per-basis
    exploration covariances Sigma_b^0.
    """

    dmps: list
    initial_index: int
    sigma0: np.ndarray
    ridge: float = field(default=0.0)
    #: The DmpConfig the fits used (``scaled_dims`` filled in); execute them with it.
    config: DmpConfig | None = None
    #: Why each weight column is scaled or not (:func:`scale_choice`); empty when not chosen.
    scale_reasons: dict = field(default_factory=dict)

    @property
    def initial(self) -> Dmp:
        return self.dmps[self.initial_index]


def fit_demonstrations(
    demonstrations: Sequence[tuple],
    config: DmpConfig | None = None,
    *,
    seed: int = 0,
    ridge: float = 0.1,
    floor: float = 1e-8,
) -> DemonstrationFit:
    """Fits one DMP per demonstration of a skill (docs/method.md section 2, thesis 5.2).

    ``demonstrations``: sequence of ``(times (T_i,), poses (T_i, 7))``, at
    least 2. Quaternion signs are made consistent across demonstrations by
    putting every demonstration's first quaternion on the hemisphere of the
    first demonstration's. Returns the fits, the seeded initial choice
    (:func:`initial_weights`) and Sigma^0 (:func:`exploration_covariance`).
    """
    config = (config or DmpConfig()).validate()
    if len(demonstrations) < 2:
        raise ValueError(f"demonstrations: expected at least 2 (covariance across fits), got {len(demonstrations)}")
    reference = None
    checked_demos = []
    for i, demo in enumerate(demonstrations):
        if len(demo) != 2:
            raise ValueError(f"demonstrations[{i}]: expected a pair (times, poses), got {len(demo)} items")
        times, poses = demo
        _, checked = validate_demonstration(times, poses, name=f"demonstrations[{i}]")
        if reference is None:
            reference = checked[0, 3:]
        checked[:, 3:] = make_quaternions_continuous(checked[:, 3:], reference=reference)
        checked_demos.append((times, checked))
    reasons: dict[int, str] = {}
    if not config.scale_by_amplitude and config.scale_threshold > 0:
        reasons = scale_choice([p for _, p in checked_demos], config)
        dims = [i for i, why in reasons.items() if why == "scaled"]
        config = dataclasses.replace(config, scaled_dims=dims).validate()
    dmps = [fit_dmp(t, p, config) for t, p in checked_demos]   # quaternions already on the reference's side
    index, _ = initial_weights(dmps, seed)
    return DemonstrationFit(dmps=dmps, initial_index=index, sigma0=exploration_covariance(dmps, ridge, floor),
                            ridge=ridge, config=config, scale_reasons=reasons)


def scale_choice(paths: Sequence[np.ndarray], config: DmpConfig) -> dict[int, str]:
    """Why each weight column is or is not scaled by ``g - y0`` (docs/method.md section 2.1).

    ``paths``: each demonstration's poses (T, 7), quaternions continuous.
    Returns {column: reason}, reason one of "scaled", "unscaled_dims" (the
    skill file says so), "moves < threshold" (some demonstration moves less
    than ``scale_threshold`` along it) and, with ``scale_rule = "span"``,
    "via point outside span": some demonstration's path leaves
    ``[min(y0, g) - m, max(y0, g) + m]`` with ``m = max(SPAN_MARGIN_MIN,
    SPAN_MARGIN_FRACTION |g - y0|)`` (m, or unitless for a quaternion
    component). Stretching by ``(g - y0) / (g - y0_demo)`` keeps a point in
    place in the object frame only between start and goal; a point beyond
    them moves with the start, so those columns are left unscaled. The
    "span" test applies to the position columns and, in the vector
    formulation, to the quaternion components alike; with "ude" the
    rotation columns keep the amplitude rule (a rotation vector has no span
    along the path).
    """
    amp_config = DmpConfig(quaternion=config.quaternion, scale_by_amplitude=True, amplitude_floor=1e-300)
    amplitudes = np.stack([np.abs(forcing_amplitude(p[0], p[-1], amp_config)) for p in paths])
    span_dims = range(POSE_DIM if config.quaternion == "vector" else 3)
    reasons = {}
    for i in range(config.weight_dim):
        if i in config.unscaled_dims:
            reasons[i] = "unscaled_dims"
        elif config.scale_rule == "joined":
            reasons[i] = "joins the demonstration before contact"
        elif not np.all(amplitudes[:, i] >= config.scale_threshold):
            reasons[i] = "moves < threshold"
        elif config.scale_rule == "span" and i in span_dims and not all(_within_span(p[:, i]) for p in paths):
            reasons[i] = "via point outside span"
        else:
            reasons[i] = "scaled"
    return reasons


def _within_span(values: np.ndarray) -> bool:
    """True when a column's path stays within its start-goal span (with the margin of :func:`scale_choice`)."""
    lo, hi = sorted((float(values[0]), float(values[-1])))
    margin = max(SPAN_MARGIN_MIN, SPAN_MARGIN_FRACTION * (hi - lo))
    return bool(values.min() >= lo - margin and values.max() <= hi + margin)


def initial_weights(dmps: Sequence[Dmp], seed: int) -> tuple[int, np.ndarray]:
    """Picks the initial policy weights among the per-demonstration fits (thesis 5.2).

    Returns ``(index, W copy (B, d))`` with index drawn uniformly by
    ``numpy.random.default_rng(seed)``.
    """
    if len(dmps) == 0:
        raise ValueError("dmps: expected at least one fitted DMP, got none")
    index = int(np.random.default_rng(seed).integers(len(dmps)))
    return index, dmps[index].weights.copy()


def exploration_covariance(dmps_or_weights, ridge: float = 0.1, floor: float = 1e-8) -> np.ndarray:
    """Initial exploration covariances Sigma_b^0, (N, B, d) weights -> (B, d, d).

    ``C_b`` = sample covariance (ddof = 1) of w_b across the N >= 2
    per-demonstration fits (thesis 5.2, Eq. 5.3). With N = 2-3 fits C_b has
    rank <= N - 1 < d, so a ridge is added, scaled per dimension so that
    position and quaternion weights are treated alike::

        Sigma_b^0 = C_b + ridge * diag(diag(C_b)) + floor * I

    This is symmetric positive definite for ridge > 0 and floor > 0.
    Accepts a sequence of :class:`Dmp` or an array (N, B, d).
    """
    if isinstance(dmps_or_weights, np.ndarray):
        w = np.asarray(dmps_or_weights, dtype=float)
    else:
        w = np.stack([np.asarray(d.weights if isinstance(d, Dmp) else d, dtype=float) for d in dmps_or_weights])
    if w.ndim != 3 or w.shape[0] < 2:
        raise ValueError(f"weights: expected shape (N >= 2 fits, B, d), got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("weights: contain NaN or inf")
    if not (math.isfinite(ridge) and ridge >= 0):
        raise ValueError(f"ridge: expected a finite value >= 0, got {ridge!r}")
    if not (math.isfinite(floor) and floor > 0):
        raise ValueError(f"floor: expected a finite value > 0, got {floor!r}")
    dev = w - w.mean(axis=0)
    cov = np.einsum("nbi,nbj->bij", dev, dev) / (w.shape[0] - 1)
    d = w.shape[2]
    diag = np.einsum("bii->bi", cov)
    out = cov + (ridge * diag)[:, :, None] * np.eye(d) + floor * np.eye(d)
    return 0.5 * (out + np.swapaxes(out, 1, 2))


# --------------------------------------------------------------------------
# Integration
# --------------------------------------------------------------------------


def _check_steps(t_max: float, dt: float) -> None:
    """Raises ValueError when integrating to ``t_max`` s at step ``dt`` would exceed MAX_INTEGRATION_STEPS."""
    steps = t_max / dt
    if steps > MAX_INTEGRATION_STEPS:
        raise ValueError(
            f"times: integrating to {t_max:.6g} s at DmpConfig.dt = {dt:g} s takes {steps:.3g} steps, more than "
            f"the {MAX_INTEGRATION_STEPS:.0e} allowed; shorten tau / the requested times or raise DmpConfig.dt")


def default_times(tau: float, dt: float) -> np.ndarray:
    """Uniform times ``0, dt, ..., ceil(tau/dt) dt`` (s) covering [0, tau]."""
    n = int(math.ceil(tau / dt - 1e-9))
    return dt * np.arange(n + 1)


def _discrete_filter(K: float, D: float, tau: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """IIR coefficients (b, a) of the exact ZOH discretisation of
    ``tau^2 e'' + D tau e' + K e = u`` (state (e, e'), output e), step h.

    ``Ad = expm(A h)`` and ``Gamma = A^-1 (Ad - I) B`` in closed form for the
    2x2 companion matrix ``A = [[0, 1], [-K/tau^2, -D/tau]]`` (any damping,
    the critically damped case through the series of sinh(s h)/s). Written
    out rather than calling ``scipy.linalg.expm``: the latter goes through
    BLAS, whose thread start-up costs milliseconds on a loaded machine for a
    3x3 matrix. Checked against ``expm`` in tests/test_dmp.py.
    """
    mu = -0.5 * D / tau
    delta = K / tau**2
    s = cmath.sqrt(mu * mu - delta)
    sh = s * h
    if abs(sh) < 1e-3:
        c = 1.0 + sh * sh / 2.0 + sh**4 / 24.0
        sinc = h * (1.0 + sh * sh / 6.0 + sh**4 / 120.0)
    else:
        c = cmath.cosh(sh)
        sinc = cmath.sinh(sh) / s
    c, sinc, e = c.real, sinc.real, math.exp(mu * h)
    # expm(A h) = e^{mu h} (cosh(s h) I + sinh(s h)/s (A - mu I)).
    a00 = e * (c - mu * sinc)
    a01 = e * sinc
    a10 = -e * delta * sinc
    a11 = e * (c + mu * sinc)
    # Gamma = A^-1 (Ad - I) [0, 1/tau^2], A^-1 = [[2 mu, -1], [delta, 0]] / delta.
    g0 = (2.0 * mu * a01 - (a11 - 1.0)) / (delta * tau**2)
    g1 = a01 / tau**2
    # Output e: C adj(zI - Ad) Gamma / det(zI - Ad) with C = [1, 0].
    b = np.array([0.0, g0, -a11 * g0 + a01 * g1])
    a = np.array([1.0, -(a00 + a11), a00 * a11 - a01 * a10])
    return b, a


@functools.lru_cache(maxsize=16)
def _operators(n_basis: int, alpha_x: float, width_scale: float, K: float, D: float, tau: float, h: float, n: int):
    """Zero-state responses on the grid ``k h``, k = 0..n: G (n+1, B) to the
    basis features and s (n+1,) to a unit step. Read-only, cached."""
    c, w = basis_centres_widths(n_basis, alpha_x, width_scale)
    x_mid = phase((np.arange(n + 1) + 0.5) * h, tau, alpha_x)
    u = np.empty((n + 1, n_basis + 1))
    u[:, :n_basis] = basis_features(x_mid, c, w)
    u[:, n_basis] = 1.0
    b, a = _discrete_filter(K, D, tau, h)
    # Compiled IIR filter along time: exact ZOH recursion, zero initial state.
    resp = scipy.signal.lfilter(b, a, u, axis=0)
    g = np.ascontiguousarray(resp[:, :n_basis])
    s = np.ascontiguousarray(resp[:, n_basis])
    g.setflags(write=False)
    s.setflags(write=False)
    return g, s


def clear_operator_cache() -> None:
    """Drops cached integration operators (for cold-start timing)."""
    _operators.cache_clear()


def _grid_for(times: np.ndarray, dt: float):
    """Internal grid step h, length n, and per-time (index, fraction) for linear interpolation."""
    t_max = float(times[-1])
    if times.size >= 2 and times[0] == 0.0:
        step = np.diff(times)
        d = float(step.mean())
        if d > 0 and np.allclose(step, d, rtol=1e-9, atol=1e-12):
            m = max(1, int(math.ceil(d / dt - 1e-9)))
            idx = np.arange(times.size) * m
            return d / m, int(idx[-1]), idx, np.zeros(times.size)
    h = dt
    n = max(1, int(math.ceil(t_max / h - 1e-9)))
    pos = times / h
    idx = np.minimum(np.floor(pos).astype(np.int64), n - 1)
    frac = np.clip(pos - idx, 0.0, 1.0)
    return h, n, idx, frac


def _rows(arr: np.ndarray, idx: np.ndarray, frac: np.ndarray) -> np.ndarray:
    if not np.any(frac):
        return arr[idx]
    f = frac.reshape((-1,) + (1,) * (arr.ndim - 1))
    return arr[idx] * (1.0 - f) + arr[np.minimum(idx + 1, arr.shape[0] - 1)] * f


def _check_weights(weights, n_basis: int, d: int) -> np.ndarray:
    w = np.asarray(weights, dtype=float)
    if w.ndim not in (2, 3) or w.shape[-2:] != (n_basis, d):
        raise ValueError(f"weights: expected shape ({n_basis}, {d}) or (S, {n_basis}, {d}), got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"weights: contain NaN or inf (shape {w.shape})")
    return w


def _apply(g_rows: np.ndarray, wa: np.ndarray) -> np.ndarray:
    """``G (T, B) @ Wa`` for Wa (B, d) -> (T, d) or (S, B, d) -> (S, T, d).

    The batch is one GEMM (T, B) @ (B, S d); the result is returned as a
    transposed view (no copy of the S T d array)."""
    if wa.ndim == 2:
        return g_rows @ wa
    n_s, n_b, n_d = wa.shape
    flat = np.ascontiguousarray(np.moveaxis(wa, 0, 1)).reshape(n_b, n_s * n_d)
    return (g_rows @ flat).reshape(g_rows.shape[0], n_s, n_d).transpose(1, 0, 2)


def integrate(
    dmp: Dmp,
    config: DmpConfig | None = None,
    times=None,
    *,
    weights=None,
    normalize_quaternion: bool = True,
) -> np.ndarray:
    """Integrates the DMP from ``dmp.y0`` at rest towards ``dmp.goal`` over ``dmp.tau``.

    ``times``: (T,) s from the start of the movement, non-decreasing, >= 0;
    defaults to :func:`default_times` (tau, config.dt). Times past tau keep
    integrating the (converging) dynamics. ``weights``: overrides
    ``dmp.weights``; (B, d) or a batch (S, B, d). Returns poses (T, 7) or
    (S, T, 7): xyz m + quaternion wxyz, the quaternion normalised to unit
    length unless ``normalize_quaternion`` is False (vector formulation only).
    A batch result is a transposed view of one (T, S, 7) buffer (no copy).
    """
    config = (config or DmpConfig()).validate()
    d = config.weight_dim
    w = _check_weights(dmp.weights if weights is None else weights, dmp.n_basis, d)
    if dmp.weights.shape[1] != d:
        raise ValueError(f"dmp.weights: has {dmp.weights.shape[1]} columns "
                         f"but config.quaternion={config.quaternion!r} needs {d}")
    t_max = dmp.tau if times is None else None
    t = _validate_times(times) if times is not None else None
    _check_steps(t_max if t is None else float(t[-1]), config.dt)
    if t is None:
        t = default_times(dmp.tau, config.dt)
    h, n, idx, frac = _grid_for(t, config.dt)
    g_op, s_op = _operators(
        dmp.n_basis, float(config.alpha_x), float(config.width_scale), float(config.K), float(config.D), dmp.tau, h, n)
    g_rows = _rows(g_op, idx, frac)  # (T, B)
    s_rows = _rows(s_op, idx, frac)  # (T,)
    a = forcing_amplitude(dmp.y0, dmp.goal, config)
    join = _start_join(dmp, config, t, s_rows)
    if config.quaternion == "vector":
        # y(t) = y0 + K s(t) (g - y0) + G(t) (W * a): one matmul for the batch.
        y = _apply(g_rows, w * a)
        y += dmp.y0 + config.K * s_rows[:, None] * (dmp.goal - dmp.y0)
        if join is not None:
            y += join
        if normalize_quaternion:
            q = y[..., 3:]
            norm = np.sqrt(np.einsum("...i,...i->...", q, q))
            if not np.all(norm > 1e-9):
                raise ValueError("weights: the integrated quaternion passes through zero norm (no "
                                 "orientation); these weights drive the 4-D quaternion through the origin")
            q /= norm[..., None]
        return y
    pos = _apply(g_rows, w[..., :3] * a[:3])
    pos += dmp.y0[:3] + config.K * s_rows[:, None] * (dmp.goal[:3] - dmp.y0[:3])
    if join is not None:
        pos += join[:, :3]
    q = _integrate_ude_orientation(dmp, w[..., 3:] * a[3:], config, h, n, idx, frac)
    return np.concatenate([pos, q], axis=-1)


def _start_join(dmp: Dmp, config: DmpConfig, t: np.ndarray, s_rows: np.ndarray) -> np.ndarray | None:
    """What ``DmpConfig.start_join`` adds to the path (T, 7), or None when nothing.

    In a column that is not scaled, the start offset ``d = y0 - y0_demo``
    enters the path as ``d (1 - K s(t))``, the spring's transient. With
    ``T_j = start_join tau`` it enters as ``d (1 - m(t / T_j))`` instead, ``m``
    the minimum-jerk ramp ``10 u^3 - 15 u^4 + 6 u^5`` (zero velocity and
    acceleration at both ends): from ``t = T_j`` on the path is the one
    fitted to the demonstration, so a via point after ``T_j`` stays where it
    was shown in the object frame. The returned term is the difference of the
    two; only position columns (and quaternion components in the vector
    formulation) that are not scaled are touched.
    """
    if config.start_join <= 0 or dmp.y0_demo is None or config.scale_by_amplitude:
        return None
    offset = dmp.y0 - dmp.y0_demo
    columns = [i for i in range(POSE_DIM if config.quaternion == "vector" else 3) if i not in config.scaled_dims]
    if not columns or not np.any(offset[columns]):
        return None
    u = np.clip(t / (config.start_join * dmp.tau), 0.0, 1.0)
    fade = 1.0 - (10 * u**3 - 15 * u**4 + 6 * u**5)
    out = np.zeros((t.size, POSE_DIM))
    out[:, columns] = (fade - (1.0 - config.K * s_rows))[:, None] * offset[columns]
    return out


def _integrate_ude_orientation(dmp: Dmp, wa: np.ndarray, config: DmpConfig, h, n, idx, frac) -> np.ndarray:
    """Ude et al. 2014 orientation DMP, semi-implicit Euler with step h.

    ``wa``: (B, 3) or (S, B, 3) weights times amplitude. Returns (T, 4) or
    (S, T, 4) unit quaternions at the requested rows.
    """
    c, width = basis_centres_widths(dmp.n_basis, config.alpha_x, config.width_scale)
    phi = basis_features(phase(np.arange(n + 1) * h, dmp.tau, config.alpha_x), c, width)  # (n+1, B)
    forcing = np.matmul(phi, wa)  # (n+1, 3) or (S, n+1, 3)
    batch = wa.shape[:-2]
    if not batch:
        out = _ude_steps_single(dmp.y0[3:], dmp.goal[3:], forcing, config.K, config.D, h / dmp.tau, n)
        return _quaternion_rows(out, idx, frac)
    q = np.broadcast_to(dmp.y0[3:], batch + (4,)).copy()
    eta = np.zeros(batch + (3,))
    g = dmp.goal[3:]
    out = np.empty(batch + (n + 1, 4))
    out[..., 0, :] = q
    kt, dt_tau = config.K, h / dmp.tau
    for k in range(n):
        err = 2.0 * quat_log(quat_multiply(g, quat_conjugate(q)))
        eta = eta + dt_tau * (kt * err - config.D * eta + forcing[..., k, :])
        q = quat_multiply(quat_exp(0.5 * dt_tau * eta), q)
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        out[..., k + 1, :] = q
    return _quaternion_rows(out, idx, frac)


def _quaternion_rows(out: np.ndarray, idx: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Grid quaternions (..., n+1, 4) at rows idx (+ frac, normalised linear interpolation)."""
    rows = np.take(out, idx, axis=-2)
    if np.any(frac):
        nxt = np.take(out, np.minimum(idx + 1, out.shape[-2] - 1), axis=-2)
        rows = rows * (1.0 - frac[:, None]) + nxt * frac[:, None]
        rows /= np.linalg.norm(rows, axis=-1, keepdims=True)
    return rows


def _ude_steps_single(q0, goal, forcing, K: float, D: float, dt_tau: float, n: int) -> np.ndarray:
    """Same recursion as the batched loop above for one trajectory, on Python
    floats: numpy's per-call overhead dominates for (4,)-sized arrays.
    Returns (n+1, 4)."""
    gw, gx, gy, gz = (float(v) for v in goal)
    w, x, y, z = (float(v) for v in q0)
    ex = ey = ez = 0.0  # eta
    f = forcing.tolist()
    out = np.empty((n + 1, 4))
    out[0] = (w, x, y, z)
    sqrt, atan2, sin, cos = math.sqrt, math.atan2, math.sin, math.cos
    for k in range(n):
        # r = goal * conj(q); err = 2 log(r)
        rw = gw * w + gx * x + gy * y + gz * z
        rx = -gw * x + gx * w - gy * z + gz * y
        ry = -gw * y + gx * z + gy * w - gz * x
        rz = -gw * z - gx * y + gy * x + gz * w
        nv = sqrt(rx * rx + ry * ry + rz * rz)
        sc = 2.0 * (atan2(nv, rw) / nv if nv > 1e-12 else 1.0 / rw)
        fk = f[k]
        ex += dt_tau * (K * sc * rx - D * ex + fk[0])
        ey += dt_tau * (K * sc * ry - D * ey + fk[1])
        ez += dt_tau * (K * sc * rz - D * ez + fk[2])
        # q <- exp(dt/(2 tau) eta) * q
        ax, ay, az = 0.5 * dt_tau * ex, 0.5 * dt_tau * ey, 0.5 * dt_tau * ez
        na = sqrt(ax * ax + ay * ay + az * az)
        s = sin(na) / na if na > 1e-8 else 1.0 - na * na / 6.0
        c = cos(na)
        ax, ay, az = ax * s, ay * s, az * s
        w, x, y, z = (
            c * w - ax * x - ay * y - az * z,
            c * x + ax * w + ay * z - az * y,
            c * y - ax * z + ay * w + az * x,
            c * z + ax * y - ay * x + az * w,
        )
        nq = sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / nq, x / nq, y / nq, z / nq
        out[k + 1] = (w, x, y, z)
    return out

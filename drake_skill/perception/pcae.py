"""Point-cloud autoencoder (PCAE): the skill-agnostic perception features.

docs/method.md section 3, thesis section 3.5 and 6.4 (after Achlioptas et al. 2017).

Architecture (N = 2048 points, code size 128)::

    points (B, N, 3) --normalise--> (B, N, 3)
      encoder: shared per-point MLP 3-64-128-128-256-128, each layer
               Linear + BatchNorm (over the channel axis) + ReLU  -> (B, N, 128)
               max-pool over the N points                        -> code (B, 128)
      decoder: Linear 128-256 + ReLU, 256-256 + ReLU, 256-(N*3) (no activation)
                                                                  -> (B, N, 3)

The per-point layers are ``nn.Linear`` on the last axis of a (B, N, C) tensor,
which is faster on a CPU than ``Conv1d`` with kernel size 1 (``drake-skill bench perception``).
In eval mode :meth:`PointCloudAutoencoder.encode_fast` folds every BatchNorm
into the preceding Linear layer (same numbers up to float rounding).

Input normalisation (:func:`normalize_points`): each cloud, given in metres in
a gravity-aligned frame (z up: the world frame, or the perceived object frame,
:func:`cloud_in_object_frame`), is centred on the centre of its
axis-aligned bounding box and divided by the FIXED length
``NORMALIZATION_SCALE_M`` = 0.25 m. No per-cloud scaling is done, so the
object's size and the extent changes that encode its state (a lid opening, a
drawer sliding out) stay in the input; centring on the box centre removes the
object's position on the table. The encoder is trained on views from all
azimuths; a skill expresses its clouds in the perceived object frame
(``SkillConfig.cloud_frame``), which removes the object's yaw on the table.

Losses, in the units of their inputs:

- Chamfer (:func:`chamfer_distance`): mean over points of the squared distance
  to the nearest point of the other cloud, summed over both directions (the
  form used by Achlioptas et al. 2017). Units: length squared.
- EMD (:func:`earth_movers_distance`): thesis Eq. 3.32 divided by N, i.e. the
  mean distance between points matched by the optimal bijection, solved exactly
  with ``scipy.optimize.linear_sum_assignment``. Units: length. Used for
  evaluation only (not differentiable here).

Weights are stored as safetensors (never pickles); :func:`load_pcae` checks
every tensor's name and shape and raises errors that name the file.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from drake_skill.common import N_POINTS

"""Points per cloud the PCAE reads and writes (docs/method.md 3)."""
CODE_SIZE = 128
"""Size of the code (bottleneck), thesis 3.5."""
ENCODER_WIDTHS = (64, 128, 128, 256, CODE_SIZE)
DECODER_WIDTHS = (256, 256)
NORMALIZATION_SCALE_M = 0.25
"""Fixed length (m) every centred cloud is divided by (see module docstring)."""

MAX_COORDINATE_M = 1000.0
"""Largest accepted point coordinate (m): beyond it float32 arithmetic may overflow."""

DEFAULT_WEIGHTS_FILE = "pcae.safetensors"
"""The shipped weights' file in the models package (card: ``pcae.json``)."""


def default_weights() -> Path:
    """The shipped weights, trained by ``tools/train_pcae.py``: ``pcae.safetensors`` of ``drake_skill.models``."""
    from drake_skill.resources import model_path

    return model_path(DEFAULT_WEIGHTS_FILE)


# --------------------------------------------------------------------------- input


def check_points(points, name: str = "points", n_points: int | None = N_POINTS) -> np.ndarray:
    """Validates a cloud ``(N, 3)`` or a batch ``(B, N, 3)``; returns float32 numpy.

    Raises ValueError naming ``name`` when the shape is wrong or a value is not finite.
    """
    arr = np.asarray(points)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
        raise ValueError(f"{name}: expected a numeric array of shape (N, 3) or (B, N, 3), got dtype {arr.dtype}")
    if arr.ndim not in (2, 3) or arr.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3) or (B, N, 3), got {arr.shape}")
    if n_points is not None and arr.shape[-2] != n_points:
        raise ValueError(f"{name}: expected {n_points} points (shape (..., {n_points}, 3)), got shape {arr.shape}")
    if arr.shape[-2] == 0:
        raise ValueError(f"{name}: the cloud is empty (shape {arr.shape})")
    if arr.ndim == 3 and arr.shape[0] == 0:
        raise ValueError(f"{name}: the batch is empty (shape {arr.shape}); expected at least one cloud")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite coordinates (shape {arr.shape})")
    with np.errstate(over="ignore"):  # a float64 beyond float32's range becomes inf, refused below
        out = arr.astype(np.float32, copy=False)
    # Bounded so float32 arithmetic (centring, the encoder's layers) cannot overflow.
    big = float(np.abs(out).max())
    if not big <= MAX_COORDINATE_M:
        raise ValueError(f"{name}: coordinate of magnitude {big:.3g} m; expected points within "
                         f"{MAX_COORDINATE_M:g} m of the world origin (a cloud in metres)")
    return out


def cloud_in_object_frame(points, X_WO) -> np.ndarray:
    """World-frame points expressed in the object frame O: ``p_O = R_WO^T (p_W - p_WO)``.

    points: (N, 3) or (T, N, 3) in metres; X_WO: the object pose as a (7,)
    vector (xyz m + unit quaternion wxyz) or a (4, 4) homogeneous matrix.
    Returns float32 of the same shape. The perceived O is gravity-aligned
    (a yaw about z), so the result stays z-up, as the encoder was trained.
    """
    X = np.asarray(X_WO, dtype=float)
    if X.shape == (7,):
        from drake_skill.action.quaternion import quat_to_rotation_matrix
        R, p = quat_to_rotation_matrix(X[3:]), X[:3]
    elif X.shape == (4, 4):
        R, p = X[:3, :3], X[:3, 3]
    else:
        raise ValueError(f"X_WO: expected a (7,) pose (xyz + wxyz) or a (4, 4) matrix, got shape {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("X_WO: contains NaN or inf")
    pts = np.asarray(points, dtype=np.float64)
    return ((pts - p) @ R).astype(np.float32)


def normalize_points(points, scale_m: float = NORMALIZATION_SCALE_M):
    """Centres each cloud on its bounding-box centre and divides by ``scale_m``.

    points: (N, 3) or (B, N, 3) in metres, numpy or torch. Returns the same
    type and shape, dimensionless. See the module docstring for why the scale
    is fixed.
    """
    if isinstance(points, torch.Tensor):
        lo = points.amin(dim=-2, keepdim=True)
        hi = points.amax(dim=-2, keepdim=True)
    else:
        lo = points.min(axis=-2, keepdims=True)
        hi = points.max(axis=-2, keepdims=True)
    return (points - 0.5 * (lo + hi)) / scale_m


# --------------------------------------------------------------------------- model


class PointwiseBlock(nn.Module):
    """Linear over the last axis + BatchNorm over channels + ReLU. (B, N, Cin) -> (B, N, Cout)."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__()
        self.linear = nn.Linear(c_in, c_out)
        self.bn = nn.BatchNorm1d(c_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, n, _ = x.shape
        y = self.linear(x)
        y = self.bn(y.reshape(b * n, -1)).reshape(b, n, -1)
        return torch.relu(y)

    def folded(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Eval-mode weight (Cin, Cout) and bias (Cout,) with the BatchNorm folded in."""
        bn = self.bn
        s = bn.weight / torch.sqrt(bn.running_var + bn.eps)
        w = self.linear.weight * s[:, None]
        b = (self.linear.bias - bn.running_mean) * s + bn.bias
        return w.t().contiguous(), b.contiguous()


class PointCloudAutoencoder(nn.Module):
    """The PCAE of thesis 3.5 (see module docstring for layer sizes).

    ``forward(x)`` takes NORMALISED clouds (B, N, 3) and returns
    ``(reconstruction (B, N, 3), code (B, 128))``. Use :meth:`encode_points`
    for clouds in metres.
    """

    def __init__(self, n_points: int = N_POINTS, code_size: int = CODE_SIZE):
        super().__init__()
        self.n_points = n_points
        self.code_size = code_size
        widths = list(ENCODER_WIDTHS[:-1]) + [code_size]
        blocks, c = [], 3
        for w in widths:
            blocks.append(PointwiseBlock(c, w))
            c = w
        self.encoder = nn.Sequential(*blocks)
        d1, d2 = DECODER_WIDTHS
        self.decoder = nn.Sequential(
            nn.Linear(code_size, d1), nn.ReLU(), nn.Linear(d1, d2), nn.ReLU(), nn.Linear(d2, n_points * 3)
        )
        self._folded: list[tuple[torch.Tensor, torch.Tensor]] | None = None

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """Normalised clouds (B, N, 3) -> codes (B, 128), max over points."""
        return self.encoder(x).amax(dim=1)

    def decode(self, code: torch.Tensor) -> torch.Tensor:
        """Codes (B, 128) -> normalised clouds (B, N, 3)."""
        return self.decoder(code).reshape(code.shape[0], self.n_points, 3)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        code = self.encode(x)
        return self.decode(code), code

    def train(self, mode: bool = True):
        self._folded = None  # BatchNorm statistics may change: refold on next use.
        return super().train(mode)

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        self._folded = None
        return super().load_state_dict(state_dict, strict=strict, assign=assign)

    def encode_fast(self, x: torch.Tensor) -> torch.Tensor:
        """Eval-mode encoder with BatchNorm folded into the Linear layers. (B, N, 3) -> (B, 128)."""
        if self.training:
            raise RuntimeError("encode_fast is for eval mode; call model.eval() first")
        if self._folded is None:
            with torch.no_grad():
                self._folded = [blk.folded() for blk in self.encoder]
        # All points of the batch as one (B * N, C) matrix through every layer, the
        # ReLU in place: one GEMM per layer and no intermediate reshapes or copies.
        y = x.reshape(-1, x.shape[-1])
        for w, b in self._folded:
            y = torch.addmm(b, y, w).relu_()
        return y.reshape(*x.shape[:-1], -1).amax(dim=-2)

    def encode_points(self, points, n_threads: int | None = 1) -> np.ndarray:
        """Codes of clouds in metres, world frame.

        points: (N, 3) or (B, N, 3), N = ``n_points``. Returns (128,) or (B, 128)
        float32. Runs in eval mode under ``torch.inference_mode`` with
        ``n_threads`` torch threads (restored afterwards; None leaves it).
        """
        arr = check_points(points, "points", self.n_points)
        single = arr.ndim == 2
        x = torch.from_numpy(normalize_points(arr[None] if single else arr))
        if self.training:
            self.eval()
        with _torch_threads(n_threads), torch.inference_mode():
            code = self.encode_fast(x).numpy()
        return code[0].copy() if single else code

    def reconstruct_points(self, points) -> np.ndarray:
        """Reconstruction in metres (de-normalised with the input's box centre). Same shape as ``points``."""
        arr = check_points(points, "points", self.n_points)
        single = arr.ndim == 2
        batch = arr[None] if single else arr
        lo, hi = batch.min(axis=1, keepdims=True), batch.max(axis=1, keepdims=True)
        centre = 0.5 * (lo + hi)
        if self.training:
            self.eval()
        with torch.inference_mode():
            rec, _ = self(torch.from_numpy(normalize_points(batch)))
        out = rec.numpy() * NORMALIZATION_SCALE_M + centre
        return out[0] if single else out


@contextlib.contextmanager
def _torch_threads(n: int | None):
    if n is None:
        yield
        return
    old = torch.get_num_threads()
    if old == n:          # the usual case: no thread-pool change per call
        yield
        return
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)


def weight_decay_groups(model: nn.Module, weight_decay: float) -> list[dict]:
    """Adam parameter groups: L2 ``weight_decay`` on the Linear weight matrices, none on biases and BatchNorm."""
    linear_weights = {id(m.weight) for m in model.modules() if isinstance(m, nn.Linear)}
    decay = [p for p in model.parameters() if id(p) in linear_weights]
    no_decay = [p for p in model.parameters() if id(p) not in linear_weights]
    return [{"params": decay, "weight_decay": weight_decay}, {"params": no_decay, "weight_decay": 0.0}]


# --------------------------------------------------------------------------- losses


def _nearest(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Index (B, N) of the nearest point of b (B, M, 3) for every point of a (B, N, 3); no gradient.

    A k-d tree per cloud (scipy) rather than a dense (N, M) distance matrix
    and its argmin: less memory and less time on a CPU.
    """
    from scipy.spatial import cKDTree

    a_np = a.detach().cpu().numpy()
    b_np = b.detach().cpu().numpy()
    idx = np.stack([cKDTree(b_np[k]).query(a_np[k])[1] for k in range(a_np.shape[0])])
    return torch.from_numpy(idx.astype(np.int64)).to(a.device)


def chamfer_distance(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Symmetric Chamfer distance per cloud.

    a: (B, N, 3), b: (B, M, 3). Returns (B,):
    mean_i min_j |a_i - b_j|^2 + mean_j min_i |a_i - b_j|^2 (units of a, squared).
    Nearest neighbours are found without gradient; the gradient flows through
    the matched pairs' distances (the same gradient as the min, almost everywhere).
    """
    if a.ndim != 3 or b.ndim != 3 or a.shape[-1] != 3 or b.shape[-1] != 3 or a.shape[0] != b.shape[0]:
        raise ValueError(f"chamfer_distance: expected (B, N, 3) and (B, M, 3), "
                         f"got {tuple(a.shape)} and {tuple(b.shape)}")
    i_ab = _nearest(a, b)  # (B, N) index into b
    i_ba = _nearest(b, a)  # (B, M) index into a
    b_near = torch.gather(b, 1, i_ab[..., None].expand(-1, -1, 3))
    a_near = torch.gather(a, 1, i_ba[..., None].expand(-1, -1, 3))
    return ((a - b_near) ** 2).sum(-1).mean(1) + ((b - a_near) ** 2).sum(-1).mean(1)


def earth_movers_distance(a: np.ndarray, b: np.ndarray, n_subsample: int | None = None, seed: int = 0) -> float:
    """Exact EMD between two equally sized clouds (thesis Eq. 3.32 divided by N).

    a, b: (N, 3). Returns the mean matched distance (units of a). With
    ``n_subsample`` both clouds are first subsampled (without replacement,
    seeded) to that many points, which makes the Hungarian solve cheaper but
    biases the value upward slightly (sparser matching).
    """
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial.distance import cdist

    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape != b.shape:
        raise ValueError(f"earth_movers_distance: expected two (N, 3) clouds of equal size, "
                         f"got {a.shape} and {b.shape}")
    if n_subsample is not None and n_subsample < a.shape[0]:
        rng = np.random.default_rng(seed)
        a = a[rng.choice(a.shape[0], n_subsample, replace=False)]
        b = b[rng.choice(b.shape[0], n_subsample, replace=False)]
    cost = cdist(a, b)
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].mean())


# --------------------------------------------------------------------------- files


def expected_shapes(n_points: int = N_POINTS, code_size: int = CODE_SIZE) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every tensor in a PCAE weights file (state_dict, float32 except int64 counters)."""
    model = PointCloudAutoencoder(n_points, code_size)
    return {k: tuple(v.shape) for k, v in model.state_dict().items()}


def save_pcae(model: PointCloudAutoencoder, path: str | os.PathLike, metadata: dict | None = None) -> Path:
    """Writes the model's state_dict to ``path`` as safetensors, atomically.

    ``metadata`` (str -> JSON-able) is stored in the safetensors header.
    """
    from safetensors.torch import save

    from drake_skill.fileio import atomic_write_bytes

    tensors = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    meta = {"format": "drake_skill.perception.pcae", "n_points": str(model.n_points), "code_size": str(model.code_size)}
    for k, v in (metadata or {}).items():
        meta[k] = v if isinstance(v, str) else json.dumps(v)
    return atomic_write_bytes(path, save(tensors, metadata=meta))


def load_pcae(path: str | os.PathLike | None = None) -> PointCloudAutoencoder:
    """Loads a PCAE from a safetensors file (None: the shipped weights) and returns it in eval mode.

    Raises FileNotFoundError if ``path`` does not exist, ValueError naming the
    file if it is not a safetensors file, its header describes another
    architecture (``n_points``/``code_size`` other than 2048/128), misses a
    tensor, has an extra one, or a tensor has the wrong shape, dtype or
    non-finite values. Everything in the header is checked against the
    architecture before any tensor is read, so a corrupt header cannot make
    the loader allocate memory it describes.
    """
    from safetensors import safe_open

    path = default_weights() if path is None else Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: PCAE weights file not found (train one with tools/train_pcae.py)")
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
            shapes_in_file = {k: tuple(f.get_slice(k).get_shape()) for k in f.keys()}
            dtypes_in_file = {k: str(f.get_slice(k).get_dtype()) for k in f.keys()}
            for key in ("n_points", "code_size"):
                if key in meta and meta[key] != str({"n_points": N_POINTS, "code_size": CODE_SIZE}[key]):
                    raise _HeaderError(f"header field '{key}' is {meta[key]!r}; this PCAE architecture has "
                                       f"n_points = {N_POINTS}, code_size = {CODE_SIZE}")
            expected = expected_shapes(N_POINTS, CODE_SIZE)
            missing = sorted(set(expected) - set(shapes_in_file))
            if missing:
                raise _HeaderError(f"missing tensor(s) {missing} (expected the {len(expected)} tensors of a PCAE)")
            extra = sorted(set(shapes_in_file) - set(expected))
            if extra:
                raise _HeaderError(f"unexpected tensor(s) {extra} in a PCAE weights file")
            for k, shape in expected.items():
                if shapes_in_file[k] != shape:
                    raise _HeaderError(f"tensor '{k}' has shape {shapes_in_file[k]}, expected {shape}")
                want = "I64" if k.endswith("num_batches_tracked") else "F32"
                if dtypes_in_file[k].upper() not in (want, {"I64": "INT64", "F32": "FLOAT32"}[want]):
                    raise _HeaderError(f"tensor '{k}' has dtype {dtypes_in_file[k]}, expected {want}")
            tensors = {k: f.get_tensor(k) for k in expected}
    except _HeaderError as e:
        raise ValueError(f"{path}: {e}") from None
    except Exception as e:  # safetensors raises SafetensorError / OSError on garbage.
        raise ValueError(f"{path}: not a readable safetensors file ({type(e).__name__}: {e})") from e
    for k, t in tensors.items():
        if t.is_floating_point() and not torch.isfinite(t).all():
            raise ValueError(f"{path}: tensor '{k}' contains NaN or infinite values")
    model = PointCloudAutoencoder(N_POINTS, CODE_SIZE)
    model.load_state_dict(tensors)
    model.eval()
    return model


class _HeaderError(Exception):
    """A safetensors header that does not describe this PCAE (reported by load_pcae)."""


# --------------------------------------------------------------------------- benchmark


def time_encode(n_frames: int = 50, weights: str | os.PathLike | None = None, seed: int = 0) -> float:
    """Milliseconds per frame to encode one 2048-point cloud (eval, inference_mode, 1 thread).

    Uses the shipped weights when present (random weights otherwise: the time
    does not depend on the values). Reports the median of ``n_frames`` calls
    after 5 warm-up calls, each on a fresh random cloud in metres.
    """
    if n_frames < 1:
        raise ValueError(f"n_frames: expected >= 1, got {n_frames}")
    try:
        path = Path(weights) if weights is not None else default_weights()
    except FileNotFoundError:  # the models package is not installed: time random weights
        path = None
    if path is not None and path.is_file():
        model = load_pcae(path)
    else:
        torch.manual_seed(seed)
        model = PointCloudAutoencoder().eval()
    rng = np.random.default_rng(seed)
    clouds = rng.uniform(-0.15, 0.15, size=(n_frames + 5, N_POINTS, 3)).astype(np.float32)
    times = []
    for i, cloud in enumerate(clouds):
        t0 = time.perf_counter()
        model.encode_points(cloud, n_threads=1)
        if i >= 5:
            times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3)

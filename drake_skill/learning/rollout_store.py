"""What a run keeps of every rollout, beside its records: ``rollouts/NAME.npz``.

``results.jsonl`` holds each rollout's numbers (``RolloutResult.summary``);
this keeps what a look or a replay needs, one file per set of rollouts, all
written by the driver (the process that writes ``--out``), atomically:

=================================  ==============================================
``rollouts/episode_EEE.npz``       the exploratory rollouts of update EEE (index c)
``rollouts/greedy_EEE.npz``        the greedy execution after update EEE (index 0)
``rollouts/held_out_PHASE.npz``    the held-out executions, ``before`` / ``after``
``rollouts/select.npz``            the guarded selection's executions
``rollouts/evaluation_dmp_I.npz``  ``drake-skill evaluate``'s of DMP I (skill folder)
``rollouts/exploration.npz``       ``drake-skill evaluate --explore``'s (skill folder)
=================================  ==============================================

Per rollout c, the arrays ``c{c}_NAME`` (missing where empty):
``weights`` (B, 7) and ``seed`` (what a replay re-simulates),
``object_pose`` / ``object_pose_true`` (7,) (the DMP frame's / the simulator's X_WO,
xyz m + wxyz; NaN where unknown), ``last_frame``
(h, w, 3) uint8 (the perception camera's image at the end or the stop,
downscaled), ``times`` [s], ``joints`` (N, 7) [rad], ``ee_pose`` (N, 7)
(xyz m + wxyz) and ``object_state`` (N,) [rad or m] at the rollout's
``record_hz`` up to the end or the stop (float32: 0.1 mm / 1e-7 rad); and for
a rollout that failed, ``frames`` (K, h, w, 3) with ``frame_times`` (K,) [s],
one frame a second up to the stop. ``meta`` holds the JSON text
``{"n": R}``, and for an evaluation what a replay builds the runner from
(``skill_dir``, ``station`` YAML, ``rollout`` settings, ``dmp_index``; a run's
are in its ``config.json``).

Size (compressed; Open's 71 x 67 frames, measured): about 6 kB per rollout
plus about 1.5 kB per frame a failed one keeps, so a default learn run (5 x 6
rollouts, 6 greedy executions, 10 + 10 held-out, 9 selection executions)
keeps about 1 MB (make demo's Open run, 14 of 30 rollouts stopped by the reflex: 1.1 MB).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from drake_skill.fileio import atomic_save_npz

__all__ = ["load_rollout", "rollouts_path", "save_rollouts", "stored_names"]

_PATH = ("times", "joints", "ee_pose", "object_state")
_STOP = ("frame_times", "frames")


def rollouts_path(folder, name: str) -> Path:
    """``folder/rollouts/NAME.npz`` (a run folder, or a skill folder for an evaluation)."""
    return Path(folder) / "rollouts" / f"{name}.npz"


def _weights(result) -> np.ndarray:
    try:
        return np.asarray(result.weights, dtype=float)
    except (TypeError, ValueError):     # a task that was not weights (its rollout failed as "error")
        return np.zeros((0, 7))


def _arrays(c: int, result) -> dict[str, np.ndarray]:
    out = {f"c{c}_weights": _weights(result), f"c{c}_seed": np.asarray(int(result.seed)),
           f"c{c}_object_pose": np.asarray(result.object_pose, dtype=float),
           f"c{c}_object_pose_true": np.asarray(result.object_pose_true, dtype=float)}
    last = np.asarray(result.last_frame, dtype=np.uint8)
    if last.size:
        out[f"c{c}_last_frame"] = last
    for name in _PATH + (_STOP if result.failed else ()):
        value = np.asarray(getattr(result, name))
        if value.size:
            out[f"c{c}_{name}"] = value.astype(np.uint8 if name == "frames" else
                                                np.float64 if name.endswith("times") else np.float32)
    return out


def save_rollouts(path, results, setup: dict[str, Any] | None = None) -> Path:
    """Writes what is kept of ``results`` (``RolloutResult`` list, index order) and the JSON-able
    ``setup`` (into ``meta``) to ``path`` (compressed npz, no pickle), atomically."""
    arrays: dict[str, np.ndarray] = {"meta": np.asarray(json.dumps({**(setup or {}), "n": len(results)}))}
    for c, result in enumerate(results):
        arrays.update(_arrays(c, result))
    return atomic_save_npz(path, arrays, compressed=True)


def load_rollout(path, index: int) -> dict[str, Any]:
    """Rollout ``index`` of the file ``path``: ``{"seed", "weights", NAME: array, ..., "meta": {...}}``
    (the arrays present). Errors name the file and the range of indices."""
    from drake_skill.fileio import load_npz

    path = Path(path)
    arrays = load_npz(path)
    try:
        meta = json.loads(str(arrays["meta"]))
        n = int(meta["n"])
    except (KeyError, ValueError, TypeError) as e:
        raise ValueError(f"{path}: not a rollouts file ({e}); run the learning or evaluation again") from None
    if not 0 <= int(index) < n:
        raise ValueError(f"{path}: no rollout {index}; it holds {n} (indices 0..{n - 1})")
    prefix = f"c{int(index)}_"
    out: dict[str, Any] = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
    if "weights" not in out or "seed" not in out:
        raise ValueError(f"{path}: rollout {index} has no weights or seed; run the learning or evaluation again")
    out["seed"] = int(out["seed"])
    return out | {"meta": meta}


def stored_names(folder) -> list[str]:
    """The names of the rollout files a run or skill folder holds (sorted)."""
    return sorted(p.stem for p in (Path(folder) / "rollouts").glob("*.npz"))

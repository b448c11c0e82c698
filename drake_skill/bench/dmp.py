"""Benchmark of the DMP action model: integration speed and orientation formulations.

``drake-skill bench dmp [--json]`` / ``python tools/bench_dmp.py [--json]``.

Measures, on a synthetic 5 s demonstration fitted with B = 20:

- ``single_ms``: integrate one 7-D DMP for 5 s at 1 ms steps (5001 poses,
  quaternion normalised), integration operators already cached (median);
- ``single_cold_ms``: the same with the operator cache cleared first;
- ``batch1000_s``: one call integrating 1000 weight samples (1000, 20, 7) into
  (1000, 5001, 7);
- ``movement_primitives_single_ms``: ``movement_primitives.dmp.CartesianDMP``
  (its Cython step functions when built) imitating the same demonstration and
  running ``open_loop`` over 5 s with ``dt = int_dt = 1 ms``; ``null`` if the
  package is not available. It is not a dependency of drake-skill: it is
  imported in-process if present, otherwise run with the interpreter given by
  ``--mp-python`` / ``$DRAKE_SKILL_MP_PYTHON`` / the default separate venv
  ``~/.cache/drake-skill/bench-venv``, which ``--install-mp`` creates;
- ``orientation``: reproduction errors of the thesis' vector quaternion DMP
  and of Ude et al. 2014's unit-sphere DMP on three demonstrations.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from drake_skill.action.dmp import DmpConfig, clear_operator_cache, fit_dmp, integrate
from drake_skill.action.quaternion import quat_exp, quat_multiply, rotation_angle

DEFAULT_MP_VENV = Path.home() / ".cache" / "drake-skill" / "bench-venv"


def synthetic_demonstration(duration: float = 5.0, rate_hz: float = 100.0, variant: int = 0):
    """A smooth demonstration in the object frame: ``(times (T,), poses (T, 7))``.

    Minimum-jerk reach of about 0.3 m with a sin^2 lift, and a 1 rad
    minimum-jerk rotation with a 0.2 rad bump about a tilted axis, from a
    gripper-down orientation; starts and ends at rest. ``variant`` > 0
    perturbs goal, bump and rotation deterministically (for several
    demonstrations of one skill).
    """
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    s = t / duration
    mj = 10 * s**3 - 15 * s**4 + 6 * s**5
    bump = np.sin(np.pi * s) ** 2
    p0 = np.array([0.0, 0.0, 0.15])
    p1 = np.array([0.25, 0.05, 0.05])
    lift = np.array([0.0, 0.05, 0.04])
    turn, wobble = 1.0, 0.2
    if variant:
        rng = np.random.default_rng(variant)
        p1 = p1 + rng.normal(0.0, 0.02, 3)
        lift = lift * (1.0 + 0.2 * rng.normal(size=3))
        turn += 0.1 * rng.normal()
        wobble *= 1.0 + 0.2 * rng.normal()
    pos = p0 + np.outer(mj, p1 - p0) + np.outer(bump, lift)
    axis = np.array([0.2, 0.3, 1.0]) / np.linalg.norm([0.2, 0.3, 1.0])
    angle = turn * mj + wobble * bump
    q0 = np.array([0.0, 1.0, 0.0, 0.0])  # gripper pointing down
    q = quat_multiply(quat_exp(0.5 * angle[:, None] * axis), q0)
    return t, np.concatenate([pos, q], axis=1)


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def reproduction_errors(times, poses, config: DmpConfig) -> dict:
    """Fits ``config``'s DMP to one demonstration and integrates it at the same times.

    Returns position RMSE and max error (mm), orientation RMS and max angle
    (deg), final-pose errors, and (vector formulation) the largest deviation
    of the raw integrated quaternion's norm from 1.
    """
    dmp = fit_dmp(times, poses, config)
    rel = times - times[0]
    out = integrate(dmp, config, rel)
    perr = np.linalg.norm(out[:, :3] - poses[:, :3], axis=1)
    ang = rotation_angle(out[:, 3:], poses[:, 3:])
    res = {
        "position_rmse_mm": float(np.sqrt(np.mean(perr**2)) * 1e3),
        "position_max_mm": float(perr.max() * 1e3),
        "orientation_rms_deg": float(np.degrees(np.sqrt(np.mean(ang**2)))),
        "orientation_max_deg": float(np.degrees(ang.max())),
        "final_position_mm": float(perr[-1] * 1e3),
        "final_orientation_deg": float(np.degrees(ang[-1])),
    }
    if config.quaternion == "vector":
        raw = integrate(dmp, config, rel, normalize_quaternion=False)
        res["max_norm_deviation"] = float(np.abs(np.linalg.norm(raw[:, 3:], axis=1) - 1.0).max())
    return res


def compare_orientation_formulations(rate_hz: float = 100.0, n_basis: int = 20) -> dict:
    """Vector (thesis) vs Ude et al. 2014 orientation DMP on 3 synthetic demonstrations.

    Mean over the demonstrations of :func:`reproduction_errors`, per formulation.
    """
    out = {}
    for mode in ("vector", "ude"):
        cfg = DmpConfig(n_basis=n_basis, quaternion=mode)
        rows = [reproduction_errors(*synthetic_demonstration(5.0, rate_hz, v), cfg) for v in range(3)]
        out[mode] = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}
    return out


_MP_SCRIPT = r"""
import json, sys, time, statistics
import numpy as np
from movement_primitives.dmp import CartesianDMP
try:
    import movement_primitives.dmp_fast  # noqa: F401
    compiled = True
except ImportError:
    compiled = False
data = np.load(sys.argv[1])
T, Y = data["T"], data["Y"]
dmp = CartesianDMP(execution_time=float(T[-1]), dt=0.001, n_weights_per_dim=int(data["B"]), int_dt=0.001)
dmp.imitate(T, Y)
dmp.configure(start_y=Y[0], goal_y=Y[-1])
times, out = [], None
for _ in range(int(data["repeats"])):
    t0 = time.perf_counter()
    t_out, out = dmp.open_loop()
    times.append(time.perf_counter() - t0)
err = out[:, :3] - np.array([np.interp(t_out, T, Y[:, i]) for i in range(3)]).T
print(json.dumps({"single_ms": 1e3 * statistics.median(times), "compiled": compiled,
                  "n_steps": int(len(t_out)), "position_rmse_mm": float(1e3 * np.sqrt(np.mean(np.sum(err**2, 1))))}))
"""


def _mp_python(explicit: str | None) -> str | None:
    for cand in (explicit, os.environ.get("DRAKE_SKILL_MP_PYTHON"), str(DEFAULT_MP_VENV / "bin" / "python")):
        if cand and Path(cand).is_file():
            return cand
    return None


def install_movement_primitives(venv: Path = DEFAULT_MP_VENV) -> str:
    """Creates ``venv`` and installs movement_primitives (with its Cython extension) there."""
    py = venv / "bin" / "python"
    if not py.is_file():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = [str(py), "-m", "pip", "install", "-q"]
    subprocess.run(pip + ["numpy", "scipy", "cython", "setuptools", "wheel", "pytransform3d"], check=True)
    # No build isolation so the extension is compiled against the Cython just installed.
    subprocess.run(pip + ["--no-build-isolation", "movement_primitives"], check=True)
    return str(py)


def bench_movement_primitives(times, poses, n_basis: int, repeats: int, python: str | None) -> dict | None:
    """Times CartesianDMP.open_loop in-process or with ``python``; None if unavailable."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "demo.npz")
        np.savez(path, T=times, Y=poses, B=n_basis, repeats=repeats)
        try:
            import movement_primitives  # noqa: F401

            cmd = [sys.executable, "-c", _MP_SCRIPT, path]
        except ImportError:
            if python is None:
                return None
            cmd = [python, "-c", _MP_SCRIPT, path]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if proc.returncode != 0:
            sys.stderr.write(f"movement_primitives benchmark failed:\n{proc.stderr[-2000:]}\n")
            return None
        return json.loads(proc.stdout.strip().splitlines()[-1])


def run(
    repeats: int = 20,
    batch_size: int = 1000,
    mp_python: str | None = None,
    orientation: bool = True,
    movement_primitives: bool = True,
) -> dict:
    """Runs all measurements; returns the result dict (keys in the module docstring)."""
    cfg = DmpConfig(n_basis=20)
    times, poses = synthetic_demonstration(5.0, 100.0)
    dmp = fit_dmp(times, poses, cfg)
    rng = np.random.default_rng(0)

    integrate(dmp, cfg)  # warm the operator cache
    single = _median_time(lambda: integrate(dmp, cfg), repeats)

    def cold():
        clear_operator_cache()
        integrate(dmp, cfg)

    single_cold = _median_time(cold, max(3, repeats // 4))
    samples = dmp.weights + rng.normal(0.0, 1.0, (batch_size,) + dmp.weights.shape)
    batch_out = integrate(dmp, cfg, weights=samples)  # warm-up, and shape check
    shape = list(batch_out.shape)
    del batch_out
    batch = _median_time(lambda: integrate(dmp, cfg, weights=samples), 3)

    mp = None
    if movement_primitives:
        mp = bench_movement_primitives(times, poses, cfg.n_basis, max(3, repeats // 4), _mp_python(mp_python))
    result = {
        "single_ms": 1e3 * single,
        "single_cold_ms": 1e3 * single_cold,
        "batch1000_s": batch if batch_size == 1000 else None,
        "batch_size": batch_size,
        "batch_s": batch,
        "batch_shape": shape,
        "n_steps": int(len(integrate(dmp, cfg))),
        "movement_primitives_single_ms": None if mp is None else mp["single_ms"],
        "movement_primitives": mp,
        "movement_primitives_status": "ok" if mp else ("not found" if movement_primitives else "skipped"),
        "reproduction": reproduction_errors(times, poses, cfg),
    }
    if orientation:
        result["orientation"] = compare_orientation_formulations()
    return result


def _print_table(r: dict) -> None:
    mp = r["movement_primitives_single_ms"]
    rows = [
        ("integrate one 5 s trajectory, 1 ms steps (cached operators)", f"{r['single_ms']:.3f} ms"),
        ("  same, operators rebuilt", f"{r['single_cold_ms']:.3f} ms"),
        (f"integrate batch of {r['batch_size']} weight samples", f"{r['batch_s']:.3f} s"),
        (
            "movement_primitives CartesianDMP.open_loop",
            f"n/a ({r['movement_primitives_status']})" if mp is None else f"{mp:.1f} ms"
            + ("" if r["movement_primitives"]["compiled"] else " (pure Python)"),
        ),
        ("reproduction position RMSE (B=20, LWR)", f"{r['reproduction']['position_rmse_mm']:.3f} mm"),
        ("reproduction orientation max", f"{r['reproduction']['orientation_max_deg']:.3f} deg"),
    ]
    width = max(len(a) for a, _ in rows)
    for a, b in rows:
        print(f"{a:<{width}}  {b}")
    if "orientation" in r:
        print("\norientation formulation (mean of 3 demonstrations, 100 Hz, B=20)")
        keys = ["position_rmse_mm", "orientation_rms_deg", "orientation_max_deg", "final_orientation_deg"]
        print(f"{'':<8}" + "".join(f"{k:>24}" for k in keys))
        for mode, v in r["orientation"].items():
            print(f"{mode:<8}" + "".join(f"{v[k]:>24.4f}" for k in keys))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="drake-skill bench dmp", description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--repeats", type=int, default=20, help="timing repeats for the single trajectory")
    parser.add_argument("--batch", type=int, default=1000, help="number of weight samples in the batch")
    parser.add_argument("--mp-python", default=None, help="python of a venv with movement_primitives")
    parser.add_argument("--install-mp", action="store_true", help=f"create {DEFAULT_MP_VENV} with movement_primitives")
    parser.add_argument("--no-orientation", action="store_true", help="skip the vector-vs-Ude comparison")
    parser.add_argument("--no-mp", action="store_true", help="skip movement_primitives (reported as null)")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.batch < 1:
        parser.error("--repeats and --batch must be >= 1")
    mp_python = args.mp_python
    if args.install_mp:
        mp_python = install_movement_primitives()
    result = run(
        args.repeats, args.batch, mp_python, orientation=not args.no_orientation, movement_primitives=not args.no_mp
    )
    if args.json:
        print(json.dumps(result))
    else:
        _print_table(result)
        if result["movement_primitives_single_ms"] is None and not args.no_mp:
            print(
                "\nmovement_primitives not found. It is not a drake-skill dependency; to compare, run\n"
                f"  drake-skill bench dmp --install-mp     (creates {DEFAULT_MP_VENV})\n"
                "or point --mp-python / DRAKE_SKILL_MP_PYTHON at a venv where\n"
                "  pip install numpy scipy cython setuptools wheel pytransform3d &&\n"
                "  pip install --no-build-isolation movement_primitives\n"
                "succeeded."
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

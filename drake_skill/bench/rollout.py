"""Benchmark of one rollout: the whole perception-to-reward chain against the plant alone.

``drake-skill bench rollout [--json]`` / ``python tools/bench_rollout.py [--json]``.

One process. A skill is fitted first (scripted demonstrations,
``drake_skill.demos.demonstrator.ScriptedDemonstrator`` with a fixed seed, then
``drake_skill.fitted_skill.fit_skill``) and cached under ``--cache`` (default
``results/bench_rollout/``), so the benchmark runs on a fresh clone; a second
run loads it. Then the skill's initial weights are executed from the same
object pose by the rollout runner policy search uses
(``drake_skill.learning.rollout.RolloutRunner``, with its per-step collision
reflex monitor; the reflex itself is disabled so that every run lasts the
skill's whole duration):

- ``rtf_plant``: the same diagram with the perception systems removed
  (ground-truth object frame, no goal pipeline) and the camera built but
  never rendered; ``rtf_plant_no_camera``: the same without the camera (a
  renderer in the scene costs a little every plant step: it is sent the
  geometry poses);
- ``rtf_full``: the whole chain, station + DMP + camera at 10 Hz + object
  segmenter (object frame perceived on the first frame) + PCAE featurizer +
  POMRP reward (``add_goal_pipeline``);
- ``ratio`` = ``rtf_full / rtf_plant`` (the issue asks >= 0.4);
- ``bare_plant_ms_per_s``: the scene's MultibodyPlant alone, built from the
  same scenario (:func:`bare_plant_ms_per_s`: Panda + hand + table + object,
  the scenario's ``MultibodyPlantConfig``, the arm and fingers held at
  ``q_home`` by their PD actuators, nothing else in the diagram), simulated
  for the rollout's duration; the floor a rollout can approach at the
  present physics. ``ratio_to_bare`` = the whole chain's ms of wall time per
  simulated second / the bare plant's (required <= 2.5); ``plant_only_ratio_to_bare``
  the same for the plant with its drivers (``plant_only`` below);
- ``driven_plant_ms_per_s``: the same bare plant, but its arm driven along the
  plant-only rollout's own joint path by Drake's ``TrajectorySource`` into the
  plant's joint PD (with the station's gravity compensation), the fingers at the
  skill's opening, the object at that rollout's pose (:func:`bare_plant_ms_per_s`
  with ``arm_path``): the hand meets the object as in the rollout, so this is
  the rollout's physics (motion and contact) with Drake's own systems only.
  ``plant_only_ratio_to_driven`` and ``ratio_to_driven`` divide by it: what the
  station's drivers and the perception chain add to that physics.

Real-time factor = simulated s / wall s, over the whole rollout (``tau`` +
the settle time), after a short warm-up (the renderer's first frame). The
plant and the whole chain run alternately ``--repeats`` times (default 3) and
the fastest run of each counts: on a machine shared with other work that is
the least disturbed one.
The breakdown (``breakdown_ms_per_s``: ms of wall time per simulated second)
is measured in the full run itself, by timing the perception systems'
callbacks (patched on their classes for the run, exclusive of what they
call): when the segmenter reads its cloud, the images it is made from are
evaluated first (``render``), then the cloud (``cloud``), both then cached
for the segmenter; the segmentation of the frame (``segmentation``), the
featurizer's update (``encoding``: PCAE and PCA) and the reward's
(``reward``); ``plant`` is the rest (MultibodyPlant, controllers, DMP,
reflex monitor, simulator). ``plant_only`` is the same figure from the
``rtf_plant`` run. ``calls_per_frame`` counts each part per camera frame.
"""

import os

if "numpy" not in __import__("sys").modules:   # single-threaded libraries when we are first
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import argparse
import contextlib
import json
import math
import time
from pathlib import Path

import numpy as np

DEFAULT_CACHE = Path("results") / "bench_rollout"
RATIO_REQUIRED = 0.4
RATIO_TO_BARE_REQUIRED = 2.5


def fitted_skill(skill: str = "open", seed: int = 0, cache: Path = DEFAULT_CACHE, progress: bool = False):
    """The skill fitted from scripted demonstrations (seed ``seed``), cached in ``cache``."""
    from drake_skill.fitted_skill import Skill, default_skill_config, fit_skill

    directory = Path(cache) / f"skill_{skill}_seed{seed}"
    if (directory / "skill.json").is_file():
        return Skill.load(directory)
    from drake_skill.demos.demonstrator import DemonstratorConfig, ScriptedDemonstrator

    demos = ScriptedDemonstrator(skill, DemonstratorConfig(seed=seed)).record_many(progress=progress)
    fitted = fit_skill(demos, default_skill_config(skill))
    fitted.save(directory, overwrite=True)
    return Skill.load(directory)


class _Timers:
    """Accumulated exclusive wall time per named part [s]: a part timed inside
    another (the segmenter evaluated from the featurizer's update) counts
    only for itself."""

    def __init__(self):
        self.total = {}
        self.calls = {}
        self._stack = []

    @contextlib.contextmanager
    def part(self, name):
        self._stack.append(0.0)          # time spent in nested parts
        t0 = time.perf_counter()
        try:
            yield
        finally:
            elapsed = time.perf_counter() - t0
            inner = self._stack.pop()
            self.total[name] = self.total.get(name, 0.0) + elapsed - inner
            self.calls[name] = self.calls.get(name, 0) + 1
            if self._stack:
                self._stack[-1] += elapsed

    def wrap(self, cls, method, name):
        """Times ``cls.method`` (patched on the class, before systems are built); returns an undo."""
        original = getattr(cls, method)
        timers = self

        def timed(self_, *args):
            with timers.part(name):
                return original(self_, *args)

        setattr(cls, method, timed)
        return lambda: setattr(cls, method, original)


def _runner(skill, perception: bool, camera: bool = True):
    """The rollout runner of ``drake_skill.learning.rollout``: the whole chain (object frame
    perceived, goal pipeline), or the plant alone (ground-truth object frame, no
    perception systems; the camera built but never rendered, or not built)."""
    from drake_skill.learning.rollout import RolloutConfig, RolloutRunner
    from drake_skill.skills import scenario_for_skill

    station_config = scenario_for_skill(skill.name)
    station_config.enable_camera = camera
    # The collision reflex would stop a pushing imitation part-way; a benchmark
    # rollout runs its whole duration (the monitor still runs every step).
    station_config.reflex.enabled = False
    config = RolloutConfig(object_pose="perceived" if perception else "ground_truth", goal_model=perception)
    return RolloutRunner(skill, station_config, config)


def bare_plant_ms_per_s(station_config, duration: float, repeats: int = 3, arm_path=None, X_WO=None,
                        gripper_opening: float | None = None) -> float:
    """Milliseconds of wall time per simulated second of the scenario's plant alone
    (module docstring), the fastest of ``repeats`` runs of ``duration`` s.

    ``arm_path`` = (times (N,) [s], q (N, 7) [rad]): the *driven* plant. The arm's desired
    state follows that path (Drake's ``TrajectorySource`` of its first-order hold and the
    hold's derivative, into the plant's own joint PD, with the station's gravity
    compensation, Drake's ``InverseDynamics``) instead of holding ``q_home``, and
    the object stands at ``X_WO`` (7: xyz + wxyz; default the nominal pose), the fingers
    at ``gripper_opening`` [m] (default the scenario's home opening). Given a
    rollout's own joint path and object pose, the hand meets the object as in the
    rollout: the cost of the same physics with only Drake's own systems driving it.
    """
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial

    from drake_skill.station.placement import nominal_object_pose
    from drake_skill.station.recording import vector_to_pose
    from drake_skill.station.sim.builder import add_gravity_compensation, add_scene_plant

    builder = DiagramBuilder()
    scene = add_scene_plant(builder, station_config)
    plant = scene.plant
    q_home = np.asarray(station_config.q_home, dtype=float)
    opening = station_config.gripper_home if gripper_opening is None else float(gripper_opening)
    fingers = np.full(2, opening / 2)
    instances = [scene.panda, scene.hand, scene.object_instance]
    desired = [np.r_[q_home, np.zeros(7)], np.r_[fingers, np.zeros(2)], np.zeros(2)]
    sources = [ConstantVectorSource(x) for x in desired]
    if arm_path is not None:
        times, q = (np.asarray(v, dtype=float) for v in arm_path)
        sources[0] = TrajectorySource(PiecewisePolynomial.FirstOrderHold(times, q.T), output_derivative_order=1)
        gravity_plant = add_gravity_compensation(builder, scene, station_config.directives)   # noqa: F841 (kept alive)
    for i, (instance, source) in enumerate(zip(instances, sources)):
        builder.Connect(builder.AddSystem(source).get_output_port(), plant.get_desired_state_input_port(instance))
        if arm_path is None or i == 2:
            n = plant.num_actuated_dofs(instance)
            builder.Connect(builder.AddSystem(ConstantVectorSource(np.zeros(n))).get_output_port(),
                            plant.get_actuation_input_port(instance))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    simulator = Simulator(diagram, context)
    X_WO = nominal_object_pose(station_config) if X_WO is None else vector_to_pose(X_WO)
    best = math.inf
    for _ in range(max(1, repeats)):
        diagram.SetDefaultContext(context)
        context.SetTime(0.0)
        plant_context = plant.GetMyMutableContextFromRoot(context)
        plant.SetFreeBodyPose(plant_context, scene.object_base, X_WO)
        scene.object_base.Lock(plant_context)
        plant.SetPositions(plant_context, scene.hand, fingers)
        if arm_path is not None:
            plant.SetPositions(plant_context, scene.panda, q[0])
        simulator.Initialize()
        start = time.perf_counter()
        simulator.AdvanceTo(duration)
        best = min(best, time.perf_counter() - start)
    return 1e3 * best / duration


def _run(runner, skill, seed: int, timers: "_Timers | None" = None, warmup_s: float = 0.3) -> dict:
    """One rollout of the skill's initial weights (after a short warm-up: the renderer's
    first frame, the first encoding); returns its wall time, simulated time, return, verdict."""
    runner.reset(skill.initial_weights, seed)
    runner.simulator.AdvanceTo(warmup_s)
    if timers is not None:
        timers.total.clear()
        timers.calls.clear()
    result = runner.run(skill.initial_weights, seed)
    if result.failed:
        raise RuntimeError(f"the benchmark rollout failed ({result.reason}): {result.message}")
    simulated = float(result.times[-1] - result.times[0])
    return {"wall_s": result.wall_s, "simulated_s": simulated, "rtf": simulated / result.wall_s,
            "times": result.times, "joints": result.joints, "object_pose_true": result.object_pose_true,
            "return": result.dense_return, "verdict": result.verdict, "frames": len(result.rewards),
            "final_object_state": result.final_object_state, "success": result.success}


def _perception_ports(station, pipeline) -> dict:
    """The station output ports the segmenter's cloud is computed from: the object
    camera's (cropped) when the segmenter reads it, else the full frame's."""
    camera = getattr(station, "object_camera", None)
    config = pipeline.segmenter.config
    if camera is not None and (config.image_height, config.image_width) == camera.window.shape:
        images, cloud = camera.image_port_names, camera.cloud_port_name
    else:
        images, cloud = ("color_image", "depth_image"), "point_cloud"
    return {"images": [station.GetOutputPort(n) for n in images], "cloud": station.GetOutputPort(cloud)}


def run(skill_name: str = "open", seed: int = 0, object_seed: int = 3, cache: Path = DEFAULT_CACHE,
        progress: bool = False, repeats: int = 3) -> dict:
    import logging

    import torch

    torch.set_num_threads(1)
    logging.getLogger("drake").setLevel(logging.ERROR)   # differential IK's per-step warnings
    from drake_skill.perception.systems import ObjectSegmenter, PcaeFeaturizer
    from drake_skill.reward.systems import PomrpReward

    skill = fitted_skill(skill_name, seed, cache, progress)
    plant_runner = _runner(skill, perception=False)
    no_camera = _run(_runner(skill, perception=False, camera=False), skill, object_seed)

    timers = _Timers()
    rig = {}
    original_read = ObjectSegmenter._read_cloud

    def read_cloud(segmenter, context):
        # The images and the cloud the segmenter reads, evaluated (and timed) first;
        # the segmenter's own evaluation then finds them cached.
        station_context = rig["station"].GetMyContextFromRoot(rig["context"])
        with timers.part("render"):
            for port in rig["ports"]["images"]:
                port.Eval(station_context)
        with timers.part("cloud"):
            rig["ports"]["cloud"].Eval(station_context)
        return original_read(segmenter, context)

    ObjectSegmenter._read_cloud = read_cloud
    undo = [lambda: setattr(ObjectSegmenter, "_read_cloud", original_read),
            timers.wrap(ObjectSegmenter, "_calc_frame", "segmentation"),
            timers.wrap(PcaeFeaturizer, "_update_frame", "encoding"),
            timers.wrap(PomrpReward, "_update", "reward")]
    try:
        runner = _runner(skill, perception=True)
        rig.update(station=runner.station, context=runner.context,
                   ports=_perception_ports(runner.station, runner.pipeline))
        # Plant and whole chain alternately, ``repeats`` times each; the least disturbed
        # (fastest) run of each counts, its own breakdown with it.
        plant, full, best = None, None, None
        for _ in range(max(1, repeats)):
            p = _run(plant_runner, skill, object_seed)
            plant = p if plant is None or p["wall_s"] < plant["wall_s"] else plant
            f = _run(runner, skill, object_seed, timers)
            if full is None or f["wall_s"] < full["wall_s"]:
                full, best = f, (dict(timers.total), dict(timers.calls))
        timers.total, timers.calls = best
    finally:
        for u in undo:
            u()
    bare_ms = bare_plant_ms_per_s(runner.config, full["simulated_s"], repeats)
    driven_ms = bare_plant_ms_per_s(runner.config, full["simulated_s"], repeats,
                                    arm_path=(plant["times"], plant["joints"]), X_WO=plant["object_pose_true"],
                                    gripper_opening=skill.gripper_opening)
    parts = {k: timers.total.get(k, 0.0) for k in ("render", "cloud", "segmentation", "encoding", "reward")}
    parts["plant"] = full["wall_s"] - sum(parts.values())
    per_s = {k: round(1e3 * v / full["simulated_s"], 2) for k, v in parts.items()}
    per_s["plant_only"] = round(1e3 * plant["wall_s"] / plant["simulated_s"], 2)
    frames = max(1, timers.calls.get("encoding", 1))
    camera = getattr(runner.station, "object_camera", None)
    window = camera.window if camera is not None else None
    return {
        "skill": skill_name, "skill_seed": seed, "object_seed": object_seed, "repeats": max(1, repeats),
        "simulated_s": round(full["simulated_s"], 3),
        "rtf_plant": round(plant["rtf"], 3), "rtf_full": round(full["rtf"], 3),
        "ratio": round(full["rtf"] / plant["rtf"], 3), "ratio_required": RATIO_REQUIRED,
        "rtf_plant_no_camera": round(no_camera["rtf"], 3),
        "full_ms_per_s": round(1e3 / full["rtf"], 2),
        "bare_plant_ms_per_s": round(bare_ms, 2),
        "ratio_to_bare": round(1e3 / full["rtf"] / bare_ms, 3), "ratio_to_bare_required": RATIO_TO_BARE_REQUIRED,
        "plant_only_ratio_to_bare": round(per_s["plant_only"] / bare_ms, 3),
        "driven_plant_ms_per_s": round(driven_ms, 2),
        "plant_only_ratio_to_driven": round(per_s["plant_only"] / driven_ms, 3),
        "ratio_to_driven": round(1e3 / full["rtf"] / driven_ms, 3),
        "breakdown_ms_per_s": per_s,
        "per_frame_ms": {k: round(1e3 * parts[k] / frames, 2)
                         for k in ("render", "cloud", "segmentation", "encoding", "reward")},
        "calls_per_frame": {k: round(v / frames, 2) for k, v in timers.calls.items()},
        "object_camera": None if window is None else {"x0": window.x0, "y0": window.y0,
                                                      "width": window.width, "height": window.height},
        "return": round(full["return"], 4), "verdict": full["verdict"], "goal_frames": full["frames"],
        "final_object_state": round(full["final_object_state"], 4), "success": full["success"],
        "final_object_state_plant": round(plant["final_object_state"], 4),
        "load_average": [round(v, 2) for v in os.getloadavg()],
    }


def encode_variants(n: int = 40, seed: int = 0) -> dict:
    """Milliseconds per 2048-point encoding (one thread; min and median of ``n`` fresh
    clouds) of the shipped PCAE's encoder run five ways: the module's own
    ``encode_points`` (BatchNorm folded, one GEMM + in-place ReLU per layer under
    ``torch.inference_mode``), the unfolded ``nn.Module`` under ``inference_mode`` and
    under ``no_grad``, ``torch.compile`` of the folded encoder, and plain numpy
    matmuls (float32) of the folded weights. The fastest is what ``encode_points`` does."""
    import torch

    from drake_skill.perception.pcae import load_pcae, normalize_points

    torch.set_num_threads(1)
    model = load_pcae()
    clouds = np.random.default_rng(seed).uniform(-0.15, 0.15, (n + 3, 2048, 3)).astype(np.float32)
    x = lambda c: torch.from_numpy(normalize_points(c[None]))       # noqa: E731
    with torch.inference_mode():
        model.encode_fast(x(clouds[0]))
    folded = [(w.numpy().copy(), b.numpy().copy()) for w, b in model._folded]

    def numpy_encode(c):
        y = normalize_points(c)
        for w, b in folded:
            y = y @ w
            y += b
            np.maximum(y, 0.0, out=y)
        return y.max(axis=0)

    def inference(c):
        with torch.inference_mode():
            return model.encode(x(c))

    def no_grad(c):
        with torch.no_grad():
            return model.encode(x(c))

    compiled = torch.compile(model.encode_fast)

    def compiled_encode(c):
        with torch.inference_mode():
            return compiled(x(c))

    variants = {"encode_points": model.encode_points, "module_inference_mode": inference,
                "module_no_grad": no_grad, "torch_compile": compiled_encode, "numpy": numpy_encode}
    out = {}
    for name, f in variants.items():
        for c in clouds[:3]:
            f(c)
        times = []
        for c in clouds[3:]:
            t0 = time.perf_counter()
            f(c)
            times.append(time.perf_counter() - t0)
        out[name] = {"min_ms": round(1e3 * min(times), 3), "median_ms": round(1e3 * float(np.median(times)), 3)}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="drake-skill bench rollout", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--skill", default="open", metavar="SKILL")
    parser.add_argument("--seed", type=int, default=0, help="demonstrator seed of the fitted skill")
    parser.add_argument("--object-seed", type=int, default=3, help="object pose of the timed rollout")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help="where the fitted skill is kept")
    parser.add_argument("--repeats", type=int, default=3,
                        help="runs of each case, alternating; the fastest of each counts")
    parser.add_argument("--encode-variants", action="store_true",
                        help="only time the PCAE encoder's inference variants (see encode_variants)")
    args = parser.parse_args(argv)
    if args.encode_variants:
        print(json.dumps(encode_variants()) if args.json else
              "\n".join(f"{k:24s} min {v['min_ms']:6.2f} ms  median {v['median_ms']:6.2f} ms"
                        for k, v in encode_variants().items()))
        return 0
    if args.cache.exists() and not args.cache.is_dir():
        raise NotADirectoryError(f"--cache {args.cache}: not a directory; give a directory for the fitted skill")
    if args.repeats < 1:
        raise ValueError(f"--repeats {args.repeats}: expected at least 1 run per case")
    result = run(args.skill, args.seed, args.object_seed, args.cache, progress=not args.json,
                 repeats=args.repeats)
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"one {args.skill} rollout, {result['simulated_s']:g} s simulated, one process "
          f"(load {result['load_average'][0]:.2f})")
    print(f"  plant alone        {result['rtf_plant']:7.2f} x real time")
    print(f"  whole chain        {result['rtf_full']:7.2f} x real time")
    print(f"  ratio              {result['ratio']:7.3f} (required >= {RATIO_REQUIRED})")
    print(f"  bare plant         {result['bare_plant_ms_per_s']:7.1f} ms per simulated s; whole chain "
          f"{result['full_ms_per_s']:.1f}: ratio_to_bare {result['ratio_to_bare']:.2f} "
          f"(required <= {RATIO_TO_BARE_REQUIRED}); plant with drivers {result['plant_only_ratio_to_bare']:.2f}")
    print(f"  driven plant       {result['driven_plant_ms_per_s']:7.1f} ms per simulated s (the same scene along "
          f"the rollout's joint path, Drake's own systems only): plant with drivers "
          f"{result['plant_only_ratio_to_driven']:.2f}, whole chain {result['ratio_to_driven']:.2f}")
    print("  ms per simulated s: " + ", ".join(f"{k} {v:.1f}" for k, v in result["breakdown_ms_per_s"].items()))
    print(f"  return {result['return']:.3f}, verdict {'success' if result['verdict'] else 'failure'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Benchmark of the simulated station: real-time factor with and without the camera.

``drake-skill bench station [--json]`` / ``python tools/bench_station.py [--json]``.

Simulates the scripted Open motion for ``--duration`` s (default 5) twice in
one process: (a) the plant alone (no camera), (b) plant + RGB-D camera at its
rate (10 Hz) + the coloured point cloud, evaluated at every camera frame as a
consumer would. Prints the real-time factors (simulated s / wall s) and their
ratio. JSON keys: ``rtf_plant``, ``rtf_with_camera``, ``ratio``.
"""

from __future__ import annotations

import argparse
import json
import time


def _rtf(with_camera: bool, duration: float, seed: int) -> float:
    from drake_skill.demos.scripted import scripted_plan
    from drake_skill.station.sim.simulation import StationSimulation
    from drake_skill.skills import scenario_for_skill

    config = scenario_for_skill("open")
    config.enable_camera = with_camera
    sim = StationSimulation(config)
    X_WO = sim.reset(seed)
    sim.set_plan(scripted_plan("open", X_WO, sim.home_pose()))
    station, context = sim.station, sim.station_context()
    cloud_port = station.GetOutputPort("point_cloud") if with_camera else None
    period = 1.0 / config.camera.fps
    steps = int(round(duration / period))
    points = 0
    start = time.perf_counter()
    for k in range(1, steps + 1):
        sim.simulator.AdvanceTo(k * period)
        if cloud_port is not None:
            points += cloud_port.Eval(context).size()
    wall = time.perf_counter() - start
    if with_camera and points == 0:
        raise RuntimeError("the camera produced no points")
    return duration / wall


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="drake-skill bench station", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated seconds per case")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rtf_plant = _rtf(False, args.duration, args.seed)
    rtf_camera = _rtf(True, args.duration, args.seed)
    result = {"rtf_plant": round(rtf_plant, 3), "rtf_with_camera": round(rtf_camera, 3),
              "ratio": round(rtf_plant / rtf_camera, 3)}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"scripted Open, {args.duration:g} s simulated, one process")
        print(f"  plant alone            {rtf_plant:7.2f} x real time")
        print(f"  plant + camera + cloud {rtf_camera:7.2f} x real time (required >= 3)")
        print(f"  ratio                  {result['ratio']:7.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

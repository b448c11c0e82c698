#!/usr/bin/env python3
"""Checks the station's physics (issue 10) and prints one summary.

    python tools/check_physics.py [--json] [--seeds 10] [--reflex] [--skills open,close,draw,slide]

For each skill: the scripted motion on ``--seeds`` object poses at the
scenario's plant step and at a 1 ms reference step (verdict of the
ground-truth judge after the settle phase, peak robot-scene contact force,
final object state), and the arm parked (the judge must say failure). Plus
the lid released 4 degrees below and above its tipping angle. ``--reflex``
runs with the collision reflex on (a trip counts as a failure); otherwise
the scenario's own setting. ``--json`` prints one JSON object:

    {"step_s": ..., "reflex_force_N": ..., "reflex_enabled": ..., "lid_falls_shut": ...,
     "lid_falls_open": ..., "skills": {"open": {"seeds": 10, "scripted_successes": ...,
     "parked_successes": ..., "peak_force_N": ..., "agree_with_1ms": ..., ...}, ...}}
"""

import argparse
import json
import logging
import math
import sys
import time


def _run(sim, skill, seed):
    from drake_skill.demos.scripted import scripted_plan

    X_WO = sim.reset(seed)
    plan = scripted_plan(skill, X_WO, sim.home_pose())
    try:
        log = sim.run(plan, plan.duration + sim.config.success.settle_time, record_hz=20)
    except RuntimeError as e:   # ReflexError, SolverError, DivergedError
        return {"success": False, "reason": getattr(e, "reason", "error"), "final": sim.object_state(),
                "peak_force_N": float(getattr(e, "force_N", math.nan))}
    return {"success": sim.judge_log(log), "reason": "", "final": log.final_object_state,
            "peak_force_N": log.peak_force}


def check_skill(skill, seeds, reflex):
    import numpy as np

    from drake_skill.skills import scenario_for_skill
    from drake_skill.station.sim.simulation import StationSimulation

    results = {}
    for label, step in (("chosen", None), ("1ms", 0.001)):
        config = scenario_for_skill(skill)
        config.enable_camera = False
        if reflex:
            config.reflex.enabled = True
        if step is not None:
            config.plant.time_step = step
        sim = StationSimulation(config)
        results[label] = [_run(sim, skill, seed) for seed in range(seeds)]
        if label == "chosen":
            step_s = config.time_step
            sim.reset(seeds + 100)
            parked = sim.run(None, 4.0, record_hz=10)
            parked_success = int(sim.judge_log(parked))
    chosen, ref = results["chosen"], results["1ms"]
    return step_s, {
        "seeds": seeds,
        "scripted_successes": int(sum(r["success"] for r in chosen)),
        "parked_successes": parked_success,
        "peak_force_N": round(float(np.nanmax([r["peak_force_N"] for r in chosen])), 1),
        "agree_with_1ms": int(sum(a["success"] == b["success"] for a, b in zip(chosen, ref))),
        "successes_1ms": int(sum(r["success"] for r in ref)),
        "final_state": [round(r["final"], 3) for r in chosen],
        "final_state_1ms": [round(r["final"], 3) for r in ref],
        "failure_reasons": [r["reason"] for r in chosen if not r["success"]],
    }


def check_lid(offset_deg):
    from drake_skill.skills import scenario_for_skill
    from drake_skill.station.sim.simulation import StationSimulation

    config = scenario_for_skill("open")
    config.enable_camera = False
    sim = StationSimulation(config)
    sim.reset(0)
    tipping = math.atan2(0.1125, 0.01)       # the lid's CoM above the hinge (models/box.sdf)
    sim.station.set_object_joint(sim.context, tipping + math.radians(offset_deg))
    log = sim.run(None, 3.0, record_hz=20)
    return log.final_object_state


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--reflex", action="store_true")
    parser.add_argument("--skills", default=None,
                        help="comma-separated skills (default: every shipped skill with keyframes)")
    args = parser.parse_args(argv)
    logging.getLogger("drake").setLevel(logging.ERROR)

    from drake_skill.skills import scenario_for_skill

    start = time.perf_counter()
    config = scenario_for_skill("open")
    report = {"step_s": config.time_step, "reflex_force_N": config.reflex.contact_force_max,
              "reflex_enabled": bool(args.reflex or config.reflex.enabled),
              "lid_falls_shut": bool(check_lid(-4.0) < 0.02), "lid_falls_open": bool(check_lid(4.0) > 1.85),
              "skills": {}}
    if args.skills is None:
        from drake_skill.skills import shipped_skills
        args.skills = ",".join(spec.name for spec in shipped_skills() if spec.keyframes)
    for skill in args.skills.split(","):
        step_s, report["skills"][skill] = check_skill(skill, args.seeds, args.reflex)
        if not args.json:
            s = report["skills"][skill]
            print(f"{skill}: scripted {s['scripted_successes']}/{s['seeds']} at {step_s * 1000:.0f} ms "
                  f"({s['successes_1ms']}/{s['seeds']} at 1 ms, verdicts agree on {s['agree_with_1ms']}), "
                  f"parked {s['parked_successes']}, peak force {s['peak_force_N']} N", flush=True)
    report["wall_s"] = round(time.perf_counter() - start, 1)
    print(json.dumps(report) if args.json else json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

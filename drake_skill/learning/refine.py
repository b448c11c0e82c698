"""Refinement of a fitted skill's DMPs on the simulated station or the robot (docs/method.md section 2.3).

A demonstration stores the *measured* hand path, which lags the
demonstrator's command by 20-30 ms and sags under load. A DMP fitted to it
commands that path, and the station lags and sags once more. The
refinement runs each demonstration's DMP in the skill's scenario on the
demonstration's own object pose (:class:`~drake_skill.learning.imitation.Imitator`)
and refits it to ``demonstration + (demonstration - imitation)``
(:func:`drake_skill.action.fitting.refine_for_tracking`), keeping the plain
fit where the refined one does not follow the demonstration more closely
(a refinement that diverges, or trips the reflex).

At fit time (``drake-skill fit``, ``drake-skill learn`` when it fits) it
runs on the simulated station only; ``SkillConfig.dmp_refine = 0`` (or
``--no-refine``) switches it off. There, demonstrations recorded on the
robot are refined against the simulated station too, so what it removes is
the simulated controller's lag, which the rollouts in simulation share. The
robot's own lag and load offset are removed by ``drake-skill hardware
refine`` (:func:`refine_on_robot`): the
same steps with every execution on the robot, each after the person at the
robot has placed the object and pressed Enter; never inside ``fit``.
"""

from __future__ import annotations

import copy

import numpy as np

from drake_skill.action.dmp import fit_dmp
from drake_skill.action.fitting import refine_for_tracking
from drake_skill.action.quaternion import make_quaternions_continuous

__all__ = ["refine_dmps", "refine_on_robot", "refine_skill", "refinement_lines"]


def _same_hemisphere(path: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``path`` (T, 7) with each quaternion flipped onto the side of ``reference``'s row (q and -q agree)."""
    out = np.array(path, dtype=float)
    flip = np.einsum("ij,ij->i", out[:, 3:], reference[:, 3:]) < 0
    out[flip, 3:] *= -1.0
    return out


def refine_skill(skill, demos, station_config=None, iterations: int | None = None, progress=None,
                 imitator=None, on: str = "simulation") -> list[dict]:
    """Refines ``skill``'s DMPs in place (one per demonstration, the fit's order); returns a report per DMP.

    ``iterations``: refinement steps (default ``skill.config.dmp_refine``); 0
    or a skill fitted to the 10 Hz data (the thesis's fit) leaves it as it
    is. ``imitator``: an :class:`~drake_skill.learning.imitation.Imitator`
    to execute on (default: one on the skill's simulated station, or on
    ``station_config``); one built on the hardware station, with ``on`` =
    "robot", refines on the robot (``drake-skill hardware refine``). ``progress(i, n, name)`` is
    called before each demonstration. The report, also stored as
    ``skill.info["dmp_refinement"]``, is :func:`refine_dmps`'s. Sigma_b^0 is
    kept: a refinement moves each DMP by its tracking error, not by the
    demonstrations' spread that Sigma_b^0 describes.
    """
    from drake_skill.learning.imitation import Imitator

    iterations = int(skill.config.dmp_refine if iterations is None else iterations)
    if iterations <= 0 or skill.config.dmp_data != "100hz":
        return []
    if imitator is None:
        if station_config is not None:   # the ground-truth object frame: no camera to render
            station_config = copy.deepcopy(station_config)
            station_config.enable_camera = False
        imitator = Imitator(skill, station_config)
    skill.dmps, report = refine_dmps(skill.dmps, demos, skill.config.dmp, imitator, iterations, progress, on)
    skill.info["dmp_refinement"] = report
    return report


def refine_dmps(dmps, demos, config, imitator, iterations: int = 1, progress=None,
                on: str = "simulation") -> tuple[list, list[dict]]:
    """``(dmps, report)``: each DMP refined on ``imitator``'s station against its demonstration.

    ``dmps`` and ``demos`` pair up in order (DMP i was fitted to the 100 Hz
    data of demonstration i with DMP hyper-parameters ``config``). Per
    demonstration the report holds the RMS error [mm] of the executed path
    against the demonstration after each execution (plain fit first),
    whether the plain fit was kept, the imitation's failure reasons when one
    failed, and ``on``: "simulation", or "robot" for an imitator on the
    hardware station.
    """
    if on not in ("simulation", "robot"):
        raise ValueError(f"on: expected 'simulation' or 'robot', got {on!r}")
    refined, report = [], []
    for i, (dmp, demo) in enumerate(zip(dmps, demos)):
        name = getattr(demo, "path", None) or f"demo {i}"
        if progress is not None:
            progress(i, len(demos), name)
        t = np.asarray(demo.times_100hz, dtype=float)
        target = np.array(demo.X_OE_100hz, dtype=float)
        target[:, 3:] = make_quaternions_continuous(target[:, 3:], reference=dmp.y0[3:])
        failures = []

        def execute(candidate, demo=demo, target=target, failures=failures):
            imitation = imitator.imitate(candidate, demo)
            if imitation.failed:
                failures.append(imitation.reason)
                return np.full_like(target, np.nan)
            return _same_hemisphere(imitation.X_OE_demo_grid, target)

        result = refine_for_tracking(lambda c, t=t: fit_dmp(t, c, config), execute, t, target, iterations)
        refined.append(result.dmp)
        report.append({"demo": str(name), "errors_mm": [round(e, 3) for e in result.errors_mm],
                       "kept_plain": bool(result.kept_plain), "failures": failures, "on": on})
    return refined, report


class _OnRobot:
    """An :class:`~drake_skill.learning.imitation.Imitator` on the hardware station whose every run
    starts at its demonstration's start: the hand is first moved there
    (:meth:`Imitator.move_to_start`, the person's prompt off), then the
    person is asked to place the object (``prompt``, the station's reset
    hook) and the DMP runs."""

    def __init__(self, imitator, prompt):
        self.imitator, self.prompt = imitator, prompt

    @property
    def station(self):
        return self.imitator.station

    def imitate(self, dmp, demo):
        self.station.set_reset_hook(None)
        self.imitator.move_to_start(demo)
        self.station.set_reset_hook(self.prompt)
        try:
            return self.imitator.imitate(dmp, demo)
        finally:
            self.station.set_reset_hook(None)


def refine_on_robot(skill, demos, station, iterations: int | None = None, progress=None,
                    prompt=None) -> list[dict]:
    """Refines ``skill``'s DMPs in place with every execution on the robot; returns the report.

    ``station``: a built hardware station (``make_station(scenario, hardware=True)``).
    Each demonstration takes ``iterations`` + 1 runs (its plain DMP, then
    each refined one); before each, the hand moves to the demonstration's
    start, then ``prompt(seed, X_WO)`` is called as the station's reset hook
    (``drake-skill hardware refine`` prints where to place the object, the
    demonstration's own pose, and waits for Enter). The hand path is the
    robot's measured one (its status), in the object frame of the placed
    pose, as the demonstration recorded it. ``iterations`` defaults to
    ``skill.config.dmp_refine`` (at least 1).
    """
    from drake_skill.learning.imitation import RECORD_HZ, Imitator
    from drake_skill.learning.rollout import RolloutConfig, RolloutRunner

    if skill.config.dmp_data != "100hz":
        raise ValueError(f"skill {skill.name!r} was fitted to the 10 Hz data (the thesis's fit): refine a skill "
                         "fitted with --fit tolerance (drake-skill fit's default)")
    iterations = max(1, int(skill.config.dmp_refine if iterations is None else iterations))
    runner = RolloutRunner(skill, config=RolloutConfig(object_pose="ground_truth", goal_model=False,
                                                       record_hz=RECORD_HZ), station=station)
    imitator = _OnRobot(Imitator(skill, runner=runner), prompt)
    return refine_skill(skill, demos, iterations=iterations, progress=progress, imitator=imitator, on="robot")


def refinement_lines(report: list[dict]) -> tuple[list[str], list[str]]:
    """``(lines, warnings)`` for ``drake-skill fit``: each DMP's executed error before and after."""
    lines, warnings = [], []
    for r in report:
        errors = r["errors_mm"]
        where = "the robot" if r.get("on") == "robot" else "the simulated station"
        if r["kept_plain"]:
            why = f" (the imitation failed: {', '.join(r['failures'])})" if r["failures"] else ""
            warnings.append(f"{r['demo']}: refining its DMP on {where} did not bring the imitation "
                            f"closer than the plain fit's {errors[0]:.1f} mm RMS{why}; the plain fit is kept")
        else:
            best = min(errors)
            lines.append(f"  {r['demo']}: imitation {errors[0]:.1f} -> {best:.1f} mm RMS from the demonstration "
                         f"after refinement on {where}")
    return lines, warnings

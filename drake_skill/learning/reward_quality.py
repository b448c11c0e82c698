"""How well the learned reward and verdict track the ground truth, over a set of rollouts.

Simulation only: every figure compares the learned reward (what a real
robot has) with the simulator's ground-truth success rule (what it has not).

:func:`reward_quality` reads rollout records as ``results.jsonl`` holds them
(:meth:`~drake_skill.learning.rollout.RolloutResult.summary`: ``failed``,
``reason``, ``dense_return`` R(G) of thesis Eq. 4.5, ``verdict`` the goal
model's success verdict, ``success`` the ground truth, ``final_object_state``
[rad or m]); :func:`records_from_report` turns an
:func:`~drake_skill.learning.evaluation.explore_skill` /
:func:`~drake_skill.learning.evaluation.evaluate_skill` report into such
records; :func:`plot_return_vs_state` draws the return against the final
object state. ``drake-skill bench reward_quality`` runs the rollouts.

No Drake import here: numpy, scipy.stats and sklearn.metrics (matplotlib when
a figure is drawn).
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Iterable

import numpy as np

__all__ = ["SUMMARY_KEYS", "plot_return_vs_state", "records_from_report", "reflex_rate", "reward_quality",
           "rule_direction"]

#: The figures of :func:`reward_quality` a learning run's ``summary.json`` and the generalization study keep.
SUMMARY_KEYS = ("reward_auc", "verdict_fpr", "verdict_fnr")

#: The fields :func:`reward_quality` reads from every record.
FIELDS = ("failed", "dense_return", "verdict", "success", "final_object_state")


def _field(rule, name):
    return rule.get(name) if isinstance(rule, Mapping) else getattr(rule, name, None)


def rule_direction(rule) -> tuple[float, int]:
    """``(threshold, sign)`` of a success rule: ``sign`` +1 for ``above`` (success: state >=
    threshold), -1 for ``below`` (state <= threshold).

    ``rule``: an object with ``above`` and ``below`` attributes
    (:class:`~drake_skill.station.scenario.SuccessConfig`) or a mapping with those keys, exactly
    one of them set.
    """
    above, below = _field(rule, "above"), _field(rule, "below")
    if (above is None) == (below is None):
        raise ValueError(f"rule: expected exactly one of 'above' and 'below' to be set, got above={above!r}, "
                         f"below={below!r}; pass the skill's success rule (skill.spec.success)")
    threshold = float(above if above is not None else below)
    if not math.isfinite(threshold):
        raise ValueError(f"rule: threshold {threshold!r} is not finite; give a joint position [rad or m]")
    return threshold, (1 if above is not None else -1)


def _checked(records) -> list[Mapping]:
    """The records as a list, each holding :data:`FIELDS`, and a finite return where not failed."""
    records = list(records)
    for i, r in enumerate(records):
        missing = [k for k in FIELDS if k not in r]
        if missing:
            raise ValueError(f"records[{i}]: missing {', '.join(missing)}; expected rollout records as "
                             "results.jsonl holds them (RolloutResult.summary())")
        if not r["failed"] and not math.isfinite(float(r["dense_return"])):
            raise ValueError(f"records[{i}]: dense_return {r['dense_return']!r} is not finite in a rollout "
                             "that did not fail; mark it failed (reason non_finite)")
    return records


def _rate(numerator: int, denominator: int) -> float | None:
    return numerator / denominator if denominator else None


def _auc(success: np.ndarray, returns: np.ndarray) -> float | None:
    """ROC AUC of ``returns`` as a score for ``success``; None with one class (or none)."""
    from sklearn.metrics import roc_auc_score

    if success.all() or not success.any():
        return None
    return float(roc_auc_score(success, returns))


def _spearman(returns: np.ndarray, states: np.ndarray) -> float | None:
    """Spearman's rho of the pairs with a finite state; None with fewer than 2 or a constant side."""
    from scipy.stats import spearmanr

    keep = np.isfinite(states)
    x, y = returns[keep], states[keep]
    if len(x) < 2 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rho = float(spearmanr(x, y).statistic)
    return rho if math.isfinite(rho) else None


def _state(value) -> float:
    return float("nan") if value is None else float(value)


def reward_quality(records: Iterable[Mapping], rule) -> dict[str, Any]:
    """How well the learned dense return and verdict track ground-truth success.

    ``records``: rollout dicts (:data:`FIELDS`, as in ``results.jsonl``);
    ``rule``: the skill's success rule (:func:`rule_direction`). Scored
    rollouts are those that did not fail (``failed`` False: no reflex trip,
    perception loss, solver failure...; a failed rollout's return is 0 by
    convention, docs/method.md section 5, and says nothing of the reward).
    Over the S scored rollouts, with ``y_i`` the ground-truth success, ``v_i``
    the verdict and ``R_i`` the dense return R(G) (thesis Eq. 4.5):

    - ``reward_auc`` = P(R_i > R_j) + P(R_i = R_j) / 2 over pairs of a
      success i and a failure j: the ROC AUC of R as a score for y (1: the
      return ranks every success above every failure; 0.5: chance; 0:
      reversed). None when the scored rollouts hold only one class.
    - ``verdict_fpr`` = #{v = 1, y = 0} / #{y = 0}: the share of
      ground-truth failures the verdict calls a success (None without a
      failure); ``verdict_fnr`` = #{v = 0, y = 1} / #{y = 1}: the share of
      successes it calls a failure (None without a success).
    - ``state_spearman`` = s * rho_Spearman(R, q_final) over the scored
      rollouts with a final object state q_final [rad or m], s = +1 for an
      ``above`` rule, -1 for a ``below`` rule: positive when the return
      grows as the object ends nearer success. None with fewer than 2 such
      rollouts or a constant return or state.

    Counts over all N rollouts: ``rollouts`` = N, ``scored`` = S, ``failed``
    = N - S, ``failed_rate`` = (N - S) / N (None when N = 0), ``failures``
    (reason -> count), ``successes`` (ground truth) and ``verdict_successes``
    (the verdict's; a failed rollout is neither).
    """
    _, sign = rule_direction(rule)
    records = _checked(records)
    scored = [r for r in records if not r["failed"]]
    y = np.array([bool(r["success"]) for r in scored], dtype=bool)
    v = np.array([bool(r["verdict"]) for r in scored], dtype=bool)
    R = np.array([float(r["dense_return"]) for r in scored], dtype=float)
    q = np.array([_state(r["final_object_state"]) for r in scored], dtype=float)
    rho = _spearman(R, q)
    failed = len(records) - len(scored)
    return {
        "reward_auc": _auc(y, R),
        "verdict_fpr": _rate(int(np.sum(v & ~y)), int(np.sum(~y))),
        "verdict_fnr": _rate(int(np.sum(~v & y)), int(np.sum(y))),
        "state_spearman": None if rho is None else sign * rho,
        "rollouts": len(records), "scored": len(scored), "failed": failed,
        "failed_rate": _rate(failed, len(records)),
        "failures": dict(sorted(Counter(str(r.get("reason") or "error") for r in records if r["failed"]).items())),
        "successes": int(y.sum()), "verdict_successes": int(v.sum()),
    }


def reflex_rate(records: Iterable[Mapping]) -> float:
    """The share of rollout records that tripped the collision reflex (``reason`` "reflex"); 0 with none."""
    records = list(records)
    return sum(r.get("reason") == "reflex" for r in records) / max(len(records), 1)


def records_from_report(report: Mapping, source: str = "") -> list[dict[str, Any]]:
    """Per-rollout records of a :func:`~drake_skill.learning.evaluation.results_report`-shaped report
    (an ``explore_skill`` report, or one policy of an ``evaluate_skill`` report): its parallel lists
    ``seeds``, ``reasons`` ("" where it did not fail), ``returns``, ``verdicts``, ``successes`` and
    ``final_object_state`` as one dict per rollout, each tagged with ``source``."""
    keys = ("seeds", "reasons", "returns", "verdicts", "successes", "final_object_state")
    sizes = {k: len(report[k]) for k in keys}
    if len(set(sizes.values())) != 1:
        raise ValueError(f"report: its per-rollout lists differ in length ({sizes}); pass one "
                         "explore_skill report or one evaluate_skill policy")
    return [{"source": source, "seed": int(s), "failed": bool(reason), "reason": str(reason),
             "dense_return": float(R), "verdict": bool(v), "success": bool(y), "final_object_state": q}
            for s, reason, R, v, y, q in zip(*(report[k] for k in keys))]


#: Colour per ground-truth outcome, face per verdict (filled: the verdict says success).
_TRUTH_COLOUR = {True: "tab:green", False: "tab:orange"}
_REASON_COLOUR = {"reflex": "tab:red"}


def _metrics_line(q: Mapping) -> str:
    def num(x, fmt):
        return "-" if x is None else format(x, fmt)

    return (f"AUC {num(q['reward_auc'], '.3f')}, verdict FPR {num(q['verdict_fpr'], '.2f')} "
            f"FNR {num(q['verdict_fnr'], '.2f')}, Spearman {num(q['state_spearman'], '+.2f')}, "
            f"failed {q['failed']}/{q['rollouts']}")


def _draw_scored(ax, scored) -> None:
    """One group per (ground truth, verdict): colour = truth, filled = verdict success."""
    for truth in (True, False):
        for verdict in (True, False):
            group = [r for r in scored if bool(r["success"]) == truth and bool(r["verdict"]) == verdict]
            if not group:
                continue
            colour = _TRUTH_COLOUR[truth]
            ax.scatter([_state(r["final_object_state"]) for r in group], [float(r["dense_return"]) for r in group],
                       s=40, marker="o", edgecolors=colour, facecolors=colour if verdict else "none",
                       linewidths=1.5, zorder=3,
                       label=f"{'success' if truth else 'failure'} (truth), verdict "
                             f"{'success' if verdict else 'failure'}: {len(group)}")


def _draw_failed(ax, side, failed) -> None:
    """Failed rollouts at return 0, one cross colour per reason: on ``ax`` at their final state, on
    the ``side`` panel (side by side, in order) without one."""
    by_reason: dict[str, list] = {}
    for r in failed:
        by_reason.setdefault(str(r.get("reason") or "error"), []).append(r)
    k = 0                                          # position on the side panel
    for reason, group in sorted(by_reason.items()):
        style = {"s": 55, "marker": "X", "color": _REASON_COLOUR.get(reason, "tab:purple"), "zorder": 4}
        label = f"failed: {reason} (return 0): {len(group)}"
        known = [_state(r["final_object_state"]) for r in group if math.isfinite(_state(r["final_object_state"]))]
        if known:
            ax.scatter(known, [0.0] * len(known), label=label, **style)
            label = None
        unknown = len(group) - len(known)
        if unknown:
            ax.scatter([], [], label=label, **style)   # the legend entry lives on the main panel
            side.scatter(range(k, k + unknown), [0.0] * unknown, **style)
            k += unknown
    if side is not None:
        side.set_xlim(-1, max(k, 1))
        side.set_xticks([])
        side.set_title("failed,\nno final state", fontsize=8)
        side.set_ylabel("learned dense return R(G)")
        side.grid(alpha=0.3)


def plot_return_vs_state(records: Iterable[Mapping], rule, path, title: str | None = None) -> Path:
    """Dense return R(G) against the final object state [rad or m], one point per rollout, to a PNG.

    Colour: ground-truth success (green) or failure (orange); filled: the
    verdict says success, hollow: failure (so a hollow green point is a
    false negative, a filled orange one a false positive). Failed rollouts
    are crosses at return 0, one colour per reason; those without a final
    state on a narrow panel of their own at the left. A dashed vertical
    line marks the rule's threshold. The subtitle gives
    :func:`reward_quality`'s figures. Written atomically
    (:func:`drake_skill.fileio.write_figure_png`); returns the path.
    """
    from drake_skill.fileio import new_figure, write_figure_png

    threshold, sign = rule_direction(rule)
    records = _checked(records)
    quality = reward_quality(records, rule)
    scored = [r for r in records if not r["failed"]]
    failed = [r for r in records if r["failed"]]
    states = [q for q in (_state(r["final_object_state"]) for r in records) if math.isfinite(q)] + [threshold]
    span = max(max(states) - min(states), 1e-3)
    stateless = any(not math.isfinite(_state(r["final_object_state"])) for r in failed)
    fig = new_figure((7.8 if stateless else 7.0, 4.6))
    fig.set_layout_engine("constrained")
    if stateless:
        side, ax = fig.subplots(1, 2, sharey=True, gridspec_kw={"width_ratios": [1, 7]})
    else:
        side, ax = None, fig.subplots()
    _draw_scored(ax, scored)
    _draw_failed(ax, side, failed)
    joint = _field(rule, "joint") or "object joint"
    ax.axvline(threshold, color="0.3", ls="--", lw=1,
               label=f"rule: {joint} {'>=' if sign > 0 else '<='} {threshold:g}")
    ax.set_xlim(min(states) - 0.1 * span, max(states) + 0.1 * span)
    ax.set_xlabel(f"final object state: {joint} [rad or m]")
    if side is None:
        ax.set_ylabel("learned dense return R(G)")
    ax.set_title(_metrics_line(quality), fontsize=9)
    ax.grid(alpha=0.3)
    if records:
        ax.legend(fontsize=7, loc="best")
    else:
        ax.text(0.5, 0.5, "no rollouts", transform=ax.transAxes, ha="center")
    fig.suptitle(title or "learned return against the object's final state", fontsize=11)
    return write_figure_png(fig, path, dpi=110)

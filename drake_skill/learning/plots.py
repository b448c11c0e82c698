"""Figures of learning runs and evaluations (PNG, written atomically).

:func:`plot_learning_curve`: a run's greedy success and returns per episode
(``learning_curve.png``); :func:`plot_outcomes_by_placement`: where on the
table each rollout of an evaluation succeeded (``evaluation.png``).
matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_learning_curve", "plot_outcomes_by_placement"]


def plot_learning_curve(curve: list[dict], path, title: str = "") -> Path:
    """Greedy success and returns per episode (0 = before learning) to a PNG."""
    from drake_skill.fileio import new_figure, write_figure_png

    episodes = [c["episode"] for c in curve]
    fig = new_figure((10, 3.8))
    (ax_s, ax_r) = fig.subplots(1, 2)
    ax_s.plot(episodes, [float(c["greedy_success"]) for c in curve], "o-", color="tab:green")
    ax_s.set_ylim(-0.05, 1.05)
    ax_s.set_xlabel("episode (update)")
    ax_s.set_ylabel("greedy success (ground truth)")
    ax_s.set_xticks(episodes)
    ax_r.plot(episodes, [c["greedy_return"] for c in curve], "o-", label="greedy return")
    learned = [c for c in curve if c.get("mean_return") is not None]
    if learned:
        learned_episodes = [c["episode"] for c in learned]
        ax_r.plot(learned_episodes, [c["mean_return"] for c in learned], "s--", label="mean rollout return")
        ax_r.plot(learned_episodes, [c["best_return"] for c in learned], "^:", label="best rollout return")
    ax_r.set_xlabel("episode (update)")
    ax_r.set_ylabel("learned return R(G)")
    ax_r.set_xticks(episodes)
    ax_r.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return write_figure_png(fig, path, dpi=110)


#: Marker and colour per rollout outcome in :func:`plot_outcomes_by_placement`.
_OUTCOME_STYLE = {"success": ("o", "tab:green"), "not achieved": ("o", "tab:orange"),
                  "reflex": ("X", "tab:red")}


def plot_outcomes_by_placement(report: dict[str, Any], path, title: str = "") -> Path:
    """Where on the table each rollout of an :func:`~drake_skill.learning.evaluation.evaluate_skill` or
    :func:`~drake_skill.learning.evaluation.explore_skill` report succeeded, to a PNG: one panel per policy,
    each object placement (x, y [mm], its x axis drawn for the yaw) marked by
    the outcome (success; run to the end without success, labelled with the
    final lid angle [rad] or drawer travel [m]; a failure, by reason).

    Plain imitation of a DMP succeeds in a band of placements around its
    demonstration's (docs/method.md section 6): the plot shows the band.
    """
    from drake_skill.fileio import new_figure, write_figure_png

    if "policies" in report:
        panels = []
        for index, p in report["policies"].items():
            role = " (learned)" if p["initial"] and report.get("learned") else " (initial)" if p["initial"] else ""
            panels.append((f"DMP {index}{role}", p))
    else:
        panels = [(f"{len(report['seeds'])} exploratory rollouts", report)]
    fig = new_figure((4.2 * len(panels), 4.2))
    axes = fig.subplots(1, len(panels), squeeze=False)
    placed = np.array([1000.0 * np.asarray(pose[:2]) for _, p in panels
                       for pose in p.get("object_poses", []) if pose is not None]).reshape(-1, 2)
    centre = placed.mean(axis=0) if len(placed) else np.zeros(2)
    half = max(float(np.abs(placed - centre).max()) if len(placed) else 0.0, 10.0) + 12.0
    seen = set()                                   # one legend entry per outcome
    for ax, (name, p) in zip(axes[0], panels):
        for k, pose in enumerate(p.get("object_poses", [])):
            if pose is None:
                continue
            x, y, yaw = 1000.0 * pose[0], 1000.0 * pose[1], pose[2]
            reason = p["reasons"][k]
            outcome = "success" if p["successes"][k] else (reason or "not achieved")
            marker, colour = _OUTCOME_STYLE.get(outcome, ("X", "tab:purple"))
            ax.plot([x, x + 8.0 * np.cos(yaw)], [y, y + 8.0 * np.sin(yaw)], "-", color="0.6", lw=1)
            ax.plot(x, y, marker, color=colour, ms=8, label=None if outcome in seen else outcome)
            seen.add(outcome)
            final = p["final_object_state"][k]
            if outcome == "not achieved" and final is not None:
                final = 0.0 if abs(final) < 5e-3 else final      # no "-0.00" for a lid at rest on its seat
                ax.annotate(f"{final:.2f}", (x, y), textcoords="offset points", xytext=(5, -10), fontsize=7)
        ax.set_title(f"{name}: {p['success_rate'] * 100:.0f} % success", fontsize=10)
        ax.set_xlabel("object x [mm] (away from the robot)")
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_aspect("equal", adjustable="box")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("object y [mm]")
    legend = {}                                    # label -> handle, over every panel
    for ax in axes[0]:
        handles, labels = ax.get_legend_handles_labels()
        legend.update(zip(labels, handles))
    rank = list(_OUTCOME_STYLE)                    # success first, failures by reason last
    labels = sorted(legend, key=lambda label: (rank.index(label) if label in rank else len(rank), label))
    fig.legend([legend[label] for label in labels], labels, loc="lower center", ncol=max(1, len(labels)),
               fontsize=8, frameon=False)
    fig.suptitle(title or f"{report['skill']}: outcome by object placement "
                          f"(object frame {report['object_pose']})", fontsize=11)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return write_figure_png(fig, path, dpi=110)

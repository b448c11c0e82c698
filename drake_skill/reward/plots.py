"""Pictures of the goal model and of an execution's return (thesis Figs. 4.1 and 4.2).

* :func:`plot_goal_model`: the HMM as a graph.  States are laid out left to
  right by their expected visit time under ``pi`` and ``P`` over the MRP
  horizon (ties by value), arrows are sized by transition probability,
  each node prints its value ``v(s)``; terminal states are green, initial
  states blue.  Optionally an inset per state shows a point cloud (e.g. the
  demonstration cloud nearest the state's mean), given as a list of
  ``(N, 3)`` arrays or a callback ``state -> (N, 3) array | None``.
* :func:`plot_return`: per-step rewards and the running return against time.

matplotlib with the Agg canvas only (no pyplot global state, no graphviz);
PNGs are written with :func:`drake_skill.fileio.write_figure_png` (atomically).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from drake_skill.fileio import new_figure, write_figure_png
from drake_skill.reward.mrp import expected_visit_times
from drake_skill.reward.pomrp import Pomrp

__all__ = ["goal_graph_layout", "plot_goal_model", "plot_return",
           "TERMINAL_COLOR", "INITIAL_COLOR", "STATE_COLOR"]

TERMINAL_COLOR = "#2ca02c"  # green
INITIAL_COLOR = "#1f77b4"  # blue
STATE_COLOR = "#c7c7c7"  # grey
_MIN_ARROW_P = 0.01  # transitions below this probability are not drawn


def goal_graph_layout(pomrp: Pomrp, length: int | None = None) -> np.ndarray:
    """Node positions ``(k, 2)``: x = rank of expected visit time, y staggered.

    ``length`` is the horizon of the visit times (default: floor of the mean
    demonstration length).  States never visited go to the right end.  Nodes
    whose visit times are within 5 % of the horizon of their left neighbour
    alternate above/below the axis so parallel branches stay apart.
    """
    gm = pomrp.goal_model
    L = int(length) if length else max(int(np.floor(gm.lengths_.mean())), 1)
    times = expected_visit_times(gm.startprob_, gm.transmat_, L)
    times = np.where(np.isfinite(times), times, L + 1.0)
    order = np.lexsort((pomrp.values, times))  # by time, then value
    pos = np.zeros((pomrp.n_states, 2))
    flip = 1.0
    for rank, s in enumerate(order):
        pos[s, 0] = rank
        if rank > 0 and abs(times[s] - times[order[rank - 1]]) < 0.05 * L:
            pos[s, 1] = 0.6 * flip
            flip = -flip
    return pos


def plot_goal_model(pomrp: Pomrp, path, *, clouds: Sequence[np.ndarray] | Callable | None = None,
                    cloud_axes: tuple[int, int] = (0, 2), title: str | None = None,
                    length: int | None = None) -> Path:
    """Draws the goal model as a graph and writes it to ``path`` as PNG (thesis Fig. 4.1).

    Args:
      pomrp: fitted goal model with state values.
      path: output ``.png`` path.
      clouds: optional per-state point clouds ``(N, 3)`` (metres), a list of
        ``k`` arrays (``None`` entries allowed) or a callback
        ``state index -> array | None``; drawn as insets projected on
        ``cloud_axes`` (default x-z, a side view).
      title: figure title.
      length: horizon for the layout (see :func:`goal_graph_layout`).

    Returns the written path.
    """
    from matplotlib.patches import Circle, FancyArrowPatch

    k = pomrp.n_states
    if clouds is not None and not callable(clouds) and len(clouds) != k:
        raise ValueError(f"clouds: expected {k} clouds (one per state) or a callback, got {len(clouds)}")
    gm = pomrp.goal_model
    pos = goal_graph_layout(pomrp, length)
    P = gm.transmat_
    terminal = set(int(s) for s in pomrp.terminal_states)
    initial = set(int(s) for s in np.flatnonzero(gm.startprob_ >= 0.5 * gm.startprob_.max()))

    fig = new_figure((max(6.0, 1.8 * k + 1.5), 4.4 if clouds is not None else 3.0))
    # A band at the top for the title, so that it never overlaps the insets' or the states' labels.
    top = (0.985 - 0.16 / fig.get_figheight()) if title else 0.99
    ax = fig.add_axes([0.03, 0.02, 0.94, 0.60 if clouds is not None else top - 0.06])
    ax.set_aspect("equal")
    ax.axis("off")
    r = 0.28
    for i in range(k):
        for j in range(k):
            p = P[i, j]
            if p < _MIN_ARROW_P:
                continue
            if i == j:
                loop = FancyArrowPatch(pos[i] + [-0.12, r * 0.95], pos[i] + [0.12, r * 0.95],
                                       connectionstyle="arc3,rad=-2.2", arrowstyle="-|>", shrinkA=0,
                                       shrinkB=0, mutation_scale=8 + 16 * p, lw=0.5 + 2.5 * p, color="0.35")
                ax.add_patch(loop)
                ax.text(pos[i, 0], pos[i, 1] + r + 0.32, f"{p:.2f}", ha="center", va="bottom", fontsize=7)
                continue
            # Arc from boundary to boundary; arc3 with rad > 0 bends to the
            # right of the direction of travel, so the ends are rotated that way.
            rad = 0.3
            u = (pos[j] - pos[i]) / np.linalg.norm(pos[j] - pos[i])
            tilt = -0.45  # radians
            rot = np.array([[np.cos(tilt), -np.sin(tilt)], [np.sin(tilt), np.cos(tilt)]])
            start = pos[i] + r * (rot @ u)
            end = pos[j] - r * (rot.T @ u)
            ax.add_patch(FancyArrowPatch(start, end, connectionstyle=f"arc3,rad={rad}", arrowstyle="-|>",
                                         shrinkA=0, shrinkB=0, mutation_scale=8 + 16 * p,
                                         lw=0.5 + 2.5 * p, color="0.35", zorder=2))
            mid = 0.5 * (start + end)
            normal = np.array([u[1], -u[0]])  # right of travel
            ax.text(*(mid + (rad * np.linalg.norm(end - start) * 0.5 + 0.08) * normal), f"{p:.2f}",
                    ha="center", va="center", fontsize=7, color="0.2")
    for s in range(k):
        color = TERMINAL_COLOR if s in terminal else INITIAL_COLOR if s in initial else STATE_COLOR
        both = s in terminal and s in initial
        ax.add_patch(Circle(pos[s], r, facecolor=color, edgecolor=INITIAL_COLOR if both else "black",
                            lw=3.5 if both else 1.5, zorder=3))
        ax.text(pos[s, 0], pos[s, 1], f"s{s}\n({pomrp.values[s]:.2f})", ha="center", va="center",
                fontsize=8, zorder=4, color="white" if color != STATE_COLOR else "black")
    ax.set_xlim(pos[:, 0].min() - 0.7, pos[:, 0].max() + 0.7)
    ax.set_ylim(pos[:, 1].min() - 0.7, pos[:, 1].max() + 0.9)

    if clouds is not None:
        a, b = cloud_axes
        x0, x1 = ax.get_xlim()
        for s in range(k):
            cloud = clouds(s) if callable(clouds) else clouds[s]
            if cloud is None:
                continue
            cloud = np.asarray(cloud, dtype=float)
            if cloud.ndim != 2 or cloud.shape[1] != 3:
                raise ValueError(f"clouds[{s}]: expected a point cloud of shape (N, 3), got {cloud.shape}")
            frac = (pos[s, 0] - x0) / (x1 - x0)
            w = min(0.9 / k, 0.2)
            inset = fig.add_axes([0.03 + 0.94 * frac - w / 2, 0.64, w, top - 0.64 - 0.05])
            inset.scatter(cloud[:, a], cloud[:, b], s=0.5, c=TERMINAL_COLOR if s in terminal else "0.3",
                          linewidths=0)
            inset.set_aspect("equal", adjustable="datalim")
            inset.set_xticks([])
            inset.set_yticks([])
            inset.set_title(f"s{s}", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10, y=0.985, va="top")
    return write_figure_png(fig, path)


def plot_return(rewards: np.ndarray | Mapping[str, np.ndarray], path, *, period: float = 0.1,
                title: str | None = None) -> Path:
    """Per-step reward and running return of executions against time (thesis Fig. 4.2).

    Args:
      rewards: ``h (T,)`` per-step rewards of one execution, or a mapping
        ``label -> (T,)`` to overlay several (e.g. smoothed and filtered, or
        a demonstration and a failed rollout).
      path: output ``.png`` path.
      period: seconds per frame (10 Hz -> 0.1 s).

    Returns the written path.
    """
    series = dict(rewards) if isinstance(rewards, Mapping) else {"reward": rewards}
    if not series:
        raise ValueError("rewards: expected at least one reward sequence")
    if not period > 0:
        raise ValueError(f"period: expected > 0 s, got {period}")
    fig = new_figure((7.0, 4.5))
    ax_h = fig.add_subplot(2, 1, 1)
    ax_r = fig.add_subplot(2, 1, 2, sharex=ax_h)
    for label, h in series.items():
        h = np.asarray(h, dtype=float)
        if h.ndim != 1 or h.size == 0 or not np.all(np.isfinite(h)):
            raise ValueError(f"rewards[{label!r}]: expected a non-empty finite 1-D array, got shape {h.shape}")
        t = period * np.arange(1, h.size + 1)
        ax_h.plot(t, h, label=label)
        ax_r.plot(t, np.cumsum(h), label=f"{label}: R = {h.sum():.1f}")
    ax_h.set_ylabel("reward h(G, t)")
    ax_r.set_ylabel("return so far")
    ax_r.set_xlabel("time [s]")
    ax_r.legend(fontsize=8, loc="upper left")
    ax_h.grid(alpha=0.3)
    ax_r.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return write_figure_png(fig, path)

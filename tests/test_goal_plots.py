"""Goal-model graph and return plots: layout, colours, PNG output, argument checks."""

import matplotlib.colors as mcolors
import matplotlib.image as mimage
import numpy as np
import pytest

from drake_skill.reward.goal_model import GoalHMM
from drake_skill.reward.plots import (
    INITIAL_COLOR,
    TERMINAL_COLOR,
    goal_graph_layout,
    plot_goal_model,
    plot_return,
)
from drake_skill.reward.pomrp import Pomrp

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _pomrp(order=(0, 1, 2, 3)):
    """A 4-state left-to-right model whose chain visits states in ``order``."""
    k, d = 4, 8
    P = np.zeros((k, k))
    for a, b in zip(order[:-1], order[1:]):
        P[a, a], P[a, b] = 0.8, 0.2
    P[order[-1], order[-1]] = 1.0
    start = np.eye(k)[order[0]]
    arrays = {"startprob": start, "transmat": P, "means": np.arange(k * d, dtype=float).reshape(k, d) / 10,
              "covars": np.broadcast_to(0.01 * np.eye(d), (k, d, d)).copy(),
              "terminal_states": np.array([order[-1]]), "lengths": np.array([40, 50]),
              "loglik_per_step": np.array([1.0, 1.2])}
    values = np.zeros(k)
    values[list(order)] = [0.5, 1.0, 2.0, 9.0]
    return Pomrp(GoalHMM.from_arrays(arrays, {"covariance_type": "full"}), values)


def _pixels_near(png_path, color, tol=0.06):
    img = mimage.imread(png_path)[..., :3]
    return int((np.abs(img - np.array(mcolors.to_rgb(color))).max(axis=2) < tol).sum())


def test_layout_follows_visit_order():
    pos = goal_graph_layout(_pomrp((2, 0, 3, 1)))
    assert pos[:, 0][[2, 0, 3, 1]].tolist() == [0, 1, 2, 3]
    assert np.all(pos[:, 1] == 0)


def test_goal_model_png_marks_initial_and_terminal(tmp_path):
    path = plot_goal_model(_pomrp(), tmp_path / "graph.png", title="Open")
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    # One initial (blue) and one terminal (green) node: both colours are drawn.
    assert _pixels_near(path, INITIAL_COLOR) > 500
    assert _pixels_near(path, TERMINAL_COLOR) > 500
    # A state both initial and terminal is green with a blue rim: far less blue.
    one = _pomrp()
    one.goal_model.terminal_states_ = np.array([0])
    path1 = plot_goal_model(one, tmp_path / "graph1.png")
    assert _pixels_near(path1, TERMINAL_COLOR) > 500
    assert 50 < _pixels_near(path1, INITIAL_COLOR) < 0.5 * _pixels_near(path, INITIAL_COLOR)


def test_cloud_insets(tmp_path):
    rng = np.random.default_rng(0)
    calls = []

    def cloud(s):
        calls.append(s)
        return None if s == 2 else rng.normal(size=(300, 3))

    path = plot_goal_model(_pomrp(), tmp_path / "clouds.png", clouds=cloud)
    assert sorted(calls) == [0, 1, 2, 3]
    plain = plot_goal_model(_pomrp(), tmp_path / "plain.png")
    assert mimage.imread(path).shape[0] > mimage.imread(plain).shape[0]  # room for the insets
    with pytest.raises(ValueError, match="clouds: expected 4 clouds"):
        plot_goal_model(_pomrp(), tmp_path / "x.png", clouds=[np.zeros((5, 3))] * 3)
    with pytest.raises(ValueError, match=r"clouds\[1\]: expected a point cloud of shape \(N, 3\)"):
        plot_goal_model(_pomrp(), tmp_path / "x.png", clouds=[np.zeros((5, 3)), np.zeros((5, 2)), None, None])


def test_return_plot(tmp_path):
    h = np.r_[np.full(20, 0.5), np.full(30, 9.0)]
    path = plot_return({"smoothed": h, "filtered": h * 0.9}, tmp_path / "ret.png", title="Open")
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    assert mimage.imread(path).shape[:2] == (450, 700)
    assert plot_return(h, tmp_path / "one.png").is_file()
    with pytest.raises(ValueError, match=r"rewards\['bad'\]: expected a non-empty finite 1-D array"):
        plot_return({"bad": np.array([1.0, np.nan])}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="period"):
        plot_return(h, tmp_path / "x.png", period=0)
    assert not (tmp_path / "x.png").exists()


def test_library_plots_leave_the_callers_matplotlib_alone(tmp_path):
    """The library draws on Figures of its own (fileio.new_figure): a notebook's backend
    stays as it was and pyplot holds no figure of the library's afterwards."""
    import subprocess
    import sys

    script = f"""
import matplotlib
matplotlib.use("svg")
import matplotlib.pyplot as plt
import numpy as np
from pathlib import Path
from drake_skill.learning.plots import plot_learning_curve, plot_outcomes_by_placement
from drake_skill.reward.plots import plot_return
out = Path({str(tmp_path)!r})
curve = [dict(episode=e, greedy_success=e > 0, greedy_return=10.0 * e, rollouts=6 * e) for e in range(3)]
plot_learning_curve(curve, out / "curve.png", title="t")
plot_return(np.ones(10), out / "ret.png")
assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
assert plt.get_fignums() == [], plt.get_fignums()
assert (out / "curve.png").read_bytes()[:8] == b"\\x89PNG\\r\\n\\x1a\\n"
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]

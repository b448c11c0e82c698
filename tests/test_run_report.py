"""A learn run's report.html (issue 51 item 4), from hand-made records and kept rollouts."""

import base64
import re

import numpy as np

from drake_skill.learning.rollout import RolloutResult
from drake_skill.learning.rollout_store import rollouts_path, save_rollouts
from drake_skill.learning.run_report import worst_ranked, write_run_report


def _rollout(index, reward, success, verdict=False, failed=False, final=1.0, **extra):
    return {"type": "rollout", "episode": 1, "index": index, "seed": 10 + index, "reward": reward,
            "dense_return": reward, "success": success, "verdict": verdict, "failed": failed,
            "reason": extra.pop("reason", ""), "final_object_state": None if failed else final, **extra}


RECORDS = [
    _rollout(0, 500.0, False, verdict=True, final=0.5),
    _rollout(1, 90.0, True, final=1.6),
    _rollout(2, 700.0, True, verdict=True, final=1.9),
    _rollout(3, 300.0, False, final=0.2),
    _rollout(4, 0.0, False, failed=True, reason="reflex",
             contact={"pairs": [["panda_hand::panda_hand", "box::box_lid", 757.7]], "point": [0.6, 0.0, 0.3],
                      "t": 6.4, "cause": "force"}),
]


def test_worst_ranked_orders_failures_by_highest_and_successes_by_lowest_return():
    failures, successes = worst_ranked(RECORDS, n=1)
    assert [r["index"] for r in failures] == [0] and [r["index"] for r in successes] == [1]
    failures, successes = worst_ranked(RECORDS)
    assert [r["index"] for r in failures] == [0, 3] and [r["index"] for r in successes] == [1, 2]
    assert worst_ranked([{**r, "final_object_state": None} for r in RECORDS]) == ([], [])   # a robot run


def _frames(tmp_path):
    """Kept rollouts of episode 1 whose last frames are a solid grey of 10 * index."""
    results = [RolloutResult(seed=10 + c, weights=np.zeros((3, 7)), last_frame=np.full((6, 8, 3), 10 * c, np.uint8),
                             failed=c == 4) for c in range(5)]
    save_rollouts(rollouts_path(tmp_path, "episode_001"), results)


def _images(page: str) -> list[bytes]:
    return [base64.b64decode(d) for d in re.findall(r'src="data:image/png;base64,([^"]+)"', page)]


def test_the_report_shows_the_worst_ranked_rollouts_with_their_last_frames(tmp_path):
    import matplotlib.image

    _frames(tmp_path)
    summary = {"skill": "open", "method": "pi2-es-cov", "reward": "dense", "held_out_before": 0.5,
               "held_out_after": 0.9, "reward_auc": 0.75, "reflex_rate": 0.2}
    page = write_run_report(tmp_path, RECORDS, summary).read_text()
    assert "<h1>open: pi2-es-cov, dense reward</h1>" in page and "<th>reward_auc</th><td>0.75</td>" in page
    worst = page[page.index("ranked worst"):page.index("the reflex stopped")]
    # Failures by highest return (0, then 3), successes by lowest (1, then 2), each with its frame.
    order = [int(m) for m in re.findall(r"episode 1, rollout (\d)", worst)]
    assert order == [0, 3, 1, 2]
    assert f"drake-skill replay {tmp_path} --episode 1 --index 3" in worst
    greys = [int(matplotlib.image.imread(__import__("io").BytesIO(b))[0, 0, 0] * 255 + 0.5) for b in _images(worst)]
    assert greys == [0, 30, 10, 20]
    trips = page[page.index("the reflex stopped"):]
    assert "t = 6.4 s, force: panda_hand::panda_hand - box::box_lid 758 N" in trips and "rollout 4" in trips


def test_a_robot_run_has_no_ground_truth_panels(tmp_path):
    robot = [{**r, "final_object_state": None} for r in RECORDS]
    page = write_run_report(tmp_path, robot, {"skill": "open"}).read_text()
    assert "ranked worst" not in page and "final state" not in page and "(no frame kept)" in page

"""The tidy table of an experiment grid: one row per run x greedy evaluation (CSV).

Columns (:data:`COLUMNS`):

    skill, method, reward, run     the cell and the run's index (seed = seed0 + run)
    episode                        updates before this greedy execution (0: before learning)
    rollouts_used                  rollouts the policy search had used by then
    success                        the greedy execution's ground-truth success, 1 or 0
    return                         its learned dense return R(G) (0 for a failed execution)
    held_out_after                 the run's held-out success after learning, fraction [0, 1]
                                   (the same on every row of a run; empty when not measured)
    held_out_before                the skill's held-out success before learning (the same
                                   for every run of the skill; empty when not measured)

Rows are sorted by skill (by name), method and reward (in the orders of
``METHODS``, ``REWARDS``), run and episode, and written from the stored run
folders alone, so the same runs give the same bytes.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from drake_skill.fileio import atomic_write_text, load_json, read_csv_rows
from drake_skill.learning.loop import REWARDS
from drake_skill.learning.policy_search import METHODS

__all__ = ["COLUMNS", "TABLE_NAME", "held_out_before", "read_table", "run_rows", "stored_runs", "table_text",
           "write_table"]

COLUMNS = ("skill", "method", "reward", "run", "episode", "rollouts_used", "success", "return",
           "held_out_after", "held_out_before")

#: The table's file name in the grid's folder.
TABLE_NAME = "table.csv"


def _order(values, value) -> int:
    return values.index(value) if value in values else len(values)


def cell_key(skill: str, method: str, reward: str) -> tuple:
    """Sort key of a cell: skills by name, then the orders of METHODS and REWARDS (unknown names last)."""
    return (skill, _order(METHODS, method), method, _order(REWARDS, reward), reward)


def stored_runs(out) -> list[dict]:
    """The ``summary.json`` of every finished run under ``out`` (``SKILL/METHOD/REWARD/run_RRR``),
    in table order. A partial run (``.run_RRR.partial``) is not one."""
    summaries = []
    for p in Path(out).glob("*/*/*/run_*/summary.json"):
        fix = f"delete that run's folder ({p.parent}); 'drake-skill experiment run' redoes it"
        summary = load_json(p, fix)
        kinds = {"skill": str, "method": str, "reward": str, "run": int}
        if not isinstance(summary, dict) or any(not isinstance(summary.get(k), t) for k, t in kinds.items()):
            raise ValueError(f"{p}: not a run summary (needs {', '.join(kinds)}); {fix}")
        summaries.append(summary)
    return sorted(summaries, key=lambda s: (*cell_key(s["skill"], s["method"], s["reward"]), int(s["run"])))


def held_out_before(out, skill: str) -> float | None:
    """The held-out success rate of a skill's fitted policy (``OUT/SKILL/held_out_before.json``); None
    when not measured."""
    path = Path(out) / skill / "held_out_before.json"
    fix = "delete it; 'drake-skill experiment run' measures it again"
    return load_json(path, fix)["success_rate"] if path.is_file() else None


def run_rows(summary: dict, held_out_before: float | None) -> list[dict]:
    """A run's rows: one per greedy execution of its learning curve."""
    per_episode = int(summary["rollouts"])
    return [{"skill": summary["skill"], "method": summary["method"], "reward": summary["reward"],
             "run": int(summary["run"]), "episode": int(c["episode"]),
             "rollouts_used": int(c["episode"]) * per_episode, "success": int(bool(c["greedy_success"])),
             "return": float(c["greedy_return"]), "held_out_after": summary.get("held_out_after"),
             "held_out_before": held_out_before}
            for c in sorted(summary["curve"], key=lambda c: int(c["episode"]))]


def _cell(value) -> str:
    if value is None:
        return ""
    return repr(float(value)) if isinstance(value, float) else str(value)


def table_text(rows) -> str:
    """CSV text of ``rows`` (header :data:`COLUMNS`, ``\\n`` line ends, floats as Python's repr)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow([_cell(row[c]) for c in COLUMNS])
    return buffer.getvalue()


def write_table(out, path=None) -> Path:
    """Writes the table of every stored run under ``out`` to ``path`` (default ``OUT/table.csv``)."""
    befores: dict[str, float | None] = {}
    rows = []
    for summary in stored_runs(out):
        skill = summary["skill"]
        if skill not in befores:
            befores[skill] = held_out_before(out, skill)
        rows += run_rows(summary, befores[skill])
    return atomic_write_text(Path(path) if path is not None else Path(out) / TABLE_NAME, table_text(rows))


def read_table(path) -> list[dict]:
    """The rows of a table written by :func:`write_table`, typed (empty cells None).

    Raises ValueError naming the file when its header is not :data:`COLUMNS`.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such table; run 'drake-skill experiment run' first")
    rebuild = "'drake-skill experiment run' with the grid's --out writes the table again from the stored runs"
    rows = read_csv_rows(path, COLUMNS, "an experiment table", rebuild)
    ints, floats = ("run", "episode", "rollouts_used", "success"), ("return", "held_out_after", "held_out_before")
    for line, row in enumerate(rows, start=2):
        try:
            for key in ints:
                row[key] = int(row[key])
            for key in floats:
                row[key] = float(row[key]) if row[key] != "" else None
        except (TypeError, ValueError):   # a cell missing (None) or not a number: a cut or edited file
            raise ValueError(f"{path}: line {line}: column '{key}' = {row.get(key)!r} is not a number (the file "
                             f"is cut short or edited); {rebuild}") from None
    return rows

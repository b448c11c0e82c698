"""Figures and ``results.md`` of an experiment grid, from its table alone (no simulation).

Curves (thesis Fig. 7.1): per cell (skill, method, reward), the greedy
success of each run at episodes 0..E, where episode k is the greedy
execution after k x C rollouts (C: the rollouts of an episode of the budget,
6 in the thesis). PoWER updates after every rollout and is executed greedily
after every C-th update (the thesis's "greedy every 6"); a table that holds
more of its greedy executions gives its curve those after k x C rollouts. Mean over the runs with a band of one
standard deviation (clipped to [0, 1]).

Area under the curve (AUC): per run, the trapezoid area under its greedy
success against episode, divided by E (0: never succeeded, 1: succeeded from
the start); reported as mean +/- standard deviation over the runs.

The thesis's three claims (section 7.1), each decided per skill from the
runs, with the rules written into ``results.md``:

1. dense rewards beat sparse ones for every method but PoWER (AUC, each
   method's dense runs against its sparse runs);
2. the black-box variants beat the per-step ones (AUC: PI^2-ES against
   PI^2, PI^2-ES-Cov against PI^2-Cov, for each reward; each reward's verdict
   alone is shown too, as the thesis's Fig. 7.1k-l compares them with the
   dense reward);
3. PI^2-ES-Cov converges fastest (AUC), highest (held-out success after
   learning) and with the lowest variance (spread of the AUC over runs),
   against the best other method with the dense reward.

"Better" needs the 95 % confidence interval of the difference of means
(Welch) to lie above 0, "worse" below 0; a spread is lower when it is the
smaller one and the Brown-Forsythe test gives p < 0.05. A claim holds when
every comparison it needs is better, does not hold when one is worse, and
otherwise cannot tell (too few runs to decide, or no difference the runs
can show).
"""

from __future__ import annotations

import contextlib
import dataclasses as dc
import math
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

from drake_skill.experiments.table import TABLE_NAME, cell_key, read_table
from drake_skill.fileio import atomic_write_text

__all__ = ["Cell", "cells_from_rows", "claims", "write_report"]

HOLDS, FAILS, UNCLEAR = "holds", "does not hold", "cannot tell"
PER_STEP_PAIRS = (("pi2-es", "pi2"), ("pi2-es-cov", "pi2-cov"))
LEADER = "pi2-es-cov"
_DPI = 100


@dc.dataclass
class Cell:
    """The runs of one (skill, method, reward): ``success`` (runs x episodes 0..E, 0/1),
    ``held_out_after`` per run (None where not measured), the skill's ``held_out_before``."""

    skill: str
    method: str
    reward: str
    runs: list
    success: np.ndarray
    held_out_after: list
    held_out_before: float | None

    @property
    def auc(self) -> np.ndarray:
        """Per run: area under greedy success against episode, over E (fraction)."""
        n = self.success.shape[1] - 1
        if n == 0:
            return self.success[:, 0].astype(float)
        s = self.success.astype(float)
        return (s[:, 1:] + s[:, :-1]).sum(axis=1) / (2 * n)

    @property
    def after(self) -> np.ndarray:
        return np.array([v for v in self.held_out_after if v is not None], dtype=float)


def _episode_length(rows) -> int:
    """C: rollouts per episode of the budget, from the table (PoWER's rows say 1; the others C)."""
    ratios = [r["rollouts_used"] // r["episode"] for r in rows if r["episode"] > 0 and r["method"] != "power"]
    return max(ratios) if ratios else 1


def cells_from_rows(rows) -> list[Cell]:
    """The cells of a table, in table order. A run's curve is its greedy successes after
    0, C, 2C, ... rollouts; a run that misses one of them (a gap) is left out."""
    C = _episode_length(rows)
    grouped: dict[tuple, dict[int, dict[int, int]]] = defaultdict(lambda: defaultdict(dict))
    extra: dict[tuple, dict] = defaultdict(dict)
    for r in rows:
        key = (r["skill"], r["method"], r["reward"])
        if r["rollouts_used"] % C == 0:
            grouped[key][r["run"]][r["rollouts_used"] // C] = r["success"]
        extra[key][r["run"]] = (r["held_out_after"], r["held_out_before"])
    cells = []
    for key in sorted(grouped, key=lambda k: cell_key(*k)):
        runs = grouped[key]
        n = max(max(points) for points in runs.values()) + 1
        complete = sorted(run for run, points in runs.items() if sorted(points) == list(range(n)))
        if not complete:
            continue
        success = np.array([[runs[run][k] for k in range(n)] for run in complete]).reshape(len(complete), n)
        before = next(iter(extra[key].values()))[1]
        cells.append(Cell(*key, complete, success, [extra[key][run][0] for run in complete], before))
    return cells


# --------------------------------------------------------------------------- statistics
def _mean_sd(values) -> tuple[float, float]:
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return math.nan, math.nan
    return float(values.mean()), float(values.std(ddof=1)) if values.size > 1 else 0.0


def _ms(values, digits: int = 2) -> str:
    m, s = _mean_sd(values)
    return "-" if math.isnan(m) else f"{m:.{digits}f} ± {s:.{digits}f}"


@contextlib.contextmanager
def _without_spread_warnings():
    """scipy warns of precision loss on a sample whose values are all equal (every run of a cell
    with the same AUC or held-out success, e.g. all 1.00); the callers handle that case."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def compare(a, b) -> tuple[str, str]:
    """Whether mean(a) > mean(b): ("better" | "worse" | "unclear", the numbers that decide it),
    by the 95 % Welch interval of the difference (scipy's ``ttest_ind(equal_var=False)``; two
    samples without spread give the difference itself)."""
    from scipy import stats

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.size < 2 or b.size < 2:
        return "unclear", f"{_ms(a)} vs {_ms(b)} (fewer than 2 runs)"
    diff = a.mean() - b.mean()
    if a.var() == 0 and b.var() == 0:
        low = high = diff
    else:
        with _without_spread_warnings():    # one sample without spread: the other's gives the interval
            low, high = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    verdict = "better" if low > 0 else "worse" if high < 0 else "unclear"
    return verdict, f"{_ms(a)} vs {_ms(b)}, difference {diff:+.2f} [{low:+.2f}, {high:+.2f}]"


def compare_spread(a, b) -> tuple[str, str]:
    """Whether a's spread is lower than b's: Brown-Forsythe test at p < 0.05."""
    from scipy import stats

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    sa, sb = _mean_sd(a)[1], _mean_sd(b)[1]
    text = f"sd {sa:.2f} vs {sb:.2f}"
    if a.size < 2 or b.size < 2 or sa == sb:
        return "unclear", text + (" (fewer than 2 runs)" if min(a.size, b.size) < 2 else "")
    with _without_spread_warnings():    # p is not finite then, handled below
        p = float(stats.levene(a, b, center="median").pvalue)
    if not math.isfinite(p):
        p = 0.0 if (sa == 0) != (sb == 0) else 1.0
    text += f", Brown-Forsythe p = {p:.3f}"
    if p >= 0.05:
        return "unclear", text
    return ("better" if sa < sb else "worse"), text


def combine(verdicts) -> str:
    """A claim from its comparisons: holds when all are better, not when one is worse."""
    verdicts = list(verdicts)
    if any(v == "worse" for v in verdicts):
        return FAILS
    if verdicts and all(v == "better" for v in verdicts):
        return HOLDS
    return UNCLEAR


# --------------------------------------------------------------------------- claims
def _index(cells) -> dict:
    return {(c.skill, c.method, c.reward): c for c in cells}


def claim_dense_beats_sparse(cells) -> tuple[str, list[str]]:
    """Claim 1: per skill and method but PoWER, dense AUC > sparse AUC (PoWER shown, not counted)."""
    index, verdicts, lines = _index(cells), [], []
    for (skill, method, reward), cell in index.items():
        sparse = index.get((skill, method, "sparse"))
        if reward != "dense" or sparse is None:
            continue
        verdict, text = compare(cell.auc, sparse.auc)
        if method != "power":
            verdicts.append(verdict)
        lines.append(f"{skill}, {method}: AUC dense vs sparse {text}: {verdict}"
                     + (" (PoWER: the thesis's exception, not counted)" if method == "power" else ""))
    return combine(verdicts), lines


def claim_black_box_beats_per_step(cells) -> tuple[str, list[str]]:
    """Claim 2: PI^2-ES > PI^2 and PI^2-ES-Cov > PI^2-Cov in AUC, per skill and reward. The
    first line gives the verdict of each reward's comparisons alone (the thesis's Fig. 7.1k-l
    compares the methods with the dense reward)."""
    index, verdicts, lines = _index(cells), defaultdict(list), []
    skills_rewards = sorted({(c.skill, c.reward) for c in cells}, key=lambda k: cell_key(k[0], "", k[1]))
    for skill, reward in skills_rewards:
        for black_box, per_step in PER_STEP_PAIRS:
            a, b = index.get((skill, black_box, reward)), index.get((skill, per_step, reward))
            if a is None or b is None:
                continue
            verdict, text = compare(a.auc, b.auc)
            verdicts[reward].append(verdict)
            lines.append(f"{skill}, {reward}: AUC {black_box} vs {per_step} {text}: {verdict}")
    if len(verdicts) > 1:
        lines.insert(0, "by reward alone: " + ", ".join(f"{reward} {combine(v)}" for reward, v in verdicts.items()))
    return combine(v for vs in verdicts.values() for v in vs), lines


def claim_leader(cells) -> tuple[str, list[str]]:
    """Claim 3: PI^2-ES-Cov (dense) against the best other dense method of each skill:
    AUC (fastest), held-out after (highest), spread of the AUC (lowest variance)."""
    verdicts, lines = [], []
    for skill in dict.fromkeys(c.skill for c in cells):
        dense = {c.method: c for c in cells if c.skill == skill and c.reward == "dense"}
        if LEADER not in dense or len(dense) < 2:
            continue
        lead, others = dense[LEADER], [c for m, c in dense.items() if m != LEADER]
        parts = [("fastest (AUC)", lambda c: c.auc, compare),
                 ("highest (held-out after)", lambda c: c.after, compare),
                 ("lowest variance (sd of AUC)", lambda c: c.auc, compare_spread)]
        for name, values, test in parts:
            if name.startswith("lowest"):
                rival = min(others, key=lambda c: _mean_sd(values(c))[1])
            else:
                rival = max(others, key=lambda c: _mean_sd(values(c))[0])
            verdict, text = test(values(lead), values(rival))
            verdicts.append(verdict)
            lines.append(f"{skill}, {name}: {LEADER} vs the best other, {rival.method}: {text}: {verdict}")
    return combine(verdicts), lines


CLAIMS = (("Learned dense rewards beat sparse ones for every method but PoWER.", claim_dense_beats_sparse),
          ("The black-box variants (PI^2-ES, PI^2-ES-Cov) beat the per-step ones (PI^2, PI^2-Cov).",
           claim_black_box_beats_per_step),
          ("PI^2-ES-Cov converges fastest, highest and with the lowest variance.", claim_leader))


def claims(cells) -> list[tuple[str, str, list[str]]]:
    """(claim, verdict, the comparisons that decide it) for each of the thesis's claims."""
    return [(text, *decide(cells)) for text, decide in CLAIMS]


# --------------------------------------------------------------------------- figures
def _band(ax, cell: Cell, label: str, color, linestyle="-", alpha=0.18) -> None:
    x = np.arange(cell.success.shape[1])
    mean = cell.success.mean(axis=0) if len(cell.runs) else np.full(len(x), np.nan)
    sd = cell.success.std(axis=0, ddof=1) if len(cell.runs) > 1 else np.zeros(len(x))
    ax.plot(x, mean, linestyle, marker="o", ms=3, color=color, label=f"{label} ({len(cell.runs)} runs)")
    ax.fill_between(x, np.clip(mean - sd, 0, 1), np.clip(mean + sd, 0, 1), color=color, alpha=alpha, lw=0)


def _axes_style(ax, title: str) -> None:
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel("episode")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")


def _save(fig, path: Path) -> Path:
    from drake_skill.fileio import write_figure_png

    return write_figure_png(fig, path, dpi=_DPI, metadata={"Software": None})


def plot_methods(cells, skill: str, path: Path) -> Path:
    """One panel per method: mean greedy success +/- sd against episode, dense against sparse."""
    from drake_skill.fileio import new_figure

    methods = list(dict.fromkeys(c.method for c in cells if c.skill == skill))
    ncols = min(3, len(methods))
    nrows = math.ceil(len(methods) / ncols)
    fig = new_figure((4.2 * ncols, 3.2 * nrows))
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax, method in zip(axes.flat, methods):
        for cell in (c for c in cells if c.skill == skill and c.method == method):
            dense = cell.reward == "dense"
            _band(ax, cell, cell.reward, "tab:blue" if dense else "tab:orange", "-" if dense else "--")
        _axes_style(ax, method)
    for ax in list(axes.flat)[len(methods):]:
        ax.axis("off")
    axes[0][0].set_ylabel("greedy success (mean ± sd)")
    fig.suptitle(f"{skill}: greedy success per method, dense against sparse reward")
    fig.tight_layout()
    return _save(fig, path)


def plot_dense(cells, skill: str, path: Path) -> Path:
    """Every method with the dense reward on one plot."""
    from drake_skill.fileio import new_figure

    fig = new_figure((6.4, 4.2))
    ax = fig.subplots()
    dense = [c for c in cells if c.skill == skill and c.reward == "dense"]
    for i, cell in enumerate(dense):
        _band(ax, cell, cell.method, f"C{i}", alpha=0.08)
    ax.set_ylabel("greedy success (mean ± sd)")
    _axes_style(ax, f"{skill}: every method, dense reward")
    fig.tight_layout()
    return _save(fig, path)


# --------------------------------------------------------------------------- results.md
#: Hand-written findings beside the table, appended to ``results.md`` as they are.
NOTES_NAME = "notes.md"

def _skill_section(cells, skill: str) -> list[str]:
    mine = [c for c in cells if c.skill == skill]
    n = max(c.success.shape[1] for c in mine)
    before = mine[0].held_out_before
    lines = [f"## {skill}", "",
             f"Held-out success before learning (the fitted skill, once): "
             f"{'-' if before is None else f'{before:.2f}'}", "",
             "| method | reward | runs | " + " | ".join(f"e{k}" for k in range(n)) + " | AUC | held-out after |",
             "|---|---|---:|" + "---:|" * n + "---:|---:|"]
    for c in mine:
        means = [f"{v:.2f}" for v in c.success.mean(axis=0)] if c.runs else ["-"] * c.success.shape[1]
        means += [""] * (n - len(means))
        lines.append(f"| {c.method} | {c.reward} | {len(c.runs)} | " + " | ".join(means)
                     + f" | {_ms(c.auc)} | {_ms(c.after)} |")
    lines += ["", f"![{skill}: per method](./{skill}_methods.png)", "",
              f"![{skill}: dense reward](./{skill}_dense.png)", ""]
    return lines


def results_markdown(cells, table_name: str, notes: str | None = None) -> str:
    """``results.md``: per skill the success table and AUC; the claims with their numbers;
    then ``notes`` verbatim (what the table cannot hold: what limits a skill, what was tried)."""
    rows = sum(c.success.size for c in cells)
    lines = ["# Experiment results", "",
             f"From `{table_name}` alone ({rows} greedy executions of {sum(len(c.runs) for c in cells)} "
             "runs). Greedy success is the simulator's ground truth; e0 is before learning, ek after k "
             "episodes (PoWER: after k x C rollouts). AUC: area under a run's greedy success against "
             "episode over E; mean ± sd over runs. Held-out after: success over the held-out poses "
             "after learning, mean ± sd over runs.", ""]
    for skill in dict.fromkeys(c.skill for c in cells):
        lines += _skill_section(cells, skill)
    lines += ["## The thesis's claims (section 7.1)", "",
              "Better/worse: the 95 % Welch interval of the difference of means lies above/below 0; "
              "a lower spread: the smaller sd with Brown-Forsythe p < 0.05. A claim holds when every "
              "comparison is better, does not hold when one is worse, and cannot tell otherwise. "
              "Reported, not tested.", ""]
    for i, (text, verdict, evidence) in enumerate(claims(cells), 1):
        lines += [f"{i}. {text} **{verdict}**", ""]
        lines += [f"   - {line}" for line in evidence] or ["   - no cells to compare in this table"]
        lines.append("")
    if notes:
        lines += [f"## Notes (`{NOTES_NAME}`, written by hand beside the table)", "", notes.strip(), ""]
    return "\n".join(lines)


def write_report(table, out_dir=None) -> list[Path]:
    """Figures (``SKILL_methods.png``, ``SKILL_dense.png``) and ``results.md`` from the
    table at ``table`` (a file, or a grid folder holding ``table.csv``) into ``out_dir``
    (default: the table's folder). A ``notes.md`` beside the table ends ``results.md``
    verbatim. The same table and notes give the same bytes."""
    table = Path(table)
    if table.is_dir():
        table = table / TABLE_NAME
    out_dir = Path(out_dir) if out_dir is not None else table.parent
    cells = cells_from_rows(read_table(table))
    if not cells:
        raise ValueError(f"{table}: no runs in the table; run 'drake-skill experiment run' first")
    written = []
    for skill in dict.fromkeys(c.skill for c in cells):
        written.append(plot_methods(cells, skill, out_dir / f"{skill}_methods.png"))
        written.append(plot_dense(cells, skill, out_dir / f"{skill}_dense.png"))
    notes_path = table.parent / NOTES_NAME
    notes = notes_path.read_text(encoding="utf-8") if notes_path.is_file() else None
    written.append(atomic_write_text(out_dir / "results.md", results_markdown(cells, table.name, notes)))
    return written

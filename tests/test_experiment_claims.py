"""The experiment report's statistics and claim rules (docs/results/experiment; thesis 7.1), on
hand-made cells: no simulation. The verdicts in ``results.md`` are decided here."""

import math

import numpy as np
import pytest

from drake_skill.experiments.report import Cell, claims, combine, compare, compare_spread

METHODS = ("power", "pi2", "pi2-cov", "pi2-es", "pi2-es-cov", "cma-es")
ALWAYS = [1] * 6                # greedy success at episodes 0..5: AUC 1.0
EARLY = [0, 1, 1, 1, 1, 1]      # AUC 0.9
MID = [0, 0, 1, 1, 1, 1]        # AUC 0.7
LATE = [0, 0, 0, 1, 1, 1]       # AUC 0.5
ZERO = [0] * 6


def _cell(method, reward, curves, after=None, skill="close"):
    success = np.array(curves, dtype=int)
    after = [1.0] * len(success) if after is None else after
    return Cell(skill, method, reward, list(range(len(success))), success, after, 0.3)


def test_compare_is_the_welch_interval_of_the_difference():
    verdict, text = compare([0.8, 0.9, 1.0, 0.7], [0.2, 0.5, 0.1, 0.3, 0.4])
    # Welch: difference 0.55, se 0.0958, df 6.98, t(0.975) 2.366.
    assert verdict == "better" and text.endswith("difference +0.55 [+0.32, +0.78]"), text
    assert compare([0.2, 0.5, 0.1, 0.3, 0.4], [0.8, 0.9, 1.0, 0.7])[0] == "worse"
    assert compare([0.2, 0.9, 0.5], [0.3, 0.8, 0.4])[0] == "unclear"
    assert compare([1.0, 1.0], [0.0, 0.0]) == ("better", "1.00 ± 0.00 vs 0.00 ± 0.00, difference +1.00 [+1.00, +1.00]")
    assert compare([1.0, 1.0], [1.0, 1.0])[0] == "unclear"
    assert compare([1.0], [0.0, 0.1]) == ("unclear", "1.00 ± 0.00 vs 0.05 ± 0.07 (fewer than 2 runs)")


def test_compare_spread_needs_brown_forsythe_below_five_percent():
    assert compare_spread([1.0] * 6, [0.0, 1.0] * 3)[0] == "better"
    assert compare_spread([0.0, 1.0] * 3, [1.0] * 6)[0] == "worse"
    verdict, text = compare_spread([0.5, 0.6, 0.7, 0.4], [0.5, 0.7, 0.8, 0.3])
    assert verdict == "unclear" and "Brown-Forsythe p = " in text


def test_a_claim_holds_when_all_are_better_and_fails_on_one_worse():
    assert combine(["better", "better"]) == "holds"
    assert combine(["better", "unclear"]) == "cannot tell"
    assert combine(["better", "worse", "unclear"]) == "does not hold"
    assert combine([]) == "cannot tell"


def test_the_three_claims_on_cells_made_to_decide_them():
    """Dense beats sparse for every method but PoWER (PoWER worse: not counted); with the dense
    reward PI^2-ES ties PI^2 and PI^2-ES-Cov beats PI^2-Cov, with the sparse one both lose;
    PI^2-ES-Cov has the best curve and held-out success and no spread."""
    cells = []
    for method in METHODS:
        dense, sparse = {"power": ([LATE, ZERO] * 3, [EARLY] * 6),
                         "pi2-es-cov": ([ALWAYS] * 6, [ZERO] * 6),
                         "pi2-es": ([EARLY, MID] * 3, [ZERO] * 6)}.get(method, ([EARLY, MID] * 3, [LATE] * 6))
        after = [1.0] * 6 if method == "pi2-es-cov" else [0.5, 0.6] * 3
        cells += [_cell(method, "dense", dense, after), _cell(method, "sparse", sparse)]
    (_, v1, lines1), (_, v2, lines2), (_, v3, lines3) = claims(cells)
    assert v1 == "holds", lines1
    assert lines1[0] == ("close, power: AUC dense vs sparse 0.25 ± 0.27 vs 0.90 ± 0.00, difference -0.65 "
                         "[-0.94, -0.36]: worse (PoWER: the thesis's exception, not counted)")
    assert v2 == "does not hold" and lines2[0] == "by reward alone: dense cannot tell, sparse does not hold"
    assert [line.rsplit(": ", 1)[1] for line in lines2[1:]] == ["unclear", "better", "worse", "worse"]
    assert v3 == "holds", lines3
    assert len(lines3) == 3 and all(line.endswith("better") for line in lines3)
    assert "highest (held-out after): pi2-es-cov vs the best other, power: 1.00 ± 0.00 vs 0.55" in lines3[1]



def test_the_spread_test_is_brown_forsythe_not_levene_s_mean_centred_one():
    """Brown-Forsythe: the one-way ANOVA of |x - median(x)|, computed here independently. On these
    runs Levene's mean-centred test (p = 0.026) would call the spread lower; Brown-Forsythe
    (p = 0.091) does not (issue 47: the swap went uncaught)."""
    from scipy import stats

    a = [0.67, 0.86, 0.86, 0.93, 0.72, 0.97]
    b = [0.41, 0.97, 0.37, 0.28, 0.57, 0.97]
    p = stats.f_oneway(np.abs(np.subtract(a, np.median(a))), np.abs(np.subtract(b, np.median(b)))).pvalue
    assert p == pytest.approx(0.0913, abs=1e-4)
    verdict, text = compare_spread(a, b)
    assert verdict == "unclear" and f"Brown-Forsythe p = {p:.3f}" in text



# ----------------------------------------------------------------------------- cells, results.md and figures
def _row(skill, method, reward, run, episode, used, success, after=None, before=None):
    return {"skill": skill, "method": method, "reward": reward, "run": run, "episode": episode,
            "rollouts_used": used, "success": success, "return": 0.0, "held_out_after": after,
            "held_out_before": before}


def _rows():
    """C = 4 rollouts per episode (PI^2's rows); PoWER's every rollout, of which every 4th counts; a PI^2
    sparse run with a gap (left out); a PI^2 dense cell one episode shorter; a skill of one run."""
    rows = []
    for run, curve, after in ((0, [0, 1, 1], 0.8), (1, [0, 0, 1], None), (2, [1, 1, 1], 1.0)):
        rows += [_row("open", "pi2", "sparse", run, e, 4 * e, s, after, 0.25) for e, s in enumerate(curve)
                 if not (run == 2 and e == 1)]
    for run in (0, 1):
        rows += [_row("open", "power", "dense", run, k, k, int(k >= 4 + run), 0.5, 0.25) for k in range(9)]
    rows.append(_row("close", "pi2", "dense", 0, 0, 0, 1))
    rows += [_row("open", "pi2", "dense", 0, e, 4 * e, s, 0.9, 0.25) for e, s in enumerate([1, 1])]
    rows += [_row("open", "pi2", "dense", 1, e, 4 * e, s, 0.7, 0.25) for e, s in enumerate([0, 1])]
    return rows


EXPECTED_MD = "\n".join([
    '# Experiment results',
    '',
    "From `t.csv` alone (17 greedy executions of 7 runs). Greedy success is the simulator's ground truth; e0 is before learning, ek after k episodes (PoWER: after k x C rollouts). AUC: area under a run's greedy success against episode over E; mean ± sd over runs. Held-out after: success over the held-out poses after learning, mean ± sd over runs.",  # noqa: E501
    '',
    '## close',
    '',
    'Held-out success before learning (the fitted skill, once): -',
    '',
    '| method | reward | runs | e0 | AUC | held-out after |',
    '|---|---|---:|---:|---:|---:|',
    '| pi2 | dense | 1 | 1.00 | 1.00 ± 0.00 | - |',
    '',
    '![close: per method](./close_methods.png)',
    '',
    '![close: dense reward](./close_dense.png)',
    '',
    '## open',
    '',
    'Held-out success before learning (the fitted skill, once): 0.25',
    '',
    '| method | reward | runs | e0 | e1 | e2 | AUC | held-out after |',
    '|---|---|---:|---:|---:|---:|---:|---:|',
    '| power | dense | 2 | 0.00 | 0.50 | 1.00 | 0.50 ± 0.35 | 0.50 ± 0.00 |',
    '| pi2 | dense | 2 | 0.50 | 1.00 |  | 0.75 ± 0.35 | 0.80 ± 0.14 |',
    '| pi2 | sparse | 2 | 0.00 | 0.50 | 1.00 | 0.50 ± 0.35 | 0.80 ± 0.00 |',
    '',
    '![open: per method](./open_methods.png)',
    '',
    '![open: dense reward](./open_dense.png)',
    '',
    "## The thesis's claims (section 7.1)",
    '',
    'Better/worse: the 95 % Welch interval of the difference of means lies above/below 0; a lower spread: the smaller sd with Brown-Forsythe p < 0.05. A claim holds when every comparison is better, does not hold when one is worse, and cannot tell otherwise. Reported, not tested.',  # noqa: E501
    '',
    '1. Learned dense rewards beat sparse ones for every method but PoWER. **cannot tell**',
    '',
    '   - open, pi2: AUC dense vs sparse 0.75 ± 0.35 vs 0.50 ± 0.35, difference +0.25 [-1.27, +1.77]: unclear',
    '',
    '2. The black-box variants (PI^2-ES, PI^2-ES-Cov) beat the per-step ones (PI^2, PI^2-Cov). **cannot tell**',
    '',
    '   - no cells to compare in this table',
    '',
    '3. PI^2-ES-Cov converges fastest, highest and with the lowest variance. **cannot tell**',
    '',
    '   - no cells to compare in this table',
    "",
])


def test_cells_from_rows_by_hand():
    from drake_skill.experiments.report import _episode_length, cells_from_rows

    assert _episode_length(_rows()) == 4
    assert _episode_length([_row("open", "power", "dense", 0, 3, 3, 0)]) == 1
    assert _episode_length([_row("open", "pi2", "dense", 0, 0, 0, 0)]) == 1
    cells = cells_from_rows(_rows())
    assert [(c.skill, c.method, c.reward, c.runs) for c in cells] == [
        ("close", "pi2", "dense", [0]), ("open", "power", "dense", [0, 1]), ("open", "pi2", "dense", [0, 1]),
        ("open", "pi2", "sparse", [0, 1])]
    np.testing.assert_array_equal(cells[1].success, [[0, 1, 1], [0, 0, 1]])      # rollouts 0, 4, 8
    np.testing.assert_array_equal(cells[3].success, [[0, 1, 1], [0, 0, 1]])
    assert cells[3].held_out_after == [0.8, None] and cells[3].held_out_before == 0.25
    assert cells[0].held_out_after == [None] and cells[0].held_out_before is None
    np.testing.assert_array_equal(cells[3].after, [0.8])
    assert cells[3].after.dtype == float and cells[0].after.shape == (0,)
    np.testing.assert_array_equal(cells[2].auc, [1.0, 0.5])
    np.testing.assert_array_equal(cells[1].auc, [0.75, 0.25])             # (0 + 2 * 1 + 1) / 4, (0 + 0 + 1) / 4
    assert cells[0].auc.tolist() == [1.0] and cells[0].auc.dtype == float  # one episode: its success
    # A cell whose every run has a gap is left out.
    gappy = [_row("open", "pi2", "dense", 0, e, 4 * e, 1) for e in (0, 2)]
    assert cells_from_rows(gappy + [_row("open", "pi2", "dense", 1, 1, 4, 1)]) == []


def test_mean_and_sd_text():
    from drake_skill.experiments.report import _mean_sd, _ms

    assert _mean_sd([]) == (pytest.approx(float("nan"), nan_ok=True), pytest.approx(float("nan"), nan_ok=True))
    assert _mean_sd([0.5]) == (0.5, 0.0)
    assert _mean_sd([1, 2, 4]) == (pytest.approx(7 / 3), pytest.approx(np.std([1, 2, 4], ddof=1)))
    assert (_ms([]), _ms([0.5]), _ms([1, 2, 4]), _ms([1, 2, 4], 3)) == ("-", "0.50 ± 0.00", "2.33 ± 1.53",
                                                                         "2.333 ± 1.528")


def test_compare_edges():
    assert compare([0.5, 0.5], [0.5]) == ("unclear", "0.50 ± 0.00 vs 0.50 ± 0.00 (fewer than 2 runs)")
    # One sample without spread: the other's gives the interval (no warning escapes).
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        verdict, text = compare([1.0, 1.0, 1.0], [0.2, 0.4, 0.3])
    assert verdict == "better" and text == "1.00 ± 0.00 vs 0.30 ± 0.10, difference +0.70 [+0.45, +0.95]"
    assert compare_spread([0.5, 0.6], [0.5, 0.6]) == ("unclear", "sd 0.07 vs 0.07")
    assert compare_spread([0.5], [0.5, 0.9]) == ("unclear", "sd 0.00 vs 0.28 (fewer than 2 runs)")
    assert compare_spread([0.5, 0.9], [0.1]) == ("unclear", "sd 0.28 vs 0.00 (fewer than 2 runs)")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert compare_spread([1.0] * 6, [0.0, 1.0] * 3) == ("better", "sd 0.00 vs 0.55, Brown-Forsythe p = 0.000")
        assert compare_spread([0.3] * 3, [0.3] * 3) == ("unclear", "sd 0.00 vs 0.00")


def test_claims_skip_what_they_cannot_compare():
    from drake_skill.experiments.report import claim_black_box_beats_per_step, claim_leader

    alone = [_cell("pi2-es-cov", "dense", [ALWAYS] * 3)]
    assert claim_leader(alone) == ("cannot tell", [])
    assert claim_black_box_beats_per_step(alone) == ("cannot tell", [])
    one_reward = [_cell("pi2-es", "dense", [ALWAYS] * 3), _cell("pi2", "dense", [ZERO] * 3)]
    verdict, lines = claim_black_box_beats_per_step(one_reward)
    assert verdict == "holds" and lines == [
        "close, dense: AUC pi2-es vs pi2 1.00 ± 0.00 vs 0.00 ± 0.00, difference +1.00 [+1.00, +1.00]: better"]
    # The leader against the best other by mean for speed and height, by the lowest sd for spread.
    cells = [_cell("pi2-es-cov", "dense", [ALWAYS] * 4, [1.0] * 4), _cell("pi2", "dense", [MID] * 4, [0.2] * 4),
             _cell("cma-es", "dense", [EARLY, EARLY, EARLY, LATE], [0.6, 0.4] * 2),
             _cell("power", "sparse", [ALWAYS] * 4)]
    verdict, lines = claim_leader(cells)
    assert [line.split(": ")[1].split(",")[1] for line in lines] == [" cma-es", " cma-es", " pi2"]
    assert lines[2].startswith("close, lowest variance (sd of AUC): pi2-es-cov vs the best other, pi2: sd 0.00 vs "
                               "0.00")


def test_results_markdown_in_full():
    from drake_skill.experiments.report import cells_from_rows, results_markdown

    cells = cells_from_rows(_rows())
    assert results_markdown(cells, "t.csv") == EXPECTED_MD
    with_notes = results_markdown(cells, "t.csv", "\n  Found: x.  \n\n")
    assert with_notes == EXPECTED_MD + "\n## Notes (`notes.md`, written by hand beside the table)\n\nFound: x.\n"


def test_write_report_files_and_errors(tmp_path, monkeypatch):
    from drake_skill.experiments.report import results_markdown, cells_from_rows, write_report
    from drake_skill.experiments.table import table_text

    grid = tmp_path / "grid"
    grid.mkdir()
    (grid / "table.csv").write_text(table_text(_rows()))
    from drake_skill.experiments import report

    titles = []
    real_save = report._save
    monkeypatch.setattr(report, "_save",
                        lambda fig, path: titles.append(fig.axes[0].get_title()) or real_save(fig, path))
    written = write_report(grid)
    assert titles == ["pi2", "close: every method, dense reward", "power", "open: every method, dense reward"]
    assert [p.name for p in written] == ["close_methods.png", "close_dense.png", "open_methods.png",
                                         "open_dense.png", "results.md"]
    assert all(p.parent == grid and p.is_file() for p in written)
    assert (grid / "results.md").read_text(encoding="utf-8") == EXPECTED_MD.replace("`t.csv`", "`table.csv`")
    (grid / "notes.md").write_text("Seen.\n", encoding="utf-8")
    out = tmp_path / "out"
    out.mkdir()
    written = write_report(grid / "table.csv", out)
    assert all(p.parent == out for p in written)
    assert (out / "results.md").read_text(encoding="utf-8") == results_markdown(cells_from_rows(_rows()),
                                                                                 "table.csv", "Seen.\n")
    (grid / "empty.csv").write_text(table_text([]))
    with pytest.raises(ValueError) as e:
        write_report(grid / "empty.csv")
    assert str(e.value) == f"{grid / 'empty.csv'}: no runs in the table; run 'drake-skill experiment run' first"


def test_figures_draw_the_bands_of_every_cell(monkeypatch):
    from matplotlib.colors import to_rgba

    from drake_skill.experiments import report

    saved = []
    monkeypatch.setattr(report, "_save", lambda fig, path: saved.append((fig, path)) or path)
    cells = report.cells_from_rows(_rows())
    assert report.plot_methods(cells, "open", "m.png") == "m.png"
    fig, _ = saved.pop()
    assert tuple(fig.get_size_inches()) == pytest.approx((8.4, 3.2))       # 2 methods: 1 x 2 panels
    power, pi2 = fig.axes
    assert (power.get_title(), pi2.get_title()) == ("power", "pi2")
    assert fig._suptitle.get_text() == "open: greedy success per method, dense against sparse reward"
    assert power.get_ylabel() == "greedy success (mean ± sd)" and pi2.get_ylabel() == ""
    for ax in (power, pi2):
        assert ax.get_ylim() == pytest.approx((-0.05, 1.05)) and ax.get_xlabel() == "episode"
        assert ax.title.get_fontsize() == 10 and ax.get_legend()._loc == 4        # lower right
        assert ax.get_legend().get_texts()[0].get_fontsize() == 7
    dense, sparse = pi2.get_lines()
    assert (dense.get_label(), sparse.get_label()) == ("dense (2 runs)", "sparse (2 runs)")
    assert (dense.get_linestyle(), sparse.get_linestyle()) == ("-", "--")
    assert to_rgba(dense.get_color()) == to_rgba("tab:blue") and to_rgba(sparse.get_color()) == to_rgba("tab:orange")
    assert dense.get_marker() == "o" and dense.get_markersize() == 3
    np.testing.assert_array_equal(dense.get_xdata(), [0, 1])
    np.testing.assert_array_equal(dense.get_ydata(), [0.5, 1.0])
    band = pi2.collections[0]
    assert band.get_alpha() == 0.18 and tuple(band.get_facecolor()[0][:3]) == to_rgba("tab:blue")[:3]
    assert band.get_linewidth()[0] == 0
    # The band: mean -/+ the sd over runs (ddof 1), clipped to [0, 1].
    sd = np.std([[1, 1], [0, 1]], axis=0, ddof=1)
    vertices = band.get_paths()[0].vertices
    edges = np.r_[np.clip([0.5, 1.0] - sd, 0, 1), np.clip([0.5, 1.0] + sd, 0, 1)]
    np.testing.assert_allclose(sorted(set(vertices[:, 1].round(12))), sorted(set(edges.round(12))))
    # Four methods: 2 x 3 panels, the last two off.
    four = [report.Cell("s", m, "dense", [0], np.array([[0, 1]]), [None], None) for m in ("a", "b", "c", "d")]
    report.plot_methods(four, "s", "x.png")
    fig, _ = saved.pop()
    assert tuple(fig.get_size_inches()) == pytest.approx((12.6, 6.4)) and len(fig.axes) == 6
    assert [ax.axison for ax in fig.axes] == [True] * 4 + [False] * 2
    one = fig.axes[0].get_lines()[0]
    np.testing.assert_array_equal(one.get_ydata(), [0, 1])
    assert fig.axes[0].collections[0].get_paths()[0].vertices[:, 1].tolist().count(0.0) >= 1   # sd 0 with one run
    assert report.plot_dense(cells, "open", "d.png") == "d.png"
    fig, _ = saved.pop()
    assert tuple(fig.get_size_inches()) == pytest.approx((6.4, 4.2)) and len(fig.axes) == 1
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.get_lines()] == ["power (2 runs)", "pi2 (2 runs)"]
    assert [to_rgba(line.get_color()) for line in ax.get_lines()] == [to_rgba("C0"), to_rgba("C1")]
    assert [c.get_alpha() for c in ax.collections] == [0.08, 0.08]
    assert ax.get_title() == "open: every method, dense reward" and ax.get_ylabel() == "greedy success (mean ± sd)"


def test_figures_are_pngs_of_their_size_without_a_software_tag(tmp_path):
    from drake_skill.experiments import report
    from drake_skill.fileio import new_figure

    fig = new_figure((6.4, 4.2))
    fig.subplots().plot([0, 1], [0, 1])
    path = report._save(fig, tmp_path / "f.png")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")) == (640, 420)
    assert b"Software" not in data


def test_report_edges_found_by_mutation():
    """Rules at their edges: C from episode 1, a skipped cell before a kept one, two-run spreads, a
    Brown-Forsythe p that is not a number (both samples' deviations all equal: p = 1)."""
    from drake_skill.experiments.report import _episode_length, cells_from_rows

    assert _episode_length([_row("open", "pi2", "dense", 0, 0, 0, 0), _row("open", "pi2", "dense", 0, 1, 6, 0)]) == 6
    gappy = [_row("close", "pi2", "dense", 0, e, 4 * e, 1) for e in (0, 2)]
    kept = [_row("open", "pi2", "dense", 0, e, 4 * e, 1) for e in (0, 1)]
    assert [c.skill for c in cells_from_rows(gappy + kept)] == ["open"]
    assert compare_spread([1.0, 1.0], [0.0, 1.0]) == ("better", "sd 0.00 vs 0.71, Brown-Forsythe p = 0.000")
    assert compare_spread([0.0, 1.0], [1.0, 1.0]) == ("worse", "sd 0.71 vs 0.00, Brown-Forsythe p = 0.000")
    assert compare_spread([0.0, 1.0], [0.0, 1.0, 0.0, 1.0]) == ("unclear", "sd 0.71 vs 0.58, Brown-Forsythe p = 1.000")
    s2 = math.sqrt(2.0)                             # an sd of exactly 1
    assert compare_spread([0.0, s2], [0.0, s2] * 2) == ("unclear", "sd 1.00 vs 0.82, Brown-Forsythe p = 1.000")
    assert compare_spread([0.0, s2] * 2, [0.0, s2]) == ("unclear", "sd 0.82 vs 1.00, Brown-Forsythe p = 1.000")


def test_claim_lines_order_and_rivals():
    from drake_skill.experiments.report import claim_black_box_beats_per_step, claim_leader

    # Skills by name, rewards in REWARDS order (an unknown reward last); a missing pair is skipped, not the end.
    cells = [_cell(m, r, [ALWAYS] * 3, skill=k) for k in ("b", "a") for r in ("dense", "aaa")
             for m in ("pi2-es-cov", "pi2-cov")]
    _, lines = claim_black_box_beats_per_step(cells)
    assert lines[0] == "by reward alone: dense cannot tell, aaa cannot tell"
    assert [line.split(": AUC")[0] for line in lines[1:]] == ["a, dense", "a, aaa", "b, dense", "b, aaa"]
    # The leader against one other; a skill without the leader first does not end the search.
    verdict, lines = claim_leader([_cell("pi2", "dense", [ZERO] * 3, skill="a"),
                                   _cell("pi2-es-cov", "dense", [ALWAYS] * 3, [1.0] * 3, skill="b"),
                                   _cell("pi2", "dense", [MID] * 3, [0.5] * 3, skill="b")])
    assert len(lines) == 3 and lines[0].startswith("b, fastest (AUC): pi2-es-cov vs the best other, pi2: ")
    # Rivals: the highest mean for speed and height, the lowest sd for spread, wherever they stand.
    cells = [_cell("pi2-es-cov", "dense", [ALWAYS] * 4, [1.0] * 4),
             _cell("cma-es", "dense", [EARLY, LATE] * 2, [0.6, 0.4] * 2), _cell("pi2", "dense", [EARLY] * 4, [0.2] * 4)]
    _, lines = claim_leader(cells)
    assert [line.split(": ")[1].split(", ")[1] for line in lines] == ["pi2", "cma-es", "pi2"]


def test_bands_of_no_runs_and_of_three(monkeypatch):
    from drake_skill.experiments import report

    saved = []
    monkeypatch.setattr(report, "_save", lambda fig, path: saved.append(fig) or path)
    runs = np.array([[0, 0, 1], [1, 0, 0], [1, 1, 1]])
    three = report.Cell("s", "pi2", "dense", [0, 1, 2], runs, [None] * 3, None)
    none = report.Cell("s", "power", "dense", [], np.zeros((0, 3), dtype=int), [], None)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)          # no mean of an empty slice
        report.plot_dense([three, none], "s", "d.png")
    ax = saved.pop().axes[0]
    np.testing.assert_array_equal(ax.get_lines()[1].get_ydata(), [np.nan] * 3)
    assert ax.get_ylim() == (-0.05, 1.05) and ax.xaxis.get_gridlines()[0].get_alpha() == 0.3
    assert ax.title.get_fontsize() == 10
    mean, sd = runs.mean(axis=0), runs.std(axis=0, ddof=1)
    low, high = np.clip(mean - sd, 0, 1), np.clip(mean + sd, 0, 1)
    assert low[1] == 0.0 and 0 < low[0] < 0.1 and high[0] == 1.0 and 0.9 < high[1] < 1.0   # clipped and not
    vertices = {(round(x, 9), round(y, 9)) for x, y in ax.collections[0].get_paths()[0].vertices}
    assert vertices == {(float(i), round(v, 9)) for i in range(3) for v in (low[i], high[i])}
    # A panel of a sparse cell alone: orange, dashed, its band orange too.
    sparse = report.Cell("s", "pi2", "sparse", [0, 1, 2], runs, [None] * 3, None)
    report.plot_methods([sparse], "s", "m.png")
    ax = saved.pop().axes[0]
    from matplotlib.colors import to_rgba

    assert to_rgba(ax.get_lines()[0].get_color()) == to_rgba("tab:orange")
    assert tuple(ax.collections[0].get_facecolor()[0][:3]) == to_rgba("tab:orange")[:3]


def test_a_cell_without_runs_has_dashes_in_its_row():
    from drake_skill.experiments.report import _skill_section

    none = Cell("s", "pi2", "dense", [], np.zeros((0, 2), dtype=int), [], 0.5)
    lines = _skill_section([none], "s")
    assert lines[6] == "| pi2 | dense | 0 | - | - | - | - |"

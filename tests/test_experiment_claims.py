"""The experiment report's statistics and claim rules (docs/results/experiment; thesis 7.1), on
hand-made cells: no simulation. The verdicts in ``results.md`` are decided here."""

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

"""The rigid model on the 16 runs of Table 1 (sine law, omega1 variable) against the paper's Table 2."""
import pytest

from labtool.models.study.paper import PAPER_DIRECTIONS, main_effects, rigid_vs_table2


@pytest.fixture(scope="module")
def table():
    return rigid_vs_table2("fast")     # the fast preset gives the standard preset's table (benchmarks/)


def test_MR13D_max_within_10_percent_on_every_run(table):
    assert table["MR13D_max_Nm_diff_pct"].abs().max() < 10.0


def test_no_jump_in_runs_9_and_13_and_jumps_in_all_others(table):
    no_jump = table["run"].isin([9, 13])
    assert (table.loc[no_jump, "jumps"] == 0).all() and (table.loc[no_jump, "impacts"] == 0).all()
    assert (table.loc[~no_jump, "jumps"] > 0).all() and (table.loc[~no_jump, "impacts"] > 0).all()


def test_jump_counts_without_load_match_the_paper(table):
    """Fu = 0 (runs 1-8): the follower bounces between the flanks over the deceleration half; the
    counts agree with Table 2 within 2 (docs/rigid_model.md explains the Fu = 65 N runs)."""
    no_load = table["Fu_N"] == 0
    assert (table.loc[no_load, "jumps_diff"].abs() <= 2).all()


_STATEMENTS = [(key, factor, sign) for key, d in PAPER_DIRECTIONS.items() for factor, sign in d.items()]


@pytest.mark.parametrize("key,factor,sign", [
    s if s != ("jumps", "A", +1) else pytest.param(*s, marks=pytest.mark.xfail(
        strict=True, reason="known difference: Fu = 65 N gives fewer, longer flights here "
                            "(docs/rigid_model.md, 'jump counts')"))
    for s in _STATEMENTS])
def test_direction_of_each_factor_effect_as_in_the_papers_discussion(table, key, factor, sign):
    ours = main_effects(table)[key][factor]
    paper = main_effects(table, prefix="paper_")[key][factor]
    assert paper * sign > 0          # the statement holds for the paper's own Table 2
    assert ours * sign > 0

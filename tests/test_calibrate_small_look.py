"""Issue 33 item 5 (small data with a strong effect) on rows too few for nested cross-validation to weigh one
term: 8 rows, 4 folds, one fitted parameter (:func:`calibrate.decidability.terms_supported` is 0). The
search used to add no step at all, so nothing was looked at and nothing held as a rival: the model was the
physics alone, and where a strong effect acted its interval missed. Now the candidates stage looks (one
step scored on the single level of folds the rows allow, claiming nothing:
:attr:`calibrate.stages.CalibrationOptions.candidate_search`), and the candidates the rows lean to are
held as rivals, whose envelope the interval is."""

from __future__ import annotations

from dataclasses import replace

from test_calibrate_small_effect import draw

from microbearing.calibrate import calibrate, parse_rows
from microbearing.calibrate.decidability import terms_supported
from microbearing.calibrate.select import SearchOptions, forward_select

ROWS = 8
FRESH = 2000


def _rows(c, measured, n):
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(n)]


def test_eight_rows_of_a_strong_humidity_effect_are_held_by_a_rival_and_covered_at_high_humidity():
    """Eight data sets (seeds 400-407, not the bench's). The issue's target is a coverage of 0.90-0.98 in
    each region asked about: at RH 0.7-0.8 the old intervals covered 0.71 and 0.60 on two of them (0.91
    pooled): the model without the effect, nothing searched. Now each holds a rival reading the humidity
    and covers; nothing is claimed (no effect, the few_rows item names the candidates leaned to)."""
    assert terms_supported(ROWS, 1, 4, 3) == 0
    for seed in range(400, 408):
        c, measured = draw(seed, ROWS + FRESH)
        report = calibrate(parse_rows(_rows(c, measured, ROWS)), ["mu_pivot"], folds=4, make_plots=False)
        assert report.effects == []
        few = [u for u in report.undecided if u["kind"] == "few_rows"]
        assert len(few) == 1 and "cannot decide" in few[0]["statement"]
        assert "none is claimed" in few[0]["statement"]
        assert any("relative_humidity" in r.label for r in report.model.rivals), seed
        assert any("relative_humidity" in t for t in few[0]["terms"]), few[0]
        fresh = {k: v[ROWS:] for k, v in c.items()}
        high = fresh["relative_humidity"] >= 0.7
        p = report.model.predict({k: v[high] for k, v in fresh.items()})
        inside = (p.mu_lower <= measured[ROWS:][high]) & (measured[ROWS:][high] <= p.mu_upper)
        # ~330 fresh points: a true 95 % share scatters by sqrt(0.95 x 0.05 / 330) = 0.012; 0.90 is four of
        # those below
        assert high.sum() > 250 and inside.mean() >= 0.90, (seed, inside.mean())


def test_a_look_scores_every_candidate_and_claims_none():
    """``SearchOptions(claim=False)``: the same step as a search's (the same candidates, scores, z's and
    threshold), with nothing added, even where the search adds a term (120 rows of a 14x humidity effect,
    far over its threshold)."""
    c, measured = draw(1, 120)
    data = parse_rows(_rows(c, measured, 120))
    # one round each (unweighted): the rounds that follow read the scatter of what each step left
    search = forward_select(data, ["mu_pivot"], folds=4, options=SearchOptions(max_terms=1, scatter_rounds=1))
    look = forward_select(data, ["mu_pivot"], folds=4,
                          options=SearchOptions(max_terms=1, scatter_rounds=1, claim=False))
    assert search.steps[0].chosen is not None and search.steps[0].chosen.z > search.steps[0].z_needed
    assert look.terms == () and look.steps[0].chosen is None
    assert "none is claimed" in look.steps[0].reason
    assert look.steps[0].z_needed == search.steps[0].z_needed
    assert [(c.term.label, c.score, c.z) for c in look.steps[0].ranked] == \
        [(c.term.label, c.score, c.z) for c in search.steps[0].ranked]


def test_when_every_joint_candidate_refits_implausibly_a_screened_one_holds_the_doubt():
    """Eight rows (the bench's seed 19) whose only jointly refitted candidate the rows lean to, a linear drift
    of mu_pivot with the humidity, refits to a pivot friction of 2 (outside its plausible 0.01-1.5) and is
    left out: no rival was held, and at RH 0.7-0.8 the physics alone covered 0.52. The screening leaned to
    humidity laws too; the first of them that refits plausibly is held instead."""
    c, measured = draw(19, ROWS + FRESH)
    report = calibrate(parse_rows(_rows(c, measured, ROWS)), ["mu_pivot"], folds=4, make_plots=False)
    assert report.effects == []
    assert [r.label for r in report.model.rivals if "relative_humidity" in r.label], report.model.rivals
    few = [u for u in report.undecided if u["kind"] == "few_rows"]
    assert len(few) == 1 and any("relative_humidity" in t for t in few[0]["terms"]), few
    fresh = {k: v[ROWS:] for k, v in c.items()}
    high = fresh["relative_humidity"] >= 0.7
    p = report.model.predict({k: v[high] for k, v in fresh.items()})
    inside = (p.mu_lower <= measured[ROWS:][high]) & (measured[ROWS:][high] <= p.mu_upper)
    # the rival widens the interval where the humidity is high: more of the fresh rows there are held than
    # by the model alone (its interval without the rivals' envelope, what the old code answered)
    q = replace(report.model, rivals=[]).predict({k: v[high] for k, v in fresh.items()})
    alone = (q.mu_lower <= measured[ROWS:][high]) & (measured[ROWS:][high] <= q.mu_upper)
    assert inside.mean() >= alone.mean() + 0.1, (inside.mean(), alone.mean())

"""The paper's numerical results (Olaru et al. 2005, Figs. 5-6), reproduced.

Reported ranges over 0-150 mm/s: case A without adhesion 0.002-0.005 and with
adhesion 0.007-0.012 (per-contact coefficient, Fig. 5); case B 0.25-0.55
(global coefficient, Fig. 6). The paper prints its ranges to one significant
digit and does not give the interfacial energy gamma (0.18 J/m^2 here; case B's
lower end falls from 0.306 to 0.259 as gamma at the race contacts goes to 0),
so each computed end may sit up to 25 % from the printed one, and the computed
range must cover at least 80 % of the printed range.
"""

import pytest

from microbearing.physics import paper
from microbearing.service.cli import main

TOLERANCE = 0.25


@pytest.mark.parametrize("name", list(paper.PAPER_CASES))
@pytest.mark.parametrize("convention", ["olaru2005", "derjaguin"])
def test_computed_range_matches_the_reported_range(name, convention):
    case = paper.PAPER_CASES[name]
    lo, hi = paper.case_range(case, convention)
    plo, phi = case.reported
    assert plo * (1 - TOLERANCE) <= lo <= plo * (1 + TOLERANCE)
    assert phi * (1 - TOLERANCE) <= hi <= phi * (1 + TOLERANCE)
    overlap = min(hi, phi) - max(lo, plo)
    assert overlap >= 0.8 * (phi - plo)


def test_case_a_is_mostly_pivoting_and_case_b_mostly_ball_ball():
    from microbearing.physics import evaluate

    a = evaluate(**paper.PAPER_CASES["A_adhesion"].params, mu_pivot=1.0, speed_m_s=0.075)
    assert a.mu_pivoting / a.mu > 0.9
    b = evaluate(**paper.PAPER_CASES["B"].params, mu_ball=1.0, speed_m_s=0.075)
    assert b.mu_ball_ball / b.mu > 0.9


def test_adhesion_raises_case_a_to_the_measured_level():
    # Lin et al. (2004) measured an average dynamic coefficient of 0.007 in case A
    lo, hi = paper.case_range(paper.PAPER_CASES["A_adhesion"])
    assert lo < 0.007 < hi
    _, hi0 = paper.case_range(paper.PAPER_CASES["A_no_adhesion"])
    assert hi0 < 0.007


def test_cli_prints_the_table_and_draws_the_figures(tmp_path, capsys):
    out = tmp_path / "paper.png"
    assert main(["paper", "--plot", str(out)]) == 0
    text = capsys.readouterr().out
    for case in paper.PAPER_CASES.values():
        lo, hi = paper.case_range(case)
        assert f"{lo:8.4f}-{hi:<8.4f}" in text
        assert f"{case.reported[0]:7.3f}-{case.reported[1]:<7.3f}" in text
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 10_000

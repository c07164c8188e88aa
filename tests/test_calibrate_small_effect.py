"""Issue 33 item 5 (small data with a strong effect): ten rows over 20-80 % RH of friction up to 14x the
physics at high humidity and low load (truth: the physics x (1 + 0.1 RH^4 / load_N), 3 % log-normal
scatter). Ten rows support one term (:func:`calibrate.decidability.terms_supported`), whose threshold (a
held-out z of 3.8-4.3 here) the effect does not reach: the report says the data cannot decide (right), and
the model is the physics without a humidity term. Its interval at RH 0.7-0.8 covered fresh measurements
0.80, 0.79 and 0.13 on the data sets drawn here (seeds 8, 9 and 15 of ``bench/calibration_trust.py --part
small-effect``, where 4 of 18 fell below 0.90, the fourth at 0.71, and the other 14 covered 0.98-1.0): the
candidates the data could not tell from the model did not widen it. Seed 8: the close call the report names
(a Kelvin law of the adhesion) refitted to 1.5 J/m², implausible, and no other close call was tried. Seeds
9 and 15: the humidity candidates' z (1.87; 1.18) fell below every close-call rule, though they lowered the
held-out loss and the score. Now every close call is tried in turn, and on few rows every candidate the
data lean to is held as a rival (:func:`calibrate.rivals.undecided_candidates`)."""

from __future__ import annotations

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import calibrate, parse_rows
from microbearing.calibrate.rivals import undecided_candidates

NOISE = 0.03
ROWS = 10
FRESH = 2000


def draw(seed: int, n: int = ROWS + FRESH) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """``n`` lab-like rows (as bench/calibration_trust.py draws them, RH 0.2-0.8): up to 14x the physics at
    80 % RH and 3 mN, 3 % log-normal scatter; the first ``ROWS`` the data here."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4.0, 6.0, 8.0], n),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.005, 0.15, n), "relative_humidity": rng.uniform(0.2, 0.8, n),
         "temperature_C": rng.uniform(20.0, 40.0, n)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.65).mu
    truth = mu * (1.0 + 0.1 * c["relative_humidity"] ** 4 / c["load_N"])
    return c, truth * np.exp(rng.normal(0.0, NOISE, n))


@pytest.mark.parametrize("seed", [8, 9, 15])
def test_ten_rows_of_a_strong_humidity_effect_are_covered_at_high_humidity(seed):
    c, measured = draw(seed)
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(ROWS)]
    report = calibrate(parse_rows(rows), ["mu_pivot"], folds=5, make_plots=False)
    assert any(u["kind"] == "few_rows" for u in report.undecided)
    fresh = {k: v[ROWS:] for k, v in c.items()}
    high = fresh["relative_humidity"] >= 0.7
    p = report.model.predict({k: v[high] for k, v in fresh.items()})
    inside = (p.mu_lower <= measured[ROWS:][high]) & (measured[ROWS:][high] <= p.mu_upper)
    # ~330 fresh points: at a true 95 % the share scatters by sqrt(0.95 x 0.05 / 330) = 0.012; 0.90 is 4 of
    # those below (the old intervals: 0.80, 0.79, 0.13)
    assert high.sum() > 250 and inside.mean() >= 0.90, (high.sum(), inside.mean())
    # what widened it: a rival that reads the humidity, said among what the data cannot decide
    assert any("relative_humidity" in r.label for r in report.model.rivals)
    assert any(u["kind"] == "rivals" and "relative_humidity" in u["terms"][0] for u in report.undecided)


class _Score:
    def __init__(self, label, z, score, joint=True):
        self.term = type("T", (), {"label": label})()
        self.z, self.score, self.joint = z, score, joint


class _Step:
    def __init__(self, ranked, current_score, z_needed=4.0, chosen=None):
        self.ranked, self.chosen, self.z_needed = ranked, chosen, z_needed
        self.current = type("C", (), {"score": current_score})()


def test_on_few_rows_every_candidate_the_data_lean_to_is_undecided():
    lean = _Score("lean", 1.5, -20.0)           # lowers the held-out loss and the score, far below 4 - 1
    close = _Score("close", 3.2, -15.0)         # within CLOSE_MARGIN of the threshold: a close call
    worse_score = _Score("worse score", 1.0, -5.0)   # z > 0 but its score above the model's
    worse_loss = _Score("worse loss", -0.5, -20.0)   # a lower score but a worse held-out loss
    screened = _Score("screened", 1.5, -20.0, joint=False)  # never refitted jointly
    step = _Step([lean, close, worse_score, worse_loss, screened], current_score=-10.0)
    assert [c.term.label for c in undecided_candidates(step)] == ["close"]
    assert [c.term.label for c in undecided_candidates(step, few_rows=True)] == ["close", "lean"]
    # a step that added a term leaves nothing undecided by either rule
    chosen = _Step([lean, close], current_score=-10.0, chosen=close)
    assert undecided_candidates(chosen, few_rows=True) == []

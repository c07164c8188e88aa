"""Every part of a calibrated model is decided for optimize's certified bounds, and the parts this release
added (unit slips' headers, the clock of ISO times, the edge trends) cost no certificate.

A part the bounds do not know is refused by them ("its <part> has no bound over a box here", said, not
guessed): the upload's ``headers`` did so silently for every renamed-column calibration until it was named
(/work/exp76/h51). The first test trips when a new part is added, so that whoever adds it decides."""

from __future__ import annotations

import dataclasses

import numpy as np

from microbearing.calibrate.candidates import EffectTerm
from microbearing.calibrate.model import CalibratedModel
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.optimize.envelope_bound import term_pieces
from microbearing.optimize.interval_bound import interval_structures

#: The parts of a calibrated model, each with how optimize's bounds take it: "bounded" (bounded over a box
#: or no part of mu), or "refused unless constant" (a scatter that depends on an input).
PARTS = {"fitted": "bounded", "fixed": "bounded", "terms": "bounded", "convention": "bounded",
         "covariance": "bounded", "noise_std_log": "bounded", "domain": "bounded", "conditions": "bounded",
         "discrepancy": "bounded", "groups": "bounded", "scatter": "refused unless constant",
         "cloud": "bounded", "domain_rows": "bounded", "rivals": "bounded", "clock": "bounded",
         "headers": "bounded", "edge_trends": "bounded"}


def test_every_part_of_a_calibrated_model_is_decided_for_the_bounds():
    parts = {f.name for f in dataclasses.fields(CalibratedModel)}
    new = sorted(parts - set(PARTS))
    assert not new, (f"a new part of a calibrated model {new}: say whether optimize's certified bounds "
                     "know it (optimize.envelope_bound's bounded parts, cloud_ratio_bound for the "
                     "interval) and add it here; else every calibration that sets it loses its certified "
                     "robust design")
    assert parts == set(PARTS), sorted(set(PARTS) - parts)


def _model(**parts) -> CalibratedPhysicsModel:
    calibrated = CalibratedModel(
        fitted={"mu_pivot": 0.6},
        terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5])],
        covariance=np.diag([1e-4, 1e-12]), noise_std_log=0.02, conditions=["relative_humidity"],
        domain={"load_N": [0.002, 0.01], "relative_humidity": [0.2, 0.5]}, **parts)
    return CalibratedPhysicsModel("calibrated:parts", calibrated)


def test_this_release_s_parts_keep_the_bounds_of_mu_and_of_its_interval():
    plain = _model()
    # a unit slip's column kept under its header, ISO times' start, a departure at the loads' low end
    held = _model(headers={"load_N": "load_mN"}, clock={"date": "2026-11-28T09:00:00+00:00"},
                  edge_trends={"load_N": [0.04, 0.12, 0.0, 0.0]})
    for interval in (False, True):
        pieces, reason = term_pieces(held, interval=interval)
        assert reason == "", reason
        assert [p.kind for p in pieces] == [p.kind for p in term_pieces(plain, interval)[0]]
    structures, reason = interval_structures(held)
    assert reason == "" and len(structures) == len(interval_structures(plain)[0])

"""optimize.plan: a design request's plain values planned into a problem and its envelope (no service)."""

from __future__ import annotations

import numpy as np
import pytest

from microbearing.calibrate import CalibratedModel, Dataset
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.optimize.plan import DesignRequest, PlanError, check_request, plan_design
from microbearing.optimize.solve import InfeasibleDesignError

BOX = {"balls": (3, 12), "groove_angle_deg": (30.0, 60.0)}


def errors(request: DesignRequest, model=None) -> list[tuple[str, str]]:
    with pytest.raises(PlanError) as caught:
        plan_design(request, model)
    return caught.value.errors


def test_a_payload_in_fixed_is_the_loads_bounds_and_the_speed_may_come_from_fixed():
    plan = plan_design(DesignRequest(**BOX, fixed={"load_N": 0.02, "speed_m_s": 0.05}))
    assert plan.problem.bounds.load_N == (0.02, 0.02) and plan.problem.speed_m_s == 0.05
    assert plan.envelope is None


@pytest.mark.parametrize(("request_", "field"), [
    (DesignRequest(**BOX, load_N=(0.001, 0.05), fixed={"load_N": 0.02}, speed_m_s=0.05), "fixed.load_N"),
    (DesignRequest(**BOX, speed_m_s=0.05), "bounds.load_N"),
    (DesignRequest(**BOX, load_N=(0.001, 0.05), fixed={"speed_m_s": 0.05}, speed_m_s=0.05), "speed_m_s"),
    (DesignRequest(**BOX, load_N=(0.001, 0.05)), "speed_m_s"),
    # a value out of its range, named where the request gave it
    (DesignRequest(**BOX, load_N=(0.001, 0.05), fixed={"speed_m_s": -1.0}), "fixed.speed_m_s"),
    (DesignRequest(**BOX, load_N=(0.001, 0.05), speed_m_s=0.05, fixed={"ball_diameter_m": -1.0}),
     "fixed.ball_diameter_m"),
])
def test_each_error_names_the_field_of_the_request(request_, field):
    assert [name for name, _ in errors(request_)] == [field]


def test_checks_without_a_model_name_pareto_and_every_label_of_conditions():
    with pytest.raises(PlanError) as caught:
        check_request(DesignRequest(**BOX, model="surrogate:x", pareto=True))
    assert caught.value.errors[0][0] == "pareto"
    with pytest.raises(PlanError) as caught:
        check_request(DesignRequest(**BOX, conditions={"specimen": "S1", "rh": 0.5}))
    assert [name for name, _ in caught.value.errors] == ["conditions", "conditions.specimen"]


def test_ranges_and_tolerances_make_an_envelope_and_the_physics_takes_no_condition():
    plan = plan_design(DesignRequest(**BOX, load_N=(0.001, 0.05), speed_m_s=[0.01, 0.1],
                                     tolerances={"groove_angle_deg": 1.0}))
    assert plan.envelope.speed_m_s == (0.01, 0.1) and plan.envelope.angle_tolerance_deg == 1.0
    # a Pareto front over a speed range alone is allowed, over a tolerance it is not
    front = plan_design(DesignRequest(**BOX, load_N=(0.001, 0.05), speed_m_s=[0.01, 0.1], pareto=True))
    assert front.envelope is None
    assert errors(DesignRequest(**BOX, load_N=(0.001, 0.05), speed_m_s=0.05, pareto=True,
                                tolerances={"groove_angle_deg": 1.0}))[0][0] == "pareto"
    assert errors(DesignRequest(**BOX, load_N=(0.001, 0.05), speed_m_s=0.05, objective="mu_upper"))[0][0] \
        == "objective"


def test_a_value_the_model_holds_is_refused_where_it_would_be_dropped_and_taken_at_one_point():
    # A calibrated model over an envelope keeps its fitted mu_pivot (its uncertainty is in mu_upper): a
    # different value in fixed would be dropped without a word, so it is refused, naming the field; the
    # same value, or a value the model does not hold, passes. At one point the value is an override.
    model = CalibratedPhysicsModel("calibrated:x", CalibratedModel(fitted={"mu_pivot": 0.8}))
    robust = dict(**BOX, load_N=(0.001, 0.05), speed_m_s=[0.01, 0.1])
    [(field, detail)] = errors(DesignRequest(**robust, fixed={"mu_pivot": 0.3}), model)
    assert field == "fixed.mu_pivot" and "holds mu_pivot = 0.8 (fitted)" in detail and "0.3" in detail
    assert plan_design(DesignRequest(**robust, fixed={"mu_pivot": 0.8}), model).envelope is not None
    kept = plan_design(DesignRequest(**robust, fixed={"ball_diameter_m": 2e-3}), model)
    assert kept.problem.fixed["ball_diameter_m"] == 2e-3
    at_point = plan_design(DesignRequest(**BOX, load_N=(0.001, 0.05), speed_m_s=0.05,
                                         fixed={"mu_pivot": 0.3}), model)
    assert at_point.envelope is None and at_point.problem.fixed["mu_pivot"] == 0.3


def test_limits_that_conflict_on_every_model_raise_the_infeasible_error():
    # a load per ball above its limit at every count and load of the box
    request = DesignRequest(**BOX, load_N=(0.04, 0.05), speed_m_s=0.05,
                            constraints={"max_load_per_ball_N": 0.001})
    with pytest.raises(InfeasibleDesignError):
        plan_design(request)


def test_a_dataset_round_trips_through_its_columns_and_json_lists():
    dataset = Dataset({"load_N": np.array([0.01, 0.02]), "balls": np.array([4, 6])},
                      {"relative_humidity": np.array([0.3, 0.6])}, np.array([0.011, 0.013]),
                      np.array([0.001, 0.002]), {"speed_m_s": 0.05}, {"specimen": np.array(["S1", "S2"])})
    as_json = {name: values.tolist() for name, values in dataset.to_columns().items()}
    again = Dataset.from_columns(as_json, dataset.fixed)
    assert again.fixed == {"speed_m_s": 0.05} and again.physics_columns["balls"].dtype.kind == "i"
    for field in ("physics_columns", "conditions", "factors"):
        ours, theirs = getattr(dataset, field), getattr(again, field)
        assert list(ours) == list(theirs) and all(np.array_equal(ours[k], theirs[k]) for k in ours)
    np.testing.assert_array_equal(again.mu_measured, dataset.mu_measured)
    np.testing.assert_array_equal(again.mu_measured_std, dataset.mu_measured_std)
    without_std = Dataset.from_columns({k: v for k, v in as_json.items() if k != "mu_measured_std"}, {})
    assert without_std.mu_measured_std is None

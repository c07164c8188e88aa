"""The certified worst case over an envelope (optimize.envelope_bound) against brute force, same model."""

import dataclasses
import itertools
import types

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate.candidates import EffectTerm
from microbearing.calibrate.model import CalibratedModel
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.optimize import certificates, robust
from microbearing.optimize.certificates import certified_search, certified_upper_search
from microbearing.optimize.envelope_bound import (
    AxisCosts,
    BranchAndBound,
    certified_max,
    mu_box_bound,
    term_pieces,
)
from microbearing.optimize.interval_bound import interval_structures
from microbearing.optimize.over_envelope import (
    envelope_columns,
    evaluator,
    objective_values,
    with_model_values,
)
from microbearing.optimize.problem import Constraints, DesignBounds, DesignProblem

# A log-quadratic temperature term peaking inside the envelope (at 40 + 0.2 x 10 / (2 x 0.3) C, by hand) and
# a Stribeck term falling with speed while the physics rises with it: the worst case is at no vertex.
C1, C2, CENTRE, SCALE = 0.2, -0.3, 40.0, 10.0
PEAK_C = CENTRE - C1 * SCALE / (2 * C2)


def _model(data_range: dict | None = None) -> CalibratedPhysicsModel:
    """``data_range``: the temperature data's low and high, beyond which the quadratic goes on along its
    tangent (physics.effects: a term fitted since keeps them)."""
    calibrated = CalibratedModel(
        fitted={"mu_pivot": 0.6},
        terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5]),
               (EffectTerm("generic_quadratic", ("temperature_C",),
                           {"centre": CENTRE, "scale": SCALE, **(data_range or {})}), [C1, C2]),
               (EffectTerm("stribeck_breakaway", ("speed_m_s",)), [0.01, 0.02])],
        covariance=np.diag([1e-4, 1e-12, 1e-4, 1e-4, 1e-6, 1e-8]), noise_std_log=0.02,
        conditions=["relative_humidity", "temperature_C"])
    return CalibratedPhysicsModel("calibrated:test", calibrated)


ENVELOPE = robust.Envelope((0.01, 0.1), {"relative_humidity": (0.3, 0.7), "temperature_C": (20.0, 60.0)},
                           {"groove_angle_deg": 0.5})


def _grid_points(levels: int, extra=()):
    axes = ENVELOPE.axes()
    names = list(axes)
    values = [np.unique(np.r_[np.linspace(*axes[n], levels), [e for a, e in extra if a == n]]) for n in names]
    return [ENVELOPE.point(dict(zip(names, c, strict=True))) for c in itertools.product(*values)]


def _bracket(problem, model, design):
    pieces, reason = term_pieces(model)
    assert pieces is not None, reason

    def physics_mu(offset, speed):
        return physics.evaluate(convention=problem.convention, outputs=["mu"], **problem.physics_inputs(
            design["balls"], design["groove_angle_deg"] + offset, design["load_N"], speed_m_s=speed)).mu

    evaluate = evaluator(problem, ENVELOPE, model, "mu", design, 0.0)
    return certified_max(mu_box_bound(pieces, physics_mu, ENVELOPE, design), evaluate, ENVELOPE), evaluate


def _grid_at_the_worst_point(model, held, result, objective: str) -> np.ndarray:
    """``objective`` of every design of a 6 x 6 x 8 grid (3-8 balls, 40-60 deg, 1-50 mN) at the envelope
    point where the returned design is worst (groove-angle offset +0.5 deg)."""
    where = ENVELOPE.point({"speed_m_s": result.worst_case["speed_m_s"], "groove_angle_offset_deg": 0.5,
                            **{f"conditions.{n}": v for n, v in result.worst_case["conditions"].items()}})
    grid = list(itertools.product(range(3, 9), np.linspace(40, 60, 6), np.linspace(0.001, 0.05, 8)))
    designs = {"balls": np.array([g[0] for g in grid], dtype=float),
               "groove_angle_deg": np.array([g[1] for g in grid]), "load_N": np.array([g[2] for g in grid])}
    return objective_values(model, objective, envelope_columns(held, ENVELOPE, designs, [where], 0.0),
                                    held.convention)


def test_certified_worst_case_brackets_brute_force_inside_the_envelope():
    model = _model()
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    design = {"balls": 5.0, "groove_angle_deg": 45.0, "load_N": 0.01}
    bracket, evaluate = _bracket(problem, model, design)
    # The maximum is inside the envelope in temperature, at the quadratic's peak: no vertex reaches it.
    assert bracket.point["conditions"]["temperature_C"] == pytest.approx(PEAK_C, rel=1e-9)
    vertices = _grid_points(2)
    assert max(evaluate(vertices)) < bracket.value * (1 - 1e-3)
    # Brute force, a grid of 11 levels per axis with the peak temperature added: never above the certified
    # bound, and its maximum within the bracket's tolerance of the value found.
    brute = evaluate(_grid_points(11, extra=[("conditions.temperature_C", PEAK_C)]))
    assert brute.max() <= bracket.upper_bound
    assert brute.max() == pytest.approx(bracket.value, rel=1e-6)
    assert bracket.upper_bound <= bracket.value * (1 + 1e-6)
    # The value found is the model's own.
    assert float(evaluate([bracket.point])[0]) == pytest.approx(bracket.value, rel=1e-12)


def test_certified_worst_case_holds_where_the_quadratic_goes_on_along_its_tangent_beyond_its_data():
    # Temperature data at 20-42 C: the quadratic's peak (43.3 C) lies beyond them, where the term goes on
    # along its tangent (slope 0.2 - 0.6 x 0.2 = 0.08 per 10 C in log mu, rising): the worst temperature is
    # then the envelope's end, 60 C, and the declared stationary point is one value among the candidates, not
    # the peak.
    model = _model({"low": 20.0, "high": 42.0})
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                              Constraints()), model)
    design = {"balls": 5.0, "groove_angle_deg": 45.0, "load_N": 0.01}
    bracket, evaluate = _bracket(problem, model, design)
    assert bracket.point["conditions"]["temperature_C"] == pytest.approx(60.0)
    brute = evaluate(_grid_points(11, extra=[("conditions.temperature_C", PEAK_C)]))
    assert brute.max() <= bracket.upper_bound
    assert brute.max() == pytest.approx(bracket.value, rel=1e-6)


def test_robust_mu_with_non_monotone_terms_is_proven_and_no_grid_design_beats_the_bound():
    model = _model()
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu")
    proof = result.proof
    assert proof["method"] == "outer-approximation-certified"
    assert proof["proven"], proof["statement"]
    assert proof["relative_gap"] <= robust.GAP_TARGET
    assert proof["lower_bound"] <= result.worst_case["mu"] <= proof["upper_bound"]
    held = with_model_values(problem, model)
    # The worst case at the design against brute force through the same model.
    design = dict(result.result.design)
    evaluate = evaluator(held, ENVELOPE, model, "mu", design, 0.0)
    brute = evaluate(_grid_points(9, extra=[("conditions.temperature_C", PEAK_C)]))
    assert brute.max() <= proof["upper_bound"]
    assert brute.max() == pytest.approx(result.worst_case["mu"], rel=1e-6)
    # No design of a grid over the design box beats the certified lower bound: each one's mu at the worst
    # point found is already at least the bound.
    where = robust.Envelope.point(ENVELOPE, {"speed_m_s": result.worst_case["speed_m_s"],
                                             "groove_angle_offset_deg": 0.5,
                                             **{f"conditions.{n}": v
                                                for n, v in result.worst_case["conditions"].items()}})
    grid = list(itertools.product(range(3, 9), np.linspace(40, 60, 6), np.linspace(0.001, 0.05, 8)))
    designs = {"balls": np.array([g[0] for g in grid], dtype=float),
               "groove_angle_deg": np.array([g[1] for g in grid]), "load_N": np.array([g[2] for g in grid])}
    at_worst = objective_values(model, "mu", envelope_columns(held, ENVELOPE, designs, [where], 0.0),
                                        held.convention)
    assert at_worst.min() >= proof["lower_bound"] * (1 - 1e-9)


def test_structures_without_a_bound_say_why():
    unknown = types.SimpleNamespace(kind="other", label="a future kind of term")
    other = types.SimpleNamespace(reference="calibrated:o",
                                  calibrated=types.SimpleNamespace(terms=[(unknown, [1.0])], fitted={}))
    assert term_pieces(other)[0] is None and "no known bound" in term_pieces(other)[1]
    # a drift of a parameter in which the physics' monotonicity is not proven (a Poisson ratio)
    drift = types.SimpleNamespace(kind="drift", label="ball_poisson_ratio linear in temperature_C",
                                  parameter="ball_poisson_ratio")
    calibrated = types.SimpleNamespace(discrepancy=None, terms=[(drift, [1.0])], fitted={})
    drifting = types.SimpleNamespace(reference="calibrated:d", calibrated=calibrated)
    assert term_pieces(drifting)[0] is None and "monotonicity is not proven" in term_pieces(drifting)[1]
    # a proven direction: a drift piece, for mu and for mu_upper (its share of the physics in closed form)
    drift = types.SimpleNamespace(kind="drift", label="viscosity_Pa_s drifts with temperature_C",
                                  parameter="viscosity_Pa_s")
    calibrated = types.SimpleNamespace(discrepancy=None, terms=[(drift, [1.0])], fitted={})
    drifting = types.SimpleNamespace(reference="calibrated:d", calibrated=calibrated)
    assert [p.kind for p in term_pieces(drifting)[0]] == ["drift"]
    assert [p.kind for p in term_pieces(drifting, interval=True)[0]] == ["drift"]


def _interval_model() -> CalibratedPhysicsModel:
    """Fitted mu_pivot, menisci, the log-quadratic temperature term and a viscous drag, all uncertain."""
    calibrated = CalibratedModel(
        fitted={"mu_pivot": 0.6},
        terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5]),
               (EffectTerm("generic_quadratic", ("temperature_C",), {"centre": CENTRE, "scale": SCALE}),
                [C1, C2]),
               (EffectTerm("viscous_drag", ("speed_m_s", "load_N")), [1e-5])],
        covariance=np.diag([1e-4, 1e-12, 1e-4, 1e-4, 1e-12]), noise_std_log=0.02,
        conditions=["relative_humidity", "temperature_C"])
    return CalibratedPhysicsModel("calibrated:interval", calibrated)


def test_certified_mu_upper_bounds_brute_force_where_the_interval_peaks_inside():
    model = _interval_model()
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu_upper")
    proof = result.proof
    assert proof["method"] == "outer-approximation-certified" and proof["proven"], proof["statement"]
    held = with_model_values(problem, model)
    evaluate = evaluator(held, ENVELOPE, model, "mu_upper", dict(result.result.design), 0.0)
    # The interval widens away from the quadratic's centre: mu_upper peaks inside the temperature range, near
    # (not at) mu's peak; brute force on a grid refined around it never exceeds the certified bound.
    peak_c = result.worst_case["conditions"]["temperature_C"]
    assert 20.0 < peak_c < 60.0
    brute = evaluate(_grid_points(9, extra=[("conditions.temperature_C", t)
                                            for t in np.linspace(peak_c - 1, peak_c + 1, 41)]))
    assert brute.max() <= proof["upper_bound"]
    assert proof["upper_bound"] <= result.worst_case["mu_upper"] * (1 + 1e-5)
    assert brute.max() == pytest.approx(result.worst_case["mu_upper"], rel=1e-5)
    # The lower bound over the designs (optimize.design_bound) closes the gap; no design of a grid beats it at
    # the worst point.
    assert proof["relative_gap"] <= robust.GAP_TARGET
    at_worst = _grid_at_the_worst_point(model, held, result, "mu_upper")
    assert at_worst.min() >= proof["lower_bound"]


def test_a_value_without_a_bound_leaves_mu_upper_searched():
    model = _model()  # the Stribeck speed's effect on mu has no closed-form bound over a box here
    problem = DesignProblem(DesignBounds((3, 5), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu_upper", max_rounds=2)
    assert result.proof["method"] == "outer-approximation-local" and result.proof["proven"] is False
    assert "No proof" in result.proof["statement"]


def test_certified_mu_upper_holds_the_rivals_envelope():
    # A rival law of humidity (log-linear instead of the Kelvin menisci) whose interval is wider at high
    # humidity: mu_upper is the envelope of both, and the certified bound must hold it.
    from microbearing.calibrate.model import RivalModel

    rival = RivalModel("generic_linear on relative_humidity instead of humidity_meniscus", {"mu_pivot": 0.7},
                       [(EffectTerm("generic_linear", ("relative_humidity",), {"centre": 0.5, "scale": 0.1}),
                         [1.5])], np.diag([1e-3, 1e-2]))
    base = _interval_model().calibrated
    model = CalibratedPhysicsModel("calibrated:rivals", dataclasses.replace(base, rivals=[rival]))
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    structures, reason = interval_structures(model)
    assert structures is not None and len(structures) == 2, reason
    design = {"balls": 4.0, "groove_angle_deg": 50.0, "load_N": 0.005}
    bracket = certified_upper_search(problem, ENVELOPE, model, structures, design, 0.0)
    evaluate = evaluator(problem, ENVELOPE, model, "mu_upper", design, 0.0)
    brute = evaluate(_grid_points(7, extra=[("conditions.temperature_C", PEAK_C)]))
    assert brute.max() <= bracket.upper_bound <= bracket.value * (1 + 1e-5)
    assert brute.max() == pytest.approx(bracket.value, rel=1e-4)
    # the rival decides the worst case here: without it mu_upper is lower there
    alone = CalibratedPhysicsModel("calibrated:alone", base)
    without = evaluator(problem, ENVELOPE, alone, "mu_upper", design, 0.0)([bracket.point])[0]
    assert without < bracket.value


def test_a_bound_whose_premise_fails_is_caught_and_the_search_takes_over():
    # A box bound that ignores the physics (zero) is below the model everywhere: the check at the points
    # evaluated raises (optimize_robust then falls back to the searched outer approximation, unproven).
    from microbearing.optimize.envelope_bound import BoundFailedError

    def wrong(lo, hi):
        return np.zeros(len(lo)), hi

    model = _model()
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    evaluate = evaluator(problem, ENVELOPE, model, "mu", {"balls": 4.0, "groove_angle_deg": 50.0,
                                                                  "load_N": 0.005}, 0.0)
    with pytest.raises(BoundFailedError):
        certified_max(wrong, evaluate, ENVELOPE)


def test_a_part_the_bounds_do_not_know_is_refused():
    @dataclasses.dataclass(frozen=True)
    class Later:  # a calibrated model with a part added later (say, a scatter that depends on the inputs)
        terms: list = dataclasses.field(default_factory=list)
        discrepancy: object = None
        scatter_model: object = None

    plain = types.SimpleNamespace(reference="calibrated:later", calibrated=Later())
    assert term_pieces(plain)[0] == []
    later = types.SimpleNamespace(reference="calibrated:later",
                                  calibrated=Later(scatter_model={"slope": 1.0}))
    assert term_pieces(later)[0] is None and "scatter_model" in term_pieces(later)[1]


# --------------------------------------------------------------------------------------------------
# The data cloud's widening of the interval, bounded over a box


def test_cloud_score_bound_holds_every_point_of_a_box_and_closes_on_a_point():
    from microbearing.calibrate.domain import DataCloud

    rng = np.random.default_rng(3)
    speed = rng.uniform(0.005, 0.15, 200)
    cloud = DataCloud.from_columns({"speed_m_s": speed,
                                    "temperature_C": 25 + 300 * speed + rng.normal(0, 2, 200),
                                    "relative_humidity": rng.uniform(0.3, 0.6, 200)})
    names = ["speed_m_s", "temperature_C", "relative_humidity"]
    low = {"speed_m_s": np.array([0.01, 0.1, 0.12]), "temperature_C": np.array([20.0, 20.0, 70.0]),
           "relative_humidity": np.array([0.3, 0.6, 0.2])}
    width = {"speed_m_s": 0.02, "temperature_C": 15.0, "relative_humidity": 0.2}
    high = {n: low[n] + width[n] for n in names}
    bound = cloud.score_bound(low, high, (3,))
    least = cloud.score_lower_bound(low, high, (3,))
    # Brute force: 2,000 random points and every corner of each box, scored by the cloud itself.
    for box in range(3):
        samples = {n: rng.uniform(low[n][box], high[n][box], 2000) for n in names}
        corners = list(itertools.product(*[(low[n][box], high[n][box]) for n in names]))
        for i, n in enumerate(names):
            samples[n] = np.r_[samples[n], [c[i] for c in corners]]
        scores, _ = cloud.score(samples, (2008,))
        assert least[box] <= scores.min() and scores.max() <= bound[box]
        # a loose bound of a wide box, but a bound: within the box's scaled half-diagonal of the best
        assert bound[box] < scores.max() + 3.0
    # A box of one point: the bound is the score itself (to rounding); a small box, close to it.
    point = {n: low[n][:1] for n in names}
    assert cloud.score_bound(point, point, (1,))[0] == pytest.approx(cloud.score(point, (1,))[0][0], rel=1e-9)
    assert cloud.score_lower_bound(point, point, (1,))[0] == pytest.approx(cloud.score(point, (1,))[0][0],
                                                                           rel=1e-9)
    small = {n: low[n][:1] + 1e-6 * width[n] for n in names}
    assert cloud.score_bound(point, small, (1,))[0] == pytest.approx(cloud.score(point, (1,))[0][0], rel=1e-4)
    # The widening is the one rule of the model's interval: max(ratio, 1), non-decreasing.
    ratios = np.linspace(0, 4, 41)
    assert np.all(np.diff(cloud.widening(ratios)) >= 0) and cloud.widening(0.5) == 1.0
    assert cloud.widening(2.5) == 2.5


def _cloud_model(together: bool = True) -> CalibratedPhysicsModel:
    """The interval model with a data cloud: calibration rows at low speed and humidity rising together
    (or, ``together`` false, humidity 30-50 % whatever the speed), temperatures 30-50 C, so the envelope's
    far corners lie well beyond the data."""
    from microbearing.calibrate.domain import DataCloud

    rng = np.random.default_rng(11)
    n = 120
    speed = rng.uniform(0.01, 0.05, n)
    humidity = 0.3 + 5 * (speed - 0.01) + rng.normal(0, 0.02, n) if together else rng.uniform(0.3, 0.5, n)
    columns = {"balls": rng.choice([3.0, 5.0, 8.0], n), "groove_angle_deg": rng.choice([45.0, 50.0, 55.0], n),
               "load_N": rng.choice([0.005, 0.01, 0.02], n), "speed_m_s": speed,
               "relative_humidity": humidity, "temperature_C": rng.uniform(30.0, 50.0, n)}
    cloud = DataCloud.from_columns(columns)
    return CalibratedPhysicsModel("calibrated:cloud", dataclasses.replace(_interval_model().calibrated,
                                                                          cloud=cloud))


def test_certified_mu_upper_bounds_the_cloud_widening_against_brute_force():
    model = _cloud_model(together=False)
    structures, reason = interval_structures(model)
    assert structures is not None, reason
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    design = {"balls": 5.0, "groove_angle_deg": 50.0, "load_N": 0.01}
    bracket = certified_upper_search(problem, ENVELOPE, model, structures, design, 0.0)
    # The bracket closes to about its 1e-5 target (the box limit may stop it a little short: it says so).
    assert bracket.upper_bound <= bracket.value * (1 + 2e-5)
    assert bracket.relative_gap <= 1e-5 or not bracket.complete
    evaluate = evaluator(problem, ENVELOPE, model, "mu_upper", design, 0.0)
    # The worst case lies beyond the data cloud (its interval widened there) and inside the envelope in
    # temperature (the quadratic's peak and the cloud's distance trade off): no vertex reaches it.
    where = bracket.point
    columns = envelope_columns(problem, ENVELOPE, {k: np.array([v]) for k, v in design.items()}, [where], 0.0)
    held = {*model.fixed, *model.fitted}
    ratio = model.calibrated.cloud_ratio({k: v for k, v in columns.items() if k not in held})
    assert ratio[0] > 1.5
    assert 20.0 < where["conditions"]["temperature_C"] < 60.0
    assert max(evaluate(_grid_points(2))) < bracket.value * (1 - 1e-3)
    # Brute force through the same model: a grid of 9 levels per axis and a fine one around the point found
    # (not the point itself); never above the certified bound, and its best within 1e-4 of the value found.
    axes = ENVELOPE.axes()
    local = [ENVELOPE.point({n: float(np.clip(where_value + d, *axes[n]))
                             for (n, where_value), d in zip(_axis_values(where).items(), delta, strict=True)})
             for delta in itertools.product(*[np.linspace(-0.02, 0.02, 5) * (axes[n][1] - axes[n][0])
                                              for n in axes])]
    brute = evaluate(_grid_points(9) + local)
    assert brute.max() <= bracket.upper_bound
    assert brute.max() == pytest.approx(bracket.value, rel=1e-4)
    # Without the widening the bound would fall below the model there: the cloud decides the worst case.
    plain = CalibratedPhysicsModel("calibrated:plain", dataclasses.replace(model.calibrated, cloud=None))
    assert evaluator(problem, ENVELOPE, plain, "mu_upper", design, 0.0)([where])[0] < bracket.value


def _axis_values(point):
    values = {"speed_m_s": point["speed_m_s"]}
    values.update({f"conditions.{n}": v for n, v in point["conditions"].items()})
    values["groove_angle_offset_deg"] = point["groove_angle_offset_deg"]
    return {n: values[n] for n in ENVELOPE.axes()}


def test_robust_mu_upper_of_a_model_with_a_cloud_is_certified_at_its_design():
    model = _cloud_model()
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu_upper")
    proof = result.proof
    assert proof["method"] == "outer-approximation-certified", proof["statement"]
    assert "cloud" in proof["statement"]
    held = with_model_values(problem, model)
    evaluate = evaluator(held, ENVELOPE, model, "mu_upper", dict(result.result.design), 0.0)
    brute = evaluate(_grid_points(7))
    assert brute.max() <= proof["upper_bound"] <= result.worst_case["mu_upper"] * (1 + 1e-5)
    # The lower bound over designs (the cloud's least widening over the design box at the worst point in
    # it): no design of a grid has a smaller mu_upper there.
    assert proof["lower_bound"] is not None
    at_worst = _grid_at_the_worst_point(model, held, result, "mu_upper")
    assert at_worst.min() >= proof["lower_bound"]


# --------------------------------------------------------------------------------------------------
# Drifting physics parameters and group effects


def test_the_physics_moves_with_every_drifting_parameter_in_its_stated_direction():
    from microbearing.physics.effects import PARAMETER_SHARES

    # Designs, speeds and both conventions; each parameter from a fifth to five times its default.
    grid = list(itertools.product([1.0, 2.0, 3.0, 8.0, 30.0], [30.0, 45.0, 60.0, 80.0], [1e-4, 0.01, 1.0],
                                  [1e-3, 0.1]))
    columns = {name: np.array([g[i] for g in grid]) for i, name in
               enumerate(["balls", "groove_angle_deg", "load_N", "speed_m_s"])}
    factors = np.geomspace(0.2, 5.0, 9)
    for convention in physics.CONVENTIONS:
        for name, direction in ((n, s.direction) for n, s in PARAMETER_SHARES.items()):
            default = physics.defaults()[name]
            spec = physics.PARAMETERS[name]
            values = [v for v in default * factors if spec.maximum is None or v < spec.maximum]
            mu = np.array([physics.evaluate(convention=convention, outputs=["mu"], **columns,
                                            **{name: v}).mu for v in values])
            steps = direction * np.diff(mu, axis=0)
            assert np.all(steps >= -1e-12 * mu[1:]), (convention, name)


def _drift_model() -> CalibratedPhysicsModel:
    """Viscosity falling with temperature (Arrhenius, a strong film) and a log-quadratic in humidity peaking
    inside the range: mu's worst case at the lowest temperature and inside the humidity range."""
    from microbearing.calibrate.candidates import DriftTerm
    from microbearing.physics.effects import DRIFT_LAWS

    constants = DRIFT_LAWS["arrhenius"].constants("temperature_C", [20.0, 40.0, 60.0])
    drift = DriftTerm("viscosity_Pa_s", "arrhenius", "temperature_C", constants)
    calibrated = CalibratedModel(
        fitted={"mu_pivot": 0.6}, fixed={"viscosity_Pa_s": 0.05},
        terms=[(drift, [3e4]),
               (EffectTerm("generic_quadratic", ("relative_humidity",), {"centre": 0.5, "scale": 0.1}),
                [0.1, -0.2])],
        covariance=np.diag([1e-4, 1e4, 1e-4, 1e-4]), noise_std_log=0.02,
        conditions=["relative_humidity", "temperature_C"])
    return CalibratedPhysicsModel("calibrated:drift", calibrated)


def test_certified_worst_case_with_a_drifting_viscosity_brackets_brute_force():
    model = _drift_model()
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    design = {"balls": 5.0, "groove_angle_deg": 45.0, "load_N": 0.002}
    bracket = certified_search(problem, ENVELOPE, model, term_pieces(model)[0], design, 0.0)
    evaluate = evaluator(problem, ENVELOPE, model, "mu", design, 0.0)
    # By hand: the quadratic peaks at 0.5 - 0.1 x 0.1 / (2 x -0.2) = 0.525; viscosity is highest when cold.
    peak_h = 0.5 - 0.1 * 0.1 / (2 * -0.2)
    assert bracket.point["conditions"]["relative_humidity"] == pytest.approx(peak_h, rel=1e-9)
    assert bracket.point["conditions"]["temperature_C"] == 20.0
    # the drift matters: the same point warm is lower
    warm = ENVELOPE.point({"speed_m_s": bracket.point["speed_m_s"], "conditions.relative_humidity": peak_h,
                           "conditions.temperature_C": 60.0, "groove_angle_offset_deg": 0.5})
    assert evaluate([warm])[0] < bracket.value * (1 - 1e-3)
    brute = evaluate(_grid_points(11, extra=[("conditions.relative_humidity", peak_h)]))
    assert brute.max() <= bracket.upper_bound <= bracket.value * (1 + 1e-6)
    assert brute.max() == pytest.approx(bracket.value, rel=1e-6)


def test_robust_mu_with_a_drift_is_proven_and_no_grid_design_beats_the_bound():
    model = _drift_model()
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu")
    proof = result.proof
    assert proof["method"] == "outer-approximation-certified" and proof["proven"], proof["statement"]
    held = with_model_values(problem, model)
    evaluate = evaluator(held, ENVELOPE, model, "mu", dict(result.result.design), 0.0)
    assert evaluate(_grid_points(7)).max() <= proof["upper_bound"]
    # Every design of a grid has mu at the worst point at least the certified lower bound.
    at_worst = _grid_at_the_worst_point(model, held, result, "mu")
    assert at_worst.min() >= proof["lower_bound"] * (1 - 1e-9)
    # the nominal design's worst case in the price of robustness is certified too
    nominal = result.price_of_robustness["nominal"]
    assert nominal["worst_case_certified"] is True
    nominal_eval = evaluator(held, ENVELOPE, model, "mu", nominal["design"], 0.0)
    assert nominal_eval(_grid_points(7)).max() <= nominal["worst_case_upper_bound"]
    assert nominal["worst_case_upper_bound"] <= nominal["worst_case"] * (1 + 1e-6)


def _groups(fitted_parameter: bool = True):
    from microbearing.calibrate.groups import GroupEffect

    # Six specimens and six builds: a new one's variance is the spread^2 (1 + 1/6) (t_5 / z)^2.
    out = [GroupEffect("specimen", "mu", 0.05, (0.03, 0.1), 0.03,
                       {str(i): [0.01 * (i - 2.5), 1e-4, 10.0] for i in range(6)})]
    if fitted_parameter:
        out.append(GroupEffect("build", "mu_pivot", 0.05, (0.03, 0.1), 0.04,
                               {f"b{i}": [0.01 * (i - 2.5), 1e-4, 8.0] for i in range(6)}))
    return out


def test_certified_mu_upper_with_groups_bounds_brute_force():
    base = _interval_model().calibrated
    model = CalibratedPhysicsModel("calibrated:groups", dataclasses.replace(base, groups=_groups()))
    structures, reason = interval_structures(model)
    assert structures is not None, reason
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    design = {"balls": 4.0, "groove_angle_deg": 50.0, "load_N": 0.005}
    bracket = certified_upper_search(problem, ENVELOPE, model, structures, design, 0.0)
    evaluate = evaluator(problem, ENVELOPE, model, "mu_upper", design, 0.0)
    brute = evaluate(_grid_points(7, extra=[("conditions.temperature_C", bracket.point["conditions"][
        "temperature_C"])]))
    assert brute.max() <= bracket.upper_bound <= bracket.value * (1 + 2e-5)
    assert brute.max() == pytest.approx(bracket.value, rel=1e-4)
    # the groups decide the worst case: without them mu_upper is lower there
    plain = evaluator(problem, ENVELOPE, _interval_model(), "mu_upper", design, 0.0)
    assert plain([bracket.point])[0] < bracket.value * (1 - 1e-3)


def test_robust_mu_with_a_group_on_mu_is_proven_and_one_on_a_fitted_parameter_is_said_to_be_unbounded():
    base = _model().calibrated
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    model = CalibratedPhysicsModel("calibrated:groups", dataclasses.replace(base, groups=_groups(False)))
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu")
    assert result.proof["method"] == "outer-approximation-certified" and result.proof["proven"]
    held = with_model_values(problem, model)
    evaluate = evaluator(held, ENVELOPE, model, "mu", dict(result.result.design), 0.0)
    brute = evaluate(_grid_points(9, extra=[("conditions.temperature_C", PEAK_C)]))
    assert brute.max() <= result.proof["upper_bound"]
    assert brute.max() == pytest.approx(result.worst_case["mu"], rel=1e-6)
    # the group's offset moves mu by exp(0.03) at every point that names no group
    alone = robust.optimize_robust(problem, ENVELOPE, _model(), objective="mu")
    assert result.worst_case["mu"] == pytest.approx(alone.worst_case["mu"] * np.exp(0.03), rel=1e-6)
    both = CalibratedPhysicsModel("calibrated:both", dataclasses.replace(base, groups=_groups()))
    pieces, reason = term_pieces(both)
    assert pieces is None and "mu_pivot" in reason


# --------------------------------------------------------------------------------------------------
# A Gaussian-process discrepancy


def _gp_state(features=("temperature_C", "relative_humidity"), seed=5):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(30, len(features)))
    y = 0.05 * np.sin(1.5 * x[:, 0]) + 0.02 * x[:, -1]
    centre = {"temperature_C": 40.0, "relative_humidity": 0.5, "load_N": 0.01}
    scale = {"temperature_C": 10.0, "relative_humidity": 0.1, "load_N": 0.005}
    return {"features": list(features), "centre": [centre[f] for f in features],
            "scale": [scale[f] for f in features], "length_scale": [0.7] * len(features),
            "amplitude": 0.004, "noise": 1e-4, "x": x.tolist(), "y": y.tolist()}


def _gp_model(features=("temperature_C", "relative_humidity")) -> CalibratedPhysicsModel:
    from microbearing.calibrate.model import GPCorrection

    base = _interval_model().calibrated
    return CalibratedPhysicsModel("calibrated:gp", dataclasses.replace(
        base, discrepancy=GPCorrection(_gp_state(features))))


def test_gp_bounds_hold_every_point_of_a_box_and_close_on_a_point():
    from microbearing.calibrate.model import GPCorrection

    gp = GPCorrection(_gp_state())
    rng = np.random.default_rng(2)
    low = {"temperature_C": np.array([20.0, 35.0, 45.0]), "relative_humidity": np.array([0.3, 0.45, 0.6])}
    width = {"temperature_C": np.array([40.0, 5.0, 1.0]), "relative_humidity": np.array([0.4, 0.1, 0.01])}
    high = {n: low[n] + width[n] for n in low}
    mean_lo, mean_hi, var_hi = gp.bound(low, high, (3,))
    for box in range(3):
        samples = {n: rng.uniform(low[n][box], high[n][box], 3000) for n in low}
        mean, variance = gp(samples, (3000,))
        assert mean_lo[box] <= mean.min() and mean.max() <= mean_hi[box]
        assert variance.max() <= var_hi[box]
    # a box of one point: the GP's own mean and variance (to rounding); a small box, close to them
    point = {n: low[n][1:2] for n in low}
    mean, variance = gp(point, (1,))
    bounds = gp.bound(point, point, (1,))
    assert bounds[0][0] == pytest.approx(mean[0], abs=1e-10)
    assert bounds[1][0] == pytest.approx(mean[0], abs=1e-10)
    assert bounds[2][0] == pytest.approx(variance[0], rel=1e-6, abs=1e-12)
    small = {n: point[n] + 1e-5 * width[n][1] for n in low}
    assert gp.bound(point, small, (1,))[1][0] == pytest.approx(mean[0], abs=1e-5)


def test_certified_worst_case_with_a_gp_discrepancy_brackets_brute_force_for_mu_and_mu_upper():
    model = _gp_model()
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    design = {"balls": 5.0, "groove_angle_deg": 45.0, "load_N": 0.01}
    pieces, reason = term_pieces(model)
    assert pieces is not None, reason
    structures, reason = interval_structures(model)
    assert structures is not None, reason
    for objective, bracket in [
            ("mu", certified_search(problem, ENVELOPE, model, pieces, design, 0.0)),
            ("mu_upper", certified_upper_search(problem, ENVELOPE, model, structures, design, 0.0))]:
        evaluate = evaluator(problem, ENVELOPE, model, objective, design, 0.0)
        # Here the GP's mean and the quadratic term slope opposite ways at the worst temperature: bounded
        # factor by factor, a box's bound exceeds the value by their slopes times its width, and the branch
        # and bound stops at its box limit with the bracket it has (said: complete False, and its gap).
        tolerance = bracket.relative_gap
        assert tolerance <= 1e-2 and (bracket.complete or bracket.boxes >= 20000)
        # inside the envelope in temperature (the GP's and the quadratic's bumps), at no vertex
        assert 20.0 < bracket.point["conditions"]["temperature_C"] < 60.0
        assert max(evaluate(_grid_points(2))) < bracket.value * (1 - 1e-4)
        t = bracket.point["conditions"]["temperature_C"]
        brute = evaluate(_grid_points(9, extra=[("conditions.temperature_C", x)
                                                for x in np.linspace(t - 0.5, t + 0.5, 41)]))
        assert brute.max() <= bracket.upper_bound
        assert brute.max() == pytest.approx(bracket.value, rel=1e-5)
        # the bracket's stated gap: upper = value / (1 - gap)
        assert bracket.upper_bound <= max(brute.max(), bracket.value) / (1 - tolerance) * (1 + 1e-9)
        # the discrepancy decides it: without it the worst case is elsewhere or lower
        plain = evaluator(problem, ENVELOPE, _interval_model(), objective, design, 0.0)
        assert abs(plain([bracket.point])[0] / bracket.value - 1) > 1e-4


def test_robust_mu_with_a_gp_is_certified_at_its_design_and_no_grid_design_beats_the_lower_bound():
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    # The GP reads conditions only: every design's mu at a point has the same factor, so the lower bound over
    # designs is tight (to 1e-6 of the worst case found); the proof's gap is then the bracket's at the design.
    result = robust.optimize_robust(problem, ENVELOPE, _gp_model(), objective="mu")
    proof = result.proof
    assert proof["method"] == "outer-approximation-certified"
    assert proof["lower_bound"] >= result.worst_case["mu"] * (1 - 1e-6)
    assert proof["relative_gap"] == pytest.approx(proof["worst_case_relative_gap"], abs=2e-6)
    assert proof["proven"] == (proof["relative_gap"] <= robust.GAP_TARGET)
    held = with_model_values(problem, _gp_model())
    evaluate = evaluator(held, ENVELOPE, _gp_model(), "mu", dict(result.result.design), 0.0)
    assert evaluate(_grid_points(7)).max() <= proof["upper_bound"]
    # A GP reading the load too: the worst case at the design is still certified; the lower bound over
    # designs takes the GP's least mean over the whole design box, and no grid design beats it.
    model = _gp_model(("temperature_C", "load_N"))
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu")
    proof = result.proof
    assert proof["method"] == "outer-approximation-certified" and proof["worst_case_relative_gap"] < 5e-3
    held = with_model_values(problem, model)
    at_worst = _grid_at_the_worst_point(model, held, result, "mu")
    assert proof["lower_bound"] is not None and at_worst.min() >= proof["lower_bound"]


def _drift_interval_model() -> CalibratedPhysicsModel:
    """Two drifts with uncertain coefficients (the viscosity by Arrhenius in temperature, the fitted mu_pivot
    linear in humidity) and a log-quadratic in temperature: mu_upper's worst case inside the envelope."""
    from microbearing.calibrate.candidates import DriftTerm
    from microbearing.physics.effects import DRIFT_LAWS

    viscosity = DriftTerm("viscosity_Pa_s", "arrhenius", "temperature_C",
                          DRIFT_LAWS["arrhenius"].constants("temperature_C", [20.0, 40.0, 60.0]))
    pivot = DriftTerm("mu_pivot", "linear", "relative_humidity",
                      DRIFT_LAWS["linear"].constants("relative_humidity", [0.3, 0.5, 0.7]))
    calibrated = CalibratedModel(
        fitted={"mu_pivot": 0.6}, fixed={"viscosity_Pa_s": 0.05},
        terms=[(viscosity, [3e4]), (pivot, [0.5]),
               (EffectTerm("generic_quadratic", ("temperature_C",), {"centre": CENTRE, "scale": SCALE}),
                [C1, C2])],
        covariance=np.diag([1e-4, 1e6, 1e-2, 1e-4, 1e-4]), noise_std_log=0.02,
        conditions=["relative_humidity", "temperature_C"])
    return CalibratedPhysicsModel("calibrated:drifts", calibrated)


def test_certified_mu_upper_with_drifting_parameters_bounds_brute_force():
    from microbearing.physics.effects import PARAMETER_SHARES

    model = _drift_interval_model()
    structures, reason = interval_structures(model)
    assert structures is not None, reason
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    design = {"balls": 4.0, "groove_angle_deg": 50.0, "load_N": 0.003}
    bracket = certified_upper_search(problem, ENVELOPE, model, structures, design, 0.0)
    evaluate = evaluator(problem, ENVELOPE, model, "mu_upper", design, 0.0)
    # The drift and the quadratic slope opposite ways in temperature at the worst point: factor by factor the
    # bracket closes linearly with the box, and stops at the box limit with its gap stated.
    assert bracket.relative_gap <= 1e-3 and (bracket.complete or bracket.boxes >= 20000)
    assert 20.0 < bracket.point["conditions"]["temperature_C"] < 60.0
    t = bracket.point["conditions"]["temperature_C"]
    brute = evaluate(_grid_points(9, extra=[("conditions.temperature_C", x)
                                            for x in np.linspace(t - 1, t + 1, 41)]))
    assert brute.max() <= bracket.upper_bound
    assert brute.max() == pytest.approx(bracket.value, rel=2e-5)
    assert bracket.upper_bound <= max(brute.max(), bracket.value) / (1 - bracket.relative_gap) * (1 + 1e-9)
    # the drifts' coefficients widen the interval: with their variances zero mu_upper is lower there
    narrow = dataclasses.replace(model.calibrated, covariance=np.diag([1e-4, 0.0, 0.0, 1e-4, 1e-4]))
    plain = evaluator(problem, ENVELOPE, CalibratedPhysicsModel("n", narrow), "mu_upper", design, 0.0)
    assert plain([bracket.point])[0] < bracket.value * (1 - 1e-3)
    # the shares' exponents are the physics' own: the rolling force grows as viscosity^0.66 (eq 9)
    columns = {"balls": 4.0, "groove_angle_deg": 50.0, "load_N": 0.003, "speed_m_s": 0.05}
    output, exponent = PARAMETER_SHARES["viscosity_Pa_s"].output, PARAMETER_SHARES["viscosity_Pa_s"].exponent
    shares = [float(getattr(physics.evaluate(outputs=[output], **columns, viscosity_Pa_s=v), output))
              for v in (0.01, 0.02)]
    assert shares[1] / shares[0] == pytest.approx(2.0**exponent, rel=1e-12)
    # a drift of a Young's modulus: its share has no closed form, said (the adhesion energy's, through the
    # contact load, has: tests/test_optimize_contact_load.py)
    modulus = types.SimpleNamespace(kind="drift", label="ball_youngs_modulus_Pa drifts with temperature_C",
                                    parameter="ball_youngs_modulus_Pa")
    holder = types.SimpleNamespace(reference="calibrated:a", calibrated=types.SimpleNamespace(
        terms=[(modulus, [1.0])], fitted={}))
    assert term_pieces(holder)[0] is not None
    assert term_pieces(holder, interval=True)[0] is None and "modulus" in term_pieces(holder, True)[1]


def test_the_departure_from_a_line_of_columns_moving_together_is_bounded_over_boxes():
    # Speed and humidity rise together in the rows: a point off their line is off the data, and the
    # interval widens by its departure, which is linear in the two scaled columns; so its range over a box
    # is exact at the corners, and the certified worst case holds above a brute-force grid.
    model = _cloud_model(together=True)
    cloud = model.calibrated.cloud
    low = {"speed_m_s": np.array([0.02, 0.09]), "relative_humidity": np.array([0.3, 0.3]),
           "temperature_C": np.array([35.0, 35.0])}
    high = {"speed_m_s": np.array([0.03, 0.1]), "relative_humidity": np.array([0.4, 0.35]),
            "temperature_C": np.array([40.0, 40.0])}
    upper, lower = cloud.score_bound(low, high, (2,)), cloud.score_lower_bound(low, high, (2,))
    grid = [np.linspace(low[c][:, None], high[c][:, None], 7, axis=1) for c in low]
    mesh = [np.stack(np.meshgrid(*[g[b, :, 0] for g in grid], indexing="ij"), axis=-1).reshape(-1, 3)
            for b in range(2)]
    for b in range(2):
        points = {c: mesh[b][:, i] for i, c in enumerate(low)}
        ratio, _ = cloud.score(points, (mesh[b].shape[0],))
        assert lower[b] <= ratio.min() and ratio.max() <= upper[b]
    assert lower[1] > 1  # fast and dry: off the line, flagged whatever the box's point
    structures, reason = interval_structures(model)
    assert structures is not None, reason
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    design = {"balls": 5.0, "groove_angle_deg": 50.0, "load_N": 0.01}
    bracket = certified_upper_search(problem, ENVELOPE, model, structures, design, 0.0)
    evaluate = evaluator(problem, ENVELOPE, model, "mu_upper", design, 0.0)
    brute = evaluate(_grid_points(9))
    assert brute.max() <= bracket.upper_bound and brute.max() <= bracket.value * (1 + 1e-9)
    assert bracket.value <= bracket.upper_bound


@pytest.mark.parametrize("over_design_boxes", [True, False])
def test_the_lower_bound_of_mu_upper_takes_the_clouds_least_widening_and_no_grid_design_beats_it(
        over_design_boxes, monkeypatch):
    # Menisci alone: mu's worst case is one vertex (geometric programming), and there the data cloud (rows at
    # low speed) is far from every design: every design's interval is widened at least by the least ratio.
    # Both lower bounds take it: the branch and bound over design boxes (optimize.design_bound) and, where
    # that one does not apply, the noise floor times the proven least mu times the least widening.
    from microbearing.calibrate.domain import DataCloud

    base = _cloud_model().calibrated
    meniscus = CalibratedModel(fitted={"mu_pivot": 0.6},
                               terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5])],
                               covariance=np.diag([1e-4, 1e-12]), noise_std_log=0.02,
                               conditions=["relative_humidity", "temperature_C"], cloud=base.cloud)
    assert isinstance(meniscus.cloud, DataCloud)
    model = CalibratedPhysicsModel("calibrated:meniscus-cloud", meniscus)
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05, Constraints())
    if not over_design_boxes:
        monkeypatch.setattr(certificates, "with_design_bound", lambda *args: "switched off in this test")
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu_upper")
    proof = result.proof
    if over_design_boxes:
        # tight from below; the worst case at the design (the interval widened off the line along which
        # speed and humidity move in the rows) is bracketed to the box limit, which sets the gap
        assert "the data cloud's widening of sigma at least" in proof["statement"]
        assert proof["upper_bound_certified"] and proof["relative_gap"] <= 1e-3
    else:
        assert "the data cloud's least widening there" in proof["statement"]
    held = with_model_values(problem, model)
    vertex = ENVELOPE.point({"speed_m_s": 0.1, "conditions.relative_humidity": 0.7,
                             "conditions.temperature_C": 20.0, "groove_angle_offset_deg": 0.5})
    grid = list(itertools.product(range(3, 9), np.linspace(40, 60, 6), np.geomspace(0.001, 0.05, 8)))
    designs = {"balls": np.array([g[0] for g in grid], dtype=float),
               "groove_angle_deg": np.array([g[1] for g in grid]), "load_N": np.array([g[2] for g in grid])}
    # Each grid design's worst case over a grid of the envelope (and the vertex) is at least the bound.
    points = [vertex, *_grid_points(3)]
    columns = envelope_columns(held, ENVELOPE, designs, points, 0.0)
    values = objective_values(model, "mu_upper", columns, held.convention)
    worst = np.asarray(values, dtype=float).reshape(len(points), len(grid)).max(axis=0)
    assert worst.min() >= proof["lower_bound"]
    # and the bound is above the scatter's alone (exp(1.96 x 0.02) times the proven least worst mu)
    least_mu = robust.optimize_robust(problem, ENVELOPE, model, objective="mu").proof["lower_bound"]
    assert proof["lower_bound"] > least_mu * np.exp(1.96 * 0.02) * (1 + 1e-3)


def test_a_bracket_run_in_stages_is_the_one_run_box_for_box():
    # A robust design's rounds bracket each design first to a share of the boxes and then on to the limit
    # (optimize.robust_outer): the second run continues the first, so the bracket is the same, to the bit,
    # as one run to the limit; the first run's bracket is wider and holds the final one.
    model = _interval_model()
    problem = with_model_values(DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                                                      Constraints()), model)
    structures, reason = interval_structures(model)
    assert structures is not None, reason
    design = {"balls": 4.0, "groove_angle_deg": 50.0, "load_N": 0.005}
    whole = certified_upper_search(problem, ENVELOPE, model, structures, design, 0.0)
    staged = certificates.upper_bracket(problem, ENVELOPE, model, structures, design, 0.0)
    first = staged.run(2000, final=False)
    assert first.boxes < whole.boxes and not first.complete
    assert first.upper_bound >= whole.upper_bound and first.value <= whole.value
    assert staged.run(2000, final=False) == first  # asked again at the same share: nothing more is done
    last = staged.run()
    assert (last.value, last.upper_bound, last.boxes, last.complete) == (
        whole.value, whole.upper_bound, whole.boxes, whole.complete)
    assert last.point == whole.point
    assert staged.run(10) is last  # a final bracket stands


def test_a_bound_loose_in_one_axis_closes_by_halving_that_axis():
    # f peaks inside the temperature range, where a rising and a falling factor balance; the bound takes
    # each factor's own maximum over the box, so it over-estimates by about the box's width in temperature
    # alone (first order) and is exact in the other three axes. Halving the widest axis in turn left a gap
    # of 0.16 after 20,000 boxes (each temperature halving near the peak paid for halvings of the three
    # other axes); halving where the bound has fallen most (AxisCosts) closes it to 1e-3 in a few thousand.
    a, b, t0 = 0.05, 0.001, 20.0
    j = list(ENVELOPE.axes()).index("conditions.temperature_C")

    def f(t):
        return np.exp(a * (t - t0) - b * (t - t0) ** 2)

    def bound(lo, hi):
        rising = np.exp(a * (hi[:, j] - t0))
        falling = np.exp(-b * (lo[:, j] - t0) ** 2)  # (t - t0)^2 is least at the box's low end
        return rising * falling * (1 + 1e-12), 0.5 * (lo + hi)

    def evaluate(points):
        return f(np.array([p["conditions"]["temperature_C"] for p in points]))

    bracket = certified_max(bound, evaluate, ENVELOPE, rtol=1e-3, max_boxes=20000)
    brute = f(np.linspace(20.0, 60.0, 400001)).max()  # the peak at t0 + a / (2 b) = 45 C
    assert bracket.complete and bracket.boxes < 6000, bracket.boxes
    assert bracket.value <= brute * (1 + 1e-12) and bracket.upper_bound >= brute * (1 - 1e-12)
    assert bracket.upper_bound <= bracket.value * (1 + 1e-3)


def _balanced_toy(order):
    """A peak inside the temperature range where a rise and a fall balance, with a box bound of the given
    order in the box's temperature width: 1, each factor at its own maximum; 2, the value at the box's
    centre plus the largest slope there times the half-width plus half the largest curvature times its
    square (a Taylor bound, exact to second order at the peak)."""
    a, b, t0 = 0.05, 0.001, 20.0
    j = list(ENVELOPE.axes()).index("conditions.temperature_C")

    def log_f(t):
        return a * (t - t0) - b * (t - t0) ** 2

    def bound(lo, hi):
        if order == 1:
            upper = np.exp(a * (hi[:, j] - t0) - b * (lo[:, j] - t0) ** 2)
        else:
            c, h = 0.5 * (lo[:, j] + hi[:, j]), 0.5 * (hi[:, j] - lo[:, j])
            upper = np.exp(log_f(c) + np.abs(a - 2 * b * (c - t0)) * h)  # log f is concave: tangent bound
        return upper * (1 + 1e-12), 0.5 * (lo + hi)

    def evaluate(points):
        return np.exp(log_f(np.array([p["conditions"]["temperature_C"] for p in points])))

    return bound, evaluate


def test_a_bracket_stopped_open_says_how_it_was_narrowing():
    # A bound exact only to first order narrows the gap as a power of the boxes: with the peak curved in one
    # axis the boxes left open are those within ~w of the peak's value, ~w^(-1/2) of them at width w, so the
    # gap ~ w narrows at order 2 (Narrowing's docstring). The order read at the stop predicts the gap
    # further on; the words say which limit stopped it and what a power law means. A bound exact to second
    # order at the peak (the tangent of the concave log) closes geometrically, in a thousand boxes to 1e-12.
    bound, evaluate = _balanced_toy(1)
    staged = BranchAndBound(bound, evaluate, ENVELOPE, rtol=1e-12)
    early = staged.run(3000, final=False)
    assert not early.complete and early.narrowing.limit == "box limit"
    assert 1.5 < early.narrowing.order < 2.6, early.narrowing
    late = staged.run(12000, final=False)
    predicted = early.narrowing.gap * (early.boxes / late.boxes) ** early.narrowing.order
    assert predicted / 3 < late.narrowing.gap < predicted * 3, (predicted, late.narrowing)
    words = early.stopped_words()
    assert words.startswith(", stopped at the box limit: the relative gap went from")
    assert "first order" in words
    assert early.narrowing.boxes_to_close > 12000
    tangent = BranchAndBound(*_balanced_toy(2), ENVELOPE, rtol=1e-12).run(3000, final=False)
    assert tangent.complete and tangent.stopped_words() == "" and tangent.boxes < early.boxes
    timed = BranchAndBound(bound, evaluate, ENVELOPE, rtol=1e-12).run(time_limit_s=0.0)
    assert timed.stopped_words().startswith(", stopped at the time limit")


def test_axis_costs_halve_a_flat_axis_never_and_an_untried_one_first():
    costs = AxisCosts(3)
    widths = np.array([[0.5, 1.0, 0.0], [0.5, 0.25, 0.0]])
    assert costs.choose(widths).tolist() == [1, 0]  # nothing learnt: the widest, never the flat third
    costs.learn(np.array([1]), np.array([1.0]), np.array([2.0]), np.array([1.9]))  # rate 0.05 per width
    assert costs.choose(widths).tolist() == [0, 0]  # axis 0 untried: tried first
    costs.learn(np.array([0]), np.array([0.5]), np.array([2.0]), np.array([2.0]))  # no fall: rate 0
    assert costs.choose(widths).tolist() == [1, 1]
    # a bound that rose on halving (rounding) or was infinite teaches nothing wrong
    costs.learn(np.array([1, 1]), np.array([0.5, 0.5]), np.array([1.0, np.inf]), np.array([1.1, 1.0]))
    assert costs.choose(widths).tolist() == [1, 1]


def test_how_a_point_s_keys_are_read_is_no_part_that_stops_a_bound():
    # before: a calibration uploaded with a column in another unit (its header kept, `headers`) or with ISO
    # 8601 times (`clock`) had "its headers has no bound over a box here": no certified worst case, no lower
    # bound over the designs; both say how a point is read, not what mu is there
    model = _interval_model()
    read = dataclasses.replace(model.calibrated, headers={"temperature_C": "T [degF]"},
                               clock={"date": "2026-12-02T09:00:00+00:00"})
    held = CalibratedPhysicsModel("calibrated:read", read)
    for interval in (False, True):
        pieces, reason = term_pieces(held, interval=interval)
        assert reason == "" and [p.kind for p in pieces] == [p.kind for p in term_pieces(model, interval)[0]]
    structures, reason = interval_structures(held)
    assert reason == "" and len(structures) == len(interval_structures(model)[0])

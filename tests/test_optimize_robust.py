"""Robust designs over an operating envelope: checked by brute force, by the physics' monotonicity and
against the cantilever beam of Dakota's examples."""

from __future__ import annotations

import itertools

import cvxpy as cp
import numpy as np
import pytest
from scipy import optimize as sciopt

from microbearing import physics
from microbearing.calibrate import CalibratedModel
from microbearing.calibrate.candidates import EffectTerm
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.optimize import Constraints, DesignBounds, DesignProblem
from microbearing.optimize.robust import Envelope, optimize_robust, robust_gp

SPEEDS = (0.01, 0.1)
DELTA = 0.5


def test_physics_mu_pressure_and_friction_never_fall_as_the_angle_or_the_speed_grows():
    # The vertex argument of optimize.robust, checked on the exact physics (both conventions, balls apart
    # and touching, with and without adhesion, one ball to many).
    theta = np.linspace(1.0, 89.0, 881)[:, None]
    speed = np.linspace(0.0, 2.0, 41)[None, :]
    for convention, touching, z, load, energy in itertools.product(
            physics.CONVENTIONS, (False, True), (1, 2, 4, 18), (1e-4, 0.01, 1.0), (0.0, 0.18)):
        r = physics.evaluate(balls=z, groove_angle_deg=theta, load_N=load, speed_m_s=speed,
                             balls_touching=touching, adhesion_energy_J_m2=energy, convention=convention)
        for name in ("mu", "max_contact_pressure_Pa", "friction_force_N"):
            values = np.broadcast_to(getattr(r, name), (theta.size, speed.size))
            assert (np.diff(values, axis=0) >= -1e-15 * values[:-1]).all(), (name, convention, touching, z)
            assert (np.diff(values, axis=1) >= -1e-15 * values[:, :-1]).all(), (name, convention, touching, z)


def _brute_force(evaluate, designs, envelope_points):
    """Worst case of every design over every envelope point: an array of len(designs)."""
    return np.array([max(evaluate(d, e) for e in envelope_points) for d in designs])


def test_physics_robust_optimum_is_the_brute_force_one_with_a_closed_certified_gap():
    limit = 7e8
    problem = DesignProblem(DesignBounds((3, 6), (45, 60), (0.002, 0.02)), 0.05,
                            Constraints(max_contact_pressure_Pa=limit))
    envelope = Envelope(SPEEDS, tolerances={"groove_angle_deg": DELTA})
    robust = optimize_robust(problem, envelope)
    document = robust.to_dict()
    design = document["design"]
    # Exhaustively: designs on a grid, each judged at a 5 x 5 grid of speeds and angle offsets.
    z, theta, load = (a.reshape(-1) for a in np.meshgrid(np.arange(3, 7), np.linspace(45, 60, 31),
                                                         np.geomspace(0.002, 0.02, 61), indexing="ij"))
    offsets, speeds = np.meshgrid(np.linspace(-DELTA, DELTA, 5), np.linspace(*SPEEDS, 5), indexing="ij")
    mu = np.full(z.size, -np.inf)
    pressure = np.full(z.size, -np.inf)
    for offset, speed in zip(offsets.reshape(-1), speeds.reshape(-1), strict=True):
        r = physics.evaluate(balls=z, groove_angle_deg=theta + offset, load_N=load, speed_m_s=speed)
        mu, pressure = np.maximum(mu, r.mu), np.maximum(pressure, r.max_contact_pressure_Pa)
    feasible = pressure <= limit
    assert feasible.any() and not feasible.all()
    # No grid design that meets the limit over the envelope beats the robust optimum ...
    assert mu[feasible].min() >= robust.worst_case["mu"] * (1 - 1e-9)
    # ... whose worst case is the brute-force maximum over the same grid at its design,
    pairs = zip(offsets.reshape(-1), speeds.reshape(-1), strict=True)
    at = [physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"] + o,
                           load_N=design["load_N"], speed_m_s=s) for o, s in pairs]
    assert max(float(r.mu) for r in at) == pytest.approx(robust.worst_case["mu"], rel=1e-12)
    assert max(float(r.max_contact_pressure_Pa) for r in at) <= limit * (1 + 1e-9)
    # at the angle made high and the highest speed,
    assert robust.worst_case["speed_m_s"] == SPEEDS[1]
    assert robust.worst_case["groove_angle_deg"] == pytest.approx(design["groove_angle_deg"] + DELTA)
    assert document["mu"] == robust.worst_case["mu"]
    # and the certificate's bound is below every achievable worst case, within the target of the optimum.
    proof = robust.proof
    assert proof["proven"] and proof["relative_gap"] <= 1e-6
    assert proof["lower_bound"] <= mu[feasible].min()
    assert proof["lower_bound"] <= robust.worst_case["mu"] <= proof["lower_bound"] * (1 + 1e-6)
    # The nominal angle stays in the box the designer gave.
    assert 45 <= design["groove_angle_deg"] <= 60


def test_price_of_robustness_the_nominal_optimum_breaks_the_limit_over_the_envelope():
    limit = 6e8
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05,
                            Constraints(max_contact_pressure_Pa=limit))
    robust = optimize_robust(problem, Envelope(SPEEDS, tolerances={"groove_angle_deg": DELTA}))
    price = robust.price_of_robustness
    nominal = price["nominal"]["design"]
    # The nominal design, optimized at the centre (0.055 m/s, the angle as drawn), evaluated independently:
    centre = physics.evaluate(**nominal, speed_m_s=0.055)
    assert price["nominal"]["at_centre"] == pytest.approx(float(centre.mu), rel=1e-12)
    worst = physics.evaluate(balls=nominal["balls"], groove_angle_deg=nominal["groove_angle_deg"] + DELTA,
                             load_N=nominal["load_N"], speed_m_s=SPEEDS[1])
    assert price["nominal"]["worst_case"] == pytest.approx(float(worst.mu), rel=1e-12)
    holds = price["nominal"]["limits_hold_over_envelope"]
    assert (float(worst.max_contact_pressure_Pa) > limit) == (not holds)
    assert not price["nominal"]["limits_hold_over_envelope"]
    assert price["robust"]["worst_case"] == robust.worst_case["mu"]
    assert price["ratio"] == pytest.approx(price["nominal"]["worst_case"] / price["robust"]["worst_case"])


def test_without_limits_robustness_costs_the_nominal_design_its_worst_case():
    problem = DesignProblem(DesignBounds((3, 8), (40, 60), (0.001, 0.05)), 0.05)
    robust = optimize_robust(problem, Envelope(SPEEDS, tolerances={"groove_angle_deg": DELTA}))
    price = robust.price_of_robustness
    # The robust design is optimal for the worst case: the nominal one can only be as good or worse there.
    assert price["robust"]["worst_case"] <= price["nominal"]["worst_case"] * (1 + 1e-9)
    assert price["nominal"]["at_centre"] <= price["robust"]["at_centre"] * (1 + 1e-9)


def _cantilever(bound: float):
    """Dakota's cantilever beam: minimize w t under stress and displacement limits, w, t in [1, bound]."""
    length, displacement = 100.0, 2.2535
    w, t = cp.Variable(pos=True), cp.Variable(pos=True)

    def constraints(v):
        return [600 * v["Y"] / (w * t**2) + 600 * v["X"] / (w**2 * t) <= v["R"],
                4 * length**3 / (v["E"] * w * t) * cp.sqrt((v["Y"] / t**2) ** 2 + (v["X"] / w**2) ** 2)
                <= displacement, w >= 1, t >= 1, w <= bound, t <= bound]

    def scipy_optimum(R, E, X, Y):
        # The same problem by SLSQP on its own formulas, from several starts (independent of cvxpy).
        cons = [{"type": "ineq",
                 "fun": lambda x: R - 600 * Y / (x[0] * x[1] ** 2) - 600 * X / (x[0] ** 2 * x[1])},
                {"type": "ineq", "fun": lambda x: displacement - 4 * length**3 / (E * x[0] * x[1])
                 * np.hypot(Y / x[1] ** 2, X / x[0] ** 2)}]
        best = min((sciopt.minimize(lambda x: x[0] * x[1], start, method="SLSQP", bounds=[(1, bound)] * 2,
                                    constraints=cons, options={"ftol": 1e-12, "maxiter": 500})
                    for start in ([2.5, 2.5], [1.5, 3.5], [3.5, 1.5], [bound, bound])),
                   key=lambda r: r.fun if r.success else np.inf)
        return best.fun, best.x

    return w, t, constraints, scipy_optimum


def test_dakota_cantilever_deterministic_and_robust_optima():
    means = {"R": 40000.0, "E": 2.9e7, "X": 500.0, "Y": 1000.0}
    sd = {"R": 2000.0, "E": 1.45e6, "X": 100.0, "Y": 100.0}
    w, t, constraints, scipy_optimum = _cantilever(4.0)
    nominal = robust_gp({"w": w, "t": t}, lambda v: w * t, constraints, {k: (m, m) for k, m in means.items()})
    # Dakota's deterministic optimum: 7.8235 at w = 2.35, t = 3.33
    assert nominal.value == pytest.approx(7.8235, abs=5e-5)
    assert nominal.variables["w"] == pytest.approx(2.35, abs=5e-3)
    assert nominal.variables["t"] == pytest.approx(3.33, abs=5e-3)
    box = {k: (means[k] - 3 * sd[k], means[k] + 3 * sd[k]) for k in means}
    robust = robust_gp({"w": w, "t": t}, lambda v: w * t, constraints, box)
    assert robust.vertices == 16 and robust.relative_gap <= 1e-6
    assert robust.lower_bound <= robust.value
    # Independently: the worst case of both limits is the weakest, softest beam under the largest loads
    # (stress and displacement grow with X, Y and fall with R, E); SLSQP on every one of the 16 vertices
    # confirms that vertex is the binding one, and its optimum is the robust weight, 10.91.
    by_vertex = {corner: scipy_optimum(*corner)[0] for corner in itertools.product(*(box[k] for k in "REXY"))}
    hand = (box["R"][0], box["E"][0], box["X"][1], box["Y"][1])
    assert max(by_vertex, key=by_vertex.get) == hand
    weight, _ = scipy_optimum(*hand)
    assert weight == pytest.approx(10.91, abs=5e-3)
    assert robust.value == pytest.approx(weight, rel=1e-6)
    # every vertex's limits hold at the robust design
    for R, E, X, Y in by_vertex:
        wv, tv = robust.variables["w"], robust.variables["t"]
        assert 600 * Y / (wv * tv**2) + 600 * X / (wv**2 * tv) <= R * (1 + 1e-6)
        assert 4e6 / (E * wv * tv) * np.hypot(Y / tv**2, X / wv**2) <= 2.2535 * (1 + 1e-6)


def _meniscus_model() -> CalibratedPhysicsModel:
    model = CalibratedModel(fitted={"mu_pivot": 0.6},
                            terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5])],
                            covariance=np.diag([1e-4, 1e-12]), noise_std_log=0.02,
                            domain={"load_N": [0.001, 0.05], "relative_humidity": [0.2, 0.8]},
                            conditions=["relative_humidity"])
    return CalibratedPhysicsModel("calibrated:meniscus", model)


@pytest.mark.parametrize("objective", ["mu", "mu_upper"])
def test_calibrated_model_robust_design_against_brute_force(objective):
    model = _meniscus_model()
    problem = DesignProblem(DesignBounds((3, 5), (45, 60), (0.002, 0.02)), 0.05)
    envelope = Envelope(SPEEDS, {"relative_humidity": (0.3, 0.7)}, {"groove_angle_deg": DELTA})
    robust = optimize_robust(problem, envelope, model, objective=objective, starts=2)
    design = robust.result.design
    grid = list(itertools.product(np.linspace(*SPEEDS, 5), np.linspace(0.3, 0.7, 5),
                                  np.linspace(-DELTA, DELTA, 5)))

    def worst(z, theta, load):
        columns = {"balls": z, "groove_angle_deg": theta[..., None] + np.array([g[2] for g in grid]),
                   "load_N": load[..., None], "speed_m_s": np.array([g[0] for g in grid]),
                   "relative_humidity": np.array([g[1] for g in grid])}
        values = model.predict(columns)
        return np.max(values.mu if objective == "mu" else values.mu_upper, axis=-1)

    at_design = float(worst(design["balls"], np.array(design["groove_angle_deg"]),
                            np.array(design["load_N"])))
    # the reported worst case is at least the grid's maximum at the design (the search goes beyond the grid)
    assert robust.worst_case[objective] >= at_design * (1 - 1e-12)
    assert robust.worst_case[objective] <= at_design * (1 + 1e-6)
    theta, load = np.meshgrid(np.linspace(45, 60, 16), np.geomspace(0.002, 0.02, 31), indexing="ij")
    best_grid = min(float(worst(z, theta, load).min()) for z in (3, 4, 5))
    assert robust.worst_case[objective] <= best_grid * (1 + 1e-6)
    if objective == "mu":
        # The physics plus a positive monomial in balls / load_N growing with humidity: a GP at one vertex.
        proof = robust.proof
        assert proof["proven"] and proof["method"] == "robust-gp-vertex" and proof["relative_gap"] <= 1e-6
        assert proof["lower_bound"] <= best_grid and proof["lower_bound"] <= robust.worst_case["mu"]
    else:  # the worst case at the design certified by branch and bound over the envelope, the best achievable
        # one bounded below by branch and bound over the designs (optimize.design_bound): proven
        proof = robust.proof
        assert proof["proven"] and proof["method"] == "outer-approximation-certified", proof["statement"]
        assert proof["upper_bound_certified"] and proof["relative_gap"] <= 1e-6
        assert at_design <= proof["upper_bound"] <= robust.worst_case["mu_upper"] * (1 + 1e-6)
        assert proof["lower_bound"] <= best_grid and proof["lower_bound"] <= robust.worst_case["mu_upper"]
        # Non-trivial: the parameters' share of the interval matters (mu_pivot known to 1.7 %). The bound from
        # the scatter alone, exp(1.96 noise) times the proven least worst mu, is below it by far more than the
        # gap.
        worst_mu = optimize_robust(problem, envelope, model, objective="mu").proof["lower_bound"]
        assert proof["lower_bound"] > worst_mu * np.exp(1.96 * 0.02) * (1 + 1e-3)
    # The price of robustness: the nominal design's objective at the envelope's centre, by the model itself.
    nominal = robust.price_of_robustness["nominal"]
    centre = model.predict({**nominal["design"], "speed_m_s": 0.055, "relative_humidity": 0.5})
    assert nominal["at_centre"] == pytest.approx(float(np.squeeze(getattr(centre, objective))), rel=1e-9)
    assert robust.price_of_robustness["robust"]["worst_case"] <= nominal["worst_case"] * (1 + 1e-6)
    # Friction grows with humidity (the menisci) and speed, and with the angle: the far corner.
    assert robust.worst_case["conditions"]["relative_humidity"] == pytest.approx(0.7)
    assert robust.worst_case["speed_m_s"] == pytest.approx(0.1)


def test_a_worst_case_inside_the_envelope_is_found_and_designed_for():
    # log mu = ... - 3 z^2 with z = (h - 0.5) / 0.1 peaks at h = 0.5: the vertices alone (h = 0.3, 0.7)
    # miss the worst case, the search finds it and the loop designs for it.
    term = EffectTerm("generic_quadratic", ("relative_humidity",), {"centre": 0.5, "scale": 0.1})
    model = CalibratedPhysicsModel("calibrated:peak", CalibratedModel(
        fitted={"mu_pivot": 0.6}, terms=[(term, [0.0, -3.0])], conditions=["relative_humidity"]))
    problem = DesignProblem(DesignBounds((3, 4), (45, 60), (0.002, 0.02)), 0.05)
    robust = optimize_robust(problem, Envelope(SPEEDS, {"relative_humidity": (0.3, 0.7)}), model, starts=1)
    assert robust.worst_case["conditions"]["relative_humidity"] == pytest.approx(0.5, abs=1e-3)
    design = robust.result.design
    exact = model({**design, "speed_m_s": 0.1, "relative_humidity": 0.5})
    assert robust.worst_case["mu"] == pytest.approx(float(np.squeeze(exact)), rel=1e-6)


def test_refusals_name_the_field():
    problem = DesignProblem(DesignBounds((3, 4), (45, 60), (0.002, 0.02)), 0.05)
    with pytest.raises(ValueError, match=r"^objective: mu_upper"):
        optimize_robust(problem, Envelope(SPEEDS), objective="mu_upper")
    with pytest.raises(ValueError, match=r"^conditions: "):
        optimize_robust(problem, Envelope(SPEEDS, {"relative_humidity": (0.3, 0.7)}))
    with pytest.raises(ValueError, match=r"^conditions\.relative_humidity: "):
        optimize_robust(problem, Envelope(SPEEDS), _meniscus_model())
    with pytest.raises(ValueError, match=r"^conditions\.temperature_C is not a condition"):
        optimize_robust(problem, Envelope(SPEEDS, {"relative_humidity": 0.5, "temperature_C": (20, 60)}),
                        _meniscus_model())
    with pytest.raises(ValueError, match=r"^tolerances\.load_N"):
        Envelope(SPEEDS, tolerances={"load_N": 0.001})
    with pytest.raises(ValueError, match=r"^conditions\.relative_humidity: low must not exceed high"):
        Envelope(SPEEDS, {"relative_humidity": (0.7, 0.3)})
    edge = DesignProblem(DesignBounds((3, 4), (45, 89.9), (0.002, 0.02)), 0.05)
    with pytest.raises(ValueError, match=r"^tolerances\.groove_angle_deg"):
        optimize_robust(edge, Envelope(SPEEDS, tolerances={"groove_angle_deg": 0.5}))


def test_calibrated_gp_proof_on_the_four_dimensional_envelope_against_brute_force():
    # menisci growing with humidity, shear strength falling with temperature (so the worst case is cold),
    # a viscous drag growing with speed, and the angle made to +- 0.5 deg
    model = CalibratedPhysicsModel("calibrated:four", CalibratedModel(
        fitted={"mu_pivot": 0.6},
        terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5]),
               (EffectTerm("thermal_shear_strength", ("temperature_C",), {"reference": 40.0}), [0.004]),
               (EffectTerm("viscous_drag", ("speed_m_s", "load_N")), [1e-3])],
        conditions=["relative_humidity", "temperature_C"]))
    limit = 6e8
    problem = DesignProblem(DesignBounds((3, 5), (45, 60), (0.002, 0.02)), 0.05,
                            Constraints(max_contact_pressure_Pa=limit))
    envelope = Envelope(SPEEDS, {"relative_humidity": (0.3, 0.7), "temperature_C": (20.0, 60.0)},
                        {"groove_angle_deg": DELTA})
    robust = optimize_robust(problem, envelope, model)
    proof = robust.proof
    assert proof["proven"] and proof["relative_gap"] <= 1e-6
    assert robust.worst_case["conditions"] == {"relative_humidity": 0.7, "temperature_C": 20.0}
    assert robust.worst_case["speed_m_s"] == SPEEDS[1]
    # Brute force: designs on a grid, each at 3^4 envelope points; limits judged by the exact physics.
    z, theta, load = (a.reshape(-1, 1) for a in np.meshgrid(np.arange(3, 6), np.linspace(45, 60, 16),
                                                            np.geomspace(0.002, 0.02, 41), indexing="ij"))
    env = np.array(list(itertools.product(np.linspace(*SPEEDS, 3), (0.3, 0.5, 0.7), (20.0, 40.0, 60.0),
                                          (-DELTA, 0.0, DELTA)))).T
    columns = {"balls": z, "groove_angle_deg": theta + env[3], "load_N": load, "speed_m_s": env[0],
               "relative_humidity": env[1], "temperature_C": env[2]}
    worst = model(columns).max(axis=1)
    pressure = physics.evaluate(balls=z[:, 0], groove_angle_deg=theta[:, 0] + DELTA, load_N=load[:, 0],
                                speed_m_s=0.1, mu_pivot=0.6).max_contact_pressure_Pa
    feasible = pressure <= limit
    assert feasible.any() and not feasible.all()
    assert worst[feasible].min() >= robust.worst_case["mu"] * (1 - 1e-9)
    assert proof["lower_bound"] <= worst[feasible].min()
    design = robust.result.design
    at = {"balls": design["balls"], "groove_angle_deg": design["groove_angle_deg"] + env[3],
          "load_N": design["load_N"], "speed_m_s": env[0], "relative_humidity": env[1],
          "temperature_C": env[2]}
    assert model(at).max() == pytest.approx(robust.worst_case["mu"], rel=1e-12)


def test_a_surrogate_of_the_physics_gives_the_physics_robust_design_to_its_accuracy():
    from scipy.stats import qmc

    from microbearing.surrogate import GaussianProcessSurrogate, Space
    from microbearing.surrogate.model_view import SurrogateModel

    space = Space({"balls": (3, 8), "groove_angle_deg": (40, 61), "load_N": (0.002, 0.02),
                   "speed_m_s": (0.0, 0.12)})
    X = space.from_unit(qmc.Sobol(4, seed=0).random(128))
    model = SurrogateModel("surrogate:physics", GaussianProcessSurrogate(space, random_state=0).fit(
        X, space.evaluate(X)))
    problem = DesignProblem(DesignBounds((3, 8), (45, 60), (0.002, 0.02)), 0.05)
    envelope = Envelope(SPEEDS, tolerances={"groove_angle_deg": DELTA})
    robust = optimize_robust(problem, envelope, model)
    truth = optimize_robust(problem, envelope)  # the physics, proven
    design = robust.result.design
    exact = physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"] + DELTA,
                             load_N=design["load_N"], speed_m_s=SPEEDS[1])
    # The surrogate's design, judged by the physics at its worst case, is within the surrogate's error of
    # the proven optimum; the surrogate's own worst case is within that error of the physics there.
    assert float(exact.mu) <= truth.worst_case["mu"] * (1 + 1e-3)
    assert robust.worst_case["mu"] == pytest.approx(float(exact.mu), rel=1e-3)
    assert robust.proof["proven"] is False and "not a calibrated model" in robust.proof["statement"]
    # Its 95 % upper bound, designed for: the worst mu_upper at that design is the surrogate's own, above mu.
    upper = optimize_robust(problem, envelope, model, objective="mu_upper")
    d = upper.result.design
    at = model.evaluate({"balls": d["balls"], "groove_angle_deg": upper.worst_case["groove_angle_deg"],
                         "load_N": d["load_N"], "speed_m_s": upper.worst_case["speed_m_s"]},
                        ["mu", "mu_upper"])
    assert upper.worst_case["mu_upper"] == pytest.approx(float(np.squeeze(at.values["mu_upper"])), rel=1e-9)
    assert upper.worst_case["mu_upper"] > float(np.squeeze(at.values["mu"]))
    assert upper.proof["lower_bound"] is None and upper.proof["proven"] is False


def test_physics_friction_force_limit_holds_over_the_envelope_against_brute_force():
    # A friction-force limit mu G (worst at the high speed and the angle made high, as mu) with a minimum
    # load: the optimum sits on the limit at its worst corner.
    force = 1.3e-4
    problem = DesignProblem(DesignBounds((3, 6), (45, 60), (0.002, 0.05)), 0.05,
                            Constraints(max_friction_force_N=force, min_load_capacity_N=0.01))
    robust = optimize_robust(problem, Envelope(SPEEDS, tolerances={"groove_angle_deg": DELTA}))
    z, theta, load = (a.reshape(-1) for a in np.meshgrid(np.arange(3, 7), np.linspace(45, 60, 31),
                                                         np.geomspace(0.01, 0.05, 81), indexing="ij"))
    mu, friction = np.full(z.size, -np.inf), np.full(z.size, -np.inf)
    for offset, speed in itertools.product(np.linspace(-DELTA, DELTA, 3), np.linspace(*SPEEDS, 3)):
        r = physics.evaluate(balls=z, groove_angle_deg=theta + offset, load_N=load, speed_m_s=speed)
        mu, friction = np.maximum(mu, r.mu), np.maximum(friction, r.friction_force_N)
    feasible = friction <= force
    assert feasible.any() and not feasible.all()
    assert mu[feasible].min() >= robust.worst_case["mu"] * (1 - 1e-9)
    design = robust.result.design
    worst = physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"] + DELTA,
                             load_N=design["load_N"], speed_m_s=SPEEDS[1])
    assert float(worst.friction_force_N) <= force * (1 + 1e-9)
    assert robust.proof["proven"] and robust.proof["lower_bound"] <= mu[feasible].min()


def test_calibrated_friction_force_limit_is_judged_by_the_model_over_the_envelope():
    model = _meniscus_model()
    force = 2.5e-4
    problem = DesignProblem(DesignBounds((3, 5), (45, 60), (0.002, 0.05)), 0.05,
                            Constraints(max_friction_force_N=force, min_load_capacity_N=0.01))
    envelope = Envelope(SPEEDS, {"relative_humidity": (0.3, 0.7)}, {"groove_angle_deg": DELTA})
    robust = optimize_robust(problem, envelope, model)
    assert robust.proof["proven"] and robust.proof["method"] == "robust-gp-vertex"
    z, theta, load = (a.reshape(-1, 1) for a in np.meshgrid(np.arange(3, 6), np.linspace(45, 60, 31),
                                                            np.geomspace(0.01, 0.05, 81), indexing="ij"))
    env = np.array(list(itertools.product(np.linspace(*SPEEDS, 3), (0.3, 0.5, 0.7), (-DELTA, 0.0, DELTA)))).T
    mu = model({"balls": z, "groove_angle_deg": theta + env[2], "load_N": load, "speed_m_s": env[0],
                "relative_humidity": env[1]}).max(axis=1)
    feasible = mu * load[:, 0] <= force
    assert feasible.any() and not feasible.all()
    assert mu[feasible].min() >= robust.worst_case["mu"] * (1 - 1e-9)
    assert robust.worst_case["mu"] * robust.result.design["load_N"] <= force * (1 + 1e-9)
    assert robust.proof["lower_bound"] <= mu[feasible].min()


def test_an_outer_approximation_cut_short_says_so():
    # The interior peak of test_a_worst_case_inside_the_envelope_is_found_and_designed_for needs a second
    # round; one round, or a time limit already spent, stops before it and the result says so.
    term = EffectTerm("generic_quadratic", ("relative_humidity",), {"centre": 0.5, "scale": 0.1})
    model = CalibratedPhysicsModel("calibrated:peak", CalibratedModel(
        fitted={"mu_pivot": 0.6}, terms=[(term, [0.0, -3.0])], conditions=["relative_humidity"]))
    problem = DesignProblem(DesignBounds((3, 4), (45, 60), (0.002, 0.02)), 0.05)
    envelope = Envelope(SPEEDS, {"relative_humidity": (0.3, 0.7)})
    for options in ({"max_rounds": 1}, {"time_limit_s": 0.0}):
        robust = optimize_robust(problem, envelope, model, starts=1, **options)
        assert len(robust.proof["rounds"]) == 1 and "stopped" in robust.proof["statement"]
        assert ("time limit" in robust.proof["statement"]) == ("time_limit_s" in options)
        # the worst case reported is the one found (the peak), not the optimized set's
        assert robust.worst_case["conditions"]["relative_humidity"] == pytest.approx(0.5, abs=1e-3)
        assert robust.worst_case["mu"] > robust.proof["rounds"][0]["on_set"]

"""Optimal designs of calibrate.design against textbook answers, and the honesty of its bounds.

Textbook answers, quoted with their sources:

* D-optimal design of the full quadratic model in two factors on [-1, 1]^2: the 3 x 3 grid with
  weights 0.1458 at the corners, 0.0802 at the edge midpoints and 0.0962 at the centre (Atkinson,
  Donev and Tobias, Optimum Experimental Designs, with SAS, 2007, Table 11.5; Kiefer 1961).
* T-optimal design of Atkinson and Fedorov (1975, Biometrika 62, 57-70), 4.5 - 1.5 e^x - 2 e^-x
  against a quadratic on [-1, 1]: support -1, -0.669, 0.144, 0.957 with weights 0.253, 0.428,
  0.247, 0.072.
"""

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from microbearing.calibrate.design import DesignError, FunctionModel, efficient_rounding, plan


def quadratic_2d():
    return FunctionModel(
        ["1", "x1", "x2", "x1^2", "x2^2", "x1 x2"],
        lambda p: np.column_stack([np.ones_like(p["x1"]), p["x1"], p["x2"], p["x1"] ** 2, p["x2"] ** 2,
                                   p["x1"] * p["x2"]]),
    )


def square_grid(levels=21):
    g = np.linspace(-1, 1, levels)
    x1, x2 = np.meshgrid(g, g)
    return {"x1": x1.ravel(), "x2": x2.ravel()}


def quadratic_1d():
    return FunctionModel(["1", "x", "x^2"],
                         lambda p: np.column_stack([np.ones_like(p["x"]), p["x"], p["x"] ** 2]))


def weight_near(candidates, weights, **where):
    close = np.ones(weights.size, dtype=bool)
    for name, value in where.items():
        close &= np.abs(candidates[name] - value) < 0.011
    return float(weights[close].sum())


def test_d_optimal_full_quadratic_is_the_weighted_3x3_grid_with_bound_one():
    candidates = square_grid()
    design = plan(quadratic_2d(), candidates, 30, "parameters")
    corners = [weight_near(candidates, design.weights, x1=a, x2=b) for a in (-1, 1) for b in (-1, 1)]
    edges = [weight_near(candidates, design.weights, x1=a, x2=b)
             for a, b in ((0, -1), (0, 1), (-1, 0), (1, 0))]
    centre = weight_near(candidates, design.weights, x1=0, x2=0)
    assert corners == pytest.approx([0.1458] * 4, abs=5e-4)
    assert edges == pytest.approx([0.0802] * 4, abs=5e-4)
    assert centre == pytest.approx(0.0962, abs=5e-4)
    assert sum(corners) + sum(edges) + centre == pytest.approx(1.0, abs=1e-6)  # nothing elsewhere
    assert design.continuous_efficiency_lower_bound == pytest.approx(1.0, abs=1e-4)
    assert design.counts.sum() == 30 and design.counts.dtype.kind == "i"
    assert 0.0 <= design.efficiency_lower_bound <= 1.0


def test_d_bound_never_exceeds_the_true_efficiency_of_the_whole_runs():
    # 7 runs cannot carry the 9-point weights: the bound must stay below the efficiency computed
    # against the known optimum (the textbook weights above, information computed here).
    candidates = square_grid(3)
    f = quadratic_2d().sensitivities(candidates)
    corner = (np.abs(candidates["x1"]) == 1) & (np.abs(candidates["x2"]) == 1)
    centre = (candidates["x1"] == 0) & (candidates["x2"] == 0)
    optimum = np.where(corner, 0.1458, np.where(centre, 0.0962, 0.0802))
    m_star = f.T @ (f * optimum[:, None])
    for runs in (7, 8, 11):
        for polish in (False, True):
            design = plan(quadratic_2d(), candidates, runs, "parameters", polish=polish)
            w = design.counts / runs
            m = f.T @ (f * w[:, None])
            true_efficiency = (np.linalg.det(m) / np.linalg.det(m_star)) ** (1 / 6)
            assert design.efficiency_lower_bound <= true_efficiency + 1e-3
            assert design.efficiency_lower_bound > 0.5


def test_t_optimal_atkinson_fedorov_1975():
    x = np.linspace(-1, 1, 1001)
    truth = FunctionModel([], lambda p: np.zeros((p["x"].size, 0)),
                          response_function=lambda p: 4.5 - 1.5 * np.exp(p["x"]) - 2 * np.exp(-p["x"]))
    design = plan(truth, {"x": x}, 20, "discriminate", rivals=[quadratic_1d()])
    for point, weight in zip((-1, -0.669, 0.144, 0.957), (0.253, 0.428, 0.247, 0.072), strict=True):
        assert weight_near({"x": x}, design.weights, x=point) == pytest.approx(weight, abs=0.004)
    assert design.continuous_efficiency_lower_bound > 0.999
    # Independent check of the criterion: the quadratic's weighted least-squares misfit at the runs.
    w = design.counts / 20
    f = quadratic_1d().sensitivities({"x": x})
    y = truth.response({"x": x})
    theta = np.linalg.lstsq(f * np.sqrt(w)[:, None], y * np.sqrt(w), rcond=None)[0]
    assert design.criterion == pytest.approx(20 * np.sum(w * (y - f @ theta) ** 2), rel=1e-6)
    assert 0.9 < design.efficiency_lower_bound <= 1.0


def test_i_optimal_quadratic_matches_a_brute_force_search():
    # I-optimal for the quadratic on [-1, 1], variance averaged over a uniform envelope: by symmetry
    # weight a at +-1 and 1 - 2a at 0; the best a found here by a scalar search.
    x = np.linspace(-1, 1, 201)
    model = quadratic_1d()
    envelope = {"x": np.linspace(-1, 1, 401)}
    c = model.sensitivities(envelope)

    def average_variance(a):
        f = model.sensitivities({"x": np.array([-1.0, 0.0, 1.0])})
        m = f.T @ (f * np.array([a, 1 - 2 * a, a])[:, None])
        return float(np.mean(np.einsum("ij,jk,ik->i", c, np.linalg.inv(m), c)))

    best = minimize_scalar(average_variance, bounds=(0.05, 0.45), method="bounded", options={"xatol": 1e-8})
    design = plan(model, {"x": x}, 40, "predict", envelope=envelope)
    for point, weight in ((-1, best.x), (0, 1 - 2 * best.x), (1, best.x)):
        assert weight_near({"x": x}, design.weights, x=point) == pytest.approx(weight, abs=2e-3)
    assert design.continuous_efficiency_lower_bound == pytest.approx(1.0, abs=1e-3)
    assert design.criterion == pytest.approx(average_variance(best.x) / 40, rel=0.02)


def test_prior_information_moves_the_design_to_what_the_data_lack():
    # Data already taken pin the intercept and slope: the information left to gain is on the
    # curvature, sum of n x^4, largest at +-1 only (without the prior the centre gets a third).
    x = np.linspace(-1, 1, 41)
    prior = np.diag([1e4, 1e4, 0.0])
    design = plan(FunctionModel(["1", "x", "x^2"], quadratic_1d().sensitivity_function, prior=prior),
                  {"x": x}, 10, "parameters")
    assert design.counts.sum() == 10
    assert set(x[design.counts > 0].tolist()) <= {-1.0, 1.0}
    without = plan(quadratic_1d(), {"x": x}, 9, "parameters")
    assert without.counts[x == 0.0].item() == 3
    assert design.continuous_efficiency_lower_bound > 0.99


@pytest.mark.parametrize("goal", ["parameters", "predict"])
def test_a_parameter_no_candidate_moves_is_held_by_the_data_taken(goal):
    # A run-in's scale with its cycles held at 0: no candidate moves the third parameter, the data taken
    # hold it (prior). Scaled by its zero spread it overflowed to inf and the solver never returned; now
    # the runs serve the two others as if the third were known: the D-optimal line on [-1, 1] puts half
    # the runs at each end (hand: det of [[n, s], [s, q]] is largest with s = 0, q = n).
    x = np.linspace(-1, 1, 21)
    model = FunctionModel(["1", "x", "held"], lambda p: np.column_stack([np.ones_like(p["x"]), p["x"],
                                                                          np.zeros_like(p["x"])]),
                          prior=np.diag([1.0, 1.0, 4.0]))
    envelope = {"x": np.linspace(-0.5, 0.5, 5)} if goal == "predict" else None
    design = plan(model, {"x": x}, 10, goal, envelope=envelope)
    assert design.counts.sum() == 10 and np.all(np.isfinite(design.information_after))
    assert np.isfinite(design.criterion) and design.efficiency_lower_bound > 0.9
    if goal == "parameters":
        assert design.counts[0] == design.counts[-1] == 5


def test_efficient_rounding_sums_and_follows_pukelsheim_rieder():
    assert efficient_rounding(np.array([0.5, 0.3, 0.2]), 10).tolist() == [5, 3, 2]
    weights = np.array([0.1458] * 4 + [0.0802] * 4 + [0.0962])
    for runs in (1, 5, 9, 13, 100):
        counts = efficient_rounding(weights, runs)
        assert counts.sum() == runs and np.all(counts >= 0)
        # the rounding's defining property: max (n_i - 1) / w_i <= min n_j / w_j
        assert np.max((counts - 1) / weights) <= np.min(counts / weights) + 1e-12


def test_unidentifiable_parameters_are_named():
    x = np.linspace(-1, 1, 11)
    model = FunctionModel(["a", "b"], lambda p: np.column_stack([np.ones_like(p["x"]), np.ones_like(p["x"])]))
    with pytest.raises(DesignError, match="cannot identify"):
        plan(model, {"x": x}, 5, "parameters")
    with pytest.raises(DesignError, match="goal must be"):
        plan(quadratic_1d(), {"x": x}, 5, "best")
    with pytest.raises(DesignError, match="envelope"):
        plan(quadratic_1d(), {"x": x}, 5, "predict")


def test_model_robust_i_optimal_with_an_identical_rival_is_the_plain_design():
    # Summing the envelope variance of two identical models doubles it: the same optimum, bound 1.
    x = np.linspace(-1, 1, 101)
    envelope = {"x": np.linspace(0.5, 1.0, 51)}
    plain = plan(quadratic_1d(), {"x": x}, 30, "predict", envelope=envelope)
    robust = plan(quadratic_1d(), {"x": x}, 30, "predict", envelope=envelope, rivals=[quadratic_1d()])
    assert np.allclose(plain.weights, robust.weights, atol=2e-3)
    assert robust.continuous_efficiency_lower_bound == pytest.approx(1.0, abs=1e-3)
    # A cubic rival pulls runs toward where the cubic's envelope variance is learnt.
    cubic = FunctionModel(["1", "x", "x^2", "x^3"],
                          lambda p: np.column_stack([np.ones_like(p["x"]), p["x"], p["x"] ** 2, p["x"] ** 3]))
    hedged = plan(quadratic_1d(), {"x": x}, 30, "predict", envelope=envelope, rivals=[cubic])
    assert np.count_nonzero(hedged.weights > 1e-3) >= 4  # a cubic needs four support points
    assert hedged.continuous_efficiency_lower_bound > 0.99


def test_planned_runs_count_as_information_taken():
    # Quadratic on [-1, 1], D-optimal: a third of the runs at -1, 0, 1. With 12 runs already planned at
    # 0, the 12 new runs all go to the ends: the best of every split of 24 runs that keeps the planned 12
    # at 0, found here by enumeration.
    x = np.linspace(-1, 1, 41)
    design = plan(quadratic_1d(), {"x": x}, 12, "parameters", planned={"x": np.zeros(12)})
    assert design.counts[x == -1.0].item() + design.counts[x == 1.0].item() == 12
    f = quadratic_1d().sensitivities

    def logdet(left, middle, right):
        points = np.array([-1.0] * left + [0.0] * middle + [1.0] * right)
        m = f({"x": points}).T @ f({"x": points})
        return np.linalg.slogdet(m)[1]

    best = max(((a, 24 - a - b, b) for a in range(1, 12) for b in range(1, 12) if 24 - a - b >= 12),
               key=lambda split: logdet(*split))
    got = (design.counts[x == -1.0].item(), 12, design.counts[x == 1.0].item())
    assert logdet(*got) == pytest.approx(logdet(*best), abs=1e-9)
    assert design.criterion == pytest.approx(logdet(*got), rel=1e-9)

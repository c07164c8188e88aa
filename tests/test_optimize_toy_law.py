"""Adding a named law is one module plus its tests (README, "Adding a law"): a toy law registered with
:func:`physics.effects.register_effect` is found by calibration on data generated with it, and the robust
design and the bounds over a box read what it declares (how it enters mu, its direction, its value forms).

The toy: a drag force proportional to a vibration amplitude x, mu = mu_model + k x / load_N (k [N/um]).
The data are written here from that formula, independently of the law's ``correct``.
"""

import dataclasses
import itertools

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import calibrate
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.optimize import DesignBounds, DesignProblem
from microbearing.optimize.interval_bound import interval_structures
from microbearing.optimize.robust import Envelope, optimize_robust
from microbearing.physics.effects import EFFECTS, Effect, EffectParameter, register_effect

TRUE_FORCE_N_UM = 4e-5  # drag per micrometre of vibration [N/um]
MU_PIVOT = 0.7

TOY = Effect(
    name="vibration_drag",
    title="Drag growing with the vibration amplitude of the stage (a toy law of the tests)",
    formula="mu = mu_model + vibration_force_N_um * x / load_N",
    parameters=(EffectParameter("vibration_force_N_um", "N/driver", "Drag force per unit of amplitude.",
                                0.0, 1.0),),
    driver_description="vibration amplitude x >= 0, in the column's unit",
    reference="A toy law: what a new named law declares.",
    driver_keywords=("vib",),
    correct=lambda mu, x, columns, p, c: mu + p[0] * x / np.asarray(columns["load_N"], dtype=float),
    make_initial=lambda mu, x, columns, c: [
        0.1 * float(np.median(mu * np.asarray(columns["load_N"], dtype=float))) / max(float(np.median(x)),
                                                                                     1e-12)],
    accepts_values=lambda x: bool(np.all(x >= 0)),
    enters="add", direction=lambda v: (v[0] > 0) - (v[0] < 0), value_forms=("scale",),
)


@pytest.fixture
def toy_law():
    saved = dict(EFFECTS)
    register_effect(TOY)
    try:
        yield TOY
    finally:
        EFFECTS.clear()
        EFFECTS.update(saved)


def _rows(n: int = 120, seed: int = 3) -> list[dict]:
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 6, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.0, 0.15, n),
         "vibration_um": rng.uniform(0.0, 10.0, n)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                          mu_pivot=MU_PIVOT).mu
    mu = mu + TRUE_FORCE_N_UM * c["vibration_um"] / c["load_N"]
    measured = mu * np.exp(rng.normal(0.0, 0.02, n))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(n)]


def test_registering_checks_the_declarations(toy_law):
    assert list(EFFECTS).index("vibration_drag") < list(EFFECTS).index("generic_linear")  # named first
    with pytest.raises(ValueError, match="registered already"):
        register_effect(TOY)
    with pytest.raises(ValueError, match="one value form per parameter"):
        register_effect(dataclasses.replace(TOY, name="other", value_forms=("scale", "log")))
    with pytest.raises(ValueError, match="stationary point"):
        register_effect(dataclasses.replace(TOY, name="other", monotone=False))


def test_a_toy_law_is_found_by_calibration_and_its_robust_design_reads_its_declarations(toy_law):
    result = calibrate(_rows(), ["mu_pivot"], folds=3, make_plots=False)
    effect = result.missing_effect
    assert effect is not None and effect["name"] == "vibration_drag", result.decision
    assert effect["drivers"][0] == "vibration_um"
    assert effect["parameters"]["vibration_force_N_um"] == pytest.approx(TRUE_FORCE_N_UM, rel=0.15)
    model = CalibratedPhysicsModel("calibrated:toy", result.model)

    # mu: the law declares it adds a term rising with x, so the worst case is at the largest amplitude and
    # the robust problem a geometric program at that vertex, proven.
    problem = DesignProblem(DesignBounds((3, 6), (45, 60), (0.002, 0.02)), 0.05)
    envelope = Envelope((0.01, 0.1), {"vibration_um": (0.0, 8.0)})
    robust = optimize_robust(problem, envelope, model, starts=1)
    assert robust.proof["proven"] and robust.proof["method"] == "robust-gp-vertex", robust.proof["statement"]
    assert robust.worst_case["conditions"]["vibration_um"] == pytest.approx(8.0)
    # brute force at the design: no point of a grid of the envelope above the proven worst case
    design = {k: robust.result.design[k] for k in ("balls", "groove_angle_deg", "load_N")}
    grid = np.array(list(itertools.product(np.linspace(0.01, 0.1, 7), np.linspace(0.0, 8.0, 9))))
    held = {*result.model.fitted, *result.model.fixed}
    columns = {k: v for k, v in {**design, "speed_m_s": grid[:, 0], "vibration_um": grid[:, 1]}.items()
               if k not in held}
    brute = np.asarray(model(columns), dtype=float)
    assert brute.max() <= robust.worst_case["mu"] * (1 + 1e-9)
    assert brute.max() == pytest.approx(robust.worst_case["mu"], rel=1e-9)  # the vertex is on the grid

    # mu_upper: the interval's bound over a box reads the declared value form of its fitted value; a law
    # declaring none is refused, naming the value.
    structures, reason = interval_structures(model)
    assert structures is not None, reason
    EFFECTS["vibration_drag"] = dataclasses.replace(TOY, value_forms=(None,))
    structures, reason = interval_structures(model)
    assert structures is None and "vibration_force_N_um" in reason

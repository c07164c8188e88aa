"""Request examples of the operations that create jobs or use stored models, as the OpenAPI spec shows them.

Each is a request the server accepts (``tests/test_service_schemathesis.py`` sends every example
of the spec and expects 2xx; the examples that name a stored model are sent to the model the
examples before them made): a reader copies it, a generated client documents it, and schemathesis
mixes it into the requests it generates (about one in five), so that its stateful phase obtains a
job (202) that finishes in a second or two and follows the links to the job's routes and to the
stored surrogate or calibration. They are named examples of the media type (``content.
application/json.examples``), where schemathesis reads them; an ``examples`` list beside a
``$ref`` schema is not read.
"""

from __future__ import annotations

from typing import Any

__all__ = ["CALIBRATION", "CALIBRATION_UNITS", "FIRST_EXPERIMENTS", "NEXT_EXPERIMENTS", "OPTIMIZATION",
           "PARETO", "PREDICT", "SURROGATE", "SWEEP", "media_examples"]


def media_examples(**examples: tuple[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """``Body(openapi_examples=...)``: named examples of the JSON body, ``name=(summary, value)``."""
    return {name: {"summary": summary, "value": value} for name, (summary, value) in examples.items()}


#: A 10 x 10 grid of mu over load and speed with four balls (100 points).
SWEEP: dict[str, Any] = {
    "design": "grid", "fixed": {"balls": 4}, "outputs": ["mu"],
    "axes": {"load_N": {"start": 0.001, "stop": 0.05, "num": 10},
             "speed_m_s": {"start": 0.0, "stop": 0.2, "num": 10}}}

#: The least-friction ball count, groove angle and load at 0.05 m/s under a contact-pressure limit.
OPTIMIZATION: dict[str, Any] = {
    "bounds": {"balls": [4, 24], "groove_angle_deg": [35, 70], "load_N": [0.001, 0.05]},
    "fixed": {"speed_m_s": 0.05}, "constraints": {"max_contact_pressure_Pa": 1e9}}

#: A Gaussian-process surrogate of the physics over load and speed, four balls, 30 evaluations.
SURROGATE: dict[str, Any] = {
    "space": {"load_N": [0.001, 0.05], "speed_m_s": [0.001, 0.2]}, "fixed": {"balls": 4}, "budget": 30}

#: mu_pivot fitted on 24 measurements (the physics with mu_pivot 0.7 and about 1 % noise).
CALIBRATION: dict[str, Any] = {
    "fit_parameters": ["mu_pivot"], "folds": 3,
    "data": [{"balls": b, "load_N": f, "speed_m_s": v, "mu_measured": m} for b, f, v, m in (
        (4, 0.003, 0.01, 0.019547), (4, 0.003, 0.1, 0.02025), (4, 0.006, 0.01, 0.016227),
        (4, 0.006, 0.1, 0.016234), (4, 0.012, 0.01, 0.014555), (4, 0.012, 0.1, 0.015186),
        (4, 0.024, 0.01, 0.014302), (4, 0.024, 0.1, 0.014854), (8, 0.003, 0.01, 0.026419),
        (8, 0.003, 0.1, 0.028762), (8, 0.006, 0.01, 0.01916), (8, 0.006, 0.1, 0.020455),
        (8, 0.012, 0.01, 0.016068), (8, 0.012, 0.1, 0.0164), (8, 0.024, 0.01, 0.014846),
        (8, 0.024, 0.1, 0.014663), (12, 0.003, 0.01, 0.033769), (12, 0.003, 0.1, 0.037039),
        (12, 0.006, 0.01, 0.022598), (12, 0.006, 0.1, 0.024584), (12, 0.012, 0.01, 0.017503),
        (12, 0.012, 0.1, 0.01866), (12, 0.024, 0.01, 0.014999), (12, 0.024, 0.1, 0.015687))]}

#: The optimization of OPTIMIZATION with a Pareto front of 5 points of mu against the load (a job).
PARETO: dict[str, Any] = {**OPTIMIZATION, "pareto": {"objective": "load_N", "points": 5}}

#: Where a surrogate of SURROGATE predicts: three loads at 0.05 m/s.
PREDICT: dict[str, Any] = {"points": {"load_N": [0.002, 0.01, 0.04], "speed_m_s": 0.05}}

#: Six first runs to fit mu_pivot over 4-12 balls, 3-24 mN and two speeds.
FIRST_EXPERIMENTS: dict[str, Any] = {
    "runs": 6, "fit_parameters": ["mu_pivot"],
    "space": {"balls": {"low": 4, "high": 12}, "load_N": {"low": 0.003, "high": 0.024},
              "speed_m_s": {"values": [0.01, 0.1]}}}

#: Six next runs for a calibration of CALIBRATION (its data's ranges), shrinking its parameters' spread.
NEXT_EXPERIMENTS: dict[str, Any] = {
    "runs": 6, "goal": "parameters",
    "space": {"balls": {"low": 4, "high": 12}, "load_N": {"low": 0.003, "high": 0.024},
              "speed_m_s": {"values": [0.01, 0.1]}}}

#: The measurements of CALIBRATION as a spreadsheet might name them: load in mN and speed in mm/s
#: (converted to SI; the report's intake lists each conversion).
CALIBRATION_UNITS: dict[str, Any] = {
    "fit_parameters": ["mu_pivot"], "folds": 3,
    "data": [{"balls": row["balls"], "load [mN]": round(row["load_N"] * 1e3, 9),
              "speed [mm/s]": round(row["speed_m_s"] * 1e3, 9), "mu_measured": row["mu_measured"]}
             for row in CALIBRATION["data"]]}

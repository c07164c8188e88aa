"""Simulated lab data shared by the experiment-design tests (the truth written here, not taken from
``physics.effects``)."""

from __future__ import annotations

import numpy as np

from bench.calibrated_batch import measurements
from microbearing import physics


def kelvin_rows(seed: int = 3, n: int = 150, humidity: tuple[float, float] = (0.2, 0.5),
                noise: float = 0.02) -> list[dict]:
    """Adhesion growing with humidity by a Kelvin law (0.05 (1 + 1.5 / ln(1/h)) J/m^2, mu_pivot 0.7),
    measured at ``n`` random settings in the ``humidity`` range with ``noise`` (SD of log mu) scatter."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 6, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.0, 0.15, n), "relative_humidity": rng.uniform(*humidity, n)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7,
                          adhesion_energy_J_m2=0.05 * (1 + 1.5 / np.log(1 / c["relative_humidity"]))).mu
    mu = mu * np.exp(rng.normal(0, noise, n))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]


def lab_header_rows(seed: int = 3) -> list[dict]:
    """bench/calibrated_batch.py's menisci data under a lab's headers: humidity in percent as
    ``relative humidity [%]``, temperature in degF as ``temp_F`` (converted by hand: F = C * 9/5 + 32)."""
    rows = []
    for row in measurements(seed):
        row = dict(row)
        row["relative humidity [%]"] = row.pop("relative_humidity") * 100.0
        row["temp_F"] = row.pop("temperature_C") * 9.0 / 5.0 + 32.0
        rows.append(row)
    return rows

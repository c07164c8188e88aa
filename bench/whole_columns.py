"""What taking ``4.0`` as a ball count costs a batch column: validation of /v1/friction/batch bodies.

A column of a whole-number input (``"balls": [4, 6, ...]``) used to be validated as strict ``int``
(``4.0`` refused); its elements now go through :func:`service.schemas.base.whole_number` as every other
whole-number field does (``4.0`` read as 4). This bench validates the same JSON bodies with
``FrictionBatchPoints`` (the service's model) and with a copy built the old way, side by side in one
run: a ball column written as integers, the same written with fractions (refused by the old model,
so only the new one is timed there), and a batch whose ball count is a scalar (both models do the
same work). The load and speed columns are lists in every body, as in a real batch; median of
repeats, in ms per body.

    .venv/bin/python bench/whole_columns.py            # 100,000 and 1,000,000 points
    .venv/bin/python bench/whole_columns.py --quick    # 100,000 points
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from typing import Annotated

import numpy as np
from pydantic import Field, ValidationError, create_model

from microbearing import physics
from microbearing.service.schemas.base import StrictModel, parameter_fields
from microbearing.service.schemas.friction import FrictionBatchPoints


def _old_model() -> type[StrictModel]:
    """FrictionBatchPoints as it was: a column's whole-number elements strict ``int`` (4.0 refused)."""
    fields = parameter_fields(columns=True)
    spec = physics.PARAMETERS["balls"]
    scalar = fields["balls"][0].__args__[0]  # the scalar branch (unchanged)
    element = Annotated[int, Field(ge=int(spec.minimum), le=int(spec.maximum))]
    fields["balls"] = (scalar | list[element], fields["balls"][1])
    return create_model("OldFrictionBatchPoints", __base__=StrictModel, **fields)


def _bodies(points: int) -> dict[str, bytes]:
    rng = np.random.default_rng(0)
    loads = rng.uniform(1e-3, 1e-2, points).tolist()
    speeds = rng.uniform(0.0, 0.15, points).tolist()
    balls = rng.integers(3, 25, points)
    return {
        "balls a column of integers": json.dumps(
            {"balls": balls.tolist(), "load_N": loads, "speed_m_s": speeds}).encode(),
        "balls a column written 4.0": json.dumps(
            {"balls": balls.astype(float).tolist(), "load_N": loads, "speed_m_s": speeds}).encode(),
        "balls a scalar": json.dumps({"balls": 4, "load_N": loads, "speed_m_s": speeds}).encode(),
    }


def _time(model: type[StrictModel], body: bytes, repeats: int) -> float | None:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        try:
            model.model_validate_json(body)
        except ValidationError:
            return None
        times.append(time.perf_counter() - start)
    return statistics.median(times) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="100,000 points only")
    args = parser.parse_args()
    old, new = _old_model(), FrictionBatchPoints
    print(f"before: {os.cpu_count()} CPUs, load average {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
    for points in (100_000,) if args.quick else (100_000, 1_000_000):
        repeats = 7 if points <= 100_000 else 3
        print(f"{points:,} points, median of {repeats}, ms per body "
              "(old: strict int elements; new: whole_number)")
        for label, body in _bodies(points).items():
            t_old, t_new = _time(old, body, repeats), _time(new, body, repeats)
            old_text = "refused" if t_old is None else f"{t_old:8.1f}"
            ratio = "" if t_old is None or t_new is None else f"   new / old {t_new / t_old:.2f}"
            print(f"  {label:28s} old {old_text:>8s}   new {t_new:8.1f}{ratio}")
    print(f"after:  {os.cpu_count()} CPUs, load average {', '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()

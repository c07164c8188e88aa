"""The bearing's friction coefficient and every other output: :func:`evaluate`.

Equations 1-23 of Olaru et al. (2005), composed at every point by
:func:`physics.kernel.point_outputs` from the equations' own functions. This module checks the
inputs, runs that kernel (on Python floats for one point, on numpy arrays block by block, or
compiled by numba), shares large calls between the threads of an executor the caller passes in,
and returns the outputs. The ball's balance (eqs 14, 18-23) is :mod:`physics.balance`, whose
functions are re-exported here.

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 1-23.
.. [2] M.R.D. Balan, L. Houpert, A. Tufescu, D.N. Olaru, Lubricants 3(2), 2015
   (the ball balance F_S = ΣM/d + F_R).
"""

from __future__ import annotations

import functools
import itertools
import math
import operator
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from . import compiled, kernel, replay
from .balance import (
    MIN_BALLS_TOUCHING,
    ball_ball_contact,
    ball_race_force,
    checked_convention,
    contact_shear_force,
    force_balance_residual,
    friction_coefficient,
    moment_balance_residual,
    sliding_force,
    total_friction_force,
)
from .execution import ExecutionOptions
from .parameters import DEFAULT_CONVENTION, checked_inputs

__all__ = [
    "ExecutionOptions",
    "FrictionResult",
    "OUTPUTS",
    "evaluate",
    "evaluate_point",
    "sliding_force",
    "contact_shear_force",
    "ball_race_force",
    "total_friction_force",
    "friction_coefficient",
    "force_balance_residual",
    "MIN_BALLS_TOUCHING",
    "ball_ball_contact",
    "moment_balance_residual",
]


#: Every output of :func:`evaluate`: name -> (unit, description).
OUTPUTS: dict[str, tuple[str, str]] = {
    "mu": ("1", "Global friction coefficient of the bearing, F_total / G (eq 23)."),
    "mu_contact": ("1", "Per-contact ball-race coefficient F_ballrace / (2 Q0) of the "
                   "paper's Fig. 5; equals mu * cos(theta)."),
    "friction_force_N": ("N", "Total tangential resistance on the slider, z F_ballrace (eq 22)."),
    "mu_pivoting": ("1", "Part of mu due to the pivoting moments."),
    "mu_hysteresis": ("1", "Part of mu due to the elastic-hysteresis moments."),
    "mu_rolling": ("1", "Part of mu due to the hydrodynamic rolling forces."),
    "mu_ball_ball": ("1", "Part of mu due to the ball-ball capillary friction moment."),
    "contact_load_N": ("N", "Applied normal load Q0 on each ball-race contact (eq 7)."),
    "contact_load_adhesive_N": ("N", "JKR apparent load Q = Q0 plus adhesion (eq 8)."),
    "contact_radius_m": ("m", "JKR contact radius a (eq 3)."),
    "contact_area_m2": ("m^2", "Contact area pi a^2 (eq 3)."),
    "max_contact_pressure_Pa": ("Pa", "Peak pressure 3Q / (2 pi a^2) at a ball-race contact: the Hertz "
                                "peak of the adhesion-enhanced JKR load Q (eq 8) over the JKR contact "
                                "radius a (eq 3), not the applied load Q0 (the JKR distribution itself "
                                "is not Hertzian: it turns tensile at the edge)."),
    "adhesion_force_N": ("N", "JKR pull-off force 3 pi gamma R of a ball on a flank (eq 1)."),
    "capillary_force_ball_ball_N": ("N", "Capillary force between touching balls, 4 pi gamma_w R* "
                                    "(eqs 5-6); 0 when balls do not touch or balls = 1."),
    "rolling_force_N": ("N", "Houpert hydrodynamic rolling force F_R of one contact (eq 9)."),
    "pressure_force_N": ("N", "Pressure force F_P = 2 F_R on the ball centre (eq 13)."),
    "sliding_force_N": ("N", "Sliding traction F_S of one contact from the ball balance (eq 20)."),
    "hysteresis_moment_Nm": ("N*m", "Elastic-hysteresis moment M_ER of one contact (eq 15)."),
    "pivoting_moment_Nm": ("N*m", "Pivoting moment M_P of one contact (eq 16)."),
    "ball_ball_moment_Nm": ("N*m", "Ball-ball friction moment M_b of one ball (eq 17)."),
    "ball_race_force_N": ("N", "Tangential resistance F_ballrace of one ball (eq 21)."),
}


@dataclass(frozen=True)
class FrictionResult:
    """Outputs of :func:`evaluate`, each an array of the broadcast input shape.

    The attributes are the keys of :data:`OUTPUTS`, where each has its unit
    and meaning. ``mu_pivoting + mu_hysteresis + mu_rolling + mu_ball_ball``
    equals ``mu``. Outputs left out by ``evaluate(outputs=...)`` are ``None``.
    """

    mu: np.ndarray | None
    mu_contact: np.ndarray | None
    friction_force_N: np.ndarray | None
    mu_pivoting: np.ndarray | None
    mu_hysteresis: np.ndarray | None
    mu_rolling: np.ndarray | None
    mu_ball_ball: np.ndarray | None
    contact_load_N: np.ndarray | None
    contact_load_adhesive_N: np.ndarray | None
    contact_radius_m: np.ndarray | None
    contact_area_m2: np.ndarray | None
    max_contact_pressure_Pa: np.ndarray | None
    adhesion_force_N: np.ndarray | None
    capillary_force_ball_ball_N: np.ndarray | None
    rolling_force_N: np.ndarray | None
    pressure_force_N: np.ndarray | None
    sliding_force_N: np.ndarray | None
    hysteresis_moment_Nm: np.ndarray | None
    pivoting_moment_Nm: np.ndarray | None
    ball_ball_moment_Nm: np.ndarray | None
    ball_race_force_N: np.ndarray | None
    convention: str = DEFAULT_CONVENTION

    def to_dict(self, outputs=None) -> dict[str, np.ndarray]:
        """The outputs as a dict of arrays: those named, or every one computed."""
        if outputs is None:
            return {name: value for name in OUTPUTS if (value := getattr(self, name)) is not None}
        values = {name: getattr(self, name) for name in _output_names(outputs)}
        missing = [name for name, value in values.items() if value is None]
        if missing:
            raise ValueError(f"outputs {', '.join(missing)} were not computed; "
                             "name them in evaluate(outputs=...)")
        return values


if [f.name for f in fields(FrictionResult)][:-1] != list(OUTPUTS):  # explicit: asserts vanish under -O
    raise ImportError("FrictionResult's fields must be OUTPUTS in order, then the convention")

def evaluate(convention: str = DEFAULT_CONVENTION, outputs: Iterable[str] | None = None, *,
             execution: ExecutionOptions | None = None, **params: Any) -> FrictionResult:
    r"""Friction of a micro linear ball bearing by the model of Olaru et al. (2005).

    Parameters
    ----------
    convention : {"olaru2005", "derjaguin"}, default "olaru2005"
        Reading of the paper's ambiguous ball-ball terms; see
        :data:`physics.CONVENTIONS`.
    outputs : iterable of str, optional
        Names from :data:`OUTPUTS` to return; by default all. The others are
        ``None`` in the result. Most outputs are each other's intermediates and
        are computed anyway, but only those asked for are stored (on large
        inputs, writing 21 arrays to fresh memory costs as much as the
        arithmetic); the area, peak pressure, F_P, mu_contact and the breakdown
        of μ, which nothing else needs, are computed only when one of them is
        asked for.
    execution : ExecutionOptions, optional
        The kernel of a call on arrays and the threads (an executor) that share a large call;
        by default numpy's kernel in the caller's thread.
    **params : numeric, bool or array_like
        The inputs of :data:`physics.PARAMETERS` by name: ``balls`` [1] (every
        ball of both grooves: the paper's case B, 9 per groove, is 18),
        ``load_N`` [N] and ``speed_m_s`` [m/s] are required, the rest have
        defaults (stainless-steel balls of 285 um on silicon at 54.7 deg, water
        film, γ = 0.18 J/m²). Scalars and arrays broadcast together.

    Returns
    -------
    FrictionResult
        Every quantity of :data:`OUTPUTS` (or those of ``outputs``), as arrays
        of the broadcast shape.

    Raises
    ------
    ValueError
        For unknown or missing parameters, values out of range (naming the
        parameter and its range), shapes that do not broadcast, unknown
        output names.

    Notes
    -----
    Per contact: Q0 (eq 7), Q (eq 8), a (eq 3), F_R with E', Rx = R, k = 1,
    v = V/2 (eqs 9-12), F_P = 2 F_R (eq 13), M_ER (eq 15) and M_P (eq 16) with
    Q; per ball M_b (eq 17) with F_cb from eqs 5-6 when balls touch and there
    are at least two of them (:func:`ball_ball_contact`; ``balls`` counts the
    balls of both grooves, and one ball has no neighbour). Then F_S
    (eq 20), F_ballrace (eq 21), F_total (eq 22) and μ (eq 23). Speed enters
    only through F_R.

    Every output is :func:`physics.kernel.point_outputs`, the composition of the
    equations' functions, run on numpy arrays of 16,384 points at a time (so that the
    intermediates stay in the CPU's cache; from 1,024 points on as its trace replayed into one
    workspace, :mod:`physics.replay`, the same operations), or compiled by numba
    (``execution=ExecutionOptions(kernel="numba")``, ``pip install microbearing[fast]``), which
    agrees with numpy to 1e-12 relative (tested). Calls of 8 blocks or more are split into up to
    ``execution.threads`` contiguous runs of blocks on ``execution.executor`` (numpy and the
    compiled loop release the GIL; throughput: ``bench/physics.py``). The power laws of eqs 9
    and 15 are exp of logarithms, and tan θ is taken directly and cos θ from it; this agrees
    with the plain composition of the equations' functions to ~1e-13 (tested). Every point
    runs the same operations whatever the size of the call or the number of threads, so results
    do not depend on batching. A call whose inputs are all scalars runs the same functions on
    Python floats (numpy's tan, cbrt, log and exp), after the same checks, without numpy's
    per-call overhead, and returns ``numpy.float64`` values equal bit for bit to the same point
    inside an array.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005.

    Examples
    --------
    Case A of the paper (4 balls, slider of 0.9 g, no adhesion, μs = 1):

    >>> r = evaluate(balls=4, load_N=0.9e-3 * 9.80665, speed_m_s=0.1,
    ...              mu_pivot=1.0, adhesion_energy_J_m2=0.0)
    >>> round(float(r.mu_contact), 4)
    0.0051
    """
    checked_convention(convention)
    execution = _SERIAL if execution is None else execution
    p, shape = checked_inputs(params)  # scalars as Python numbers: their products fold before arrays
    wanted = list(OUTPUTS) if outputs is None else _output_names(outputs)
    extras = not _EXTRAS.isdisjoint(wanted)
    if not shape:  # one point: the same functions on Python floats, without numpy's per-call overhead
        return _point_result(_point(p, convention, extras), wanted, convention)
    size = math.prod(shape)
    flat = {k: np.broadcast_to(v, shape).reshape(-1) if isinstance(v, np.ndarray) else v
            for k, v in p.items()}
    kept = np.empty((len(wanted), size))
    point = tuple(flat[name] for name in kernel.POINT_INPUTS)
    material = _material(flat, convention)
    runner = _compiled_runner if execution.kernel == "numba" else _numpy_runner
    _run_parts(runner(point, material, kept, [_POSITIONS[name] for name in wanted], extras), size, execution)
    values = dict(zip(wanted, kept.reshape(len(wanted), *shape), strict=True))
    return FrictionResult(**{k: values.get(k) for k in OUTPUTS}, convention=convention)


def evaluate_point(convention: str = DEFAULT_CONVENTION, **params: Any) -> dict[str, float]:
    """Every output of :func:`evaluate` at one point, as Python floats by name (in :data:`OUTPUTS` order).

    The same checks and operations as :func:`evaluate` with scalar inputs, whose outputs are
    these floats as ``numpy.float64``: for callers of one point at a time (the REST API's
    ``/v1/friction``), to whom building those scalars and a :class:`FrictionResult` would cost
    half as much again as the point itself.

    Parameters
    ----------
    convention : {"olaru2005", "derjaguin"}, default "olaru2005"
        As in :func:`evaluate`.
    **params : float, int or bool
        Scalar inputs of :data:`physics.PARAMETERS` by name, as in :func:`evaluate`.

    Returns
    -------
    dict of float
        Every output of :data:`OUTPUTS` in its unit.

    Raises
    ------
    ValueError
        As :func:`evaluate` does, and for an input that is an array (naming it).

    Examples
    --------
    >>> point = evaluate_point(balls=4, load_N=0.9e-3 * 9.80665, speed_m_s=0.1)
    >>> type(point["mu"]).__name__, point["mu"] == float(evaluate(balls=4, load_N=0.9e-3 * 9.80665,
    ...                                                           speed_m_s=0.1).mu)
    ('float', True)
    """
    checked_convention(convention)
    p, shape = checked_inputs(params)
    if shape:
        arrays = [name for name, value in p.items() if isinstance(value, np.ndarray)]
        raise ValueError(f"{arrays[0]} must be a scalar for evaluate_point; use evaluate for arrays")
    return dict(zip(OUTPUTS, _point(p, convention, True), strict=True))


#: Outputs that no other output needs: the kernel skips them when none is asked for.
_EXTRAS = frozenset({"contact_area_m2", "max_contact_pressure_Pa", "pressure_force_N", "mu_contact",
                     "mu_pivoting", "mu_hysteresis", "mu_rolling", "mu_ball_ball"})
#: Position of each output in what :func:`physics.kernel.point_outputs` returns.
_POSITIONS = {name: position for position, name in enumerate(OUTPUTS)}
#: How a call runs when the caller says nothing: numpy's kernel, in the caller's thread.
_SERIAL = ExecutionOptions()


def _output_names(outputs: Iterable[str]) -> list[str]:
    names = [outputs] if isinstance(outputs, str) else list(outputs)
    unknown = [n for n in names if n not in OUTPUTS]
    if unknown or not names:
        raise ValueError(f"outputs must be names from {', '.join(OUTPUTS)}; got {names!r}")
    return list(dict.fromkeys(names))


def _point_result(values: tuple[float, ...], wanted: list[str], convention: str) -> FrictionResult:
    """The result of one point from the kernel's floats, as ``numpy.float64`` like an array's items.

    Filled through the instance's ``__dict__``: the frozen dataclass's ``__init__`` sets its 22
    fields one ``object.__setattr__`` call at a time, which would cost a third of the point. Each
    float becomes a ``numpy.float64`` by itself (exact): a one-point array and its items would
    cost twice as much.
    """
    result = object.__new__(FrictionResult)
    state = result.__dict__
    state.update(dict.fromkeys(OUTPUTS), convention=convention)
    state.update((name, np.float64(values[_POSITIONS[name]])) for name in wanted)
    return result


def _point(p: dict[str, Any], convention: str, extras: bool) -> tuple[float, ...]:
    """The outputs of one checked point (Python numbers), in :data:`OUTPUTS` order."""
    return kernel.point_outputs(_point_inputs(p), _material(p, convention), extras)


_point_inputs = operator.itemgetter(*kernel.POINT_INPUTS)
_material_inputs = operator.itemgetter(*kernel.MATERIAL_INPUTS)


def _material(p: dict[str, Any], convention: str) -> tuple:
    """:func:`physics.kernel.material` of the call: floats unless a material input varies."""
    values = _material_inputs(p)
    if all(type(v) is float for v in values):
        return _scalar_material(values, convention)
    return kernel.material(dict(zip(kernel.MATERIAL_INPUTS, values, strict=True)), convention)


@functools.lru_cache(maxsize=64)
def _scalar_material(values: tuple[float, ...], convention: str) -> tuple[float, ...]:
    # Repeated single-point calls (the REST API's) mostly share their materials; Python floats
    # keep the one-point kernel in Python's own arithmetic.
    material = kernel.material(dict(zip(kernel.MATERIAL_INPUTS, values, strict=True)), convention)
    return tuple(map(float, material))


#: Points per block of the numpy kernel: the block's intermediates stay in the CPU's cache.
_BLOCK_POINTS = 16384
#: Fewest blocks a thread is given: below 2 x 4 blocks a call runs in the caller's thread.
_MIN_BLOCKS_PER_THREAD = 4
#: Fewest points of a call that :mod:`physics.replay` runs: below, its Python steps (about 50 ufunc
#: calls into a workspace) cost more than the temporaries of the equation functions on the arrays
#: (``bench/physics.py``; both the same under 1 ms at 1,000 points).
_REPLAY_POINTS = 1024


def _numpy_runner(point: tuple, material: tuple, kept: np.ndarray, positions: list[int],
                  extras: bool) -> Callable[[int, int], None]:
    """``run(lo, hi)``: :func:`physics.kernel.point_outputs` over points ``lo:hi`` into ``kept``.

    From :data:`_REPLAY_POINTS` points on, its trace replayed as numpy calls into a block's
    workspace (:mod:`physics.replay`); below, the function itself on the arrays (the same
    operations: the same bits). Calls on disjoint ranges may run in parallel threads.
    """
    if kept.shape[1] >= _REPLAY_POINTS:
        return replay.runner((*point, *material), kept, positions, extras, _BLOCK_POINTS)

    def run(lo: int, hi: int) -> None:
        with np.errstate(divide="ignore"):  # log of a zero speed is -inf, exp(-inf) = 0
            values = kernel.point_outputs(_slices(point, lo, hi), _slices(material, lo, hi), extras)
        for row, position in zip(kept, positions, strict=True):
            row[lo:hi] = values[position]
    return run


def _slices(values: tuple, start: int, stop: int) -> tuple:
    return tuple(v[start:stop] if isinstance(v, np.ndarray) else v for v in values)


def _compiled_runner(point: tuple, material: tuple, kept: np.ndarray, positions: list[int],
                     extras: bool) -> Callable[[int, int], None]:
    """``run(lo, hi)`` of :func:`physics.compiled.points` over the call's inputs, into ``kept``."""
    rows = [-1] * len(OUTPUTS)
    for row, position in enumerate(positions):
        rows[position] = row
    return compiled.points((*point, *material), kept, rows, extras)


def _run_parts(run: Callable[[int, int], None], size: int, execution: ExecutionOptions) -> None:
    """``run`` over every point: in the caller's thread, or as runs of whole blocks on the executor."""
    blocks = -(-size // _BLOCK_POINTS)
    large = blocks >= 2 * _MIN_BLOCKS_PER_THREAD
    parts = min(execution.threads, blocks // _MIN_BLOCKS_PER_THREAD) if large else 1
    if parts < 2:
        run(0, size)
        return
    edges = [_BLOCK_POINTS * (blocks * i // parts) for i in range(parts)] + [size]
    for future in [execution.executor.submit(run, lo, hi) for lo, hi in itertools.pairwise(edges)]:
        future.result()

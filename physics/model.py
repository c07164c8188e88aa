"""What a model of μ is, for every layer above the physics: inputs, outputs, intervals, domain, derivatives.

A :class:`Model` is the physics (:class:`PhysicsModel`, here), a calibrated model
(:class:`calibrate.model_view.CalibratedPhysicsModel`) or a surrogate
(:class:`surrogate.model_view.SurrogateModel`); the service only resolves references
(``"physics"``, ``"calibrated:<id>"``, ``"surrogate:<id>"``) to them, and
:mod:`optimize` uses them without the service. A model states

- its inputs (:class:`ModelInput`: name, unit, allowed range, and the value taken when a
  point does not give it: the physics default, or the value the model fixed or fitted),
  then the condition columns it reads (a calibrated model's effect drivers, e.g.
  ``relative_humidity``);
- the outputs it answers (:attr:`Model.outputs`), μ with its 95 % interval (``mu_lower``,
  ``mu_upper`` [1]) where the model has one (:attr:`Model.has_interval`);
- its domain: :meth:`Model.evaluate` flags the points where its figures do not hold
  (``outside_domain``: a surrogate outside its trained space, a calibrated model outside the
  range of its data).

It is also the ``mu_model(points) -> mu`` callable that :mod:`optimize` and :mod:`surrogate`
take, and it keeps the attributes their callers read (``convention``, ``fixed``, ``fitted``,
``required_columns``). :func:`jacobian` differentiates any model's outputs with respect to its
continuous inputs.

Errors: :class:`InputError` for an input a model refuses (naming the input and the first
offending point), :class:`ModelError` for inputs that are valid one by one but leave no finite
answer (a JSON pointer and a detail per error, which the service answers as a 422 problem).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.differentiate import derivative

from . import bearing, parameters
from .columns import outside_mask, outside_range
from .execution import ExecutionOptions
from .parameters import DEFAULT_CONVENTION, PARAMETERS

__all__ = ["Evaluation", "InputError", "Model", "ModelError", "ModelInput", "PhysicsModel",
           "evaluate_finite", "jacobian", "physics_in", "physics_inputs"]

#: First finite-difference step of a derivative, relative to the input's value. [1]
_RELATIVE_STEP = 1e-2
#: First step where an input is zero, in the input's unit.
_ZERO_STEP = 1e-6
#: Why a non-finite output is refused.
NOT_FINITE = "outside the range where the model is numerically meaningful"


class ModelError(ValueError):
    """Inputs a model accepts one by one that leave no finite answer, or conditions outside a term's law.

    Parameters
    ----------
    errors : list of dict
        ``{"pointer": JSON pointer of the offending field, "detail": what is wrong}`` items.
    """

    def __init__(self, errors: list[dict[str, str]]):
        super().__init__("; ".join(f"{e['pointer']}: {e['detail']}" for e in errors))
        self.errors = errors


def evaluate_finite(inputs: Mapping[str, Any], outputs: Sequence[str] | None, convention: str,
                    pointer: str = "", first_index: int = 0, *,
                    execution: ExecutionOptions | None = None) -> dict[str, np.ndarray]:
    """Run :func:`physics.evaluate` and insist on finite outputs.

    Parameters
    ----------
    inputs : mapping
        Physics inputs by name (scalars or arrays that broadcast), in the units of
        :data:`physics.PARAMETERS`.
    outputs : sequence of str or None
        Outputs to keep (all when None).
    convention : str
        Key of :data:`physics.CONVENTIONS`.
    pointer : str, default ""
        JSON pointer of the inputs in a request body, for the errors.
    first_index : int, default 0
        Index of the first point in the whole request [1], for the errors.
    execution : ExecutionOptions, optional
        The kernel and threads of :func:`physics.evaluate`; by default numpy's in the caller's thread.

    Returns
    -------
    dict of numpy.ndarray
        The chosen outputs, in their units.

    Raises
    ------
    ModelError
        For inputs the physics rejects (pointer ``<pointer>/<name>``) or that drive an output out of
        floating-point range (pointer ``<pointer>``, naming the point).
    """
    outputs = None if outputs is None else [str(name) for name in outputs]
    try:
        # Extreme but allowed inputs (a groove angle next to 90 deg) overflow: refused below.
        with np.errstate(all="ignore"):
            result = bearing.evaluate(convention=str(convention), outputs=outputs, execution=execution,
                                      **inputs).to_dict(outputs)
    except ModelError:
        raise
    except ValueError as exc:
        name = str(exc).split(" ", 1)[0]
        where = f"{pointer}/{name}" if name in PARAMETERS else pointer
        raise ModelError([{"pointer": where, "detail": str(exc)}]) from None
    for name, values in result.items():
        finite = np.isfinite(values)
        if not finite.all():
            index = first_index + int(np.flatnonzero(~finite.reshape(-1))[0])
            at = f" at point {index}" if np.ndim(values) else ""
            raise ModelError([{"pointer": pointer or "/", "detail":
                               f"the model output {name} is not finite{at}: the inputs are {NOT_FINITE}"}])
    return result


class InputError(ValueError):
    """An input value a model refuses.

    Parameters
    ----------
    name : str
        The input.
    index : int or None
        The first offending point (0-based), None for a single value.
    message : str
        What is wrong, naming the allowed range.
    """

    def __init__(self, name: str, index: int | None, message: str):
        super().__init__(message)
        self.name = name
        self.index = index


@dataclass(frozen=True)
class ModelInput:
    """One input of a model.

    Attributes
    ----------
    name : str
        Keyword and column name (a :data:`PARAMETERS` name or a condition column).
    unit : str
        Its unit (``"1"`` for dimensionless).
    description : str
        What it is.
    kind : {"float", "int", "bool", "label"}
        Value type.
    minimum, maximum : float or None
        The allowed range (None: unbounded).
    default : float, bool or None
        The value a point takes when it does not give this input (the physics default or the
        value the model fixed or fitted); None when the input is required.
    domain : tuple of float or None
        Where the model's figures hold, when narrower than the allowed range (a surrogate's
        trained bounds); None otherwise.
    """

    name: str
    unit: str
    description: str
    kind: str = "float"
    minimum: float | None = None
    maximum: float | None = None
    default: float | bool | None = None
    domain: tuple[float, float] | None = None

    @property
    def continuous(self) -> bool:
        """Whether derivatives with respect to this input exist (a real number, not a count or a flag)."""
        return self.kind == "float"

    def coerce(self, values: Any) -> np.ndarray:
        """The values as an array, numbers 0 and 1 as false and true for a boolean input."""
        arr = np.asarray(values)
        if self.kind == "bool" and arr.dtype != np.bool_ and np.isin(arr, (0, 1)).all():
            return arr.astype(bool)
        return arr

    def check(self, values: Any) -> np.ndarray:
        """The values as an array, or :class:`InputError` naming the first offending point.

        Parameters
        ----------
        values : scalar or array_like
            Values of this input, in its unit; numbers 0 and 1 are read as false and true for a
            boolean input, whole floats as counts for an integer one.

        Returns
        -------
        numpy.ndarray
            ``float64`` (``bool`` for a boolean input), in the shape given.
        """
        if self.kind == "label":  # a factor column's group labels (calibrate.groups): text, any value
            return np.asarray(values, dtype=object).astype(str)
        arr = self.coerce(values)
        if self.name in PARAMETERS:
            try:
                return parameters.validate(self.name, arr)
            except ValueError as exc:
                raise InputError(self.name, _first_bad(self.name, arr), str(exc)) from None
        arr = np.asarray(arr, dtype=np.float64)
        finite = np.isfinite(arr)
        if not finite.all():
            index = int(np.flatnonzero(~finite.reshape(-1))[0]) if arr.ndim else None
            raise InputError(self.name, index, f"{self.name} must be a finite number [{self.unit}]")
        outside = outside_mask(self.name, arr, self.minimum, self.maximum)
        if outside.any():  # a condition's physical range (a time counted from zero, a fraction)
            index = int(np.flatnonzero(outside.reshape(-1))[0]) if arr.ndim else None
            value = arr.reshape(-1)[index or 0]
            raise InputError(self.name, index, outside_range(self.name, value, self.minimum, self.maximum,
                                                             self.unit))
        return arr


def _first_bad(name: str, arr: np.ndarray) -> int | None:
    """Index of the first value :func:`physics.validate` refuses (only on the error path)."""
    if not arr.ndim:
        return None
    for index, value in enumerate(arr.reshape(-1)):
        try:
            parameters.validate(name, value.item() if hasattr(value, "item") else value)
        except ValueError:
            return index
    return None


@dataclass(frozen=True)
class Evaluation:
    """Outputs of a model at columnar points.

    Attributes
    ----------
    values : dict of str to numpy.ndarray
        The outputs asked for, in their units, one value per point.
    outside_domain : numpy.ndarray of bool
        True where the model's figures do not hold (a surrogate outside its trained space).
    warnings : list of str
        One sentence per input or condition outside a calibrated model's data, naming the column,
        the values and the range (empty for other models).
    """

    values: dict[str, np.ndarray]
    outside_domain: np.ndarray
    warnings: list[str] = field(default_factory=list)


def physics_inputs(values: Mapping[str, Any], domains: Mapping[str, tuple[float, float]] | None = None,
                    required: Sequence[str] = ()) -> dict[str, ModelInput]:
    """The :class:`ModelInput` of every physics parameter, with defaults taken from ``values``."""
    inputs = {}
    for name, spec in PARAMETERS.items():
        default = None if name in required else values.get(name, spec.default)
        inputs[name] = ModelInput(name, spec.unit, spec.description, spec.kind, spec.minimum, spec.maximum,
                                  default, (domains or {}).get(name))
    return inputs


class Model:
    """A model of μ: the physics, a calibrated model or a surrogate (see the module docstring).

    Subclasses set the attributes and implement :meth:`evaluate` and :meth:`__call__`.

    Attributes
    ----------
    reference : str
        ``"physics"``, ``"calibrated:<id>"`` or ``"surrogate:<id>"``.
    kind : str
        One of :data:`KINDS`.
    convention : str
        Reading of the physics (:data:`physics.CONVENTIONS`).
    fixed : dict
        Physics inputs the model holds at a value (a calibration's fixed values, a surrogate's).
    fitted : dict
        Physics inputs a calibration fitted (empty for other models).
    required_columns : list of str
        Condition columns a point must give besides the physics inputs.
    inputs : dict of str to ModelInput
        Every input the model reads: the physics parameters in table order, then the conditions.
    outputs : tuple of str
        Output names :meth:`evaluate` answers.
    has_interval : bool
        Whether ``mu_lower`` and ``mu_upper`` (95 %) are among the outputs.
    derivative_rtol : float
        Relative accuracy a derivative of :func:`jacobian` must reach (scipy's error estimate). [1]
    """

    reference: str
    kind: str
    convention: str
    fixed: dict[str, Any]
    fitted: dict[str, float]
    required_columns: list[str]
    inputs: dict[str, ModelInput]
    outputs: tuple[str, ...]
    has_interval: bool = False
    derivative_rtol: float = 1e-6

    @property
    def default_inputs(self) -> list[str]:
        """The inputs a point must give: those with no default."""
        return [name for name, spec in self.inputs.items() if spec.default is None]

    @property
    def headers(self) -> dict[str, str]:
        """Each column's header as the model's data sent it in another unit than its name says (a
        calibration's upload), for :func:`physics.slips.unstated_unit`; none here."""
        return {}

    @property
    def column_checks(self) -> dict[str, ModelInput]:
        """Every column a point may give, with its check: :attr:`inputs` (a calibrated model adds the
        condition columns of its data that its terms do not read, checked against the data's range)."""
        return self.inputs

    def check(self, points: Mapping[str, Any]) -> dict[str, Any]:
        """Checked columns: every given input through :meth:`ModelInput.check`, the rest filled in.

        Raises
        ------
        InputError
            For an unknown input, an invalid value or a missing required input.
        """
        unknown = [name for name in points if name not in self.inputs]
        if unknown:
            raise InputError(unknown[0], None, f"{unknown[0]} is not an input of {self.reference}; its "
                             f"inputs are {', '.join(self.inputs)}")
        missing = [name for name in self.default_inputs if name not in points]
        if missing:
            raise InputError(missing[0], None, f"{self.reference} needs {', '.join(missing)}")
        return {name: self.inputs[name].check(value) for name, value in points.items()}

    def unread_words(self, name: str, value: float) -> str | None:
        """Why this model cannot be asked at ``value`` of an input it holds at another value (its default in
        :attr:`inputs`), without its reference; None when it reads the input whatever it holds (the physics,
        a calibrated model: a given value overrides). The caller compares the values."""
        return None

    def evaluate(self, points: Mapping[str, Any], outputs: Sequence[str], *, pointer: str = "",
                 first_index: int = 0) -> Evaluation:
        """The outputs at columnar points (checked with :meth:`check` first).

        Parameters
        ----------
        points : mapping of str to array_like
            Inputs by name, broadcasting together; inputs not given take their default.
        outputs : sequence of str
            Names from :attr:`outputs`.
        pointer : str, default ""
            JSON pointer of the points in the request body, for the problems a physics
            evaluation raises.
        first_index : int, default 0
            Index of the first point in the whole request [1] (a chunk's offset), for those problems.

        Returns
        -------
        Evaluation

        Raises
        ------
        InputError
            For invalid inputs.
        ModelError
            When an output is not finite, or a condition is outside a term's law.
        """
        raise NotImplementedError

    def __call__(self, points: Mapping[str, Any]) -> np.ndarray:
        """μ [1] at columnar points: the ``mu_model(points)`` seam of optimize and surrogate."""
        raise NotImplementedError


class PhysicsModel(Model):
    """The declared friction model, :func:`physics.evaluate`, in one convention and execution."""

    kind = "physics"
    outputs = tuple(bearing.OUTPUTS)

    def __init__(self, convention: str = DEFAULT_CONVENTION, execution: ExecutionOptions | None = None):
        self.reference = "physics"
        self.convention = str(convention)
        self.execution = execution
        self.fixed, self.fitted, self.required_columns = {}, {}, []
        self.inputs = physics_inputs({})

    def evaluate(self, points: Mapping[str, Any], outputs: Sequence[str], *, pointer: str = "",
                 first_index: int = 0) -> Evaluation:
        # physics.evaluate checks its inputs itself; only a refusal is checked again, to name the point.
        try:
            values = evaluate_finite(dict(points), list(outputs), self.convention, pointer, first_index,
                                     execution=self.execution)
        except ModelError:
            self.check(points)
            raise
        return Evaluation(values, np.zeros(np.broadcast_shapes(*(np.shape(v) for v in values.values())),
                                           dtype=bool))

    def __call__(self, points: Mapping[str, Any]) -> np.ndarray:
        return bearing.evaluate(convention=self.convention, outputs=["mu"], execution=self.execution,
                                **points).mu


@functools.cache
def physics_in(convention: str = DEFAULT_CONVENTION,
               execution: ExecutionOptions | None = None) -> PhysicsModel:
    """The physics in one convention (one instance each: it holds no state).

    What a reference ``"physics"`` resolves to; batches, sweeps and the optimizer, which evaluate
    only the physics, take it from here.

    Parameters
    ----------
    convention : str
        Key of :data:`physics.CONVENTIONS`.
    execution : ExecutionOptions, optional
        The kernel and threads of its evaluations (the service's settings); by default numpy's in
        the caller's thread.

    Returns
    -------
    PhysicsModel
    """
    return PhysicsModel(str(convention), execution)


def _steps(spec: ModelInput, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First step and direction of :func:`scipy.differentiate.derivative` inside an input's range.

    Central differences reach one step either side; where a bound is closer, the steps go
    one-sided toward the interior, at most half-way to the other bound.
    """
    step = np.where(x != 0, _RELATIVE_STEP * np.abs(x), _ZERO_STEP)
    below = np.inf if spec.minimum is None else x - spec.minimum
    above = np.inf if spec.maximum is None else spec.maximum - x
    central = (below > step) & (above > step)
    direction = np.where(central, 0, np.where(above >= below, 1, -1))
    room = np.where(direction > 0, above, below)
    step = np.where(central, step, np.minimum(step, 0.5 * room))
    return step, direction


def jacobian(model: Model, points: Mapping[str, Any], wrt: Sequence[str],
             outputs: Sequence[str]) -> np.ndarray:
    """Derivatives of outputs with respect to continuous inputs, at each of ``n`` points.

    By :func:`scipy.differentiate.derivative` (finite differences of order 8 with Richardson
    extrapolation and an error estimate), all points, inputs and outputs in one vectorized
    call of the model per iteration, steps kept inside each input's allowed range.

    Parameters
    ----------
    model : Model
        The model.
    points : mapping of str to array_like
        Inputs by name: arrays of length ``n`` or scalars.
    wrt : sequence of str
        Continuous inputs to differentiate with respect to; each must be in ``points``.
    outputs : sequence of str
        Outputs to differentiate.

    Returns
    -------
    numpy.ndarray of shape (n, len(outputs), len(wrt))
        d output / d input, in output unit per input unit.

    Raises
    ------
    InputError
        For an input that is not continuous, or where the derivative does not reach
        ``model.derivative_rtol`` (no derivative at a bound or a kink, e.g. d mu / d speed at
        speed 0).
    """
    checked = model.check(points)
    n = int(np.prod(np.broadcast_shapes(*(np.shape(v) for v in checked.values()))))
    columns = {name: np.broadcast_to(value, (n,)) if np.ndim(value) else value
               for name, value in checked.items()}
    for name in wrt:
        spec = model.inputs[name]
        if not spec.continuous:
            raise InputError(name, None, f"{name} is a {'count' if spec.kind == 'int' else 'flag'}: "
                             "derivatives are taken with respect to continuous inputs only")
    x0 = np.stack([np.broadcast_to(np.asarray(columns[name], dtype=float), (n,)) for name in wrt])  # (k, n)
    steps, directions = zip(*(_steps(model.inputs[name], row) for name, row in zip(wrt, x0, strict=True)),
                            strict=True)
    grid = (len(outputs), len(wrt), n)
    out_index, in_index, point_index = np.indices(grid)

    def f(x: np.ndarray, out_i: np.ndarray, in_i: np.ndarray, point_i: np.ndarray) -> np.ndarray:
        shape = np.broadcast_shapes(x.shape, out_i.shape, in_i.shape, point_i.shape)
        x, out_i, in_i, point_i = (a.reshape(-1) for a in np.broadcast_arrays(x, out_i, in_i, point_i))
        at = {name: value[point_i] if np.ndim(value) else value for name, value in columns.items()}
        for j, name in enumerate(wrt):
            at[name] = np.where(in_i == j, x, at[name])
        values = model.evaluate(at, outputs).values
        stacked = np.stack([np.broadcast_to(values[name], x.shape) for name in outputs])
        return stacked[out_i.astype(int), np.arange(x.size)].reshape(shape)

    x = np.broadcast_to(x0, grid)
    first_step = np.broadcast_to(np.stack(steps), grid)
    with np.errstate(all="ignore"):
        result = derivative(f, x, args=(out_index, in_index, point_index), initial_step=first_step,
                            step_direction=np.broadcast_to(np.stack(directions), grid))
        # An output that does not depend on an input has a derivative of zero up to rounding: the
        # error is judged against the output's own scale per unit of the input too.
        scale = np.abs(f(x, out_index, in_index, point_index)) / np.maximum(np.abs(x), first_step)
    accurate = np.isfinite(result.df) & (result.error <= model.derivative_rtol * (np.abs(result.df) + scale))
    if not accurate.all():
        _, j, i = (int(a[0]) for a in np.nonzero(~accurate))
        raise InputError(wrt[j], i, f"the derivative with respect to {wrt[j]} at {wrt[j]} = {x0[j, i]:g} "
                         f"[{model.inputs[wrt[j]].unit}] cannot be computed to {model.derivative_rtol:g} "
                         "relative accuracy (no derivative there, e.g. at a bound of its range)")
    return np.moveaxis(result.df, -1, 0)

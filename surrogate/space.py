"""The input space of a surrogate: named physics parameters with bounds, the rest fixed.

A :class:`Space` maps three coordinate systems onto each other:

* **physical** ``X[n, d]``: the values of the ``d`` free parameters in their SI
  units (degrees for the groove angle), columns in :attr:`Space.names` order;
  booleans as 0/1, integers as whole floats;
* **unit** ``U[n, d]`` in ``[0, 1]^d``: where designs of experiments live. Each
  dimension is mapped by its *scale*: ``"log"`` for positive, scale-spanning
  inputs (load, speed, diameter...), ``"power"`` (``x**p``) for inputs whose
  range starts at 0 (speed ``V**0.66`` because the rolling force grows as
  ``V**0.66``; adhesion energy ``sqrt(γ)`` from the JKR load), ``"linear"``
  otherwise. Integer dimensions are rounded and boolean ones thresholded at 0.5
  on the way back, so a design is always physically valid;
* **features** ``Z[n, k]``: the inputs of the Gaussian process (see
  :meth:`Space.features`), continuous even for integer ``balls``.

The physics (or any ``mu_model(points) -> mu`` callable, such as a calibrated
model) is evaluated through :meth:`Space.evaluate` (vectorized, like the
``Problem`` classes of SMT).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

import microbearing.physics.contact  # noqa: F401  (loads the submodule)
from microbearing import physics

__all__ = ["SCALES", "FEATURE_SETS", "Space"]

#: Allowed per-dimension scales of the unit-cube map.
SCALES = ("log", "power", "linear")

#: Allowed feature sets of :meth:`Space.features`.
FEATURE_SETS = ("dry_contact", "physics", "scaled", "raw")

# Exponents of the "power" scale, used when a range starts at 0 so that log is undefined:
# mu grows with the rolling force F_R ∝ V**0.66 (Houpert, eq 9), and the JKR load
# Q = Q0 + c + sqrt(2 c Q0 + c²) with c ∝ γ varies like sqrt(γ) near γ = 0 (eq 8).
_POWER_EXPONENTS = {"speed_m_s": 0.66, "adhesion_energy_J_m2": 0.5}
_DEFAULT_POWER_EXPONENT = 0.5
# A positive range spanning at least this ratio is mapped in log.
_LOG_RATIO = 4.0


def _as_float(name: str, value: Any) -> float:
    """A bound as float: validated against the parameter's range; booleans as 0/1."""
    if physics.PARAMETERS[name].kind == "bool":
        if isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, np.integer)) and value in (0, 1)):
            return float(value)
        raise ValueError(f"{name} bounds must be true/false (or 0/1); got {value!r}")
    return float(physics.validate(name, value))


class Space:
    """Bounded physics parameters (the dimensions) and fixed values for the others.

    Parameters
    ----------
    bounds : mapping of str to (lower, upper)
        Free dimensions: a name of :data:`physics.PARAMETERS` and its range,
        in that parameter's unit (e.g. ``{"load_N": (0.001, 0.05)}`` [N]).
        Integer parameters (``balls``) need whole-number bounds; boolean ones
        (``balls_touching``) take ``(False, True)``.
    fixed : mapping of str to value, optional
        Values of parameters that are not dimensions, in their units. Required
        physics inputs (``balls``, ``load_N``, ``speed_m_s``) must be either a
        dimension or fixed; the others default to :func:`physics.defaults`.
    convention : str, default physics.DEFAULT_CONVENTION
        Reading of the physics model (see :data:`physics.CONVENTIONS`).
    scales : mapping of str to {"log", "power", "linear"}, optional
        Overrides the automatic scale of a dimension (log for positive ranges
        spanning a factor of 4 or more, power when the range starts at 0 for
        speed and adhesion energy, linear otherwise).

    Attributes
    ----------
    names : tuple of str
        The dimensions, in column order.
    lower, upper : numpy.ndarray
        Bounds per dimension, in the parameters' units.
    kinds : tuple of str
        ``"float"``, ``"int"`` or ``"bool"`` per dimension.
    scale_of : dict of str to str
        The unit-cube scale of each dimension.

    Raises
    ------
    ValueError
        For unknown names, empty or inverted ranges, bounds outside a
        parameter's allowed range, a name both free and fixed, a missing
        required parameter, or a scale that cannot apply (log of a range
        including 0).

    Examples
    --------
    >>> s = Space({"load_N": (0.001, 0.05), "balls": (3, 40)}, fixed={"speed_m_s": 0.01})
    >>> s.names, s.scale_of["load_N"]
    (('load_N', 'balls'), 'log')
    >>> s.from_unit([[0.0, 1.0]]).tolist()
    [[0.001, 40.0]]
    """

    def __init__(self, bounds: Mapping[str, Any], fixed: Mapping[str, Any] | None = None,
                 convention: str = physics.DEFAULT_CONVENTION,
                 scales: Mapping[str, str] | None = None):
        fixed = dict(fixed or {})
        scales = dict(scales or {})
        if not bounds:
            raise ValueError("bounds must name at least one parameter of physics.PARAMETERS with its range")
        if convention not in physics.CONVENTIONS:
            raise ValueError(f"convention must be one of {', '.join(physics.CONVENTIONS)}; "
                             f"got {convention!r}")
        for label, names in (("bounds", bounds), ("fixed", fixed), ("scales", scales)):
            unknown = sorted(set(names) - set(physics.PARAMETERS))
            if unknown:
                raise ValueError(f"{label}: unknown parameter(s) {', '.join(unknown)}; "
                                 f"known: {', '.join(physics.PARAMETERS)}")
        both = sorted(set(bounds) & set(fixed))
        if both:
            raise ValueError(f"{', '.join(both)} cannot be both a dimension (bounds) and fixed; keep one")
        not_free = sorted(set(scales) - set(bounds))
        if not_free:
            raise ValueError(f"scales given for {', '.join(not_free)}, which are not dimensions in bounds")
        missing = [n for n, p in physics.PARAMETERS.items()
                   if p.required and n not in bounds and n not in fixed]
        if missing:
            raise ValueError(f"required parameter(s) {', '.join(missing)} must be given in bounds or fixed")

        self.names = tuple(bounds)
        self.kinds = tuple(physics.PARAMETERS[n].kind for n in self.names)
        lower, upper = [], []
        for name in self.names:
            try:
                lo, hi = bounds[name]
            except (TypeError, ValueError):
                raise ValueError(f"bounds[{name!r}] must be a pair (lower, upper); "
                                 f"got {bounds[name]!r}") from None
            lo, hi = _as_float(name, lo), _as_float(name, hi)
            if not lo < hi:
                raise ValueError(f"bounds[{name!r}] must have lower < upper; got ({lo:g}, {hi:g}); "
                                 f"put a single value in fixed instead")
            lower.append(lo)
            upper.append(hi)
        self.lower = np.array(lower)
        self.upper = np.array(upper)
        self.fixed = {n: (bool(physics.validate(n, v)) if physics.PARAMETERS[n].kind == "bool"
                          else float(physics.validate(n, v))) for n, v in fixed.items()}
        self.convention = convention

        self.scale_of = {}
        self._exponent = np.ones(len(self.names))
        for i, (name, kind) in enumerate(zip(self.names, self.kinds, strict=True)):
            scale = scales.get(name, self._auto_scale(name, kind, self.lower[i], self.upper[i]))
            if scale not in SCALES:
                raise ValueError(f"scales[{name!r}] must be one of {', '.join(SCALES)}; got {scale!r}")
            if kind == "bool" and scale != "linear":
                raise ValueError(f"scales[{name!r}] must be 'linear' for a boolean dimension; got {scale!r}")
            if scale == "log" and self.lower[i] <= 0:
                raise ValueError(f"scales[{name!r}] = 'log' needs a lower bound > 0; got {self.lower[i]:g}; "
                                 f"use 'power' or 'linear'")
            if scale == "power":
                if self.lower[i] < 0:
                    raise ValueError(f"scales[{name!r}] = 'power' needs a lower bound >= 0")
                self._exponent[i] = _POWER_EXPONENTS.get(name, _DEFAULT_POWER_EXPONENT)
            self.scale_of[name] = scale
        self._scales = dict(scales)

    @property
    def ranged(self) -> list[int]:
        """Positions of the dimensions that take a range of values: every one but the booleans, which sit
        at an end of their unit interval whatever their value. [1]"""
        return [j for j, kind in enumerate(self.kinds) if kind != "bool"]

    @staticmethod
    def _auto_scale(name: str, kind: str, lo: float, hi: float) -> str:
        if kind == "bool":
            return "linear"
        # hi >= ratio * lo, not hi / lo >= ratio: a lower bound of 1e-308 overflows the division
        # (a numpy RuntimeWarning), never the product (Python floats).
        if lo > 0 and float(hi) >= _LOG_RATIO * float(lo):
            return "log"
        if lo == 0 and name in _POWER_EXPONENTS:
            return "power"
        return "linear"

    @property
    def dimension(self) -> int:
        """Number of free dimensions ``d``."""
        return len(self.names)

    @property
    def finite(self) -> bool:
        """Whether the space has finitely many points: only integer and boolean dimensions."""
        return all(kind != "float" for kind in self.kinds)

    def __repr__(self) -> str:
        dims = ", ".join(f"{n}=[{lo:g}, {hi:g}]" for n, lo, hi in zip(self.names, self.lower, self.upper,
                                                                      strict=True))
        return f"Space({dims}; fixed={self.fixed})"

    # ------------------------------------------------------------------ coordinates
    def _forward(self, X: np.ndarray) -> np.ndarray:
        """Physical values to the scaled (not yet normalized) coordinate of each dimension."""
        T = np.array(X, dtype=float, copy=True)
        for i, name in enumerate(self.names):
            scale = self.scale_of[name]
            if scale == "log":
                T[:, i] = np.log(np.maximum(T[:, i], np.finfo(float).tiny))
            elif scale == "power":
                T[:, i] = np.power(np.maximum(T[:, i], 0.0), self._exponent[i])
        return T

    def _backward(self, T: np.ndarray) -> np.ndarray:
        X = np.array(T, dtype=float, copy=True)
        for i, name in enumerate(self.names):
            scale = self.scale_of[name]
            if scale == "log":
                X[:, i] = np.exp(X[:, i])
            elif scale == "power":
                X[:, i] = np.power(np.maximum(X[:, i], 0.0), 1.0 / self._exponent[i])
        return X

    def check_X(self, X: Any) -> np.ndarray:
        """Validate physical points as a float array of shape ``(n, d)``.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]

        Returns
        -------
        numpy.ndarray of shape (n, d)
            The points as float. [parameter units]

        Raises
        ------
        ValueError
            If ``X`` is not 2-D with ``d`` columns, or holds NaN or infinities.
        """
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.dimension:
            raise ValueError(f"X must have shape (n, {self.dimension}) with columns {list(self.names)}; "
                             f"got shape {X.shape}")
        if not np.all(np.isfinite(X)):
            raise ValueError("X must be finite (no NaN or infinities)")
        return X

    def to_unit(self, X: Any) -> np.ndarray:
        """Map physical points to the unit cube of the design.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]

        Returns
        -------
        numpy.ndarray of shape (n, d)
            Coordinates, in [0, 1] for points inside the bounds. [1]
        """
        X = self.check_X(X)
        lo = self._forward(self.lower[None, :])
        hi = self._forward(self.upper[None, :])
        return (self._forward(X) - lo) / (hi - lo)

    def radius(self, X: Any) -> np.ndarray:
        """Distance of each point from the centre of the space, on the design's scale, as a share of a
        corner's: the root mean square over the inputs of ``2 u - 1`` (``u`` the unit coordinate;
        beyond the bounds counts as the bound). 0 at the centre, 1 at a corner; a uniform point of many
        inputs lies near 0.58 (1 / sqrt(3)). A boolean input, always at an end, is left out. [1]

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]

        Returns
        -------
        numpy.ndarray of shape (n,)
            In [0, 1]; 0 for a space of booleans only. [1]

        Examples
        --------
        >>> s = Space({"load_N": (0.001, 0.1), "groove_angle_deg": (40, 60)},
        ...           fixed={"balls": 4, "speed_m_s": 0.01})
        >>> s.radius([[0.01, 50.0], [0.1, 50.0], [0.1, 60.0], [0.1, 70.0]]).round(4).tolist()
        [0.0, 0.7071, 1.0, 1.0]
        """
        U = self.to_unit(X)
        ranged = self.ranged
        if not ranged:
            return np.zeros(U.shape[0])
        W = np.minimum(np.abs(2.0 * U[:, ranged] - 1.0), 1.0)
        return np.sqrt(np.mean(W * W, axis=1))

    def from_unit(self, U: Any) -> np.ndarray:
        """Map unit-cube coordinates to valid physical points.

        Integer dimensions are rounded to the nearest whole number (after the
        scale's inverse, so a log-scaled ``balls`` stays log-uniform) and
        boolean ones are 1 where the coordinate is >= 0.5.

        Parameters
        ----------
        U : array_like of shape (n, d)
            Coordinates in [0, 1]. [1]

        Returns
        -------
        numpy.ndarray of shape (n, d)
            Points in the units of :attr:`names`, inside the bounds. [parameter units]

        Raises
        ------
        ValueError
            If ``U`` has the wrong shape or leaves [0, 1].
        """
        U = np.asarray(U, dtype=float)
        if U.ndim != 2 or U.shape[1] != self.dimension:
            raise ValueError(f"U must have shape (n, {self.dimension}); got shape {U.shape}")
        if np.any(~np.isfinite(U)) or np.any(U < 0) or np.any(U > 1):
            raise ValueError("U must lie in the unit cube [0, 1]^d")
        lo = self._forward(self.lower[None, :])
        hi = self._forward(self.upper[None, :])
        X = self._backward(lo + U * (hi - lo))
        # The scale's round trip (exp of log) is not exact; corners must be the bounds themselves.
        X = np.where(U <= 0.0, self.lower, np.where(U >= 1.0, self.upper, X))
        for i, kind in enumerate(self.kinds):
            if kind == "int":
                X[:, i] = np.round(X[:, i])
            elif kind == "bool":
                X[:, i] = (U[:, i] >= 0.5).astype(float)
        return np.clip(X, self.lower, self.upper)

    def contains(self, X: Any) -> np.ndarray:
        """Whether each physical point lies inside the bounds (and is whole/boolean where needed).

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]

        Returns
        -------
        numpy.ndarray of bool, shape (n,)
            True inside the space.
        """
        X = self.check_X(X)
        inside = np.all((X >= self.lower) & (X <= self.upper), axis=1)
        for i, kind in enumerate(self.kinds):
            if kind in ("int", "bool"):
                inside &= X[:, i] == np.round(X[:, i])
        return inside

    def held_values(self) -> dict[str, Any]:
        """The value of every physics parameter that is not a dimension: its fixed value or the physics'
        default (those without one, required inputs, are dimensions or fixed)."""
        return {name: value for name, value in {**physics.defaults(), **self.fixed}.items()
                if name not in self.names}

    def unread_words(self, name: str, value: float) -> str:
        """Why a value of ``name``, a parameter that is no dimension, cannot be asked: the surrogate does not
        read it, so its answer would be the trained value's (a caller says whose words these are).

        >>> Space({"load_N": (0.001, 0.05)}, fixed={"balls": 4, "speed_m_s": 0.05}).unread_words("balls", 8)
        'was trained at balls = 4, not a dimension of its space: it cannot answer at 8 (leave it out, or \
train a surrogate with balls among its dimensions)'
        """
        return (f"was trained at {name} = {float(self.held_values()[name]):g}, not a dimension of its space: "
                f"it cannot answer at {float(value):g} (leave it out, or train a surrogate with {name} among "
                "its dimensions)")

    def outside_words(self, point: Mapping[str, Any]) -> list[str]:
        """One sentence per input of one point that leaves the trained space: a dimension beyond its
        bounds, another parameter at a value other than the one the space was built with (its fixed value
        or the physics' default); empty inside.

        Examples
        --------
        >>> s = Space({"groove_angle_deg": (40, 65)}, fixed={"balls": 4, "load_N": 0.01, "speed_m_s": 0.01})
        >>> s.outside_words({"groove_angle_deg": 30.0, "balls": 6, "load_N": 0.01})
        ['groove_angle_deg = 30 deg lies outside the trained range [40, 65] deg', 'balls = 6 differs from \
the value the surrogate was trained at, 4']
        """
        reference = self.held_values()
        words = []
        for name, value in point.items():
            unit = physics.unit_suffix(name)
            if name in self.names:
                i = self.names.index(name)
                if not self.lower[i] <= float(value) <= self.upper[i]:
                    words.append(f"{name} = {float(value):g}{unit} lies outside the trained range "
                                 f"[{self.lower[i]:g}, {self.upper[i]:g}]{unit}")
            elif name in reference and float(value) != float(reference[name]):
                words.append(f"{name} = {float(value):g}{unit} differs from the value the surrogate was "
                             f"trained at, {float(reference[name]):g}{unit}")
        return words

    def all_points(self, max_points: int) -> np.ndarray | None:
        """Every point of a finite space (only integer and boolean dimensions), if there are few.

        Parameters
        ----------
        max_points : int
            Largest number of points to list. [1]

        Returns
        -------
        numpy.ndarray of shape (m, d) or None
            All ``m`` points in the units of :attr:`names` (sorted), or None when a
            dimension is continuous or ``m > max_points``. [parameter units]

        Examples
        --------
        >>> Space({"balls": (3, 4), "balls_touching": (False, True)},
        ...       fixed={"load_N": 0.01, "speed_m_s": 0.01}).all_points(10).tolist()
        [[3.0, 0.0], [3.0, 1.0], [4.0, 0.0], [4.0, 1.0]]
        """
        if not self.finite:
            return None
        counts = [int(hi - lo) + 1 for lo, hi in zip(self.lower, self.upper, strict=True)]
        if math.prod(counts) > max_points:
            return None
        axes = [np.arange(lo, hi + 1.0) for lo, hi in zip(self.lower, self.upper, strict=True)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.dimension)

    # ------------------------------------------------------------------ physics
    def points(self, X: Any) -> dict[str, np.ndarray]:
        """Columnar keyword inputs of :func:`physics.evaluate` for physical points.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]

        Returns
        -------
        dict of str to numpy.ndarray or scalar
            Every dimension as a column (booleans as bool) plus the fixed values.
        """
        X = self.check_X(X)
        columns: dict[str, Any] = dict(self.fixed)
        for i, (name, kind) in enumerate(zip(self.names, self.kinds, strict=True)):
            columns[name] = X[:, i] >= 0.5 if kind == "bool" else X[:, i]
        return columns

    def evaluate(self, X: Any, mu_model: Callable[[Mapping[str, Any]], Any] | None = None) -> np.ndarray:
        """The friction coefficient μ of the physics, or of another model, at physical points (vectorized).

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]
        mu_model : callable, optional
            ``mu_model(points) -> mu`` [1] taking the columnar inputs of :meth:`points` (e.g. a
            calibrated model, which adds its fitted parameters and effect); default
            :func:`physics.evaluate` with this space's convention.

        Returns
        -------
        numpy.ndarray of shape (n,)
            μ at each point. [1]

        Raises
        ------
        ValueError
            From :func:`physics.evaluate` (or ``mu_model``) for invalid values, or when
            ``mu_model`` does not answer one μ per point.

        Examples
        --------
        >>> s = Space({"load_N": (0.001, 0.05)}, fixed={"balls": 4, "speed_m_s": 0.01})
        >>> mu = s.evaluate([[0.01]])
        >>> bool(s.evaluate([[0.01]], lambda p: 2 * physics.evaluate(**p).mu)[0] == 2 * mu[0])
        True
        """
        X = self.check_X(X)
        if mu_model is None:
            return np.asarray(physics.evaluate(convention=self.convention, **self.points(X)).mu, dtype=float)
        mu = np.asarray(mu_model(self.points(X)), dtype=float)
        try:
            return np.broadcast_to(mu, (X.shape[0],)).copy()
        except ValueError:
            raise ValueError(f"mu_model must answer one mu per point ({X.shape[0]}); "
                             f"got shape {mu.shape}") from None

    def from_points(self, points: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """Turn columnar physics inputs into physical points and an outside-space flag.

        Parameters
        ----------
        points : mapping of str to array_like
            Values by parameter name, broadcasting together like
            :func:`physics.evaluate`. Every dimension must be given; other
            parameters may be given and are then compared with the fixed value
            (or physics default) the space was built with.

        Returns
        -------
        X : numpy.ndarray of shape (n, d)
            The points. [parameter units]
        outside_space : numpy.ndarray of bool, shape (n,)
            True where a dimension leaves its bounds or a non-dimension
            parameter differs from the space's fixed value: there the
            surrogate extrapolates and its figures do not apply.

        Raises
        ------
        ValueError
            For unknown names, a missing dimension, invalid values or shapes
            that do not broadcast.
        """
        unknown = sorted(set(points) - set(physics.PARAMETERS))
        if unknown:
            raise ValueError(f"points: unknown parameter(s) {', '.join(unknown)}; "
                             f"known: {', '.join(physics.PARAMETERS)}")
        missing = [n for n in self.names if n not in points]
        if missing:
            raise ValueError(f"points must give every dimension of the space; missing {', '.join(missing)}")
        checked = {}
        for name, value in points.items():
            if physics.PARAMETERS[name].kind == "bool":
                arr = np.asarray(value)
                if arr.dtype != np.bool_ and np.all(np.isin(arr, (0, 1))):
                    arr = arr.astype(bool)
                checked[name] = physics.validate(name, arr)
            else:
                checked[name] = physics.validate(name, value)
        try:
            shape = np.broadcast_shapes(*(a.shape for a in checked.values()))
        except ValueError:
            raise ValueError("points: arrays do not broadcast together: "
                             f"{ {n: a.shape for n, a in checked.items()} }") from None
        flat = {n: np.broadcast_to(a, shape).reshape(-1) for n, a in checked.items()}
        n = int(np.prod(shape)) if shape else 1
        X = np.column_stack([flat[name].astype(float) for name in self.names]) if n else \
            np.empty((0, self.dimension))
        outside = ~self.contains(X)
        reference = self.held_values()
        for name, column in flat.items():
            if name not in self.names:
                outside |= column.astype(float) != float(reference[name])
        return X, outside

    # ------------------------------------------------------------------ features
    def features(self, X: Any, kind: str = "physics") -> np.ndarray:
        """Inputs of the Gaussian process for physical points.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]
        kind : {"dry_contact", "physics", "scaled", "raw"}, default "physics"
            ``"raw"``: the physical values themselves; ``"scaled"``: each
            dimension on its scale (log load, log speed, ...); ``"physics"``:
            the scaled coordinates with changes that follow the model, each
            measured in ``bench/surrogate.py``: ``load_N`` becomes log(load
            per ball) (μ depends on load and balls only through G/z, eq 7,
            so the length scale of log balls can grow long); the groove
            angle becomes (log tan θ, log cos θ), the factors by which θ
            enters the pivoting and ball-ball terms (eqs 7, 20); when the
            adhesion energy is a dimension, log Q (the JKR apparent load,
            eq 8) is added, in which the pivoting, hysteresis and rolling
            terms are power laws (Q^4/3, Q^1.33, Q^0.47). Integer
            dimensions stay continuous (the relaxation the GP interpolates).
            ``"dry_contact"``: the ``"physics"`` features and, last, log of
            :meth:`dry_contact_mu` (the physics' dry-contact share of μ,
            evaluated in closed form at the point).

        Returns
        -------
        numpy.ndarray of shape (n, k)
            Features (not normalized; the model standardizes them). [1]

        Raises
        ------
        ValueError
            For an unknown ``kind``.
        """
        if kind not in FEATURE_SETS:
            raise ValueError(f"kind must be one of {', '.join(FEATURE_SETS)}; got {kind!r}")
        X = self.check_X(X)
        if kind == "raw":
            return X.copy()
        T = self._forward(X)
        if kind == "scaled":
            return T
        Z = self._physics_features(X, T)
        if kind == "dry_contact":
            return np.column_stack([Z, np.log(np.maximum(self.dry_contact_mu(X), np.finfo(float).tiny))])
        return Z

    def dry_contact_mu(self, X: Any) -> np.ndarray:
        """The physics' dry-contact share of μ at physical points: pivoting, hysteresis and ball-ball terms.

        μ of the physics is a sum of four positive terms (eqs 20-23): the pivoting (eq 16), elastic
        hysteresis (eq 15) and ball-ball (eq 17) moments of the dry Hertz/JKR contacts, and Houpert's
        hydrodynamic rolling force (eq 9). The first three are closed-form power laws of the contact
        load and radius and cost a few array operations; a surrogate that evaluates them where it
        predicts learns, from its budget, only how the learned model departs from them (the rolling
        term of the physics, and whatever a calibrated model changes or adds). Evaluated with this
        space's convention and fixed values (the physics' defaults for the others).

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of :attr:`names`. [parameter units]

        Returns
        -------
        numpy.ndarray of shape (n,)
            ``mu_pivoting + mu_hysteresis + mu_ball_ball`` of :func:`physics.evaluate`. [1]

        Examples
        --------
        >>> s = Space({"speed_m_s": (0.0, 0.2)}, fixed={"balls": 4, "load_N": 0.01})
        >>> X = [[0.0], [0.2]]
        >>> dry, mu = s.dry_contact_mu(X), s.evaluate(X)
        >>> bool(dry[0] == dry[1] and abs(dry[0] / mu[0] - 1) < 1e-12 and mu[1] > dry[1])
        True
        """
        X = self.check_X(X)
        r = physics.evaluate(convention=self.convention, **self.points(X))
        return np.broadcast_to(np.asarray(r.mu_pivoting + r.mu_hysteresis + r.mu_ball_ball, dtype=float),
                               (X.shape[0],)).copy()

    def _adhesive_contact_load(self, X: np.ndarray) -> np.ndarray:
        p = {**physics.defaults(), **self.points(X)}
        q0 = physics.contact.ball_race_load(p["load_N"], p["balls"], np.deg2rad(p["groove_angle_deg"]))
        radius = 0.5 * np.asarray(p["ball_diameter_m"])
        q = physics.contact.jkr_contact_load(q0, radius, p["adhesion_energy_J_m2"])
        return np.broadcast_to(q, (X.shape[0],))

    @property
    def _adhesive_load_feature(self) -> bool:
        # With γ fixed, Q is a smooth function of Q0 that the process learns by itself (an
        # extra feature made the 4-D benchmark worse); with γ free, log Q linearizes the terms.
        return "adhesion_energy_J_m2" in self.names

    def _physics_features(self, X: np.ndarray, T: np.ndarray) -> np.ndarray:
        balls = X[:, self.names.index("balls")] if "balls" in self.names else self.fixed["balls"]
        columns = []
        for i, name in enumerate(self.names):
            if name == "load_N":
                columns.append(np.log(X[:, i] / balls))
            elif name == "groove_angle_deg":
                theta = np.deg2rad(X[:, i])
                columns += [np.log(np.tan(theta)), np.log(np.cos(theta))]
            else:
                columns.append(T[:, i])
        if self._adhesive_load_feature:
            columns.append(np.log(self._adhesive_contact_load(X)))
        return np.column_stack(columns)

    def feature_names(self, kind: str = "physics") -> list[str]:
        """Names of the columns of :meth:`features` for ``kind``.

        Parameters
        ----------
        kind : {"dry_contact", "physics", "scaled", "raw"}, default "physics"
            Feature set.

        Returns
        -------
        list of str
            One name per feature column.
        """
        if kind not in FEATURE_SETS:
            raise ValueError(f"kind must be one of {', '.join(FEATURE_SETS)}; got {kind!r}")
        if kind == "raw":
            return list(self.names)
        label = {"log": "log({})", "power": "{}^p", "linear": "{}"}
        names = []
        for name in self.names:
            if kind != "scaled" and name == "load_N":
                names.append("log(load_N/balls)")
            elif kind != "scaled" and name == "groove_angle_deg":
                names += ["log(tan(theta))", "log(cos(theta))"]
            else:
                names.append(label[self.scale_of[name]].format(name))
        if kind != "scaled" and self._adhesive_load_feature:
            names.append("log(Q)")
        if kind == "dry_contact":
            names.append("log(mu_dry)")
        return names

    # ------------------------------------------------------------------ data
    def to_dict(self) -> dict[str, Any]:
        """The space as JSON-ready data (see :meth:`from_dict`).

        Returns
        -------
        dict
            ``bounds``, ``fixed``, ``convention`` and ``scales``.
        """
        bounds = {}
        for name, kind, lo, hi in zip(self.names, self.kinds, self.lower, self.upper, strict=True):
            bounds[name] = [bool(lo), bool(hi)] if kind == "bool" else [float(lo), float(hi)]
        return {"bounds": bounds, "fixed": dict(self.fixed), "convention": self.convention,
                "scales": dict(self.scale_of)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Space:
        """Rebuild a space from :meth:`to_dict` data.

        Parameters
        ----------
        data : mapping
            Output of :meth:`to_dict`.

        Returns
        -------
        Space
            An equal space.
        """
        return cls({k: tuple(v) for k, v in data["bounds"].items()}, data.get("fixed"),
                   data.get("convention", physics.DEFAULT_CONVENTION), data.get("scales"))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Space) and self.to_dict() == other.to_dict()

    __hash__ = None

"""The surrogate estimator: a Gaussian process on physics-aware features of a :class:`~surrogate.Space`.

The target is log μ (μ > 0 spans decades and is a sum of power laws, so
log μ is smooth in log inputs). A prior mean of log μ in the features is fitted
first by least squares and the Gaussian process models what it leaves. By
default (issue 35) the features end with log μ_dry, the physics' dry-contact
share of μ evaluated in closed form at the point (:meth:`Space.dry_contact_mu`),
and the mean is a *posynomial*: the log of the sum of two power laws of the
features' quantities, one that can follow μ_dry and one fitted for what μ_dry
leaves out (Houpert's rolling force of the physics, ∝ (ηV)^0.66 Q^0.47, or what a
calibrated model adds). Earlier: a linear mean (one power law) on the physics
features. The kernel is a constant times an anisotropic Matérn 5/2 (or RBF)
kernel with one length scale per feature, plus a white-noise term (μ is
analytic, and RBF measured 2-4x more accurate in ``bench/surrogate.py``, but its
predictive variance far less reliably calibrated: see the ``kernel``
parameter); its hyperparameters maximize the log marginal likelihood (Rasmussen & Williams
2006, Alg. 2.1 and Sect. 5.4.1, as implemented by
:class:`sklearn.gaussian_process.GaussianProcessRegressor`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import cho_solve
from scipy.optimize import least_squares
from scipy.stats import norm
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Kernel, Matern, WhiteKernel
from sklearn.utils.validation import check_is_fitted
from threadpoolctl import threadpool_limits

from .space import FEATURE_SETS, Space

__all__ = ["KERNELS", "MEANS", "CALIBRATIONS", "VARIANCE_SCALES", "DEFAULT_KERNEL", "conformal_scale",
           "radius_bins", "radius_scales", "RadiusScales", "RADIUS_BINS", "KFOLD_BELOW_POINTS_PER_FEATURE",
           "MIN_VALIDATION_POINTS", "RELATIVE_RESOLUTION",
           "DEFAULT_CALIBRATION", "Hyperparameters", "SurrogatePrediction", "GaussianProcessSurrogate",
           "build_kernel", "prior_mean", "fit_prior_mean"]

#: Points predicted per block (memory of one call bounded by one block's covariances). [1]
_PREDICT_BLOCK = 8192

#: Allowed stationary kernels.
KERNELS = ("rbf", "matern52", "matern32")
#: Allowed prior means of the target.
MEANS = ("posynomial", "linear", "constant")
#: Allowed variance calibrations.
CALIBRATIONS = ("auto", "loo", "kfold", "none")
#: Allowed rules from standardized cross-validation errors to the variance scale.
VARIANCE_SCALES = ("rms", "central")
#: The default kernel and variance calibration.
DEFAULT_KERNEL, DEFAULT_CALIBRATION = "matern52", "auto"
_FOLDS = 5
#: ``calibrate_variance="auto"`` refits the hyperparameters per fold (k-fold) below this many
#: training points per feature, and uses closed-form leave-one-out errors from there on. [1]
KFOLD_BELOW_POINTS_PER_FEATURE = 10

_LENGTH_SCALE_BOUNDS = (1e-2, 1e3)
_AMPLITUDE_BOUNDS = (1e-4, 1e4)
_NOISE_BOUNDS = (1e-12, 1e-1)
#: Intercept that switches off the second term of a posynomial mean: exp(-1000) is 0 in float64.
_NO_TERM = -1e3
#: Starting share of μ of the learned term of a posynomial mean (its slopes start at 0). [1]
_TERM_START_SHARE = 0.02


def prior_mean(coef: np.ndarray, Zs: np.ndarray) -> np.ndarray:
    """A prior mean of the target at rows of standardized features, from its coefficients.

    Parameters
    ----------
    coef : numpy.ndarray
        ``[a0, a...]`` (``k + 1`` values: linear, or constant with zero slopes) or
        ``[a0, a..., b0, b...]`` (``2 (k + 1)``: posynomial). [1]
    Zs : numpy.ndarray of shape (n, k)
        Standardized features. [1]

    Returns
    -------
    numpy.ndarray of shape (n,)
        ``a0 + Zs a``, or ``log(exp(a0 + Zs a) + exp(b0 + Zs b))``. [1]
    """
    k = Zs.shape[1]
    first = coef[0] + Zs @ coef[1:k + 1]
    if coef.size == 2 * (k + 1):
        return np.logaddexp(first, coef[k + 1] + Zs @ coef[k + 2:])
    return first


def fit_prior_mean(kind: str, Zs: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Coefficients of a prior mean of ``kind`` fitted to the target by least squares (:func:`prior_mean`).

    ``"posynomial"`` fits log μ as the log of a sum of two power laws of the features'
    underlying quantities, starting from the linear fit and a second term of
    :data:`_TERM_START_SHARE` of μ (Levenberg-Marquardt); it keeps the linear fit, with the
    second term off, where that fits no worse or there are too few points for both terms.
    Too few points for the linear fit give zero slopes (the process's normalization centres
    the target).

    Parameters
    ----------
    kind : {"posynomial", "linear", "constant"}
        The mean.
    Zs : numpy.ndarray of shape (n, k)
        Standardized features. [1]
    t : numpy.ndarray of shape (n,)
        The target. [1]

    Returns
    -------
    numpy.ndarray
        ``k + 1`` coefficients, ``2 (k + 1)`` for ``"posynomial"``. [1]
    """
    k = Zs.shape[1]
    linear = np.zeros(k + 1)
    if kind != "constant" and len(t) > k + 1:
        linear = np.linalg.lstsq(np.column_stack([np.ones(len(t)), Zs]), t, rcond=None)[0]
    if kind != "posynomial":
        return linear
    off = np.concatenate([linear, [_NO_TERM], np.zeros(k)])
    if len(t) <= 2 * (k + 1):
        return off
    start = np.concatenate([linear, [float(np.mean(t)) + math.log(_TERM_START_SHARE)], np.zeros(k)])
    fitted = least_squares(lambda coef: prior_mean(coef, Zs) - t, start, method="lm")
    if not np.all(np.isfinite(fitted.x)) or np.sum(fitted.fun**2) >= np.sum((prior_mean(off, Zs) - t) ** 2):
        return off
    return fitted.x


def one_blas_thread() -> threadpool_limits:
    """Keep BLAS calls in the calling thread (a context manager).

    The matrices of a surrogate (at most a thousand rows) gain nothing from BLAS threads, and on
    a machine whose cores are busy (a server's other jobs) they lose: a 300 x 300 Cholesky
    factorization measured 14 ms with two OpenBLAS threads against 2 ms with one.
    """
    return threadpool_limits(1, user_api="blas")


def build_kernel(kind: str, n_features: int) -> Kernel:
    """The prior covariance: amplitude × anisotropic stationary kernel + white noise.

    Parameters
    ----------
    kind : {"matern52", "matern32", "rbf"}
        Stationary correlation function.
    n_features : int
        Number of (standardized) inputs, one length scale each. [1]

    Returns
    -------
    sklearn.gaussian_process.kernels.Kernel
        ``ConstantKernel * (Matern | RBF) + WhiteKernel`` at initial
        hyperparameters (unit amplitude and length scales, noise 1e-6).

    Raises
    ------
    ValueError
        For an unknown ``kind``.
    """
    if kind not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}; got {kind!r}")
    scales = np.ones(n_features)
    if kind == "rbf":
        correlation = RBF(scales, _LENGTH_SCALE_BOUNDS)
    else:
        correlation = Matern(scales, _LENGTH_SCALE_BOUNDS, nu=2.5 if kind == "matern52" else 1.5)
    return ConstantKernel(1.0, _AMPLITUDE_BOUNDS) * correlation + WhiteKernel(1e-6, _NOISE_BOUNDS)


@dataclass(frozen=True)
class Hyperparameters:
    """How a :class:`GaussianProcessSurrogate` chooses its kernel's hyperparameters.

    Attributes
    ----------
    initial_theta : sequence of float, optional
        Starting point of the optimizer: the kernel's ``theta`` (log amplitude², log length scales,
        log noise) from an earlier fit, e.g. on fewer points (adaptive sampling warm-starts each
        round this way). Default: unit amplitude and length scales. [1]
    optimize : bool, default True
        Maximize the marginal likelihood; False keeps ``initial_theta`` as it is (adaptive sampling
        does so in rounds where the design has grown little).
    n_restarts_optimizer : int, default 1
        Extra random starts of the optimizer (each costs a full optimization; keep small). [1]
    """

    initial_theta: Any = None
    optimize: bool = True
    n_restarts_optimizer: int = 1


@dataclass(frozen=True)
class SurrogatePrediction:
    """Prediction of μ with its interval.

    Attributes
    ----------
    mu : numpy.ndarray
        Predicted μ (the exponential of the predicted log μ: its median). [1]
    mu_lower, mu_upper : numpy.ndarray
        Bounds of the central interval at the requested level. [1]
    outside_space : numpy.ndarray of bool
        True where the point is outside the trained space (extrapolation).
    log_std : numpy.ndarray
        Predictive standard deviation of log μ (of μ for a linear target). [1]
    """

    mu: np.ndarray
    mu_lower: np.ndarray
    mu_upper: np.ndarray
    outside_space: np.ndarray
    log_std: np.ndarray


#: Narrowest half-width of an interval, relative to μ: float64 evaluations of μ (the physics' own
#: operations, the process's prediction) agree to a few 1e-15, not beyond. [1]
RELATIVE_RESOLUTION = 1e-12

#: Fewest validation points of :meth:`GaussianProcessSurrogate.calibrate`: the split-conformal 95 %
#: quantile is the ceil(0.95 (n + 1))-th smallest of n standardized errors, which exists from n = 19.
MIN_VALIDATION_POINTS = 19

#: Most bins of distance from the centre of the space (:meth:`Space.radius`) that
#: :meth:`GaussianProcessSurrogate.calibrate` gives a conformal factor each, of equal counts of
#: validation points: 64 each at the default 512. [1]
RADIUS_BINS = 8

#: Quantile of |z| that sets the "central" variance scale, and the standard normal's value there.
_SCALE_QUANTILE = 0.8
_NORMAL_AT_SCALE_QUANTILE = float(norm.ppf(0.5 + 0.5 * _SCALE_QUANTILE))


def conformal_scale(z: np.ndarray) -> float:
    """The split-conformal 95 % factor of absolute standardized errors ``z`` (n >= 19): their ``k``-th
    smallest over 1.96, ``k = ceil(0.95 (n + 1))`` (Lei et al. 2018, sect. 5.2). [1]

    >>> round(conformal_scale(np.arange(1.0, 20.0)), 4)  # k = 19 of 19: the largest, 19 / 1.95996
    9.6941
    """
    k = math.ceil(0.95 * (len(z) + 1))
    return float(np.sort(z)[k - 1] / norm.ppf(0.975))


def radius_bins(radius: np.ndarray, edges: Any) -> np.ndarray:
    """The bin of each distance from the centre of the space (:meth:`Space.radius`) between increasing
    ``edges``: 0 below the first edge ... ``len(edges)`` from the last one. [1]

    >>> radius_bins(np.array([0.0, 0.5, 0.6, 0.95]), [0.5, 0.9]).tolist()
    [0, 1, 1, 2]
    """
    return np.searchsorted(np.asarray(edges, dtype=float), np.asarray(radius, dtype=float), side="right")


@dataclass(frozen=True)
class RadiusScales:
    """Factors on a Gaussian process's standard deviation by distance from the centre of the space.

    Attributes
    ----------
    edges : list of float
        Increasing distances (:meth:`Space.radius`) between the bins. [1]
    scales : list of float
        One factor per bin, the centre's first; never decreasing outward. [1]
    """

    edges: list[float]
    scales: list[float]

    def at(self, radius: np.ndarray) -> np.ndarray:
        """The factor at each distance from the centre. [1]"""
        return np.asarray(self.scales, dtype=float)[radius_bins(radius, self.edges)]


def radius_scales(z: np.ndarray, radius: np.ndarray) -> RadiusScales:
    """The conformal factor of each bin of distance from the centre of the space (Mondrian conformal
    prediction: one quantile per class, Vovk, Gammerman and Shafer 2005, sect. 4.5), never less than
    that of a bin nearer the centre.

    The validation points are split at their distances into up to :data:`RADIUS_BINS` bins of equal
    count, each of :data:`MIN_VALIDATION_POINTS` or more (ties kept together; a bin left short is pooled
    with its neighbours, the one farther out first). The running maximum outward only widens an
    interval: a Gaussian process has neighbours on one side only toward the bounds, and its errors
    outgrow its own standard deviation there (one factor for the whole space covered 0.68-0.88 of
    points within 2 % of every bound, 4- to 6-D surrogates of 50-100 evaluations, and 0.97-0.99 of
    those 10 % inside them all).

    Parameters
    ----------
    z : numpy.ndarray
        Absolute standardized errors of validation points, at least :data:`MIN_VALIDATION_POINTS`. [1]
    radius : numpy.ndarray
        Each point's distance from the centre of the space (:meth:`Space.radius`). [1]

    Returns
    -------
    RadiusScales

    Examples
    --------
    >>> z = np.r_[np.full(19, 1.0), np.full(19, 3.0), np.full(19, 2.0)]
    >>> fit = radius_scales(z, np.r_[np.full(19, 0.1), np.full(19, 0.3), np.full(19, 0.9)])
    >>> fit.edges, [round(s, 3) for s in fit.scales]
    ([0.3, 0.9], [0.51, 1.531, 1.531])
    """
    radius = np.asarray(radius, dtype=float)
    count = max(1, min(RADIUS_BINS, len(z) // MIN_VALIDATION_POINTS))
    ordered = np.sort(radius)
    edges = sorted({float(ordered[len(z) * j // count]) for j in range(1, count)} - {float(ordered[0])})
    bins = radius_bins(radius, edges)
    scales = []
    for b in range(len(edges) + 1):
        pool = np.zeros(len(z), dtype=bool)
        for c in sorted(range(len(edges) + 1), key=lambda c: (abs(c - b), -c)):
            pool |= bins == c
            if pool.sum() >= MIN_VALIDATION_POINTS:
                break
        scales.append(conformal_scale(z[pool]))
    return RadiusScales(edges, np.maximum.accumulate(scales).tolist())


class GaussianProcessSurrogate(RegressorMixin, BaseEstimator):
    """Gaussian-process surrogate of the friction coefficient μ over a :class:`Space`.

    Parameters
    ----------
    space : Space
        The input space; ``X`` columns follow ``space.names``.
    features : {"dry_contact", "physics", "scaled", "raw"}, default "dry_contact"
        Feature set of :meth:`Space.features` fed to the Gaussian process
        (standardized on the training data). ``"dry_contact"`` adds log μ_dry
        (:meth:`Space.dry_contact_mu`) to the ``"physics"`` features: the surrogate
        then evaluates the physics' dry-contact moments where it predicts (a few
        array operations per point) and learns the rest from its budget. Measured
        with the posynomial mean against ``"physics"`` with a linear mean (the
        earlier default) by ``bench/surrogate.py --smt``: see bench/RESULTS.md.
    kernel : {"matern52", "rbf", "matern32"}, default "matern52"
        Stationary kernel with one length scale per feature. RBF is about
        twice as accurate on μ of the 4-D benchmark space (median relative
        error 0.010-0.028 % against 0.023-0.044 % after 100 adaptive
        evaluations, 16 design seeds), but its variance is calibrated very
        unevenly from one design to the next (coverage of the 95 % interval
        75-100 %, against 87-98.5 % for Matérn 5/2 over 48 seeds), so the
        default is Matérn 5/2.
    mean : {"posynomial", "linear", "constant"}, default "posynomial"
        Prior mean of the target: ``"posynomial"``, log of the sum of two
        exponentials of linear models in the standardized features (for log μ:
        two power laws, :func:`fit_prior_mean`); ``"linear"``, a least-squares
        linear model; or a constant (the training mean).
    log_target : bool, default True
        Model log μ (μ > 0) instead of μ.
    random_state : int or None, default None
        Seed of the optimizer's restarts.
    hyperparameters : Hyperparameters, default Hyperparameters()
        Where the optimizer of the kernel's hyperparameters starts, whether it runs, and its
        restarts.
    calibrate_variance : {"auto", "loo", "kfold", "none"}, default "auto"
        Rescale the predictive standard deviation by a factor ``s`` measured on
        standardized cross-validation errors ``z_i = e_i / σ_i`` (errors
        ``e_i`` of the target at training points left out, ``σ_i`` their
        predicted standard deviations; see ``variance_scale``). ``"loo"``:
        closed-form leave-one-out errors with the hyperparameters held fixed
        (Rasmussen & Williams 2006, eqs. 5.10-5.12; no extra fit);
        ``"kfold"``: 5 folds, each with its prior mean and hyperparameters
        refitted (5 more fits, warm-started), so that no point judges
        hyperparameters it helped choose; ``"auto"``: ``"kfold"`` below
        :data:`KFOLD_BELOW_POINTS_PER_FEATURE` training points per feature,
        ``"loo"`` from there on; ``"none"``: ``s = 1``, the process's own
        variance (maximum likelihood alone is overconfident or needlessly wide
        on small designs). Measured by ``bench/surrogate.py --coverage-only``
        (spaces of 1 to 7 inputs, budgets 50 to 400, REST defaults): with few
        points per feature, leave-one-out at fixed hyperparameters is
        optimistic (the hyperparameters were fitted with the point left out:
        below 10 points per feature 82 % of the fits covered under 90 %),
        k-fold refits much less so; with more, leave-one-out on the
        space-filling rows lands in [90, 98] % for about 9 fits in 10 and
        k-fold refits (fitted on 80 % of the points) are too wide. Where the
        learned model can be evaluated more, :meth:`calibrate` on validation points
        never trained on does much better, and :func:`surrogate.fit_adaptive` (the REST
        API's) does so by default: every one of 184 fits in [90, 98] % at budgets 50
        and 100 (``bench/surrogate.py --coverage-only``, three sets of spaces).
    variance_scale : {"rms", "central"}, default "rms"
        How ``s`` follows from the ``z_i``. ``"rms"``: ``s² = mean(z²)``, the
        cross-validation variance estimate of Bachoc (2013), right when the
        points it is taken over are spread like the points predicted (a
        space-filling design: see ``calibration_rows``). ``"central"``:
        ``s = q_0.8(|z|) / 1.2816``, the scale at which the central 80 % of
        the ``z_i`` match a standard normal (1.2816 is its 90th percentile),
        unmoved by the largest 20 % (it under-covered heavy-tailed errors of
        5- and 6-input spaces: 56-88 % at budget 100).
    calibration_rows : int, optional
        Only the leave-one-out errors of the first ``calibration_rows`` rows of
        ``X`` set ``s``: the rows of a space-filling design, spread like the
        points predicted, when later rows were chosen where the process is
        least sure (adaptive batches crowd the edges, where leaving one out
        is extrapolation). Default: every row. [1]

    Attributes
    ----------
    gaussian_process_ : sklearn.gaussian_process.GaussianProcessRegressor
        The fitted process on standardized features and mean residuals.
    feature_mean_, feature_scale_ : numpy.ndarray
        Standardization of the features (training mean and standard deviation).
    mean_coef_ : numpy.ndarray
        Coefficients of the prior mean ``[intercept, feature slopes...]``, twice
        over for ``mean="posynomial"`` (:func:`prior_mean`; all zero for
        ``mean="constant"``; normalize_y then centres the target).
    X_train_, y_train_ : numpy.ndarray
        Training points (physical) and μ.
    n_features_in_ : int
        Number of columns of ``X`` (the space's dimension).
    std_scale_ : float
        Factor applied to the predictive standard deviation (1 for
        ``calibrate_variance="none"``). [1]
    variance_calibration_ : str
        The calibration applied: ``"loo"``, ``"kfold"`` or ``"none"`` (what ``"auto"`` chose), or
        ``"validation"`` after :meth:`calibrate`.
    calibration_points_ : int or None
        Number of errors ``std_scale_`` was taken from: validation points after :meth:`calibrate`,
        else the training rows cross-validated (None for ``"none"``). [1]
    radius_scales_ : RadiusScales or None
        After :meth:`calibrate`: the factors by distance from the centre of the space
        (:func:`radius_scales`), used instead of ``std_scale_``; None otherwise.

    Examples
    --------
    >>> space = Space({"load_N": (0.001, 0.05)}, fixed={"balls": 4, "speed_m_s": 0.01})
    >>> X = space.from_unit(np.linspace(0, 1, 8)[:, None])
    >>> model = GaussianProcessSurrogate(space, random_state=0).fit(X, space.evaluate(X))
    >>> x = [[0.02]]
    >>> bool(abs(model.predict(x)[0] / space.evaluate(x)[0] - 1) < 1e-3)
    True
    """

    def __init__(self, space: Space, features: str = "dry_contact", kernel: str = DEFAULT_KERNEL,
                 mean: str = "posynomial", log_target: bool = True, random_state: int | None = None,
                 hyperparameters: Hyperparameters = Hyperparameters(),
                 calibrate_variance: str = DEFAULT_CALIBRATION, variance_scale: str = "rms",
                 calibration_rows: int | None = None):
        self.space = space
        self.features = features
        self.kernel = kernel
        self.mean = mean
        self.log_target = log_target
        self.random_state = random_state
        self.hyperparameters = hyperparameters
        self.calibrate_variance = calibrate_variance
        self.variance_scale = variance_scale
        self.calibration_rows = calibration_rows

    def _validate_params(self) -> None:
        if not isinstance(self.space, Space):
            raise ValueError(f"space must be a surrogate.Space; got {type(self.space).__name__}")
        if self.features not in FEATURE_SETS:
            raise ValueError(f"features must be one of {', '.join(FEATURE_SETS)}; got {self.features!r}")
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {', '.join(KERNELS)}; got {self.kernel!r}")
        if self.mean not in MEANS:
            raise ValueError(f"mean must be one of {', '.join(MEANS)}; got {self.mean!r}")
        if self.calibrate_variance not in CALIBRATIONS:
            raise ValueError(f"calibrate_variance must be one of {', '.join(CALIBRATIONS)}; "
                             f"got {self.calibrate_variance!r}")
        if self.variance_scale not in VARIANCE_SCALES:
            raise ValueError(f"variance_scale must be one of {', '.join(VARIANCE_SCALES)}; "
                             f"got {self.variance_scale!r}")
        if self.calibration_rows is not None and (
                not isinstance(self.calibration_rows, (int, np.integer)) or self.calibration_rows < 2):
            raise ValueError(f"calibration_rows must be a whole number >= 2 or None; "
                             f"got {self.calibration_rows!r}")
        search = self.hyperparameters
        if not isinstance(search, Hyperparameters):
            raise ValueError(f"hyperparameters must be a surrogate.Hyperparameters; "
                             f"got {type(search).__name__}")
        if search.initial_theta is None and not search.optimize:
            raise ValueError("hyperparameters.optimize=False needs initial_theta "
                             "(the hyperparameters to keep)")
        restarts = search.n_restarts_optimizer
        if not isinstance(restarts, (int, np.integer)) or restarts < 0:
            raise ValueError(f"hyperparameters.n_restarts_optimizer must be a whole number >= 0; "
                             f"got {restarts!r}")

    # ------------------------------------------------------------------ fitted transforms
    def design_matrix(self, X: np.ndarray) -> np.ndarray:
        """The process's inputs at physical points: the features standardized as fitted.

        Parameters
        ----------
        X : numpy.ndarray of shape (n, d)
            Points in the units of ``space.names``. [parameter units]

        Returns
        -------
        numpy.ndarray of shape (n, n_features)
            ``(features - feature_mean_) / feature_scale_``. [1]
        """
        Z = self.space.features(X, self.features)
        return (Z - self.feature_mean_) / self.feature_scale_

    def residual_target(self, Zs: np.ndarray, y: np.ndarray) -> np.ndarray:
        """What the process models at rows ``Zs`` of :meth:`design_matrix`: the target less the prior mean.

        Parameters
        ----------
        Zs : numpy.ndarray of shape (n, n_features)
            Standardized features. [1]
        y : numpy.ndarray of shape (n,)
            μ there. [1]

        Returns
        -------
        numpy.ndarray of shape (n,)
            ``log μ`` (``μ`` for a linear target) minus the fitted prior mean. [1]
        """
        return self._target(y) - self._prior_mean(Zs)

    def check_mu(self, y: Any, n: int) -> np.ndarray:
        """``y`` as ``n`` values of μ this model can learn (finite; > 0 for a log target).

        Parameters
        ----------
        y : array_like of shape (n,)
            μ, one per row of the points. [1]
        n : int
            Number of points. [1]

        Returns
        -------
        numpy.ndarray of shape (n,)

        Raises
        ------
        ValueError
            For another shape, non-finite values, or values <= 0 with ``log_target``.
        """
        y = np.asarray(y, dtype=float)
        if y.shape != (n,):
            raise ValueError(f"y must be a 1-D array of {n} values of mu (one per row of X); "
                             f"got shape {y.shape}")
        if not np.all(np.isfinite(y)):
            raise ValueError("y must be finite")
        if self.log_target and np.any(y <= 0):
            raise ValueError("y must be > 0 for log_target=True (mu is positive); "
                             "use log_target=False otherwise")
        return y

    # ------------------------------------------------------------------ internals
    def _prior_mean(self, Zs: np.ndarray) -> np.ndarray:
        return prior_mean(self.mean_coef_, Zs)

    def _target(self, y: np.ndarray) -> np.ndarray:
        return np.log(y) if self.log_target else y

    # ------------------------------------------------------------------ estimator API
    def fit(self, X: Any, y: Any) -> GaussianProcessSurrogate:
        """Fit the prior mean and the Gaussian process to training points.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Training points in the units of ``space.names``. [parameter units]
        y : array_like of shape (n,)
            μ at those points. [1]

        Returns
        -------
        GaussianProcessSurrogate
            self, fitted.

        Raises
        ------
        ValueError
            For invalid parameters, shapes, non-finite or (with
            ``log_target``) non-positive ``y``, or fewer than 2 points.
        """
        self._validate_params()
        X = self.space.check_X(X)
        y = self.check_mu(y, X.shape[0])
        if X.shape[0] < 2:
            raise ValueError(f"X must hold at least 2 training points; got {X.shape[0]}")
        Z = self.space.features(X, self.features)
        self.feature_mean_ = Z.mean(axis=0)
        scale = Z.std(axis=0)
        # A feature constant on the training set (e.g. one value of a boolean) keeps unit scale.
        self.feature_scale_ = np.where(scale > 0, scale, 1.0)
        Zs = (Z - self.feature_mean_) / self.feature_scale_
        t = self._target(y)
        self.mean_coef_, self.gaussian_process_ = self._fit_process(
            Zs, t, self._initial_kernel(Zs.shape[1]), int(self.hyperparameters.n_restarts_optimizer))
        self.X_train_ = X
        self.y_train_ = y
        self.n_features_in_ = X.shape[1]
        self.std_scale_ = 1.0
        self.variance_calibration_ = self.calibrate_variance
        if self.calibrate_variance == "auto":
            few = len(t) < KFOLD_BELOW_POINTS_PER_FEATURE * Zs.shape[1]
            self.variance_calibration_ = "kfold" if few and len(t) >= 2 * _FOLDS else "loo"
        self.calibration_points_, self.radius_scales_ = None, None
        if self.variance_calibration_ == "loo":
            errors, variances = self._loo()
            standardized = (errors / np.sqrt(variances))[:self.calibration_rows]
            self.std_scale_, self.calibration_points_ = self._scale(standardized), len(standardized)
        elif self.variance_calibration_ == "kfold" and len(t) >= 2 * _FOLDS:
            self.std_scale_, self.calibration_points_ = self._scale(self._kfold_errors(Zs, t)), len(t)
        return self

    def calibrate(self, X: Any, y: Any) -> GaussianProcessSurrogate:
        """Set the variance scale from evaluations the fit never saw: split conformal at 95 %.

        With ``z_i`` the errors of the target at the ``n`` validation points over the process's own
        predictive standard deviation (before any scale), ``s = |z|_(k) / 1.96``, the ``k``-th
        smallest with ``k = ceil(0.95 (n + 1))`` (split conformal prediction with normalized scores,
        Lei, G'Sell, Rinaldo, Tibshirani and Wasserman 2018, JASA 113:1094, sect. 5.2): the 95 %
        interval then covers a new point drawn like the validation points with probability at
        least 95 % over the draw of both, and its coverage over such points, given the fit, is
        ``Beta(k, n + 1 - k)``-distributed (Vovk 2012): 95.0 +- 1.0 % for n = 512. Unlike the
        cross-validation errors of ``calibrate_variance``, validation points are spread like the
        points predicted when drawn like them (e.g. a space-filling design of the space), and no
        fit or hyperparameter saw them. Other interval levels keep the normal shape with this scale.

        The intervals then use one such factor per bin of distance from the centre of the space
        (:func:`radius_scales`, ``radius_scales_``; Mondrian conformal prediction): the guarantee above
        holds within each bin for points drawn like that bin's validation points, near the bounds of
        the space as near its centre, where a single factor for the whole under-covered the corners
        and over-covered the middle. :func:`surrogate.sampling.fit_adaptive` draws its validation
        points spread over that distance (:func:`surrogate.sampling.radial_design`);
        ``std_scale_`` stays the factor of all of them together.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Validation points, none of them a training point, n >= :data:`MIN_VALIDATION_POINTS`.
            [parameter units]
        y : array_like of shape (n,)
            μ there. [1]

        Returns
        -------
        GaussianProcessSurrogate
            self, with ``std_scale_``, ``radius_scales_``, ``variance_calibration_ = "validation"``
            and ``calibration_points_ = n``.

        Raises
        ------
        ValueError
            For too few points, a training point among them, or invalid ``y``.
        """
        check_is_fitted(self, "gaussian_process_")
        X = self.space.check_X(X)
        y = self.check_mu(y, X.shape[0])
        if len(X) < MIN_VALIDATION_POINTS:
            raise ValueError(f"X must hold at least {MIN_VALIDATION_POINTS} validation points; got {len(X)}")
        training = {tuple(row) for row in self.X_train_}
        if any(tuple(row) in training for row in X):
            raise ValueError("validation points must not be training points")
        Zs = self.design_matrix(X)
        mean, std = self.gaussian_process_.predict(Zs, return_std=True)
        z = np.abs(self._target(y) - mean - self._prior_mean(Zs)) / np.maximum(std, np.finfo(float).tiny)
        self.std_scale_ = conformal_scale(z)
        self.radius_scales_ = radius_scales(z, self.space.radius(X))
        self.variance_calibration_, self.calibration_points_ = "validation", len(z)
        return self

    def scale_at(self, X: Any) -> np.ndarray:
        """The factor on the process's standard deviation at each point: ``radius_scales_`` by the bin of
        the point's distance from the centre of the space after :meth:`calibrate`, else ``std_scale_``. [1]"""
        return self._scales(self.space.check_X(X))

    def _scales(self, X: np.ndarray) -> np.ndarray:
        if getattr(self, "radius_scales_", None) is None:
            return np.full(X.shape[0], self.std_scale_)
        return self.radius_scales_.at(self.space.radius(X))

    def _initial_kernel(self, n_features: int) -> Kernel:
        kernel = build_kernel(self.kernel, n_features)
        if self.hyperparameters.initial_theta is None:
            return kernel
        theta = np.asarray(self.hyperparameters.initial_theta, dtype=float)
        if theta.shape != kernel.theta.shape or not np.all(np.isfinite(theta)):
            raise ValueError(f"hyperparameters.initial_theta must hold {kernel.theta.size} finite "
                             f"log-hyperparameters "
                             f"(amplitude, {n_features} length scales, noise); got shape {theta.shape}")
        bounds = kernel.bounds
        return kernel.clone_with_theta(np.clip(theta, bounds[:, 0], bounds[:, 1]))

    def _fit_process(self, Zs: np.ndarray, t: np.ndarray, kernel: Kernel,
                     n_restarts: int) -> tuple[np.ndarray, GaussianProcessRegressor]:
        """Prior-mean coefficients and the process fitted to the residuals of the target."""
        coef = fit_prior_mean(self.mean, Zs, t)
        gp = GaussianProcessRegressor(kernel, alpha=1e-10, normalize_y=True, n_restarts_optimizer=n_restarts,
                                      random_state=self.random_state,
                                      optimizer="fmin_l_bfgs_b" if self.hyperparameters.optimize else None)
        with warnings.catch_warnings(), one_blas_thread():
            # Length scales of features μ does not depend on (e.g. log balls at fixed load per
            # ball) rightly run to their upper bound; sklearn warns about every such bound.
            warnings.simplefilter("ignore", ConvergenceWarning)
            gp.fit(Zs, t - prior_mean(coef, Zs))
        return coef, gp

    def _scale(self, standardized_errors: np.ndarray) -> float:
        """The variance scale ``s`` of ``variance_scale`` from standardized CV errors (1 for N(0, 1))."""
        z = np.abs(standardized_errors)
        if self.variance_scale == "central":
            return float(np.quantile(z, _SCALE_QUANTILE) / _NORMAL_AT_SCALE_QUANTILE)
        return float(np.sqrt(np.mean(z**2)))

    def _kfold_errors(self, Zs: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Standardized k-fold errors, the mean and hyperparameters refitted per fold."""
        order = np.random.default_rng(self.random_state).permutation(len(t))
        standardized = []
        for held in np.array_split(order, _FOLDS):
            kept = np.setdiff1d(order, held)
            # Warm start from the full-data hyperparameters: one local optimization per fold.
            coef, gp = self._fit_process(Zs[kept], t[kept], self.gaussian_process_.kernel_, 0)
            mean, std = gp.predict(Zs[held], return_std=True)
            error = t[held] - (mean + prior_mean(coef, Zs[held]))
            standardized.append(error / np.maximum(std, np.finfo(float).tiny))
        return np.concatenate(standardized)

    def predict(self, X: Any, return_std: bool = False):
        """Predicted μ at physical points.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of ``space.names``. [parameter units]
        return_std : bool, default False
            Also return the predictive standard deviation of the target (log μ,
            or μ for ``log_target=False``).

        Returns
        -------
        mu : numpy.ndarray of shape (n,)
            Predicted μ (median of the log-normal prediction). [1]
        std : numpy.ndarray of shape (n,), optional
            Predictive standard deviation of the target. [1]
        """
        check_is_fitted(self, "gaussian_process_")
        X = self.space.check_X(X)
        # In blocks: the process's cross-covariances are (points x training rows), so a large call's
        # memory stays that of one block (a few MB) whatever its size.
        blocks = [self._predict_block(X[i:i + _PREDICT_BLOCK]) for i in range(0, len(X), _PREDICT_BLOCK)]
        t = np.concatenate([b[0] for b in blocks]) if blocks else np.empty(0)
        std = np.concatenate([b[1] for b in blocks]) if blocks else np.empty(0)
        mu = np.exp(t) if self.log_target else t
        return (mu, std) if return_std else mu

    def _predict_block(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The target's mean and standard deviation at a block of checked points."""
        Zs = self.design_matrix(X)
        t, std = self.gaussian_process_.predict(Zs, return_std=True)
        return t + self._prior_mean(Zs), std * self._scales(X)

    def predict_interval(self, X: Any, level: float = 0.95) -> SurrogatePrediction:
        """Predicted μ with a central interval and the outside-space flag.

        Parameters
        ----------
        X : array_like of shape (n, d)
            Points in the units of ``space.names``. [parameter units]
        level : float, default 0.95
            Probability of the central interval, in (0, 1). [1]

        Returns
        -------
        SurrogatePrediction
            ``mu``, ``mu_lower``, ``mu_upper`` [1], ``outside_space`` and ``log_std``.

        Raises
        ------
        ValueError
            If ``level`` is not in (0, 1).
        """
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must be in (0, 1); got {level!r}")
        X = self.space.check_X(X)
        return self._interval(X, ~self.space.contains(X), level)

    def _interval(self, X: np.ndarray, outside: np.ndarray, level: float) -> SurrogatePrediction:
        mu, std = self.predict(X, return_std=True)
        # Never narrower than float64 evaluation of μ can be trusted: where μ does not depend on an
        # input, the process reproduces it to the last bit at some points and not at others.
        half = norm.ppf(0.5 + 0.5 * level) * std
        if self.log_target:
            half = np.maximum(half, RELATIVE_RESOLUTION)
            lower, upper = mu * np.exp(-half), mu * np.exp(half)
        else:
            half = np.maximum(half, RELATIVE_RESOLUTION * np.abs(mu))
            lower, upper = mu - half, mu + half
        return SurrogatePrediction(mu, lower, upper, outside, std)

    def predict_points(self, points: Mapping[str, Any], level: float = 0.95) -> SurrogatePrediction:
        """Prediction for columnar physics inputs (names of :data:`physics.PARAMETERS`).

        Parameters
        ----------
        points : mapping of str to array_like
            Every dimension of the space by name, broadcasting together; other
            parameters may be given and flag points as outside the space when
            they differ from the trained fixed values.
        level : float, default 0.95
            Probability of the central interval. [1]

        Returns
        -------
        SurrogatePrediction
            Flat arrays, one entry per broadcast point.
        """
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must be in (0, 1); got {level!r}")
        check_is_fitted(self, "gaussian_process_")
        X, outside = self.space.from_points(points)
        return self._interval(X, outside, level)

    def mu_model(self, points: Mapping[str, Any]) -> np.ndarray:
        """μ for columnar points: the ``mu_model(points)`` seam of optimize and calibrate.

        Parameters
        ----------
        points : mapping of str to array_like
            As :meth:`predict_points`.

        Returns
        -------
        numpy.ndarray
            Predicted μ, one per broadcast point. [1]
        """
        return self.predict_points(points).mu

    def loo_log_errors(self) -> np.ndarray:
        """Leave-one-out errors of the target at the training points (closed form).

        Returns
        -------
        numpy.ndarray of shape (n,)
            ``t_i - mean_{-i}`` with the hyperparameters and prior mean held
            fixed (Rasmussen & Williams 2006, eq. 5.12:
            ``t_i - mean_{-i} = [K^-1 t]_i / [K^-1]_ii``), in units of log μ. [1]
        """
        check_is_fitted(self, "gaussian_process_")
        return self._loo()[0]

    def loo_log_variances(self) -> np.ndarray:
        """Leave-one-out predictive variances of the target at the training points (closed form).

        Returns
        -------
        numpy.ndarray of shape (n,)
            The variance of ``mean_{-i}`` about ``t_i`` with the hyperparameters held fixed
            (Rasmussen & Williams 2006, eq. 5.12: ``1 / [K^-1]_ii``), before the variance scale
            :attr:`std_scale_`, in units of (log μ)²: :meth:`loo_log_errors` over their square root
            are the standardized errors the variance scale is set from. [1]
        """
        check_is_fitted(self, "gaussian_process_")
        return self._loo()[1]

    def _loo(self) -> tuple[np.ndarray, np.ndarray]:
        # Kept with the process it belongs to: the calibration and adaptive sampling both need it,
        # and each computation inverts the n x n covariance.
        cached = getattr(self, "_loo_cache", None)
        if cached is None or cached[0] is not self.gaussian_process_:
            gp = self.gaussian_process_
            K_inv_diag = np.diag(cho_solve((gp.L_, True), np.eye(gp.L_.shape[0])))
            # alpha_ and K are in normalize_y units; scale back to the target's units.
            y_std = float(np.ravel(gp._y_train_std)[0])
            errors, variances = gp.alpha_.reshape(-1) / K_inv_diag * y_std, y_std**2 / K_inv_diag
            self._loo_cache = cached = (gp, (errors, variances))
        return cached[1]

"""The Gaussian-process discrepancy of a calibrated model (:class:`GPCorrection`): its mean and latent
variance at points, and certified bounds of both over boxes of points (what a robust design bounds).

Kept beside :mod:`calibrate.model`, which holds it (``CalibratedModel.discrepancy``) and re-exports it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.linalg import cho_solve, solve_triangular

__all__ = ["GPCorrection"]


def _unique_rows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of a 2-D array in lexicographic order and, per row, the index of its own: what
    ``np.unique(x, axis=0, return_inverse=True)`` gives, by one sort of the rows (that one sorts a
    structured view of them, ~15x slower)."""
    if len(x) == 0:
        return x, np.zeros(0, dtype=int)
    order = np.lexsort(x.T[::-1])
    ordered = x[order]
    new = np.empty(len(x), dtype=bool)
    new[0] = True
    np.any(ordered[1:] != ordered[:-1], axis=1, out=new[1:])
    inverse = np.empty(len(x), dtype=int)
    inverse[order] = np.cumsum(new) - 1
    return ordered[new], inverse


class GPCorrection:
    """A Gaussian-process discrepancy of log μ, rebuilt from the data of
    :func:`calibrate.discrepancy.gp_state` as scikit-learn's regressor with those hyperparameters fixed.

    Parameters
    ----------
    state : mapping
        ``features``, ``centre``, ``scale``, ``length_scale``, ``amplitude``, ``noise``, ``x``, ``y``.

    Raises
    ------
    ValueError
        For inconsistent sizes or non-positive hyperparameters.
    """

    def __init__(self, state: Mapping[str, Any]):
        keys = ("features", "centre", "scale", "length_scale", "amplitude", "noise", "x", "y")
        missing = [k for k in keys if k not in state]
        if missing:
            raise ValueError(f"discrepancy: missing {', '.join(missing)}")
        self.state = {k: state[k] for k in keys}
        self.features = [str(f) for f in state["features"]]
        self.centre = np.asarray(state["centre"], dtype=float)
        self.scale = np.asarray(state["scale"], dtype=float)
        self.length = np.asarray(state["length_scale"], dtype=float)
        self.amplitude, self.noise = float(state["amplitude"]), float(state["noise"])
        self.x = np.asarray(state["x"], dtype=float)
        y = np.asarray(state["y"], dtype=float)
        sizes = {self.centre.size, self.scale.size, self.length.size, len(self.features)}
        if len(sizes) != 1 or self.x.ndim != 2 or self.x.shape != (y.size, len(self.features)) or y.size < 2:
            raise ValueError("discrepancy: features, centre, scale, length_scale and the columns of x must "
                             "have one size, and y one value per row of x (at least two)")
        if not (np.all(self.scale > 0) and np.all(self.length > 0) and self.amplitude > 0 and self.noise > 0):
            raise ValueError("discrepancy: scale, length_scale, amplitude and noise must be positive")
        # scikit-learn's regressor with the stored, fixed hyperparameters (optimizer=None: fitting only
        # factors the covariance of the stored data). The white noise enters as ``alpha``, on the training
        # rows only, so predictions give the latent variance: the discrepancy's own. With no relevant
        # column, one constant column gives the same covariance (the amplitude between any two points).
        # Imported here: scikit-learn takes seconds to import, and most models have no GP.
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel

        length = self.length if self.features else np.ones(1)
        kernel = ConstantKernel(self.amplitude, "fixed") * RBF(length, "fixed")
        self.gp = GaussianProcessRegressor(kernel, alpha=self.noise, normalize_y=True, optimizer=None)
        self.gp.fit(self.x if self.features else np.zeros((y.size, 1)), y)
        # the normalization of y the regressor applied (its fitted state), read once
        self._y_mean = float(np.ravel(self.gp._y_train_mean)[0])
        self._y_std = float(np.ravel(self.gp._y_train_std)[0])

    def _scaled(self, columns: Mapping[str, Any], shape: tuple[int, ...]) -> np.ndarray:
        """The scaled feature rows the regressor reads at columnar points (one per entry of ``shape``)."""
        if not self.features:
            return np.zeros((int(np.prod(shape)), 1))
        features = zip(self.features, self.centre, self.scale, strict=True)
        return np.column_stack([((np.broadcast_to(np.asarray(columns[f], float), shape) - c) / s).ravel()
                                for f, c, s in features])

    @property
    def noise_variance(self) -> float:
        """The variance of one measurement's white noise about the discrepancy, of log μ [1]."""
        return self.noise * self._y_std**2

    def covariance(self, a: Mapping[str, Any], shape_a: tuple[int, ...], b: Mapping[str, Any],
                   shape_b: tuple[int, ...]) -> np.ndarray:
        """The latent posterior covariance of the discrepancy of log μ between the points of ``a`` (rows)
        and of ``b`` (columns) given the stored data [1] (Rasmussen & Williams eq. 2.24: k(a, b) -
        k(a, X) K⁻¹ k(X, b)): what runs at ``b`` tell of it at ``a``."""
        gp = self.gp
        xa, xb = self._scaled(a, shape_a), self._scaled(b, shape_b)
        va = solve_triangular(gp.L_, gp.kernel_(xa, gp.X_train_).T, lower=True, check_finite=False)
        vb = solve_triangular(gp.L_, gp.kernel_(xb, gp.X_train_).T, lower=True, check_finite=False)
        return (gp.kernel_(xa, xb) - va.T @ vb) * self._y_std**2

    def __call__(self, columns: Mapping[str, Any], shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Mean and latent variance of the discrepancy of log μ at columnar points [1], shaped ``shape``."""
        rows, inverse = _unique_rows(self._scaled(columns, shape))  # points sharing features: each row once
        mean, variance = self._predict(rows)
        return mean[inverse].reshape(shape), variance[inverse].reshape(shape)

    def _predict(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The regressor's mean and latent variance at scaled feature rows [1], as
        ``GaussianProcessRegressor.predict(rows, return_std=True)`` computes them (Rasmussen & Williams,
        Alg. 2.1, lines 4-6, on its fitted ``kernel_``, ``alpha_`` and ``L_``), without re-validating the
        rows on every call (most of a call's time for the few rows a robust design asks about)."""
        gp = self.gp
        k_trans = gp.kernel_(rows, gp.X_train_)
        mean = self._y_std * (k_trans @ gp.alpha_) + self._y_mean
        v = solve_triangular(gp.L_, k_trans.T, lower=True, check_finite=False)
        latent = gp.kernel_.diag(rows).copy()
        latent -= np.einsum("ij,ji->i", v.T, v)
        latent[latent < 0] = 0.0  # rounding: a variance is never negative
        # the regressor's standard deviation, squared: the same numbers as through predict
        return mean, np.square(np.sqrt(latent * self._y_std**2))

    def _kernel_ends(self, low: Mapping[str, Any], high: Mapping[str, Any], shape: tuple[int, ...]) -> tuple:
        """Per box and training point: the box's scaled corners, the length scales, the farthest and the
        centre's scaled offsets, and the kernel's least, largest and centre values (:meth:`bound`)."""
        gp = self.gp
        size = int(np.prod(shape))
        train = np.asarray(gp.X_train_, dtype=float)
        if self.features:
            a, b = (np.column_stack([((np.broadcast_to(np.asarray(points[f], dtype=float), shape) - c) / s)
                                     .ravel() for f, c, s in zip(self.features, self.centre, self.scale,
                                                                 strict=True)])
                    for points in (low, high))
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            length = self.length
        else:  # one constant column: the amplitude between any two points
            lo = hi = np.zeros((size, 1))
            length = np.ones(1)
        outside = np.maximum(lo[:, None, :] - train[None], train[None] - hi[:, None, :])
        near = np.maximum(0.0, outside) / length
        far = np.maximum(np.abs(lo[:, None, :] - train[None]), np.abs(hi[:, None, :] - train[None])) / length
        middle = (0.5 * (lo + hi)[:, None, :] - train[None]) / length
        k_max = self.amplitude * np.exp(-0.5 * np.sum(near * near, axis=2))
        k_min = self.amplitude * np.exp(-0.5 * np.sum(far * far, axis=2))
        k_0 = self.amplitude * np.exp(-0.5 * np.sum(middle * middle, axis=2))
        return lo, hi, length, far, middle, k_min, k_max, k_0

    def least_variance(self, low: Mapping[str, Any], high: Mapping[str, Any], shape: tuple[int, ...]
                       ) -> np.ndarray:
        """A certified lower bound of the latent variance over boxes of points (as :meth:`bound`) [1].

        The variance is y_std² (A - q(k)), q(k) = k' K⁻¹ k; by Taylor's theorem at the box's centre's k0,
        q(k) = q(k0) + 2 (K⁻¹ k0)'(k - k0) + (k - k0)' K⁻¹ (k - k0), the last at most |k - k0|² / α (K is
        the kernel matrix plus α, the white noise, on its diagonal: its least eigenvalue is at least α), each
        k_i between its least and largest value over the box: q at most the linear part at each term's worse
        end plus that square, tending to the value as the box shrinks.
        """
        gp = self.gp
        _, _, _, _, _, k_min, k_max, k_0 = self._kernel_ends(low, high, shape)
        y_std = self._y_std
        solved = cho_solve((gp.L_, True), k_0.T).T  # K^-1 k0 per box
        gradient = 2.0 * solved
        spread = np.maximum(np.abs(k_min - k_0), np.abs(k_max - k_0))
        most = (np.sum(k_0 * solved, axis=1)
                + np.sum(np.maximum(gradient * (k_min - k_0), gradient * (k_max - k_0)), axis=1)
                + np.sum(spread * spread, axis=1) / self.noise)
        variance = np.clip(self.amplitude - most, 0.0, self.amplitude) * y_std**2
        return np.clip(variance * (1.0 - 1e-9) - 1e-15 * self.amplitude * y_std**2, 0.0, None).reshape(shape)

    def bound(self, low: Mapping[str, Any], high: Mapping[str, Any], shape: tuple[int, ...]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Certified bounds over boxes of points (each feature between its ``low`` and ``high`` value,
        columnar, one box per entry): the least and largest mean and the largest latent variance [1].

        The mean is y_mean + y_std sum_i alpha_i k(x, x_i) and the RBF kernel k(x, x_i) = A exp(-½ sum_d
        ((x_d - x_id) / l_d)²) lies between its values at the per-axis farthest and nearest distance from
        x_i to the box: each term at its end by the sign of alpha_i. The latent variance is y_std² (A -
        q(k)), q(k) = k' K⁻¹ k convex (K⁻¹ positive definite), so q at any k is at least its tangent plane
        at the box's centre's k0, q(k0) + 2 (K⁻¹ k0)'(k - k0), least over the box of kernel values at one
        of each term's ends. Both bounds tend to the values as the box shrinks.
        """
        gp = self.gp
        lo, hi, length, far, middle, k_min, k_max, k_0 = self._kernel_ends(low, high, shape)
        alpha = np.asarray(gp.alpha_, dtype=float).ravel()
        y_std, y_mean = self._y_std, self._y_mean
        upper = np.sum(np.where(alpha > 0, alpha * k_max, alpha * k_min), axis=1)
        lower = np.sum(np.where(alpha > 0, alpha * k_min, alpha * k_max), axis=1)
        # Rounding of the sum (alpha may be large and of both signs): a relative allowance on its terms.
        slack = 1e-12 * np.sum(np.abs(alpha) * k_max, axis=1)
        if self.features:
            # Taylor's theorem at the centre c, tight to the box's width squared where the terms' ends are
            # loose (alpha large and of both signs): m(x) = m(c) + grad m(c).(x - c) + ½ (x - c)' H (x - c)
            # with H at a point between. Per training point, along v (u = (x - x_i) / l, v' = v / l),
            # v' H_i v' = k_i ((u.v')² - |v'|²) lies in [-k_i |v'|², k_i (|u|² - 1) |v'|²], and
            # k (|u|² - 1) <= A max_r exp(-r²/2) (r² - 1) = 2 A exp(-3/2) at r² = 3.
            half = 0.5 * (hi - lo) / length
            rise = np.minimum(2.0 * self.amplitude * math.exp(-1.5),
                              k_max * np.maximum(np.sum(far * far, axis=2) - 1.0, 0.0))
            curvature_up = np.sum(np.where(alpha > 0, alpha * rise, -alpha * k_max), axis=1)
            curvature_down = np.sum(np.where(alpha > 0, alpha * k_max, -alpha * rise), axis=1)
            centre_mean = k_0 @ alpha
            gradient_mean = -np.einsum("nm,m,nmd->nd", k_0, alpha, middle)  # d m / d(x / l) at c
            linear = np.sum(np.abs(gradient_mean) * half, axis=1)
            square = 0.5 * np.sum(half * half, axis=1)
            upper = np.minimum(upper, centre_mean + linear + curvature_up * square)
            lower = np.maximum(lower, centre_mean - linear - curvature_down * square)
        solved = cho_solve((gp.L_, True), k_0.T).T  # K^-1 k0 per box
        gradient = 2.0 * solved
        least = (np.sum(k_0 * solved, axis=1)
                 + np.sum(np.minimum(gradient * (k_min - k_0), gradient * (k_max - k_0)), axis=1))
        variance = np.clip(self.amplitude - least, 0.0, self.amplitude) * y_std**2
        return ((y_mean + y_std * (lower - slack)).reshape(shape),
                (y_mean + y_std * (upper + slack)).reshape(shape),
                (variance * (1.0 + 1e-9) + 1e-15 * self.amplitude * y_std**2).reshape(shape))

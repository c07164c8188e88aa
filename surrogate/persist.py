"""Persistence of fitted surrogates as plain data (JSON), never pickle.

A stored surrogate holds what defines it: its space, estimator parameters,
training points and μ, feature standardization, prior-mean coefficients,
variance scale (and its factors by distance from the space's centre, with their bins) and the
kernel's hyperparameters (``theta``, the log of its
positive parameters, with the kernel kind that fixes its structure), plus the
package version and physics convention it was trained with. Loading rebuilds
the kernel with those hyperparameters and refits a
:class:`~sklearn.gaussian_process.GaussianProcessRegressor` with
``optimizer=None`` on the stored data: the same arithmetic as the original
fit, hence the same predictions.
"""

from __future__ import annotations

import json
from importlib import metadata
from typing import Any

import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor

from microbearing import physics

from .model import GaussianProcessSurrogate, Hyperparameters, RadiusScales, build_kernel
from .space import Space

__all__ = ["FORMAT", "package_version", "version_warning", "to_dict", "from_dict", "dumps", "loads"]

#: Identifier and version of the stored layout.
FORMAT = "microbearing.surrogate/1"

#: The stored parameters, in their stored order: the estimator's own, and (stored flat, under these
#: names) the fields of its :class:`Hyperparameters`.
_ESTIMATOR_PARAMS = ("features", "kernel", "mean", "log_target", "n_restarts_optimizer", "random_state",
                     "initial_theta", "calibrate_variance", "variance_scale",
                     "optimize_hyperparameters", "calibration_rows")
_SEARCH_PARAMS = {"n_restarts_optimizer": "n_restarts_optimizer", "initial_theta": "initial_theta",
                  "optimize_hyperparameters": "optimize"}


def _stored_param(model: GaussianProcessSurrogate, name: str) -> Any:
    if name not in _SEARCH_PARAMS:
        return getattr(model, name)
    value = getattr(model.hyperparameters, _SEARCH_PARAMS[name])
    return np.asarray(value).tolist() if name == "initial_theta" and value is not None else value


def _estimator(space: Space, params: dict[str, Any]) -> GaussianProcessSurrogate:
    """The estimator of stored parameters (a layout of earlier versions lacks some: their defaults)."""
    search = {field: params[name] for name, field in _SEARCH_PARAMS.items() if name in params}
    own = {name: value for name, value in params.items() if name not in _SEARCH_PARAMS}
    return GaussianProcessSurrogate(space, **own, hyperparameters=Hyperparameters(**search))


def package_version() -> str:
    """Version of the installed microbearing package ("unknown" when not installed)."""
    try:
        return metadata.version("microbearing")
    except metadata.PackageNotFoundError:
        return "unknown"


def version_warning(stored_version: str | None) -> str | None:
    """Why a surrogate stored with another package version may no longer match the physics.

    Parameters
    ----------
    stored_version : str or None
        The ``package_version`` stored with the surrogate (None when absent).

    Returns
    -------
    str or None
        None when it is the running version; else a sentence naming both versions.

    Examples
    --------
    >>> version_warning(package_version()) is None
    True
    >>> version_warning("0.0.0")[:44]
    'trained with microbearing 0.0.0, running is '
    """
    running = package_version()
    if stored_version == running:
        return None
    return (f"trained with microbearing {stored_version or 'of unknown version'}, running is {running}: "
            f"the physics may have changed since; retrain to be sure its figures still hold")


def to_dict(model: GaussianProcessSurrogate) -> dict[str, Any]:
    """A fitted surrogate as JSON-ready data.

    Parameters
    ----------
    model : GaussianProcessSurrogate
        A fitted surrogate.

    Returns
    -------
    dict
        Lists, numbers and strings only (floats survive JSON exactly).

    Raises
    ------
    ValueError
        If the model is not fitted.
    """
    if not hasattr(model, "gaussian_process_"):
        raise ValueError("model must be fitted (call fit) before it is stored")
    gp = model.gaussian_process_
    return {
        "format": FORMAT,
        "package_version": package_version(),
        "convention": model.space.convention,
        "space": model.space.to_dict(),
        "params": {name: _stored_param(model, name) for name in _ESTIMATOR_PARAMS},
        "X_train": model.X_train_.tolist(),
        "y_train": model.y_train_.tolist(),
        "feature_mean": model.feature_mean_.tolist(),
        "feature_scale": model.feature_scale_.tolist(),
        "mean_coef": model.mean_coef_.tolist(),
        "std_scale": model.std_scale_,
        "variance_calibration": model.variance_calibration_,
        "calibration_points": model.calibration_points_,
        "radius_scales": _stored_radius_scales(getattr(model, "radius_scales_", None)),
        "gp": {"kernel": str(gp.kernel_), "theta": gp.kernel_.theta.tolist(), "alpha": gp.alpha,
               "normalize_y": gp.normalize_y},
    }


def from_dict(data: dict[str, Any]) -> GaussianProcessSurrogate:
    """Rebuild a fitted surrogate from :func:`to_dict` data.

    Parameters
    ----------
    data : dict
        Output of :func:`to_dict` (possibly through JSON).

    Returns
    -------
    GaussianProcessSurrogate
        A fitted surrogate predicting exactly as the stored one, with ``package_version_`` (the
        version it was trained with) and ``version_warning_`` (:func:`version_warning`: None
        unless that differs from the running version, whose physics may differ).

    Raises
    ------
    ValueError
        For another format, an unknown convention or one differing from its space's, or
        inconsistent arrays.
    """
    if data.get("format") != FORMAT:
        raise ValueError(f"data must be a stored surrogate of format {FORMAT!r}; got {data.get('format')!r}")
    if data.get("convention") not in physics.CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(physics.CONVENTIONS)}; "
                         f"got {data.get('convention')!r}")
    space = Space.from_dict(data["space"])
    if space.convention != data["convention"]:
        raise ValueError(f"convention {data['convention']!r} differs from its space's {space.convention!r}")
    model = _estimator(space, data["params"])
    X = space.check_X(np.asarray(data["X_train"], dtype=float))
    y = model.check_mu(data["y_train"], X.shape[0])
    model.feature_mean_ = np.asarray(data["feature_mean"], dtype=float)
    model.feature_scale_ = np.asarray(data["feature_scale"], dtype=float)
    model.mean_coef_ = np.asarray(data["mean_coef"], dtype=float)
    Zs = model.design_matrix(X)
    # A posynomial mean holds two terms; the other means one (records before it: "linear" or "constant").
    size = (Zs.shape[1] + 1) * (2 if model.mean == "posynomial" else 1)
    if model.mean_coef_.shape != (size,):
        raise ValueError(f"mean_coef must hold {size} values; got {model.mean_coef_.shape}")
    stored = data["gp"]
    theta = np.asarray(stored["theta"], dtype=float)
    kernel = build_kernel(model.kernel, Zs.shape[1]).clone_with_theta(theta)
    gp = GaussianProcessRegressor(kernel, alpha=stored["alpha"], normalize_y=stored["normalize_y"],
                                  optimizer=None)
    gp.fit(Zs, model.residual_target(Zs, y))
    model.gaussian_process_ = gp
    model.X_train_ = X
    model.y_train_ = y
    model.n_features_in_ = X.shape[1]
    model.std_scale_ = float(data["std_scale"])
    # Stored before "auto" existed: the calibration was the one requested.
    model.variance_calibration_ = data.get("variance_calibration", model.calibrate_variance)
    model.calibration_points_ = data.get("calibration_points")  # absent before it was recorded
    model.radius_scales_ = _radius_scales(data)
    model.package_version_ = data.get("package_version")
    model.version_warning_ = version_warning(model.package_version_)
    return model


def _stored_radius_scales(fit: RadiusScales | None) -> dict[str, list[float]] | None:
    return None if fit is None else {"edges": list(fit.edges), "scales": list(fit.scales)}


def _radius_scales(data: dict[str, Any]) -> RadiusScales | None:
    """The stored factors by distance from the centre; None when absent (stored before they were kept:
    the single ``std_scale`` serves)."""
    stored = data.get("radius_scales")
    if stored is None:
        return None
    edges, scales = (np.asarray(stored.get(key, []), dtype=float) for key in ("edges", "scales"))
    if (scales.shape != (edges.size + 1,) or not np.all(np.isfinite(scales)) or np.any(scales <= 0)
            or np.any(np.diff(edges) <= 0) or not np.all(np.isfinite(edges))):
        raise ValueError("radius_scales must hold increasing edges and one positive factor more; "
                         f"got {stored!r}")
    return RadiusScales(edges.tolist(), scales.tolist())


def dumps(model: GaussianProcessSurrogate) -> str:
    """A fitted surrogate as a JSON string (see :func:`to_dict`)."""
    return json.dumps(to_dict(model))


def loads(text: str) -> GaussianProcessSurrogate:
    """Rebuild a surrogate from :func:`dumps` output (see :func:`from_dict`)."""
    return from_dict(json.loads(text))

"""microbearing: friction of micro linear ball bearings for MEMS (Olaru et al., COMEC 2005).

The import package of the project. Its subpackages (each a folder of the repository):

- :mod:`microbearing.physics`: the friction model (``physics.evaluate``), parameters, materials;
- :mod:`microbearing.surrogate`: Gaussian-process surrogates of the model;
- :mod:`microbearing.optimize`: least-friction designs and Pareto fronts;
- :mod:`microbearing.calibrate`: calibration on measured friction, missing-effect search;
- :mod:`microbearing.service`: the REST service and the ``microbearing`` command line.

``python -m microbearing`` runs the command line. The subpackages are imported on use
(``from microbearing import physics``), not by ``import microbearing``.
"""

from importlib.metadata import PackageNotFoundError, version

__all__ = ["SUBPACKAGES", "__version__"]

#: The subpackages, in their order of dependence (each uses only those before it).
SUBPACKAGES = ("physics", "surrogate", "optimize", "calibrate", "service")

try:
    __version__ = version("microbearing")
except PackageNotFoundError:  # the source tree without an install
    __version__ = "0+unknown"

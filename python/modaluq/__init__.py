"""modaluq: modal parameters with their uncertainty from vibration data.

Covariance-driven stochastic subspace identification (SSI-cov), output-only and
input/output, with the first-order standard deviation of every frequency, damping ratio and
mode shape at every model order, computed from one dataset.

>>> import modaluq
>>> sim = modaluq.simulate(20_000, seed=1)
>>> result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=15, orders=range(2, 31, 2))
>>> print(result.at_order(12))                                        # doctest: +SKIP
"""

from ._core import NumericalError
from ._core import __version__ as _core_version
from .identification import ModalUQWarning, Modes, Result, identify
from .simulate import Simulation, simulate
from .stabilization import (ClusteringSettings, Diagram, PoleStatus, SelectedModes, StabilityCriteria,
                            select_modes, stabilization_diagram)
from .streaming import CovarianceAccumulator
from .horizons import HorizonCheck, check_horizons

try:
    from importlib.metadata import PackageNotFoundError, version as _dist_version

    __version__ = _dist_version("modaluq")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = _core_version

__all__ = [
    "ClusteringSettings",
    "CovarianceAccumulator",
    "Diagram",
    "HorizonCheck",
    "ModalUQWarning",
    "Modes",
    "NumericalError",
    "PoleStatus",
    "Result",
    "SelectedModes",
    "Simulation",
    "StabilityCriteria",
    "check_horizons",
    "identify",
    "select_modes",
    "simulate",
    "stabilization_diagram",
    "__version__",
]

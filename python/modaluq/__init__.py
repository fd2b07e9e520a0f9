"""modaluq: modal parameters with their uncertainty from vibration data.

Covariance-driven stochastic subspace identification (SSI-cov), output-only and
input/output, with the first-order standard deviation of every frequency, damping ratio and
mode shape at every model order, computed from one dataset.

>>> import modaluq
>>> sim = modaluq.simulate(20_000, seed=1)
>>> result = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=15, orders=range(2, 31, 2))
>>> print(result.at_order(12))                                        # doctest: +SKIP

The modules form layers, each importing only those below it (docs/architecture.md):
``checks`` → ``settings``, ``preprocess``, ``auto_settings``, ``spectrum``, ``harmonics`` →
``plot``, ``export`` → ``selection`` → ``stabilization`` → ``results`` → ``identification``,
``streaming`` → ``horizons``, ``analysis`` → the ``monitoring/`` wing (many records: ``monitor``)
→ ``cli``: a result type sits above what its convenience methods reach (``Result.plot()``);
``io``, ``simulate`` and ``monitoring.simulator`` are side leaves, ``validation`` sits on
identification and the simulator.

The wing's names here (``monitor``, ``Monitoring``, ``load_tracks``, ``simulate_monitoring``,
``TrackingSettings``) are resolved on first use: ``import modaluq`` does not import the wing.
"""

from ._core import NumericalError
from .analysis import Analysis
from .buildinfo import show_config
from .comparison import ModeComparison, compare_modes
from .geometry import Geometry
from .horizons import HorizonCheck, check_horizons
from .identification import identify, identify_setups
from .intervals import interval_factor
from .poser import PoserResult, ReferenceMismatchWarning
from .results import ModalUQWarning, Modes, Result
from .selection import SelectedModes, select_modes
from .settings import ClusteringSettings, PoleStatus, Settings, StabilityCriteria
from .simulate import Simulation, simulate
from .stabilization import Diagram, modal_assurance_criterion, stabilization_diagram
from .streaming import CovarianceAccumulator
from .version import __version__

__all__ = [
    "Analysis",
    "ClusteringSettings",
    "CovarianceAccumulator",
    "Diagram",
    "Geometry",
    "HorizonCheck",
    "ModalUQWarning",
    "ModeComparison",
    "Modes",
    "Monitoring",
    "NumericalError",
    "PoleStatus",
    "PoserResult",
    "ReferenceMismatchWarning",
    "Result",
    "SelectedModes",
    "Settings",
    "Simulation",
    "StabilityCriteria",
    "TrackingSettings",
    "check_horizons",
    "compare_modes",
    "identify",
    "identify_setups",
    "interval_factor",
    "load_tracks",
    "modal_assurance_criterion",
    "monitor",
    "select_modes",
    "show_config",
    "simulate",
    "simulate_monitoring",
    "stabilization_diagram",
    "__version__",
]

#: The monitoring wing's names: imported on first use (PEP 562), so that ``import modaluq`` and
#: every command but ``modaluq monitor`` do not load the wing.
_MONITORING_NAMES = ("Monitoring", "TrackingSettings", "load_tracks", "monitor", "simulate_monitoring")


def __getattr__(name):
    if name in _MONITORING_NAMES:
        from . import monitoring

        value = getattr(monitoring, name)
        globals()[name] = value  # found directly from now on
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_MONITORING_NAMES))

"""Monitoring, the package's wing: many records → tracked modes with σ, change statistics and
alarms (docs/monitoring.md). ``import modaluq`` does not load it; its names on the package face
(``modaluq.monitor``, ...) import it on first use.

One module per concern, each importing only those listed before it:

- :mod:`~modaluq.monitoring.simulator`: a simulated campaign (a side leaf: ``checks`` and ``simulate`` only);
- :mod:`~modaluq.monitoring.tracking`: reference modes, the σ-aware assignment, a batch's tracks;
- :mod:`~modaluq.monitoring.change`: the change test, its alarm limit and calibration;
- :mod:`~modaluq.monitoring.records`: files, folders, patterns, record objects → tasks in time order, with
  their times and covariates;
- :mod:`~modaluq.monitoring.parts`: the part files that make a run restartable;
- :mod:`~modaluq.monitoring.executors`: thread pool, Dask client, LocalCluster or scheduler; worker processes'
  setup;
- :mod:`~modaluq.monitoring.worker`: one record → one part (:func:`process_record`);
- :mod:`~modaluq.monitoring.store`: the Dataset's schema, NetCDF/Zarr and the tables beside it,
  :func:`load_tracks`;
- :mod:`~modaluq.monitoring.plot`: tracked frequencies and the control chart (matplotlib: imported
  when a plot is drawn, not with the wing);
- :mod:`~modaluq.monitoring.run`: :func:`monitor` and its result :class:`Monitoring`.
"""

from .records import RecordTask, record_files, time_from_name
from .run import Monitoring, monitor
from .simulator import MonitoringSimulation, SimulatedRecord, simulate_monitoring
from .store import load_tracks
from .tracking import TrackingSettings
from .worker import TaskConfig, process_record

__all__ = ["Monitoring", "MonitoringSimulation", "RecordTask", "SimulatedRecord", "TaskConfig", "TrackingSettings",
           "load_tracks", "monitor", "process_record", "record_files", "simulate_monitoring", "time_from_name"]

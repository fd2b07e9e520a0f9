"""A simulated monitoring campaign: the chain of :func:`modaluq.simulate` recorded at a fixed
interval while its stiffness follows the temperature, and optionally damaged from one record on.

Each record is an output-only ambient record (white forces on every mass, sensor noise) of the
chain whose springs are all scaled by ``1 + temperature_coefficient (T - T_ref)``; from
``damage_record`` on, spring ``damage_element`` also loses ``damage_fraction`` of its stiffness.
The records are made lazily (:meth:`SimulatedRecord.load`), so a campaign of thousands of records
costs nothing until a worker loads one, and a record travels to a worker as a few numbers.

>>> from modaluq.monitoring import simulate_monitoring
>>> campaign = simulate_monitoring(48, n_samples=2000, seed=1)
>>> campaign.records[0].name, str(campaign.records[1].time)
('record-0000', '2026-01-01T01:00:00')
>>> campaign.frequency_hz.shape                      # true frequencies, (record, mode)
(48, 6)
>>> campaign.records[0].load().y.shape
(2000, 3)

This module is a side leaf of the package (in the monitoring wing): it imports only
:mod:`modaluq.checks` and :mod:`modaluq.simulate`.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..atomic import csv_cell
from ..checks import check_integer, check_real, check_sampling_frequency
from ..simulate import Simulation, chain_system, default_output_dofs, modal_parameters, simulate

__all__ = ["MonitoringSimulation", "SimulatedRecord", "simulate_monitoring"]


@dataclass(frozen=True)
class SimulatedRecord:
    """One record of a campaign: what :meth:`load` needs to simulate it, and its covariates."""

    name: str                  #: ``record-0000`` ...
    time: np.datetime64        #: start of the record
    covariates: dict           #: ``{"temperature": °C}``
    stiffness: tuple           #: spring stiffnesses of this record, N/m
    seed: int                  #: the campaign's seed
    index: int                 #: record index (the random stream is ``SeedSequence(seed, spawn_key=(index,))``)
    simulation: dict = field(default_factory=dict)  #: further keywords of :func:`modaluq.simulate`

    @property
    def output_names(self) -> tuple:
        """``acc1``, ``acc2``, ...: the measured degrees of freedom (1-based), the names its files get too."""
        return channel_names(self.simulation["output_dofs"])

    def load(self) -> Simulation:
        """The record's samples (:class:`~modaluq.Simulation`, output-only: ``u`` has no column)."""
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(self.index,)))
        return simulate(seed=rng, stiffness=np.asarray(self.stiffness), input_dofs=(), input_std=1.0,
                        unknown_input_std=1.0, **self.simulation)


@dataclass(frozen=True, repr=False)
class MonitoringSimulation:
    """A campaign: the records, their times and temperatures, and the true modal parameters."""

    records: tuple             #: of :class:`SimulatedRecord`
    time: np.ndarray           #: (n_records,) datetime64[s]
    temperature: np.ndarray    #: (n_records,) °C
    damaged: np.ndarray        #: (n_records,) bool
    frequency_hz: np.ndarray   #: (n_records, n_modes) true frequencies, Hz
    damping_ratio: np.ndarray  #: (n_records, n_modes) true damping ratios
    mode_shape: np.ndarray     #: (n_records, n_outputs, n_modes) true shapes, largest component 1
    fs: float                  #: Hz

    def __len__(self) -> int:
        return len(self.records)

    def __repr__(self) -> str:
        n_damaged = int(self.damaged.sum())
        return (f"MonitoringSimulation({len(self)} records from {self.time[0]} to {self.time[-1]}, "
                f"{self.temperature.min():.1f}..{self.temperature.max():.1f} °C, {n_damaged} damaged)")

    def write(self, folder, *, format: str = "csv", covariates=None) -> list:
        """Write every record to ``folder`` (``csv``: a time column and one column per output;
        ``npz``: ``y``, ``fs`` and ``channel_names``; the channels are named as
        :attr:`SimulatedRecord.output_names`) and the covariates to ``covariates`` (default
        ``<folder>.covariates.csv`` beside the folder; columns ``record``, ``time``,
        ``temperature``). Returns the record paths, in time order."""
        if format not in ("csv", "npz"):
            raise ValueError(f"format must be 'csv' or 'npz'; got {format!r}")
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for rec in self.records:
            sim = rec.load()
            path = folder / f"{rec.name}.{format}"
            names = channel_names(sim.output_dofs)
            if format == "npz":
                np.savez(path, y=sim.y, fs=sim.fs, channel_names=np.array(names))
            else:
                t = np.arange(sim.n_samples) / sim.fs
                header = "time [s]," + ",".join(names)
                np.savetxt(path, np.column_stack([t, sim.y]), delimiter=",", header=header, comments="", fmt="%.9g")
            paths.append(path)
        covariates = Path(covariates) if covariates is not None else folder.with_name(folder.name + ".covariates.csv")
        with open(covariates, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["record", "time", "temperature"])
            for rec in self.records:
                w.writerow([csv_cell(f"{rec.name}.{format}"), str(rec.time), f"{rec.covariates['temperature']:.6g}"])
        return paths


def simulate_monitoring(n_records: int = 200, *, interval_s: float = 3600.0, start: str = "2026-01-01T00:00:00",
                        n_samples: int = 20_000, seed: int = 0, temperature=None, mean_temperature: float = 10.0,
                        daily_temperature_amplitude: float = 6.0, temperature_noise: float = 1.0,
                        temperature_coefficient: float = -0.004, reference_temperature: float = 10.0,
                        damage_element: int | None = None, damage_record: int | None = None,
                        damage_fraction: float = 0.0, n_dof: int = 6, mass=1 / 20, stiffness=None,
                        output_dofs=None, damping_ratio=0.02, fs: float = 50.0,
                        noise_std: float = 0.05) -> MonitoringSimulation:
    """A monitoring campaign of ``n_records`` output-only records, one every ``interval_s`` seconds.

    Parameters
    ----------
    n_records : int, default 200
    interval_s : float, default 3600
        Seconds between the starts of consecutive records.
    start : str, default ``"2026-01-01T00:00:00"``
        Time of the first record (ISO 8601).
    n_samples : int, default 20_000
        Samples per record (at ``fs``: 400 s by default).
    seed : int, default 0
        Seeds the temperature series and every record's forces and noise.
    temperature : array_like of shape (n_records,), optional
        The temperature at each record, °C. Default: ``mean_temperature`` plus a daily sine of
        ``daily_temperature_amplitude`` plus ``temperature_noise`` of AR(1) noise (coefficient 0.8).
    temperature_coefficient : float, default -0.004
        Relative stiffness change per °C: every spring is ``k (1 + c (T - reference_temperature))``
        (-0.4 %/°C: the frequencies move about -0.2 %/°C, a few % over a day as on real bridges).
    damage_element, damage_record, damage_fraction :
        From record ``damage_record`` (0-based) on, spring ``damage_element`` (0-based, the spring
        from the ground is 0) has ``1 - damage_fraction`` of its stiffness. No damage by default.
    n_dof, mass, stiffness, output_dofs, damping_ratio, fs, noise_std :
        The chain and its recording, as in :func:`modaluq.simulate` (outputs by default
        :func:`~modaluq.simulate.default_output_dofs`).

    Returns
    -------
    MonitoringSimulation
        The records (lazy), times, temperatures, the damaged flag and the true modal parameters.

    A campaign of more records is another campaign, not this one extended: its temperature
    series is drawn for ``n_records``, and every record's stiffness follows it. To try a nightly
    run that adds records, simulate the whole campaign once and copy its files into the folder
    a few at a time.
    """
    n_records = check_integer("n_records", n_records, minimum=1)
    interval_s = check_real("interval_s", interval_s, low=0.0, low_open=True)
    n_samples = check_integer("n_samples", n_samples, minimum=100)
    seed = check_integer("seed", seed, minimum=0)
    n_dof = check_integer("n_dof", n_dof, minimum=1)
    fs = check_sampling_frequency(fs)
    damage_fraction = check_real("damage_fraction", damage_fraction, low=0.0, high=1.0, high_open=True)
    if (damage_element is None) != (damage_record is None):
        raise ValueError("damage_element and damage_record go together: give both or neither")
    if damage_element is not None:
        damage_element = check_integer("damage_element", damage_element, minimum=0, maximum=n_dof - 1)
        damage_record = check_integer("damage_record", damage_record, minimum=0)
    try:
        t0 = np.datetime64(start, "s")
    except ValueError:
        raise ValueError(f"start must be an ISO 8601 time such as 2026-01-01T00:00:00; got {start!r}") from None
    times = t0 + (np.arange(n_records) * interval_s).round().astype("timedelta64[s]")

    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(2**31,)))  # apart from the records'
    if temperature is None:
        hours = np.arange(n_records) * interval_s / 3600.0
        noise = np.empty(n_records)
        e = rng.standard_normal(n_records) * temperature_noise * np.sqrt(1 - 0.8**2)
        noise[0] = rng.standard_normal() * temperature_noise
        for k in range(1, n_records):
            noise[k] = 0.8 * noise[k - 1] + e[k]
        temperature = mean_temperature + daily_temperature_amplitude * np.sin(2 * np.pi * (hours - 9) / 24) + noise
    else:
        temperature = np.asarray(temperature, dtype=float)
        if temperature.shape != (n_records,) or not np.all(np.isfinite(temperature)):
            raise ValueError(f"temperature must be {n_records} finite values (one per record); "
                             f"got shape {temperature.shape}")

    M, K0, _ = chain_system(n_dof, mass=mass, stiffness=stiffness, damping_ratio=damping_ratio)
    k0 = springs_of(K0)
    if output_dofs is None:
        output_dofs = default_output_dofs(n_dof)
    scale = 1.0 + temperature_coefficient * (temperature - reference_temperature)
    if np.any(scale <= 0):
        raise ValueError("temperature_coefficient makes a stiffness negative at the coldest/hottest record")
    damaged = np.zeros(n_records, bool)
    if damage_element is not None:
        damaged[damage_record:] = True
    options = {"n_samples": n_samples, "n_dof": n_dof, "output_dofs": tuple(output_dofs), "mass": mass,
               "damping_ratio": damping_ratio, "fs": fs, "noise_std": noise_std}
    records, freqs, damps, shapes = [], [], [], []
    for k in range(n_records):
        springs = k0 * scale[k]
        if damaged[k]:
            springs[damage_element] *= 1.0 - damage_fraction
        M, Kk, Ck = chain_system(n_dof, mass=mass, stiffness=springs, damping_ratio=damping_ratio)
        f, xi, phi = modal_parameters(M, Kk, Ck, output_dofs=output_dofs)
        freqs.append(f)
        damps.append(xi)
        shapes.append(phi)
        records.append(SimulatedRecord(name=f"record-{k:04d}", time=times[k],
                                       covariates={"temperature": float(temperature[k])},
                                       stiffness=tuple(float(s) for s in springs), seed=seed, index=k,
                                       simulation=options))
    return MonitoringSimulation(records=tuple(records), time=times, temperature=temperature, damaged=damaged,
                                frequency_hz=np.array(freqs), damping_ratio=np.array(damps),
                                mode_shape=np.array(shapes), fs=fs)


def channel_names(output_dofs) -> tuple:
    """The channels of a campaign's records: ``acc`` and the 1-based degree of freedom."""
    return tuple(f"acc{int(d) + 1}" for d in output_dofs)


def springs_of(K: np.ndarray) -> np.ndarray:
    """The spring stiffnesses of a grounded chain's stiffness matrix (inverse of
    :func:`~modaluq.simulate.chain_system`'s assembly)."""
    n = K.shape[0]
    k = np.empty(n)
    k[1:] = -np.diag(K, 1)
    k[0] = K[0, 0] - (k[1] if n > 1 else 0.0)
    return k

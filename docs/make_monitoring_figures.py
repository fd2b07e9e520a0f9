"""The worked example of docs/monitoring.md: a simulated campaign with a temperature cycle and a
damage, monitored with modaluq.monitor; writes docs/img/monitoring_frequencies.png and
docs/img/monitoring_control_chart.png and prints the numbers the page quotes.

    python docs/make_monitoring_figures.py            # about a minute on 2 cores
"""

from pathlib import Path

import numpy as np

import modaluq
from modaluq.monitoring import TrackingSettings, monitor, simulate_monitoring

IMG = Path(__file__).resolve().parent / "img"


def main():
    # 10 days of hourly 400 s records; from day 7 the spring from the ground loses 4 % of its stiffness
    campaign = simulate_monitoring(240, n_samples=20_000, seed=7, damage_element=0, damage_record=168,
                                   damage_fraction=0.04)
    intact = simulate_monitoring(240, n_samples=20_000, seed=7)  # the same temperatures, no damage
    print(campaign)
    result = monitor(campaign.records, settings=modaluq.Settings(orders=tuple(range(2, 25, 2))),
                     tracking=TrackingSettings(reference_records=48), progress=True)
    print(result)
    ds = result.dataset
    sigma = np.nanmedian(ds["frequency_std"].values[ds["in_reference"].values], axis=0)
    shift = (intact.frequency_hz[168:] - campaign.frequency_hz[168:]).mean(axis=0)
    print("frequency drop from the damage, Hz:", np.round(shift, 4))
    print("σ_f of one record (median over the reference), Hz:", np.round(sigma, 4))
    print("drop / σ:", np.round(shift / sigma, 2))
    after = ~ds["in_reference"].values
    before = after & (np.arange(ds.sizes["record"]) < 168)
    print("alarms per mode before the damage:", ds["alarm"].values[before].sum(axis=0), "of", before.sum())
    print("alarm fraction per mode after it:", np.round(ds["alarm"].values[168:].mean(axis=0), 3))
    print("shape alarms per mode before the damage:", ds["shape_alarm"].values[before].sum(axis=0), "of", before.sum())
    print("shape alarm fraction per mode after it:", np.round(ds["shape_alarm"].values[168:].mean(axis=0), 3))
    print("MAC to the reference after it, smallest per mode:", np.round(np.nanmin(ds["mac_to_reference"].values[168:],
                                                                                  axis=0), 4))
    print("reference reduced chi2 (f, xi):", np.round(ds["reference_reduced_chi2_frequency"].values, 2),
          np.round(ds["reference_reduced_chi2_damping"].values, 2))
    fig = result.plot_frequencies(modes=[1, 2, 3])
    fig.savefig(IMG / "monitoring_frequencies.png", dpi=110)
    fig = result.plot_control_chart(modes=[1, 2, 3])
    fig.savefig(IMG / "monitoring_control_chart.png", dpi=110)


if __name__ == "__main__":
    main()

"""The options ``modaluq identify`` and ``modaluq monitor`` share: how a record is read, preprocessed,
identified and its modes selected, and their translation into the library's settings objects.

An option the user does not give is None and left out of the settings objects, so the library's
default applies (the core's, see :mod:`modaluq.settings`); ``--help`` shows that default, read
from the objects. An option's parameter name is the name of the field it sets.
"""

from __future__ import annotations

import argparse

from ..io import FORMATS
from ..settings import ClusteringSettings, Settings, StabilityCriteria
from .common import integer_option, option_error, real_option

__all__ = ["CLUSTERING_OPTIONS", "CRITERIA_OPTIONS", "OFF_AT_ZERO", "SETTINGS_OPTIONS", "add_analysis_options",
           "analysis_settings", "stated_options"]

#: Options that set the field of the same name, by the object that holds it (``--no-uncertainty``
#: sets ``Settings.uncertainty``).
SETTINGS_OPTIONS = ("frequency_range", "start", "stop", "decimate", "detrend", "highpass", "block_rows",
                    "past_block_rows", "n_blocks", "bootstrap_draws")
CRITERIA_OPTIONS = ("max_frequency_change", "max_damping_change", "min_mac", "damping_std_factor", "match_window",
                    "frequency_std_factor", "max_frequency_cov", "max_damping_ratio")
CLUSTERING_OPTIONS = ("distance_threshold", "min_cluster_size", "representative", "shape_representative")
#: Options whose 0 switches their test off (the field's None).
OFF_AT_ZERO = ("frequency_std_factor", "max_frequency_cov", "damping_std_factor")


def _shown(value) -> str:
    """A default as ``--help`` shows it."""
    return "off" if value is None else f"{value:g}"


def add_analysis_options(p: argparse.ArgumentParser) -> None:
    """The data, preprocessing, identification and selection option groups."""
    g = p.add_argument_group("data")
    g.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="sampling frequency in Hz (default: from the file, e.g. its time column)")
    g.add_argument("--format", default=None, choices=list(FORMATS),
                   help="file format (default: from the extension)")
    g.add_argument("--read-option", action="append", metavar="KEY=VALUE", default=None,
                   help="option of the file reader, e.g. dataset=/daq/acc (HDF5), variable=acc (MATLAB), "
                        "group=run1 (TDMS), time_column=clock (CSV); repeat for several")
    g.add_argument("--inputs", nargs="+", metavar="CH", default=None,
                   help="known-input channels (default: none, i.e. output-only, unless the file declares inputs)")
    g.add_argument("--outputs", nargs="+", metavar="CH", default=None,
                   help="output channels (default: every channel that is not an input)")
    g = p.add_argument_group("preprocessing (applied to outputs and inputs alike)")
    g.add_argument("--frequency-range", nargs=2, type=real_option(0, low_open=False), default=None,
                   metavar=("LO", "HI"), help="band of interest in Hz: decimation to about 3 x HI, the settings, "
                                              "the diagram and the plot follow it")
    g.add_argument("--start", type=real_option(0, low_open=False), default=None, metavar="S",
                   help="start of the time window, s from the first sample")
    g.add_argument("--stop", type=real_option(0), default=None, metavar="S", help="end of the time window, s")
    g.add_argument("--decimate", type=integer_option(1), default=None, metavar="Q",
                   help="integer decimation factor (default: from --frequency-range, else none)")
    g.add_argument("--detrend", choices=["constant", "linear"], default=None, help="detrend every channel")
    g.add_argument("--highpass", type=real_option(0), default=None, metavar="HZ",
                   help="corner of a zero-phase 4th-order Butterworth high-pass, Hz")
    g = p.add_argument_group("identification")
    g.add_argument("--block-rows", type=integer_option(2), default=None, metavar="P",
                   help="future block rows p (default: chosen from fs, the band and the record, "
                        "docs/settings.md); the largest order is (p-1) x n_outputs")
    g.add_argument("--past-block-rows", type=integer_option(1), default=None, metavar="Q",
                   help="past block rows q (default p)")
    g.add_argument("--orders", default=None, metavar="SPEC",
                   help="model orders: a:b:step (b included), a:b, n or a comma list "
                        "(default 2:M:2, M = min(100, (p-1) n_outputs, q n_references))")
    g.add_argument("--n-blocks", type=integer_option(2), default=None, metavar="NB",
                   help="blocks for the covariance of the uncertainty (default: blocks of half the decay "
                        "time of a 1 %%-damped mode at the band's lowest frequency, 10-50; docs/settings.md)")
    g.add_argument("--references", nargs="+", metavar="CH", default=None,
                   help="reference outputs of the past data matrix (default: all outputs)")
    g.add_argument("--bootstrap-draws", type=integer_option(0), default=None, metavar="B",
                   help="sigma of f and xi above the noise floor (the diagram's upper orders) from B bootstrap "
                        "draws, e.g. 100 (default 0: first-order everywhere; docs/uq-math.md §5.6)")
    g.add_argument("--no-uncertainty", action="store_true",
                   help="skip the uncertainty (the sigma criteria are then not applied)")
    g = p.add_argument_group("stabilization and mode selection")
    c, k = StabilityCriteria(), ClusteringSettings()  # the library's defaults, shown in the help
    g.add_argument("--max-frequency-change", type=float, default=None, metavar="FRAC",
                   help=f"largest relative frequency change between orders (default {_shown(c.max_frequency_change)})")
    g.add_argument("--max-damping-change", type=float, default=None, metavar="FRAC",
                   help="largest relative damping change between orders, with --damping-std-factor 0 or "
                        f"without uncertainty (default {_shown(c.max_damping_change)})")
    g.add_argument("--min-mac", type=float, default=None,
                   help=f"smallest MAC between orders (default {_shown(c.min_mac)})")
    g.add_argument("--damping-std-factor", type=float, default=None, metavar="K",
                   help="judge a damping change between orders against K x its combined std (default "
                        f"{_shown(c.damping_std_factor)}; 0: the relative test --max-damping-change)")
    g.add_argument("--match-window", type=float, default=None, metavar="FRAC",
                   help="a pole is compared only with poles of the previous order within this relative "
                        f"frequency distance (default {_shown(c.match_window)})")
    g.add_argument("--frequency-std-factor", type=float, default=None, metavar="K",
                   help="|df| <= K sqrt(std1^2 + std2^2) between orders "
                        f"(default {_shown(c.frequency_std_factor)}; 0 switches it off)")
    g.add_argument("--max-frequency-cov", type=float, default=None, metavar="FRAC",
                   help=f"reject poles with std_f / f above this (default {_shown(c.max_frequency_cov)}; "
                        "0 switches it off)")
    g.add_argument("--max-damping-ratio", type=float, default=None, metavar="FRAC",
                   help=f"reject poles with a damping ratio above this (default {_shown(c.max_damping_ratio)})")
    g.add_argument("--distance-threshold", type=float, default=None,
                   help=f"clustering cut on |df|/f + (1 - MAC) (default {_shown(k.distance_threshold)})")
    automatic = f"{_shown(k.min_cluster_fraction)} of the orders, at least 3"
    g.add_argument("--min-cluster-size", type=integer_option(1), default=None, metavar="N",
                   help=f"poles a mode needs (default: {k.min_cluster_size or automatic})")
    g.add_argument("--representative", choices=("median", "lowest"), default=None,
                   help="the pole of each mode's cluster that is reported: nearest to the cluster's median f "
                        "and damping (with the cluster's std), or the one at the lowest order that holds every "
                        "selected mode and is not below the noise floor (with its own std, whose shape std is "
                        f"calibrated; docs/shapes.md) (default {k.representative})")
    g.add_argument("--shape-representative", choices=("median", "lowest"), default=None,
                   help="the pole whose shape (and shape std) each mode reports: the representative, or the "
                        "cluster's member at the lowest order that holds every selected mode and is not below the "
                        "noise floor, whose shape std is calibrated; f and xi stay the representative's "
                        f"(docs/shapes.md) (default {k.shape_representative})")
    g.add_argument("--no-order-discrepancy", action="store_true",
                   help="do not widen a mode's std where its f or damping at the representative's order and at the "
                        "lowest sufficient order differ by more than 1.96 of their combined std (the table marks "
                        "such modes 'widened'; docs/settings.md)")
    g.add_argument("--no-drop-noise-twins", action="store_true",
                   help="keep a lightly damped cluster born above the noise floor inside the half-power band of a "
                        "mode present from a lower order (dropped by default as a fit of the covariances' estimation "
                        "error; docs/settings.md)")
    g.add_argument("--no-reassign-borrowed-poles", action="store_true",
                   help="do not give the lowest-order poles of a cluster to an alike cluster born later when each "
                        "is nearer to its median f and damping (done by default, before twins are dropped, so a "
                        "lightly damped cluster that took a mode's first poles is not kept as the mode; "
                        "docs/settings.md)")
    g.add_argument("--no-unanchored-sigma", action="store_true",
                   help="keep the frozen std of a mode none of whose poles is free of the frozen noise directions "
                        "(noise coupling above 2 at every order: the noise floor is below the mode); by default its "
                        "std is at least the poles' median rho*std, the table marks it 'rho*std' (docs/settings.md)")


def _given(args, names) -> dict:
    """The options of ``names`` the user gave, as field values (0 is None for OFF_AT_ZERO)."""
    out = {}
    for name in names:
        value = getattr(args, name)
        if value is not None:
            out[name] = None if name in OFF_AT_ZERO and value == 0 else value
    return out


def analysis_settings(args) -> tuple:
    """The options as the library's settings objects, an error naming the option."""
    options = set(vars(args))  # every option, by its parameter name
    try:
        settings = Settings(**_given(args, SETTINGS_OPTIONS), **({"uncertainty": False} if args.no_uncertainty else {}))
        criteria = StabilityCriteria(**_given(args, CRITERIA_OPTIONS))
        clustering = ClusteringSettings(**_given(args, CLUSTERING_OPTIONS),
                                        **({"order_discrepancy": False} if args.no_order_discrepancy else {}),
                                        **({"drop_noise_twins": False} if args.no_drop_noise_twins else {}),
                                        **({"reassign_borrowed_poles": False} if args.no_reassign_borrowed_poles
                                           else {}),
                                        **({"unanchored_noise_coupling": None} if args.no_unanchored_sigma else {}))
    except (TypeError, ValueError) as exc:  # "min_mac must be ..." -> "--min-mac must be ..."
        raise option_error(exc, options) from None
    return settings, criteria, clustering


def stated_options(args, criteria, clustering) -> dict:
    """``args`` as a dict for a provenance stamp, each criterion or clustering option not given
    replaced by the value used (a test that is off by 0): the run can be repeated from it."""
    out = {k: v for k, v in vars(args).items() if k not in ("func", "command")}
    for obj, names in ((criteria, CRITERIA_OPTIONS), (clustering, CLUSTERING_OPTIONS)):
        for name in names:
            if out.get(name) is None:
                value = getattr(obj, name)
                out[name] = 0.0 if value is None and name in OFF_AT_ZERO else value
    return out

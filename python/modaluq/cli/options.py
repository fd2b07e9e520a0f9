"""The options ``modaluq identify`` and ``modaluq monitor`` share: how a record is read, preprocessed,
identified and its modes selected, and their translation into the library's settings objects."""

from __future__ import annotations

import argparse

from ..io import FORMATS
from ..settings import ClusteringSettings, Settings, StabilityCriteria
from .common import integer_option, option_error, real_option

__all__ = ["add_analysis_options", "analysis_settings"]


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
    g.add_argument("--no-uncertainty", action="store_true",
                   help="skip the uncertainty (the sigma criteria are then not applied)")
    g = p.add_argument_group("stabilization and mode selection")
    g.add_argument("--max-frequency-change", type=float, default=0.01, metavar="FRAC",
                   help="largest relative frequency change between orders (default 0.01)")
    g.add_argument("--max-damping-change", type=float, default=0.10, metavar="FRAC",
                   help="largest relative damping change between orders, with --damping-std-factor 0 or "
                        "without uncertainty (default 0.10)")
    g.add_argument("--min-mac", type=float, default=0.98, help="smallest MAC between orders (default 0.98)")
    g.add_argument("--damping-std-factor", type=float, default=2.0, metavar="K",
                   help="judge a damping change between orders against K x its combined std (default 2; "
                        "0: the relative test --max-damping-change)")
    g.add_argument("--match-window", type=float, default=0.05, metavar="FRAC",
                   help="a pole is compared only with poles of the previous order within this relative "
                        "frequency distance (default 0.05)")
    g.add_argument("--frequency-std-factor", type=float, default=2.0, metavar="K",
                   help="|df| <= K sqrt(std1^2 + std2^2) between orders (default 2; 0 switches it off)")
    g.add_argument("--max-frequency-cov", type=float, default=0.05, metavar="FRAC",
                   help="reject poles with std_f / f above this (default 0.05; 0 switches it off)")
    g.add_argument("--max-damping-ratio", type=float, default=0.20, metavar="FRAC",
                   help="reject poles with a damping ratio above this (default 0.20)")
    g.add_argument("--distance-threshold", type=float, default=0.02,
                   help="clustering cut on |df|/f + (1 - MAC) (default 0.02)")
    g.add_argument("--min-cluster-size", type=integer_option(1), default=None, metavar="N",
                   help="poles a mode needs (default: a quarter of the orders, at least 3)")


def analysis_settings(args) -> tuple:
    """The options as the library's settings objects, an error naming the option."""
    options = set(vars(args))  # every option, by its parameter name
    try:
        settings = Settings(block_rows=args.block_rows, past_block_rows=args.past_block_rows, n_blocks=args.n_blocks,
                            uncertainty=not args.no_uncertainty, frequency_range=args.frequency_range,
                            start=args.start, stop=args.stop, decimate=args.decimate, detrend=args.detrend,
                            highpass=args.highpass)
        criteria = StabilityCriteria(
            max_frequency_change=args.max_frequency_change, max_damping_change=args.max_damping_change,
            min_mac=args.min_mac,
            frequency_std_factor=None if args.frequency_std_factor == 0 else args.frequency_std_factor,
            max_frequency_cov=None if args.max_frequency_cov == 0 else args.max_frequency_cov,
            max_damping_ratio=args.max_damping_ratio,
            damping_std_factor=None if args.damping_std_factor == 0 else args.damping_std_factor,
            match_window=args.match_window)
        clustering = ClusteringSettings(distance_threshold=args.distance_threshold,
                                        min_cluster_size=args.min_cluster_size)
    except (TypeError, ValueError) as exc:  # "min_mac must be ..." -> "--min-mac must be ..."
        raise option_error(exc, options) from None
    return settings, criteria, clustering

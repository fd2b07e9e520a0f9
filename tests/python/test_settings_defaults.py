"""One source per option: the defaults of Settings, StabilityCriteria and ClusteringSettings are the
core's structs' (docs/architecture.md, "Adding a setting"), and the command line's are the library's."""

import dataclasses
import json
import subprocess
import sys
import textwrap

import pytest

import modaluq
from modaluq import _core, settings
from modaluq.cli import build_parser
from modaluq.cli.options import CLUSTERING_OPTIONS, CRITERIA_OPTIONS, analysis_settings, stated_options
from modaluq.settings import ClusteringSettings, PoleStatus, Settings, StabilityCriteria

#: Each dataclass, its core struct, and why a field of one is not (or not by default) the other's.
SEAMS = {
    Settings: (_core.IdentifyOptions, {
        # core fields Python does not expose
        "fs": "the record's rate, an argument of Settings.to_core",
        "noise_floor_factor": "c of (5.12), a constant of the method (docs/uq-math.md §5.5), not a setting",
    }, {
        # fields both have whose Python default is Python's
        "block_rows": "None: chosen from the data (auto_settings); the core has no default",
        "orders": "None: chosen from the data; the core has no default",
        "n_blocks": "None: chosen from the record (auto_settings), where the core has a fixed 50",
    }),
    StabilityCriteria: (_core.StabilityCriteria, {
        "frequency_range": "the identification's band (Settings.frequency_range), set by stabilization_diagram",
    }, {}),
    ClusteringSettings: (_core.ClusteringOptions, {}, {
        "cluster_std": "None: the identification's own, resolved by select_modes (the mean for a multi-setup "
                       "merge, the core's median for one record); to_core gives the core's default",
    }),
}


@pytest.mark.parametrize("cls", list(SEAMS), ids=lambda c: c.__name__)
def test_every_field_the_core_has_defaults_to_the_core(cls):
    core_type, not_exposed, own_default = SEAMS[cls]
    ours = {f.name for f in dataclasses.fields(cls)}
    theirs = settings.core_fields(core_type)
    unexplained = [name for name in theirs if name not in ours and name not in not_exposed]
    assert not unexplained, f"{core_type.__name__} fields that {cls.__name__} does not expose: {unexplained}"
    assert set(not_exposed) <= set(theirs) - ours  # no stale explanation
    defaults, made, core = settings.core_defaults(core_type), cls(), core_type()
    compared = [name for name in theirs if name in ours and name not in own_default]
    assert compared
    for name in compared:
        assert getattr(made, name) == defaults[name], name
        field = next(f for f in dataclasses.fields(cls) if f.name == name)
        assert field.default == defaults[name], name  # the class's own default, not only the instance's
    # in the core's own terms too (the "not set" codes and enums crossing back)
    if cls is Settings:
        made = made.replace(block_rows=10, orders=(2, 4), n_blocks=core.n_blocks)
        back = made.to_core(fs=100.0)
    else:
        back = made.to_core()
    for name in theirs:
        if name in ours and name not in own_default:
            assert getattr(back, name) == getattr(core, name), name


def test_the_only_python_settings_are_the_preprocessing():
    core = set(settings.core_fields(_core.IdentifyOptions))
    assert [f.name for f in dataclasses.fields(Settings) if f.name not in core] == list(settings.PREPROCESSING_FIELDS)


def test_not_set_and_enums_cross_both_ways():
    d = settings.core_defaults(_core.ClusteringOptions)
    assert d["min_cluster_size"] is None and d["statuses"] == (PoleStatus.STABLE,) and d["linkage"] == "average"
    c = ClusteringSettings(min_cluster_size=7, statuses=("stable", "stable_frequency"), linkage="single",
                           max_frequency_std_per_bandwidth=None, distance_threshold=1).to_core()
    assert c.min_cluster_size == 7 and c.linkage == _core.Linkage.single and c.max_frequency_std_per_bandwidth is None
    assert c.statuses == [_core.PoleStatus.stable, _core.PoleStatus.stable_frequency]
    assert c.distance_threshold == 1.0 and isinstance(c.distance_threshold, float)
    assert ClusteringSettings().to_core().min_cluster_size == 0
    assert d["representative"] == "median"
    assert ClusteringSettings(representative="lowest").to_core().representative == _core.Representative.lowest
    assert d["shape_representative"] == "lowest"
    assert (ClusteringSettings(shape_representative="median").to_core().shape_representative
            == _core.Representative.median)
    assert d["order_discrepancy"] is True and ClusteringSettings(order_discrepancy=False).to_core().order_discrepancy is False
    assert d["drop_noise_twins"] is True and ClusteringSettings(drop_noise_twins=False).to_core().drop_noise_twins is False
    assert (d["reassign_borrowed_poles"] is True
            and ClusteringSettings(reassign_borrowed_poles=False).to_core().reassign_borrowed_poles is False)
    assert d["unanchored_noise_coupling"] == 2.0
    assert ClusteringSettings(unanchored_noise_coupling=None).to_core().unanchored_noise_coupling is None
    with pytest.raises(ValueError, match="unanchored_noise_coupling"):
        ClusteringSettings(unanchored_noise_coupling=0.5)  # rho is at least 1
    o = Settings(block_rows=10, orders=[4, 2], n_blocks=20, references=[1], past_block_rows=None).to_core(50.0)
    assert (o.fs, o.block_rows, o.past_block_rows, o.orders, o.references) == (50.0, 10, 0, [2, 4], [1])
    assert StabilityCriteria(frequency_std_factor=None).to_core().frequency_std_factor is None


def test_to_dict_and_record_are_unchanged():
    assert ClusteringSettings().to_dict() == {
        "distance_threshold": 0.02, "min_cluster_size": None, "min_cluster_fraction": 0.25,
        "per_cluster_min_size": False, "max_frequency_std_per_bandwidth": 1.0, "merge_fragments": True,
        "drop_doublets": True, "doublet_window": 0.05, "doublet_min_mac": 0.8, "fragment_std_factor": 3.0,
        "fragment_min_mac": 0.8, "fragment_max_shared": 0.25, "statuses": ["stable"], "linkage": "average",
        "cluster_std": None, "representative": "median", "shape_representative": "lowest",
        "order_discrepancy": True, "drop_noise_twins": True, "reassign_borrowed_poles": True,
        "unanchored_noise_coupling": 2.0}
    assert StabilityCriteria().to_dict() == {
        "max_frequency_change": 0.01, "max_damping_change": 0.1, "min_mac": 0.98, "frequency_std_factor": 2.0,
        "max_frequency_cov": 0.05, "min_damping_ratio": 0.0, "max_damping_ratio": 0.2, "damping_std_factor": 2.0,
        "max_damping_change_with_std": 0.5, "match_window": 0.05, "min_mpc": None, "max_mpd_deg": None}
    assert Settings(frequency_range=[1, 2], references=(0, 2)).to_dict() == {
        "block_rows": None, "past_block_rows": None, "orders": None, "n_blocks": None, "references": [0, 2],
        "uncertainty": True, "demean": True, "input_rcond": 1e-10, "threads": 1, "freeze_noise": True,
        "noise_coupling_limit": 20.0, "block_correlation_correction": False, "bootstrap_draws": 0, "coupling_sketch": 4,
        "keep_shape_factor": False, "frequency_range": [1, 2], "start": None, "stop": None, "decimate": None,
        "detrend": None, "highpass": None}
    record = Settings(block_rows=10, orders=(2, 4), n_blocks=20, uncertainty=False).record(50.0, 3)
    assert list(record.items()) == [
        ("fs", 50.0), ("block_rows", 10), ("past_block_rows", 10), ("orders", [2, 4]), ("n_blocks", None),
        ("references", [0, 1, 2]), ("uncertainty", False), ("demean", True), ("input_rcond", 1e-10),
        ("threads", 1), ("freeze_noise", True), ("noise_coupling_limit", 20.0), ("block_correlation_correction", False),
        ("bootstrap_draws", 0), ("coupling_sketch", 4), ("keep_shape_factor", False)]


# --------------------------------------------------------------------------- the command line


def _parse(*options):
    return build_parser().parse_args(["identify", "record.csv", *options])


def test_cli_without_options_gives_the_library_defaults():
    args = _parse()
    assert all(getattr(args, name) is None for name in CRITERIA_OPTIONS + CLUSTERING_OPTIONS)
    assert analysis_settings(args) == (Settings(), StabilityCriteria(), ClusteringSettings())
    stated = stated_options(args, StabilityCriteria(), ClusteringSettings())
    assert {k: stated[k] for k in CRITERIA_OPTIONS} == {k: getattr(StabilityCriteria(), k) for k in CRITERIA_OPTIONS}


@pytest.mark.parametrize("option, text, owner, field, value", [
    ("--min-mac", "0.9", 1, "min_mac", 0.9),
    ("--max-frequency-change", "0.02", 1, "max_frequency_change", 0.02),
    ("--max-damping-change", "0.3", 1, "max_damping_change", 0.3),
    ("--damping-std-factor", "3", 1, "damping_std_factor", 3.0),
    ("--damping-std-factor", "0", 1, "damping_std_factor", None),
    ("--frequency-std-factor", "0", 1, "frequency_std_factor", None),
    ("--max-frequency-cov", "0", 1, "max_frequency_cov", None),
    ("--max-frequency-cov", "0.1", 1, "max_frequency_cov", 0.1),
    ("--match-window", "0.04", 1, "match_window", 0.04),
    ("--max-damping-ratio", "0.1", 1, "max_damping_ratio", 0.1),
    ("--distance-threshold", "0.03", 2, "distance_threshold", 0.03),
    ("--min-cluster-size", "5", 2, "min_cluster_size", 5),
    ("--no-uncertainty", None, 0, "uncertainty", False),
    ("--n-blocks", "20", 0, "n_blocks", 20),
    ("--highpass", "0.5", 0, "highpass", 0.5),
    ("--bootstrap-draws", "100", 0, "bootstrap_draws", 100),
])
def test_cli_options_given_set_their_field_and_nothing_else(option, text, owner, field, value):
    args = _parse(option, *([text] if text else []))
    objects = analysis_settings(args)
    expected = [Settings(), StabilityCriteria(), ClusteringSettings()]
    expected[owner] = dataclasses.replace(expected[owner], **{field: value})
    assert objects == tuple(expected)
    if field in CRITERIA_OPTIONS + CLUSTERING_OPTIONS:  # the stamp records the option as typed (0: off)
        assert stated_options(args, objects[1], objects[2])[field] == float(text)


def test_cli_errors_still_name_the_option(capsys):
    from modaluq.cli import main

    assert main(["identify", "nowhere.csv", "--min-mac", "1.5"]) == 2
    assert "--min-mac must be <= 1" in capsys.readouterr().err
    assert main(["identify", "nowhere.csv", "--bootstrap-draws", "5"]) == 2
    assert "--bootstrap-draws must be 0 (off) or >= 10, got 5" in capsys.readouterr().err


def test_cli_help_shows_the_library_defaults():
    text = " ".join(build_parser()._subparsers._group_actions[0].choices["identify"].format_help().split())
    c, k = StabilityCriteria(), ClusteringSettings()
    for option, value in [("smallest MAC between orders", c.min_mac),
                          ("largest relative frequency change between orders", c.max_frequency_change),
                          ("clustering cut on |df|/f + (1 - MAC)", k.distance_threshold)]:
        assert f"{option} (default {value:g})" in text


def test_monitor_and_validate_options_default_to_the_library():
    from modaluq.cli.validate import DEFAULTS
    from modaluq.monitoring import TrackingSettings

    commands = build_parser()._subparsers._group_actions[0].choices
    args = build_parser().parse_args(["monitor", "records/", "--out", "t.nc"])
    assert all(getattr(args, option) is None for option in ("reference_records", "false_alarm_rate", "smoothing",
                                                             "tracking_min_mac"))
    text = " ".join(commands["monitor"].format_help().split())
    t = TrackingSettings()
    assert f"reference period (default {t.reference_records})" in text
    assert f"reference mode (default {t.min_mac:g})" in text
    assert DEFAULTS["noise_coupling_limit"] == Settings().noise_coupling_limit
    assert DEFAULTS["freeze_noise"] == Settings().freeze_noise


# --------------------------------------------------------------------------- a default changed in C++

#: Loads the extension without running modaluq/__init__ (which imports settings), replaces three
#: structs by subclasses whose constructor sets another default (as a changed C++ default would),
#: then imports modaluq: everything built afterwards must see the new defaults.
PATCHED_CORE = textwrap.dedent("""
    import importlib.machinery, importlib.util, json, pathlib, sys

    package = pathlib.Path(importlib.util.find_spec("modaluq").submodule_search_locations[0])
    # the baseline core, which every CPU runs (or the native one of a MODALUQ_NATIVE=ON build)
    path = next(p for name in ("_core_baseline", "_core_native") for s in importlib.machinery.EXTENSION_SUFFIXES
                if (p := package / f"{name}{s}").exists())
    spec = importlib.util.spec_from_file_location(f"modaluq.{path.name.split('.')[0]}", path)
    core = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(core)
    sys.modules["modaluq._core"] = core

    class IdentifyOptions(core.IdentifyOptions):
        def __init__(self):
            super().__init__()
            self.noise_coupling_limit = 7.5

    class StabilityCriteria(core.StabilityCriteria):
        def __init__(self):
            super().__init__()
            self.min_mac = 0.9
            self.frequency_std_factor = None

    class ClusteringOptions(core.ClusteringOptions):
        def __init__(self):
            super().__init__()
            self.distance_threshold = 0.03

    core.IdentifyOptions, core.StabilityCriteria, core.ClusteringOptions = (
        IdentifyOptions, StabilityCriteria, ClusteringOptions)

    import modaluq
    from modaluq.cli import build_parser, main
    from modaluq.cli.options import analysis_settings
    assert modaluq.settings._core is core  # what "from . import _core" found

    out = {"settings": modaluq.Settings().to_dict(), "criteria": modaluq.StabilityCriteria().to_dict(),
           "clustering": modaluq.ClusteringSettings().to_dict()}
    sim = modaluq.simulate(4_000, seed=1)
    result = modaluq.identify(sim.y, fs=sim.fs, block_rows=10, orders=range(2, 13, 2), n_blocks=20)
    out["identify"] = result.settings
    out["diagram"] = result.stabilization_diagram().criteria.to_dict()
    parser = build_parser()
    s, c, k = analysis_settings(parser.parse_args(["identify", "x.csv"]))
    out["cli"] = {"settings": s.to_dict(), "criteria": c.to_dict(), "clustering": k.to_dict()}
    commands = parser._subparsers._group_actions[0].choices
    out["help"] = " ".join(commands["identify"].format_help().split())
    out["validate_help"] = " ".join(commands["validate"].format_help().split())
    record, report = sys.argv[1], sys.argv[2]
    import numpy as np
    np.savez(record, y=sim.y, fs=sim.fs)
    out["cli_status"] = main(["identify", record, "--block-rows", "10", "--orders", "2:12:2", "--n-blocks", "20",
                              "--no-progress", "--out", report])
    print(json.dumps(out))
""")


def test_a_default_changed_in_the_core_changes_settings_identify_and_the_cli(tmp_path):
    record, report = tmp_path / "record.npz", tmp_path / "report.json"
    run = subprocess.run([sys.executable, "-c", PATCHED_CORE, str(record), str(report)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout.splitlines()[-1])
    assert out["settings"]["noise_coupling_limit"] == 7.5
    assert out["criteria"]["min_mac"] == 0.9 and out["criteria"]["frequency_std_factor"] is None
    assert out["clustering"]["distance_threshold"] == 0.03
    assert out["identify"]["noise_coupling_limit"] == 7.5
    assert out["diagram"]["min_mac"] == 0.9 and out["diagram"]["frequency_std_factor"] is None
    assert out["cli"] == {"settings": out["settings"], "criteria": out["criteria"], "clustering": out["clustering"]}
    assert "smallest MAC between orders (default 0.9)" in out["help"]
    assert "(default off; 0 switches it off)" in out["help"]  # --frequency-std-factor
    assert "(1 - MAC) (default 0.03)" in out["help"]
    assert "inflate more than this (default 7.5)" in out["validate_help"]  # monte_carlo's is Settings'
    assert out["cli_status"] == 0
    stamp = json.loads(report.read_text())["stamp"]["settings"]
    assert stamp["identification"]["noise_coupling_limit"] == 7.5
    assert stamp["stability"]["min_mac"] == 0.9 and stamp["stability"]["frequency_std_factor"] is None
    assert stamp["clustering"]["distance_threshold"] == 0.03
    assert stamp["cli_arguments"]["min_mac"] == 0.9 and stamp["cli_arguments"]["frequency_std_factor"] == 0.0
    # and this process, with the core as built, keeps the released defaults
    assert modaluq.StabilityCriteria().min_mac == _core.StabilityCriteria().min_mac

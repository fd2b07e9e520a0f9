"""The earthquake records (Meloland, Painter Street): the modes shown physical are selected by the
engineer's call, ``modaluq.identify(y, u, fs=fs, frequency_range=band).select_modes()``, output-only
and with the ground channels as inputs, within 2 % and with the expected deck pattern; and the
call selects nothing wildly spurious.

"Shown physical" and the expected frequencies come from studies/earthquake_records.py
(docs/settings.md, "Earthquake records"): found output-only and with the ground input, in both
halves of the record and at a second horizon, with a clear deck pattern, ξ < 10 % and a peak of
the pattern's spatially filtered spectrum or H1. A mode's frequency differs between the two
excitation models (up to 5 %), so each call has its own expected value (the median over the
study's runs of that model). The patterns are MACs of the shape with templates built from the
channel names. Modes shown physical that the default call misses are strict xfails that say why.
"""

import functools
import pathlib

import numpy as np
import pytest

import modaluq
from modaluq.stabilization import modal_assurance_criterion

DATA = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data"
pytestmark = pytest.mark.filterwarnings("ignore::modaluq.ModalUQWarning")

TOL = 0.02  # relative frequency tolerance

# deck templates {station: weight} (channel names "staNN|direction|location")
MELOLAND_T = {
    "transverse": {"sta03": .4, "sta05": .8, "sta07": 1, "sta09": .8, "sta13": .4},  # all in phase
    "spans out of phase": {"sta16": 1, "sta18": 1, "sta20": -1, "sta22": -1},  # vertical, S span vs N span
    "spans in phase": {"sta16": 1, "sta18": 1, "sta20": 1, "sta22": 1},  # vertical, both spans up
    "torsion": {"sta16": 1, "sta17": 1, "sta20": 1, "sta18": -1, "sta21": -1, "sta22": -1},  # W vs E edge
}
PAINTER_T = {
    "transverse": {"sta04": .6, "sta07": 1, "sta09": .6},
    "west span": {"sta06": 1},
    "spans in phase": {"sta06": 1, "sta08": 1},
    "east span": {"sta08": 1},
}
RECORDS = {
    "meloland": ("cesmd_meloland_overpass_2016.npz", (1, 20), MELOLAND_T),
    "painter": ("cesmd_painter_st_overpass_2016.npz", (1, 15), PAINTER_T),
}


def needs(name):
    return pytest.mark.skipif(not (DATA / name).exists(), reason="shared records not present")


@functools.lru_cache(maxsize=None)
def selected(record, with_input):
    file, band, _ = RECORDS[record]
    d = np.load(DATA / file)
    sel = modaluq.identify(d["y"], d["u"] if with_input else None, fs=float(d["fs"]),
                           frequency_range=band).select_modes()
    return sel, [str(n).split("|")[0] for n in d["channel_names"]]


def pattern_mac(shape, stations, template):
    t = np.array([template.get(s, 0.0) for s in stations])
    return float(modal_assurance_criterion(shape, t)[0, 0])


def miss(reason):
    return dict(marks=pytest.mark.xfail(strict=True, reason=reason))


# (record, with_input, pattern, expected f Hz, smallest template MAC or None)
PHYSICAL = [
    # Meloland: the first transverse mode; output-only it sits at the ground motion's 2.95 Hz
    # peak (the data README's 2.98 Hz), with the ground input at 3.14 Hz (H1 peak 3.17 Hz)
    ("meloland", False, "transverse", 3.00, 0.5),
    ("meloland", True, "transverse", 3.14, 0.5),
    # the first vertical mode, the spans out of phase (README 3.2 Hz); output-only its shape is
    # mixed with the transverse mode at every horizon, so only its frequency is checked there
    ("meloland", False, "spans out of phase", 3.19, None),
    ("meloland", True, "spans out of phase", 3.23, 0.8),
    # the vertical mode with both spans in phase (README 4.1-4.5 Hz)
    ("meloland", False, "spans in phase", 4.40, 0.8),
    ("meloland", True, "spans in phase", 4.54, 0.8),
    # torsion, west edge against east edge (README ANPSD peak 6.0 Hz)
    ("meloland", False, "torsion", 6.20, 0.8),
    ("meloland", True, "torsion", 6.30, 0.8),
    # Painter Street: vertical, the west span dominant (README 3.30 Hz)
    ("painter", False, "west span", 3.30, 0.8),
    ("painter", True, "west span", 3.42, 0.8),
    # the first transverse mode (README 3.9 Hz; H1 from the column base 3.98 Hz), strong motion
    ("painter", False, "transverse", 3.93, 0.5),
    pytest.param("painter", True, "transverse", 3.93, 0.5, **miss(
        "with the ground input no column: of 47 poles at 3.8-4.2 Hz, 23 are rejected (ξ < 0, σ_f/f > 5 % "
        "or ξ > 20 %), 15 unstable (12 move > 1 % between orders) and only 5 stable, at scattered orders "
        "(50-92) and 3.85-4.03 Hz, against min_cluster_size 12. Other input/output runs give 4.1-4.5 Hz "
        "with ξ 4.5-10 %")),
    # vertical, both spans in phase (near README 4.7 Hz; H1 4.83 Hz, coherence 0.96)
    pytest.param("painter", False, "spans in phase", 4.78, 0.5, **miss(
        "output-only its 20-pole cluster at 4.80 Hz is dropped: median σ_f/(f ξ) = 1.77 > 1; the run warns "
        "that H is at the level of its own estimation noise (the blocks of a transient record)")),
    ("painter", True, "spans in phase", 4.88, 0.8),
    # vertical, the west span (IO 6.10 Hz; H1 6.13 Hz, coherence 0.98)
    pytest.param("painter", False, "west span", 6.05, 0.5, **miss(
        "output-only its 14-pole cluster at 6.12 Hz is dropped: median σ_f/(f ξ) = 1.03 > 1")),
    ("painter", True, "west span", 6.10, 0.5),
    # vertical, the east span dominant (README 7.1 Hz)
    ("painter", False, "east span", 7.13, 0.8),
    ("painter", True, "east span", 7.18, 0.8),
]


@needs("cesmd_meloland_overpass_2016.npz")
@needs("cesmd_painter_st_overpass_2016.npz")
@pytest.mark.parametrize("record, with_input, pattern, f_expected, min_mac", PHYSICAL)
def test_the_engineers_call_selects_the_modes_shown_physical(record, with_input, pattern, f_expected, min_mac):
    sel, stations = selected(record, with_input)
    template = RECORDS[record][2][pattern]
    near = np.flatnonzero(np.abs(sel.frequency_hz / f_expected - 1) <= TOL)
    assert near.size, f"nothing within 2 % of {f_expected} Hz; selected {np.round(sel.frequency_hz, 3)}"
    macs = [pattern_mac(sel.mode_shape[:, k], stations, template) for k in near]
    k = near[int(np.argmax(macs))]
    if min_mac is not None:
        assert max(macs) >= min_mac, (pattern, sel.frequency_hz[near], macs)
    assert sel.damping_ratio[k] < 0.10
    # σ of a transient record is indicative (docs/settings.md): Painter Street's 7.13 Hz has 2.5 %
    # output-only, where the run warns that H is at the level of its own estimation noise
    assert 0 < sel.frequency_std[k] < 0.03 * sel.frequency_hz[k]


@needs("cesmd_meloland_overpass_2016.npz")
@needs("cesmd_painter_st_overpass_2016.npz")
@pytest.mark.parametrize("record", ["meloland", "painter"])
@pytest.mark.parametrize("with_input", [False, True], ids=["output-only", "ground input"])
def test_the_engineers_call_selects_nothing_wildly_spurious(record, with_input):
    """Every selected mode has ξ < 10 % and σ_f/f < 3 %, but a mode with no pole free of the frozen
    noise directions (``SelectedModes.unanchored``: its σ is the unfrozen bound ρσ), which must be
    one not shown physical, with σ_f/f < 5 % (Meloland's 19.26 Hz with the ground input: 0.6 %
    frozen, 3.3 % as ρσ); at most three of them are not modes shown
    physical (selected and not shown: Meloland 4.01 Hz output-only, at the ground motion's 4.05 Hz
    peak; 5.19, 8.51 and 19.26 Hz with the ground input; Painter Street 8.02 and 10.77 Hz
    output-only); nothing at the ground motion's 1.44 Hz peak (the README's 1.47 Hz pole)."""
    sel, _ = selected(record, with_input)
    f = sel.frequency_hz
    assert np.all(sel.damping_ratio < 0.10), sel.damping_ratio
    assert np.all(sel.frequency_std / f < np.where(sel.unanchored, 0.05, 0.03)), sel.frequency_std / f
    expected = [p.values[3] if hasattr(p, "values") else p[3] for p in PHYSICAL
                if (p.values if hasattr(p, "values") else p)[:2] == (record, with_input)]
    unproven = [x for x in f if not any(abs(x / e - 1) <= TOL for e in expected)]
    assert len(unproven) <= 3, unproven
    assert set(f[sel.unanchored]) <= set(unproven), (f[sel.unanchored], unproven)
    assert not np.any(np.abs(f / 1.47 - 1) <= TOL), f

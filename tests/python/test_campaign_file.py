"""modaluq.io.load_campaign: the campaign file of docs/multisetup.md, read and refused by name."""

import numpy as np
import pytest

from modaluq.io import Campaign, load_campaign


def _csv(path, names, n=200, fs=25.0, time=True):
    data = np.random.default_rng(0).standard_normal((n, len(names)))
    if time:
        data = np.column_stack([np.arange(n) / fs, data])
        names = ["time", *names]
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.8g")


@pytest.fixture
def folder(tmp_path):
    _csv(tmp_path / "a.csv", ["r1", "r2", "x1", "x2"])
    _csv(tmp_path / "b.csv", ["r1", "r2", "x1", "f"])
    (tmp_path / "geo").mkdir()
    (tmp_path / "geo" / "g.toml").write_text("nodes = []\n")
    return tmp_path


def write(folder, text):
    p = folder / "campaign.toml"
    p.write_text(text)
    return p


GOOD = '''references = ["L3", "R8"]
inputs = ["F1"]
fs = 25.0
geometry = "geo/g.toml"
[settings]
block_rows = 12
frequency_range = [0.5, 10.0]
[[setup]]
file = "a.csv"
channels = ["L3", "R8", "L1", "L2"]
[[setup]]
file = "b.csv"
name = "span 2"
channels = { r1 = "L3", r2 = "R8", x1 = "L4", f = "F1" }
'''


def test_a_campaign_is_read_with_its_setups_renamed(folder):
    c = load_campaign(write(folder, GOOD))
    assert isinstance(c, Campaign)
    assert c.references == ("L3", "R8") and c.inputs == ("F1",) and c.fs == 25.0
    assert c.geometry == (folder / "geo" / "g.toml").resolve()
    assert c.settings == {"block_rows": 12, "frequency_range": [0.5, 10.0]}
    assert c.names == ("a.csv", "span 2")
    assert c.setups[0].output_names == ("L3", "R8", "L1", "L2")
    assert c.setups[1].output_names == ("L3", "R8", "L4", "F1")
    assert c.setups[1].fs == 25.0 and c.setups[1].n_samples == 200


def test_relative_paths_are_from_the_campaign_folder(folder, monkeypatch, tmp_path_factory):
    p = write(folder, GOOD)
    monkeypatch.chdir(tmp_path_factory.mktemp("elsewhere"))
    assert load_campaign(p).setups[0].source.endswith("a.csv")


@pytest.mark.parametrize("change,error,match", [
    (('references = ["L3", "R8"]', 'refs = ["L3"]\nreferences = ["L3", "R8"]'), ValueError, "unknown key 'refs'"),
    (('references = ["L3", "R8"]\n', ""), ValueError, "references is missing"),
    (('references = ["L3", "R8"]', 'references = "L3"'), ValueError, "references must be a list"),
    (("fs = 25.0", "fs = 50.0"), ValueError, r"setup 0 \('a.csv'\): .*a.csv is sampled at 25 Hz but fs is 50 Hz"),
    (("fs = 25.0", "fs = -1"), ValueError, "fs must be a rate"),
    (('geometry = "geo/g.toml"', 'geometry = "nowhere.toml"'), FileNotFoundError, "geometry: no such file"),
    (('file = "a.csv"', 'file = "c.csv"'), FileNotFoundError, r"setup 0 \('c.csv'\): file: no such file"),
    (('file = "a.csv"', 'fil = "a.csv"'), ValueError, "setup 0: unknown key 'fil'"),
    (('channels = ["L3", "R8", "L1", "L2"]', 'channels = ["L3", "R8", "L1"]'), ValueError,
     r"setup 0 \('a.csv'\), channels: 3 names for the 4 channels"),
    (('x1 = "L4"', 'x9 = "L4"'), ValueError, r"setup 1 \('span 2'\), channels: the file has no channel 'x9'"),
    (('x1 = "L4"', 'x1 = "L3"'), ValueError, r"channels: the name\(s\) \['L3'\] are given to more than one"),
    (('name = "span 2"', 'name = "a.csv"'), ValueError, "name: setup 0 has the same name"),
    (('name = "span 2"', 'read_options = { fs = 3 }'), ValueError, "read_options: 'fs' is not a reader option"),
    (('name = "span 2"', 'read_options = { bogus = 3 }'), ValueError, r"setup 1 \('b.csv'\): read_options: "),
    (("[settings]\nblock_rows = 12\nfrequency_range = [0.5, 10.0]\n", "settings = 3\n"), ValueError, "settings must be a table"),
])
def test_mistakes_are_named(folder, change, error, match):
    old, new = change
    assert old in GOOD
    with pytest.raises(error, match=match):
        load_campaign(write(folder, GOOD.replace(old, new, 1)))


def test_no_setup_and_not_toml(folder):
    with pytest.raises(ValueError, match=r"no setup: give one \[\[setup\]\] entry"):
        load_campaign(write(folder, 'references = ["L3"]\n'))
    with pytest.raises(ValueError, match="not valid TOML"):
        load_campaign(write(folder, "references = [\n"))
    with pytest.raises(FileNotFoundError, match="no such file"):
        load_campaign(folder / "none.toml")


def test_a_file_without_its_rate_takes_the_campaigns(folder):
    _csv(folder / "c.csv", ["r1", "r2", "x"], time=False)
    text = 'references = ["r1", "r2"]\n[[setup]]\nfile = "c.csv"\n'
    with pytest.raises(ValueError, match="sampling frequency unknown"):
        load_campaign(write(folder, text))
    assert load_campaign(write(folder, "fs = 10.0\n" + text)).setups[0].fs == 10.0

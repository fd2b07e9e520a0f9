"""modaluq.identify_setups: a campaign of DataFrames merged in the core (docs/uq-math.md §13)."""

import numpy as np
import pandas as pd
import pytest

import modaluq
from modaluq.simulate.campaign import simulate_campaign

ORDERS = list(range(2, 25, 2))


def _frames(camp, io=False):
    out = []
    for s in camp.setups:
        df = pd.DataFrame(s.y, columns=list(s.channels))
        if io:
            df["F5"] = s.u[:, 0]
        out.append(df)
    return out


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(4, durations=(120.0, 140.0, 110.0, 130.0, 150.0, 120.0))


def test_global_dofs_and_modes(campaign):
    res = modaluq.identify_setups(_frames(campaign), fs=campaign.fs, references=["L3", "R8"],
                                  block_rows=15, orders=ORDERS, n_blocks=12)
    expected = ["L3", "R8"] + [c for s in campaign.setups for c in s.channels[2:]]
    assert list(res.output_names) == expected
    assert sorted(res.output_names) == sorted(campaign.dofs)
    m = res.at_order(12)
    assert m.mode_shape.shape[0] == 24
    # the true order: six modes near the truth, global shapes with MAC >= 0.99 over all 24 DOFs
    truth = campaign.mode_shape[[campaign.dofs.index(n) for n in res.output_names]]
    for k, f0 in enumerate(campaign.frequency_hz):
        i = int(np.argmin(np.abs(m.frequency_hz - f0)))
        assert abs(m.frequency_hz[i] / f0 - 1) < 0.02
        phi = m.mode_shape[:, i]
        mac = abs(np.vdot(truth[:, k], phi)) ** 2 / (np.vdot(phi, phi).real * truth[:, k] @ truth[:, k])
        assert mac > 0.99, (k, mac)
        assert 0 < m.frequency_std[i] < 0.05 * f0
    # the diagram and the selection run on the merged result as on one record
    sel = res.select_modes()
    assert len(sel.frequency_hz) == 6
    assert np.all(np.abs(sel.frequency_hz / campaign.frequency_hz - 1) < 0.01)


def test_input_output_campaign():
    camp = simulate_campaign(6, durations=(90.0, 100.0, 80.0), roving=(("L1", "L2", "L4", "L5"),
                             ("L6", "L7", "L8", "L9"), ("R2", "R3", "R4", "R5")),
                             input_dofs=("L5",), input_std=3.0, unknown_input_std=0.5)
    res = modaluq.identify_setups(_frames(camp, io=True), fs=camp.fs, references=["L3", "R8"], inputs=["F5"],
                                  block_rows=10, orders=[12], n_blocks=12)
    assert res.n_inputs == 1
    assert "F5" not in res.output_names
    m = res.at_order(12)
    assert np.all(np.abs(m.frequency_hz[:, None] - camp.frequency_hz[None]).min(axis=0) / camp.frequency_hz < 0.02)


def test_refusals(campaign):
    frames = _frames(campaign)[:3]
    with pytest.raises(ValueError, match=r"setup 1 lacks the reference channel\(s\) \['R8'\]"):
        modaluq.identify_setups([frames[0], frames[1].drop(columns="R8"), frames[2]], fs=campaign.fs,
                                references=["L3", "R8"], block_rows=10, orders=[12], n_blocks=12)
    with pytest.raises(ValueError, match="setup 2 has fs = 50.0 Hz"):
        modaluq.identify_setups(frames, fs=[25.0, 25.0, 50.0], references=["L3", "R8"], block_rows=10,
                                orders=[12], n_blocks=12)
    with pytest.raises(ValueError, match="above what the merge supports"):
        modaluq.identify_setups(frames, fs=campaign.fs, references=["L3", "R8"], block_rows=4, orders=[12],
                                n_blocks=12)
    with pytest.raises(ValueError, match="channel 'L1' is measured in setups 0 and 1"):
        modaluq.identify_setups([frames[0], frames[0]], fs=campaign.fs, references=["L3", "R8"], block_rows=10,
                                orders=[12], n_blocks=12)

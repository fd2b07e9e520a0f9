"""The simulated monitoring campaign (modaluq.monitoring.simulator)."""

import numpy as np
import pytest

from modaluq.monitoring import simulate_monitoring


def test_simulator_temperature_moves_the_frequencies_and_damage_moves_its_element(campaign):
    assert len(campaign) == 24 and campaign.frequency_hz.shape == (24, 6)
    # stiffness (1 + c (T - T0)) with c < 0: f ∝ sqrt(stiffness), so the colder the stiffer
    expected = campaign.frequency_hz[0] * np.sqrt((1 - 0.004 * (campaign.temperature[5] - 10))
                                                  / (1 - 0.004 * (campaign.temperature[0] - 10)))
    np.testing.assert_allclose(campaign.frequency_hz[5], expected, rtol=1e-10)
    damaged = simulate_monitoring(6, n_samples=1000, seed=11, temperature=np.full(6, 10.0), damage_element=0,
                                  damage_record=3, damage_fraction=0.1)
    assert damaged.damaged.tolist() == [False] * 3 + [True] * 3
    assert np.all(damaged.frequency_hz[3] < damaged.frequency_hz[2]) and np.all(damaged.frequency_hz[4] == damaged.frequency_hz[3])
    assert damaged.records[3].stiffness[0] == pytest.approx(90.0) and damaged.records[3].stiffness[1] == pytest.approx(200.0)
    # a record is the same whenever it is loaded (its own random stream)
    np.testing.assert_array_equal(campaign.records[3].load().y, campaign.records[3].load().y)
    with pytest.raises(ValueError, match="damage_element and damage_record"):
        simulate_monitoring(3, damage_element=0)

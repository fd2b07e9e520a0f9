"""What the monitoring tests share: the settings of their batches, and what "the same tracks" means."""

import numpy as np

import modaluq

#: orders of the tests' batches (the simulator's 6 modes at order 12)
SETTINGS = modaluq.Settings(orders=tuple(range(2, 25, 2)))


def assert_same_tracks(a, b, *, other_process=False):
    """The same tracks. Within one process, bit for bit. Across processes the identification
    (f, ξ, shapes), the assignment and the alarms are bit for bit the same, and σ and what is
    computed from it agree to rounding: the BLAS's last bits in the uncertainty propagation
    depend on the process (measured: 8e-14 relative between the pytest process and a Dask worker)."""
    import xarray as xr

    if not other_process:
        xr.testing.assert_identical(a.dataset, b.dataset)
        assert a.poles.equals(b.poles)
        return
    ds_a, ds_b = a.dataset, b.dataset
    assert set(ds_a.variables) == set(ds_b.variables) and ds_a.attrs == ds_b.attrs
    exact = {"frequency_hz", "damping_ratio", "mode_shape", "mode_shape_real", "mode_shape_imag", "alarm",
             "reference_frequency_hz", "reference_damping_ratio", "reference_mode_shape", "n_poles"}
    for name in ds_a.variables:
        x, y = ds_a[name].values, ds_b[name].values
        if name in exact or not np.issubdtype(x.dtype, np.floating):
            np.testing.assert_array_equal(x, y, err_msg=name)
        else:
            np.testing.assert_allclose(x, y, rtol=1e-10, atol=0, equal_nan=True, err_msg=name)
    for column in a.poles.columns:
        if a.poles[column].dtype.kind == "f" and column.endswith("_std"):
            np.testing.assert_allclose(a.poles[column], b.poles[column], rtol=1e-10, err_msg=column)
        else:
            assert a.poles[column].equals(b.poles[column]), column

"""The monitoring wing is loaded only when used: not by ``import modaluq``, not by ``modaluq
identify`` (each run in a fresh interpreter, whose modules are what that step imported)."""

import json
import subprocess
import sys

import numpy as np
import pytest

import modaluq


def modules_after(code: str) -> dict:
    """Run ``code`` in a fresh interpreter; its last line prints a JSON value."""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(run.stdout.splitlines()[-1])


def test_import_modaluq_does_not_load_the_wing_and_its_names_load_it_on_first_use():
    seen = modules_after("""
import json, sys
import modaluq
before = 'modaluq.monitoring' in sys.modules
listed = all(n in modaluq.__all__ and n in dir(modaluq) for n in
             ('monitor', 'Monitoring', 'load_tracks', 'simulate_monitoring', 'TrackingSettings'))
from modaluq import TrackingSettings
after = 'modaluq.monitoring' in sys.modules
import modaluq.monitoring as wing
print(json.dumps({'before': before, 'listed': listed, 'after': after,
                  'same': TrackingSettings is wing.TrackingSettings and modaluq.monitor is wing.monitor}))
""")
    assert seen == {"before": False, "listed": True, "after": True, "same": True}


def test_an_unknown_name_of_the_package_is_still_an_attribute_error():
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        modaluq.no_such_name  # noqa: B018


def test_modaluq_identify_does_not_load_the_wing(tmp_path):
    sim = modaluq.simulate(20_000, seed=5)
    path = tmp_path / "rec.csv"
    np.savetxt(path, np.column_stack([np.arange(sim.n_samples) / sim.fs, sim.y, sim.u]), delimiter=",",
               header="time [s],acc1,acc2,acc5,force", comments="", fmt="%.10g")
    seen = modules_after(f"""
import json, sys
from modaluq.cli import main
status = main(["identify", {str(path)!r}, "--inputs", "force", "--block-rows", "10", "--orders", "2:16:2",
               "--n-blocks", "20", "--no-progress", "--out", {str(tmp_path / "modes.json")!r}])
print(json.dumps({{'status': status, 'wing': [m for m in sys.modules if m.startswith('modaluq.monitoring')]}}))
""")
    assert seen == {"status": 0, "wing": []}


@pytest.mark.parametrize("module", ["modaluq", "modaluq.cli"])
def test_import_modaluq_is_light(module):
    # issue 22: `import modaluq` (and the command line, before a command runs) loads none of the heavy libraries; each is imported where it is used
    # (plots: matplotlib; tables: pandas; stores: xarray; many records: Dask; simulation, spectra: SciPy).
    # Its time (0.26-0.28 s here against 1.4-2.0 s before) is measured with -X importtime, not here.
    loaded = modules_after(f"""
import json, sys
import {module}
heavy = ('matplotlib', 'pandas', 'xarray', 'dask', 'distributed', 'scipy', 'h5py', 'nptdms', 'pyuff', 'zarr',
         'plotly')
print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set(heavy))))
""")
    assert loaded == []

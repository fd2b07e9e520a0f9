"""``modaluq._core``: the C++ core, in the build this CPU runs (``_dispatch``).

This module replaces itself in ``sys.modules`` with the chosen extension module, so
``from . import _core`` and ``import modaluq._core`` give the extension itself; its classes and
functions name ``modaluq._core`` as their module on every path (pickles, ``_core.pyi``).
"""

import sys

from . import _dispatch

sys.modules[__name__] = _dispatch.load()

"""The report stage: figures of runs, sweeps and diagnostics results, and an offline HTML
report (DESIGN.md §3, §4.5). The last pipeline stage: it imports the earlier ones only.

matplotlib is an optional dependency (``pip install "r2rsim[plot]"``); every function here
raises :class:`r2rsim.errors.InputError` with that advice when it is missing. The functions
return :class:`matplotlib.figure.Figure` objects, so they work in a notebook; the ``r2rsim
plot`` and ``r2rsim report`` commands save them.
"""

from ._mpl import require_matplotlib

__all__ = ["require_matplotlib"]

# ---- run and sweep figures (r2rsim plot) ----
from ._data import decimate_minmax  # noqa: E402
from ._run import plot_run  # noqa: E402
from ._sweep import plot_sweep  # noqa: E402

__all__ += ["decimate_minmax", "plot_run", "plot_sweep"]
# ---- end of run and sweep figures ----

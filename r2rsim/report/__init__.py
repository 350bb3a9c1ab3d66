"""The report stage: figures of runs, sweeps and diagnostics results, and an offline HTML
report (DESIGN.md §3, §4.5). The last pipeline stage: it imports the earlier ones only.

matplotlib is an optional dependency (``pip install "r2rsim[plot]"``); every function here
raises :class:`r2rsim.errors.InputError` with that advice when it is missing. The functions
return :class:`matplotlib.figure.Figure` objects, so they work in a notebook; the ``r2rsim
plot`` and ``r2rsim report`` commands save them.
"""

from ._mpl import require_matplotlib

__all__ = ["require_matplotlib"]

# -- diagnostics results (r2rsim diagnose / bench): figures and the HTML report --------------
from ._diagnostics import plot_mdm, plot_metric, plot_roc_pr, plot_statistic  # noqa: E402
from ._html import write_report  # noqa: E402

__all__ += ["plot_mdm", "plot_metric", "plot_roc_pr", "plot_statistic", "write_report"]

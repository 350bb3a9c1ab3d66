"""The report stage: figures of runs, sweeps and diagnostics results, and an offline HTML
report (DESIGN.md §3, §4.5). The last pipeline stage: it imports the earlier ones only.

matplotlib is an optional dependency (``pip install "r2rsim[plot]"``); every function here
raises :class:`r2rsim.errors.InputError` with that advice when it is missing. The functions
return :class:`matplotlib.figure.Figure` objects, so they work in a notebook; the ``r2rsim
plot`` and ``r2rsim report`` commands save them.
"""

from ._data import decimate_minmax
from ._diagnostics import plot_mdm, plot_metric, plot_roc_pr, plot_statistic
from ._gsmms import plot_gsmms_map, plot_gsmms_residuals, plot_severity
from ._hsov import plot_profiles, plot_residual_qq, plot_virtual_sensor
from ._html import write_report
from ._mpl import require_matplotlib
from ._parity import plot_residuals, plot_sensitivity, plot_signature
from ._run import plot_run
from ._sweep import plot_sweep

__all__ = [
    # runs and sweeps (r2rsim plot)
    "plot_run", "plot_sweep", "decimate_minmax",
    # diagnostics results (r2rsim diagnose / bench) and the HTML report (r2rsim report)
    "plot_statistic", "plot_roc_pr", "plot_metric", "plot_mdm", "write_report",
    "require_matplotlib",
    # residual-based diagnostics (the parity study, thesis Ch. 3)
    "plot_residuals", "plot_signature", "plot_sensitivity",
    # GSMMS (thesis Ch. 4)
    "plot_gsmms_map", "plot_gsmms_residuals", "plot_severity",
    # virtual sensors and regression models (thesis Ch. 2)
    "plot_virtual_sensor", "plot_residual_qq", "plot_profiles",
]

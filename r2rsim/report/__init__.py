"""The report stage: figures of runs, sweeps and diagnostics results, and an offline HTML
report (README.md, "Figures and reports"). The last pipeline stage: it imports the earlier
ones only.

matplotlib is an optional dependency (``pip install -e ".[plot]"`` in the checkout); every
function here raises :class:`r2rsim.errors.InputError` with that advice when it is missing.
The functions return :class:`matplotlib.figure.Figure` objects, so they work in a notebook;
the ``r2rsim plot`` and ``r2rsim report`` commands save them.
"""

import importlib

#: where each public name is defined: imported on first use, so that ``r2rsim plot`` does
#: not import what the diagnostics figures need (scikit-learn, the harness)
_WHERE = {
    "decimate_minmax": "_data",
    "plot_statistic": "_diagnostics",
    "plot_roc_pr": "_diagnostics",
    "plot_metric": "_diagnostics",
    "plot_mdm": "_diagnostics",
    "plot_gsmms_map": "_gsmms",
    "plot_gsmms_residuals": "_gsmms",
    "plot_severity": "_gsmms",
    "plot_profiles": "_hsov",
    "plot_residual_qq": "_hsov",
    "plot_virtual_sensor": "_hsov",
    "write_report": "_html",
    "report_figures": "_html",
    "require_matplotlib": "_mpl",
    "plot_residuals": "_parity",
    "plot_sensitivity": "_parity",
    "plot_signature": "_parity",
    "plot_run": "_run",
    "plot_sweep": "_sweep",
}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_WHERE))


__all__ = [
    # runs and sweeps (r2rsim plot)
    "plot_run",
    "plot_sweep",
    "decimate_minmax",
    # diagnostics results (r2rsim diagnose / bench) and the HTML report (r2rsim report)
    "plot_statistic",
    "plot_roc_pr",
    "plot_metric",
    "plot_mdm",
    "write_report",
    "report_figures",
    "require_matplotlib",
    # residual-based diagnostics (the parity study, thesis Ch. 3)
    "plot_residuals",
    "plot_signature",
    "plot_sensitivity",
    # GSMMS (thesis Ch. 4)
    "plot_gsmms_map",
    "plot_gsmms_residuals",
    "plot_severity",
    # virtual sensors and regression models (thesis Ch. 2)
    "plot_virtual_sensor",
    "plot_residual_qq",
    "plot_profiles",
]

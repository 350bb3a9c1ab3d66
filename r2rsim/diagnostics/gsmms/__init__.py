"""GSMMS multi-regime detection (thesis Ch. 4): a growing self-organising map over the
operating space with local parity relations fitted by mini-batch SGD.

Public API: the plug-ins :class:`GSMMS` (``gsmms``) and :class:`GlobalParity`
(``gsmms_global``, one node), and the local-relation functions :func:`fit_relations`,
:func:`oracle_relations`, :func:`objective` and :func:`residuals`.
"""

from ._local import fit_relations, objective, oracle_relations, residuals
from ._plugin import GSMMS, GlobalParity

__all__ = ["GSMMS", "GlobalParity", "fit_relations", "objective", "oracle_relations", "residuals"]

"""Stage 6 of the pipeline: diagnostic plug-ins (the contract in :mod:`.base`, baselines in
:mod:`.baselines`, discovery in :mod:`.registry`)."""

from .base import Diagnostic

__all__ = ["Diagnostic"]

"""Exceptions raised by r2rsim.

Every error a user can cause with an input file is an :class:`InputError`: it names the
file, the YAML path inside it and the problem, so the command line can print it as one line.
"""

from __future__ import annotations


class R2RError(Exception):
    """Base class of all r2rsim errors."""


class _Located:
    """A message about a place in an input file: ``file: path: message``."""

    def __init__(self, message: str, file: str | None = None, path: str | None = None):
        self.message = message
        self.file = file
        self.path = path
        super().__init__(self.format())

    def format(self) -> str:
        """Return ``file: path: message`` with the parts that are known."""
        parts = [p for p in (self.file, self.path) if p]
        return ": ".join([*parts, self.message])


class InputError(_Located, R2RError):
    """A problem with a user's input file (line, scenario) or command-line value.

    Parameters
    ----------
    message : str
        What is wrong, in words a user understands.
    file : str, optional
        The file the problem is in.
    path : str, optional
        The YAML path of the offending value, e.g. ``elements[2].radius``.
    """

    #: every problem as (YAML path, message), when a file has several (``r2rsim validate``
    #: lists them all); set by whoever raises such an error, absent otherwise
    problems: list[tuple[str, str]]


class PlausibilityWarning(_Located, UserWarning):
    """A valid but physically unusual input (a web thicker than any in physics.md §2.1, a
    tension set-point above the break tension, a loop faster than its drive...).

    Issued with :func:`warnings.warn` while a file is loaded; ``r2rsim`` prints it as
    ``warning: file: path: message`` on stderr and carries on. Turn it into an error with
    ``warnings.simplefilter("error", PlausibilityWarning)``.

    Parameters
    ----------
    message, file, path
        As for :class:`InputError`.
    """


class SimulationError(R2RError):
    """The solver could not integrate a run (reported with the time it stopped)."""


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM. ``r2rsim run`` raises it from a signal handler so that
    the run stops and cleans up as on Ctrl-C (the dataset writer removes its temporary
    directory); the command then exits 143 (128 + SIGTERM), as a shell reports a process
    ended by SIGTERM."""


class PluginError(R2RError):
    """A diagnostic plug-in cannot be loaded, or raised in one of its methods (the message
    names the plug-in, the method and the exception; the original is chained)."""

"""Exceptions raised by r2rsim.

Every error a user can cause with an input file is an :class:`InputError`: it names the
file, the YAML path inside it and the problem, so the command line can print it as one line.
"""

from __future__ import annotations


class R2RError(Exception):
    """Base class of all r2rsim errors."""


class InputError(R2RError):
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

    def __init__(self, message: str, file: str | None = None, path: str | None = None):
        self.message = message
        self.file = file
        self.path = path
        super().__init__(self.format())

    def format(self) -> str:
        """Return ``file: path: message`` with the parts that are known."""
        parts = [p for p in (self.file, self.path) if p]
        return ": ".join([*parts, self.message])


class SimulationError(R2RError):
    """The solver could not integrate a run (reported with the time it stopped)."""

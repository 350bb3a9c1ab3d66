"""Stage 1 of the pipeline: validate input files and resolve units to SI."""

from ._reference import reference_markdown
from .line import Line, check_line
from .loader import json_schema, load_line, load_scenario, read_yaml
from .materials import MATERIALS
from .scenario import Scenario

__all__ = [
    "Line",
    "Scenario",
    "MATERIALS",
    "check_line",
    "json_schema",
    "load_line",
    "load_scenario",
    "read_yaml",
    "reference_markdown",
]

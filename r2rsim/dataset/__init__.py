"""Stage 5 of the pipeline: Parquet datasets with labels and provenance."""

from .columns import true_state_columns
from .writer import SCHEMA_VERSION, DatasetWriter

__all__ = ["SCHEMA_VERSION", "DatasetWriter", "true_state_columns"]

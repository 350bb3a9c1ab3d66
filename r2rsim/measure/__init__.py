"""Stage 4 of the pipeline: turn true signals into measured channels (sampling, noise,
quantisation), with seeded noise drawn on the sensor's own sample grid."""

from .sensors import MeasurementModel

__all__ = ["MeasurementModel"]

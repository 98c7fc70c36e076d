"""Exceptions and warnings raised by lidarqa.

Every error lidarqa raises on purpose derives from :class:`LidarQAError`, so
callers (and the command line) can catch one class. Most also derive from the
matching builtin (``ValueError``, ``OSError``) so generic handlers still work.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "LidarQAError",
    "InvalidPointsError",
    "OptionError",
    "ReadError",
    "LasReadError",
    "WriteError",
    "OutputExistsError",
    "CRSMismatchError",
    "DegenerateGeometryError",
    "EstimationError",
    "ConfigError",
    "AnalysisError",
    "TargetNotMetError",
    "NothingToMeasureError",
    "TilingError",
    "CatalogError",
    "MissingDependencyError",
    "ChunkFailedError",
    "ConfigCRSMismatchError",
    "AnalysisUnavailableError",
    "EdgeExtractionUnavailableError",
    "LidarQAWarning",
    "DegenerateGeometryWarning",
    "DataQualityWarning",
]


class LidarQAError(Exception):
    """Root of every error raised by lidarqa."""


class InvalidPointsError(LidarQAError, ValueError):
    """Point array of the wrong shape or dtype, empty, or with NaN/inf."""


class OptionError(LidarQAError, ValueError):
    """An option value out of range or not one of the allowed choices."""


class ReadError(LidarQAError, OSError):
    """An input file is missing, unreadable or malformed."""


class LasReadError(ReadError):
    """A LAS/LAZ file could not be read (wraps laspy errors)."""


class WriteError(LidarQAError, OSError):
    """An output could not be written."""


class OutputExistsError(WriteError, FileExistsError):
    """The output exists and overwriting was not requested."""


class CRSMismatchError(LidarQAError, ValueError):
    """Two datasets that must share a CRS do not."""


class DegenerateGeometryError(LidarQAError, ValueError):
    """Geometry too degenerate to compute (collinear, parallel, too few points)."""


class EstimationError(LidarQAError, ValueError):
    """A least-squares or robust estimation could not be carried out."""


class ConfigError(LidarQAError, ValueError):
    """An assessment configuration is invalid (unknown key, wrong type, ...)."""


class AnalysisError(LidarQAError):
    """One or more analyses of an assessment run failed (the report says which and why)."""

    keep_outputs = True  # the report is complete and explains the failure


class TargetNotMetError(LidarQAError):
    """A run completed but an accuracy target was not met (command-line exit status 4).

    The outputs (report, JSON) are complete; the error only carries the verdict
    to scripts and CI pipelines.
    """

    keep_outputs = True


class NothingToMeasureError(LidarQAError, ValueError):
    """Nothing to measure (never reported as a NaN result).

    No check point inside the cloud, no matched pair, no sample left after filtering.
    """


class TilingError(LidarQAError):
    """Tiled processing could not be set up or merged."""


class CatalogError(TilingError, ReadError):
    """A catalog cannot be built: missing/corrupt/duplicate files, empty folder, mixed CRSs."""


class MissingDependencyError(LidarQAError, ImportError):
    """An optional dependency (extra) is needed but not installed."""


class ChunkFailedError(TilingError):
    """Some chunks failed after their retries; ``.outcomes`` holds every outcome.

    The outcomes are :class:`lidarqa.tiling.engine.ChunkOutcome` objects, one per chunk.
    """

    def __init__(self, message: str, outcomes: list[Any] | None = None) -> None:
        super().__init__(message)
        self.outcomes = outcomes or []


class ConfigCRSMismatchError(ConfigError, CRSMismatchError):
    """Inputs of an assessment declare different CRSs."""


class AnalysisUnavailableError(ConfigError):
    """An analysis needs a part of lidarqa (or an extra) that this installation lacks."""


class EdgeExtractionUnavailableError(MissingDependencyError):
    """Point-cloud input needs lidarqa.geometry.edges.extract_edges, which is not available."""


class LidarQAWarning(UserWarning):
    """Base class of lidarqa warnings."""


class DegenerateGeometryWarning(LidarQAWarning):
    """Some geometry was skipped because it was degenerate."""


class DataQualityWarning(LidarQAWarning):
    """The input data is usable but suspicious (partly-zero return numbers, few points...)."""

"""Ingest of measured maps from lab files (CSV, fieldbank HDF5, MATLAB .mat v5 and v7.3).

See :mod:`fieldbank.ingest.batch` for the flow and ``docs/formats.md`` for the file layouts.
"""

from fieldbank.ingest.batch import (
    IngestReport,
    detect_format,
    ingest_data,
    ingest_paths,
    read_file,
)
from fieldbank.ingest.hdf5fmt import write_hdf5
from fieldbank.ingest.limits import DEFAULT_LIMITS, IngestLimits
from fieldbank.ingest.matfmt import write_mat5, write_mat73
from fieldbank.ingest.options import ReadOptions

__all__ = ["DEFAULT_LIMITS", "IngestLimits", "IngestReport", "ReadOptions", "detect_format", "ingest_data",
           "ingest_paths",
           "read_file", "write_hdf5", "write_mat5", "write_mat73"]

"""Reading an HDF5 file from outside (fieldbank HDF5, MATLAB v7.3) without trusting it.

HDF5 lets a few kB declare gigabytes: a dataset of compressed zeros, or a chunked dataset whose
chunks were never written and are filled on read. h5py then allocates what the file declares.
Links can point elsewhere: a soft link to a path that does not exist, an external link to
another file on the reader's disk, a virtual dataset or external raw storage made of other
files. :class:`H5Reader` therefore

* follows only hard links (:meth:`H5Reader.child`): a soft or external link is a located
  problem, never an access;
* reads a dataset only after checking its declared size against what is left of the file's
  budget (``max_decompressed_bytes``) and the ratio of the total to the file's size
  (``max_compression_ratio``, checked once the total passes 1 MiB), then a slab at a time
  (:class:`fieldbank.measure.budget.ReadBudget`, the budget NWB and ZIP reads share), and
  refuses virtual datasets and external storage (:meth:`H5Reader.read`);
* turns every h5py failure in between into a located problem (:meth:`H5Reader.attrs` for
  attributes of odd types).
"""

from __future__ import annotations

from typing import Any

import h5py
import numpy as np

from fieldbank.errors import Problem
from fieldbank.ingest.limits import IngestLimits, LimitExceeded
from fieldbank.measure.budget import BudgetExceeded, ReadBudget

#: Failures h5py raises on a damaged or hostile file.
H5_ERRORS = (OSError, KeyError, ValueError, TypeError, RuntimeError, AttributeError)


class H5Reader:
    """Bounded access to one open HDF5 file.

    Parameters
    ----------
    file_bytes : int
        Size of the file (for the compression ratio).
    limits : IngestLimits
    """

    def __init__(self, file_bytes: int, limits: IngestLimits) -> None:
        self.file_bytes = max(1, file_bytes)
        self.limits = limits
        self.budget = ReadBudget(limits.max_decompressed_bytes, file_bytes,
                                 limits.max_compression_ratio,
                                 limits.hint("max_decompressed_bytes"),
                                 limits.hint("max_compression_ratio"))

    @property
    def total(self) -> int:
        """Bytes read so far (as declared)."""
        return self.budget.used

    def child(self, group: h5py.Group, key: str, where: str,
              problems: list[Problem]) -> Any:
        """``group[key]`` if it is there through a hard link, else None (and a problem unless
        it is simply absent)."""
        try:
            link = group.get(key, getlink=True)
        except H5_ERRORS as exc:
            problems.append(Problem(where, f"unreadable link: {exc}"))
            return None
        if link is None:
            return None
        if isinstance(link, h5py.ExternalLink):
            problems.append(Problem(where, f"an external link to {link.filename}:{link.path}; "
                                    "refused: an ingest reads only the file it is given"))
            return None
        if isinstance(link, h5py.SoftLink):
            problems.append(Problem(where, f"a soft link to {link.path}; refused: store the "
                                    "data itself"))
            return None
        try:
            return group[key]
        except H5_ERRORS as exc:
            problems.append(Problem(where, f"unreadable: {exc}"))
            return None

    def read(self, ds: h5py.Dataset, where: str) -> np.ndarray:
        """The dataset's data, after the checks in the module docstring.

        Raises
        ------
        LimitExceeded
            Over a limit; its message is the located problem.
        """
        if ds.is_virtual:
            raise LimitExceeded(f"{where}: a virtual dataset (made of other files); refused")
        if ds.external:
            raise LimitExceeded(f"{where}: stored in external files; refused")
        try:
            return self.budget.read_dataset(ds, where)
        except BudgetExceeded as exc:
            raise LimitExceeded(str(exc)) from None

    @staticmethod
    def attrs(obj: h5py.HLObject, where: str, problems: list[Problem]) -> dict[str, Any]:
        """The object's attributes; one that cannot be read is a problem, not a crash."""
        out: dict[str, Any] = {}
        try:
            names = list(obj.attrs)
        except H5_ERRORS as exc:
            problems.append(Problem(where, f"attributes unreadable: {exc}"))
            return out
        for k in names:
            try:
                out[k] = obj.attrs[k]
            except H5_ERRORS as exc:
                problems.append(Problem(where, f"attribute {k!r} unreadable: {exc}"))
        return out

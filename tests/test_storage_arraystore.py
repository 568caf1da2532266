"""The content-addressed HDF5 array store."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from fieldbank.arraystore import ArrayStore, array_key
from fieldbank.errors import IntegrityError, StorageError


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int16, np.uint8])
def test_put_get_round_trip(tmp_path: Path, dtype: type) -> None:
    store = ArrayStore(tmp_path)
    a = (np.arange(3000).reshape(1000, 3) % 200).astype(dtype)
    ref = store.put(a, "N", {"source": "test"})
    assert ref.shape == (1000, 3) and ref.dtype == np.dtype(dtype).str and ref.unit == "N"
    back = store.get(ref.sha256)
    assert back.dtype == a.dtype
    np.testing.assert_array_equal(back, a)
    attrs = store.attrs(ref.sha256)
    assert attrs["unit"] == "N" and attrs["sha256"] == ref.sha256
    assert attrs["provenance"] == {"source": "test"}
    with h5py.File(store.path(ref.sha256)) as f:
        assert f["data"].fletcher32


def test_same_content_same_file_and_key_depends_on_dtype_and_shape(tmp_path: Path) -> None:
    store = ArrayStore(tmp_path)
    a = np.arange(12.0)
    r1 = store.put(a, "m")
    r2 = store.put(a.copy(), "m")
    assert r1 == r2 and list(store.keys()) == [r1.sha256]
    assert array_key(a.reshape(3, 4)) != r1.sha256
    assert array_key(a.astype(np.float32)) != r1.sha256


def test_corruption_and_loss_are_detected(tmp_path: Path) -> None:
    store = ArrayStore(tmp_path)
    ref = store.put(np.linspace(0, 1, 5000), "s")
    p = store.path(ref.sha256)
    raw = bytearray(p.read_bytes())
    # flip bytes inside the data (far from the header): fletcher32 or the key check must fail
    mid = len(raw) - 2000
    raw[mid:mid + 8] = bytes(8 * [0xFF])
    p.write_bytes(bytes(raw))
    assert store.verify(ref.sha256) is not None
    with pytest.raises(IntegrityError):
        store.get(ref.sha256)
    p.unlink()
    assert "missing" in (store.verify(ref.sha256) or "")


def test_refuses_missing_unit_and_non_numeric(tmp_path: Path) -> None:
    store = ArrayStore(tmp_path)
    with pytest.raises(StorageError, match="unit"):
        store.put(np.zeros(3), "")
    with pytest.raises(StorageError, match="numeric"):
        store.put(np.array(["a", "b"]), "m")


def test_no_temporary_left_behind_and_strays_are_listed(tmp_path: Path) -> None:
    store = ArrayStore(tmp_path)
    ref = store.put(np.ones(10), "m")
    assert store.stray_temporaries() == []
    stray = store.path(ref.sha256).parent / ".deadbeef.x.tmp"
    stray.write_bytes(b"partial")
    assert store.stray_temporaries() == [stray]

"""On-disk cache of precomputed condensed inverses, verified before every use.

Each entry is ``<key>.npy`` plus ``<key>.json`` holding the key, shape, dtype and
SHA-256 of the array bytes. A missing, truncated, corrupted or mismatched entry
is reported (logged) and treated as absent, so it is rebuilt and never used.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

log = logging.getLogger(__name__)

CACHE_FORMAT_VERSION = 1


def default_cache_dir() -> Path:
    """The library's own default, ``~/.cache/vascsim``: the application passes its directory in
    (:func:`sessions.config.cache_dir`, the one place settings are read from the environment)."""
    return Path.home() / ".cache" / "vascsim"


def cache_key(*parts: str) -> str:
    """SHA-256 over the parts that determine a precomputation."""
    digest = hashlib.sha256(f"vascsim-composite-v{CACHE_FORMAT_VERSION}".encode())
    for part in parts:
        digest.update(b"\0" + part.encode())
    return digest.hexdigest()


def _array_digest(array: NDArray) -> str:
    return hashlib.sha256(np.ascontiguousarray(array).data).hexdigest()


def load_cached(directory: Path, key: str) -> NDArray[np.float64] | None:
    """The cached array for ``key`` if present and intact, else ``None``."""
    data_path, meta_path = directory / f"{key}.npy", directory / f"{key}.json"
    if not (data_path.exists() and meta_path.exists()):
        return None
    try:
        meta = json.loads(meta_path.read_text())
        array = np.load(data_path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as error:
        log.warning("composite cache entry %s is unreadable (%s); rebuilding it", data_path, error)
        return None
    problem = None
    if meta.get("key") != key:
        problem = "its key does not match"
    elif list(array.shape) != meta.get("shape") or str(array.dtype) != meta.get("dtype"):
        problem = f"shape/dtype {array.shape}/{array.dtype} differ from its record"
    elif _array_digest(array) != meta.get("sha256"):
        problem = "its checksum does not match (corrupted)"
    if problem:
        log.warning("composite cache entry %s is not used: %s; rebuilding it", data_path, problem)
        return None
    return array


def store_cached(directory: Path, key: str, array: NDArray[np.float64]) -> Path:
    """Write ``array`` under ``key`` atomically (temporary files, then rename)."""
    directory.mkdir(parents=True, exist_ok=True)
    data_path, meta_path = directory / f"{key}.npy", directory / f"{key}.json"
    tmp_data = data_path.with_suffix(f".npy.tmp{os.getpid()}")
    with open(tmp_data, "wb") as handle:
        np.save(handle, array, allow_pickle=False)
        handle.flush()
        os.fsync(handle.fileno())
    meta = {
        "key": key,
        "shape": list(array.shape),
        "dtype": str(array.dtype),
        "sha256": _array_digest(array),
        "format": CACHE_FORMAT_VERSION,
    }
    tmp_meta = meta_path.with_suffix(f".json.tmp{os.getpid()}")
    tmp_meta.write_text(json.dumps(meta))
    os.replace(tmp_data, data_path)
    os.replace(tmp_meta, meta_path)
    return data_path

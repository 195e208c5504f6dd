"""Atomic output files: write to a temporary file in the target folder, then rename."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Iterable

from .errors import InputError


def prepare_output_dir(path: str | os.PathLike) -> Path:
    """Create ``path`` if needed and check that it is a writable folder (fails before any work)."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"output path is not a directory: {out}")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create output directory {out}: {exc.strerror or exc}") from None
    if not out.is_dir():
        raise InputError(f"output path is not a directory: {out}")
    try:
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise InputError(f"output directory is not writable: {out} ({exc.strerror or exc})") from None
    return out


def umask() -> int:
    """The process's file-creation mask (read without changing it for good)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o666 & ~umask())  # mkstemp creates 0600; give the file ordinary permissions
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Strict JSON: NaN and infinities (a missing check, a failed residual) are written as null."""
    text = json.dumps(_strict(obj), indent=2, allow_nan=False)
    return write_bytes_atomic(path, (text + "\n").encode())


def write_csv_atomic(path: str | os.PathLike, rows: Iterable[dict]) -> Path:
    rows = list(rows)
    columns: list[str] = []
    for row in rows:
        columns.extend(k for k in row if k not in columns)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _csv_value(v) for k, v in row.items()})
    return write_bytes_atomic(path, buf.getvalue().encode())


def _csv_value(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)
    return v


def _strict(o):
    """``o`` with numpy values as Python ones and non-finite floats as ``None``."""
    import numpy as np

    if isinstance(o, dict):
        return {k: _strict(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_strict(v) for v in o]
    if isinstance(o, np.ndarray):
        if o.dtype.kind == "f" and not np.all(np.isfinite(o)):
            obj = o.astype(object)
            obj[~np.isfinite(o)] = None
            return obj.tolist()
        return o.tolist()  # already plain and finite: no walk over its elements
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, Path):
        return str(o)
    if o is None or isinstance(o, (str, int, float, bool)):
        return o
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")

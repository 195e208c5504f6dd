"""Material data files: the readers behind :meth:`MaterialDataset.from_csv
<ddcm_casadi.data.dataset.MaterialDataset.from_csv>`, ``from_npy`` and ``from_file``.

Each reader checks the file (missing, unreadable, empty, huge, malformed) and returns its strain and
stress columns, as :class:`~ddcm_casadi.data.dataset.MaterialDataset` takes them; every error is an
:class:`~ddcm_casadi.errors.InputError` with one line naming the file (and, for a CSV file, the line
and column as an editor counts them).
"""

from __future__ import annotations

import csv
import os
import re
import warnings
from pathlib import Path

import numpy as np

from ddcm_casadi.data import limits
from ddcm_casadi.data.metric import Metric
from ddcm_casadi.errors import InputError
from ddcm_casadi.inputs import input_file

#: The first bytes of every ``.npy`` file.
_NPY_MAGIC = b"\x93NUMPY"


def _components(c) -> int:
    """Strain components per point of a metric given as a number (1), a matrix or a Metric."""
    return 1 if np.ndim(c) == 0 and not isinstance(c, Metric) else Metric(c).k


def _csv_position(message: str, header: list[str]) -> str:
    """numpy's parse error with its position in the file's own terms: numpy counts data rows from
    0 after the header and columns from 1; a user's editor counts lines from 1, header included."""
    first = message.splitlines()[0] if message else "parse error"
    m = re.search(r"(.*?) at row (\d+), column (\d+)\.?$", first)
    if not m:
        return first
    line, col = int(m.group(2)) + 2, int(m.group(3))
    name = f" ({header[col - 1].strip()!r})" if 0 < col <= len(header) else ""
    return f"{m.group(1)} on line {line}, column {col}{name}"


def _csv_header(path: Path) -> list[str]:
    """The header row of a CSV data file, after the size checks (none read beyond it)."""
    size = path.stat().st_size
    if size == 0:
        raise InputError(f"data file is empty: {path}")
    if size > limits.MAX_DATA_FILE_BYTES:  # read now: a test may lower it
        raise InputError(f"data file is too large ({size} bytes > {limits.MAX_DATA_FILE_BYTES}): {path}")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            header = next(csv.reader(fh), None)
    except UnicodeDecodeError:
        raise InputError(f"data file is not UTF-8 text: {path}") from None
    except (OSError, csv.Error) as exc:
        raise InputError(f"cannot read data file {path}: {getattr(exc, 'strerror', None) or exc}") from None
    if header is None or not any(h.strip() for h in header):
        raise InputError(f"data file is empty: {path}")
    return header


def _component_counts(names: list[str]) -> tuple[int, int]:
    """How many numbered strain and stress columns (``strain_1``, ``stress_2``, ...) ``names`` hold,
    or one each for the plain ``strain`` and ``stress`` of one-component data."""
    counts = []
    for what in ("strain", "stress"):
        numbered = [n for n in names if re.fullmatch(rf"{what}_\d+", n)]
        counts.append(len(numbered) or int(what in names))
    return counts[0], counts[1]


def _csv_columns(path: Path, header: list[str], k: int) -> tuple[int, ...]:
    """The positions of the strain and stress columns of ``k`` components in ``header``.

    Refused: missing columns, and numbered strain or stress columns beyond ``k`` (a 3-D file of six
    Mandel components read by a plane-strain case would take ``e33`` for ``sqrt(2) e12``). Columns
    of other names are ignored.
    """
    names = [h.strip().lower() for h in header]
    wanted = (["strain"], ["stress"]) if k == 1 else ([f"strain_{i}" for i in range(1, k + 1)],
                                                     [f"stress_{i}" for i in range(1, k + 1)])
    missing = [w for w in wanted[0] + wanted[1] if w not in names]
    n_strain, n_stress = _component_counts(names)
    if missing or (k > 1 and (n_strain, n_stress) != (k, k)):
        cols = "'strain' and 'stress'" if k == 1 else repr(",".join(wanted[0] + wanted[1]))
        raise InputError(f"data file {path} has {n_strain} strain and {n_stress} stress components, this case "
                         f"(its metric) needs {k} of each: a header with columns {cols}")
    return tuple(names.index(w) for w in wanted[0] + wanted[1])


def read_csv(path: str | os.PathLike, *, c) -> tuple[np.ndarray, np.ndarray]:
    """The strain and stress columns of a CSV data file, for the metric ``c`` (which says how many
    components a point has); see :meth:`~ddcm_casadi.data.dataset.MaterialDataset.from_csv`.

    Returns
    -------
    strain, stress : ndarray
        ``(N,)`` each for one component, ``(N, k)`` for ``k``.

    Raises
    ------
    InputError
        Missing, unreadable, empty, huge, non-UTF-8, one-column or non-numeric file.
    """
    path = input_file(path, "data file")
    header = _csv_header(path)
    k = _components(c)
    usecols = _csv_columns(path, header, k)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported below
            table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, usecols=usecols, encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"data file is not UTF-8 text: {path}") from None
    except ValueError as exc:
        raise InputError(f"data file {path} is not numeric: {_csv_position(str(exc), header)}") from None
    except OSError as exc:
        raise InputError(f"cannot read data file {path}: {exc.strerror or exc}") from None
    if table.size == 0:
        raise InputError(f"data file has a header but no data rows: {path}")
    if k == 1:
        return table[:, 0], table[:, 1]
    return table[:, :k], table[:, k:]


def _open_npy(path: Path) -> np.ndarray:
    """The array of a ``.npy`` file, memory-mapped read-only (checked to be one)."""
    try:
        with path.open("rb") as fh:
            magic = fh.read(len(_NPY_MAGIC))
    except OSError as exc:
        raise InputError(f"cannot read data file {path}: {exc.strerror or exc}") from None
    if not magic:
        raise InputError(f"data file is empty: {path}")
    if magic != _NPY_MAGIC:
        raise InputError(f"data file {path} is not a .npy file (numpy.save format)")
    try:
        return np.load(path, mmap_mode="r", allow_pickle=False)
    except (ValueError, EOFError, SyntaxError) as exc:  # a damaged header, truncated data, objects
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"data file {path} is a damaged or unsupported .npy file: {first}") from None
    except OSError as exc:
        raise InputError(f"cannot read data file {path}: {exc.strerror or exc}") from None


def read_npy(path: str | os.PathLike, *, c) -> tuple[np.ndarray, np.ndarray]:
    """The strain and stress columns of a ``.npy`` data file (views of the memory-mapped array),
    for the metric ``c``; see :meth:`~ddcm_casadi.data.dataset.MaterialDataset.from_npy`.

    Returns
    -------
    strain, stress : ndarray
        ``(N, k)`` each.

    Raises
    ------
    InputError
        Missing, unreadable, empty, not ``.npy``, truncated, not real-valued, of another
        shape, or with more than :data:`~ddcm_casadi.data.limits.MAX_MAPPED_DATA_POINTS` points.
    """
    path = input_file(path, "data file")
    k = _components(c)
    table = _open_npy(path)
    if table.dtype.kind not in "fiu":
        raise InputError(f"data file {path} holds {table.dtype} values; the data must be real numbers")
    if table.ndim != 2 or table.shape[1] != 2 * k or table.shape[0] == 0:
        cols = "strain, stress" if k == 1 else f"strain_1..{k}, stress_1..{k}"
        found = (f" ({table.shape[1] // 2} strain and {table.shape[1] // 2} stress components; this case needs {k} "
                 f"of each)" if table.ndim == 2 and table.shape[1] % 2 == 0 and table.shape[1] != 2 * k else "")
        raise InputError(f"data file {path} holds an array of shape {table.shape}{found}; it needs (N, {2 * k}) "
                         f"with N >= 1 and the columns {cols}")
    if table.shape[0] > limits.MAX_MAPPED_DATA_POINTS:
        raise InputError(f"data file {path} holds {table.shape[0]} points, more than {limits.MAX_MAPPED_DATA_POINTS}")
    return table[:, :k], table[:, k:]


def is_npy(path: str | os.PathLike) -> bool:
    """Whether :meth:`~ddcm_casadi.data.dataset.MaterialDataset.from_file` reads ``path`` as
    ``.npy`` (by its suffix; any other is read as CSV)."""
    return str(path).lower().endswith(".npy")

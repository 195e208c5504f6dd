"""MUMPS, the multifrontal sparse direct solver, through the library CasADi's wheel ships for IPOPT.

CasADi's binary wheels carry a sequential MUMPS (``libcoinmumps``, 5.8 in casadi 3.7, with METIS
and OpenBLAS) and its C header: no dependency is added. This module reads the layout of
``DMUMPS_STRUC_C`` from that header (so the structure matches the library it ships with), loads the
library with :mod:`ctypes` and wraps one factorisation in :class:`MumpsFactor`. Importing it
raises :class:`ImportError` where the library or its header is missing (another CasADi build):
:mod:`ddcm_casadi.linalg` then lists ``"mumps"`` as unavailable, with that reason.

Why: MUMPS computes the Schur complement of chosen variables in the same elimination as the
factor (``ICNTL(19)``). Applied to ``[[A, C^T], [C, 0]]`` with the multipliers as Schur variables
it returns ``-C A^-1 C^T`` (the Delassus matrix of the classical condensation) with the factor of
``A``, and its solves with ``ICNTL(26) = 0`` solve with ``A`` alone: PARDISO's Schur mode,
without MKL (``docs/performance.md``, issue 28 item 6).
"""

from __future__ import annotations

import ctypes
import os
import re
import sys
import threading
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.schur import schur_columns

__all__ = ["MumpsFactor", "MumpsError", "version", "library_path"]


class MumpsError(RuntimeError):
    """MUMPS stopped with a negative ``INFOG(1)`` other than a singular matrix."""

    def __init__(self, message: str, infog1: int, infog2: int) -> None:
        super().__init__(message)
        self.infog1, self.infog2 = infog1, infog2


def _casadi_dir() -> Path:
    import casadi

    return Path(casadi.__file__).resolve().parent


def _find_library(root: Path) -> Path:
    names = sorted(p for pattern in ("libcoinmumps.so*", "libcoinmumps*.dylib", "libcoinmumps*.dll")
                   for p in root.glob(pattern))
    if not names:
        raise ImportError(f"CasADi at {root} ships no MUMPS library (libcoinmumps)")
    return names[0]


_C_TYPES = {"MUMPS_INT8": ctypes.c_int64, "DMUMPS_REAL": ctypes.c_double, "DMUMPS_COMPLEX": ctypes.c_double,
            "char": ctypes.c_char}


def _structure(header: str) -> tuple[type[ctypes.Structure], str]:
    """``DMUMPS_STRUC_C`` as a :class:`ctypes.Structure`, and the version, read from ``dmumps_c.h``
    (the ``#define``s it needs from its sibling headers)."""
    root = Path(header).parent
    text = "".join((root / name).read_text() for name in ("mumps_int_def.h", "dmumps_c.h") if (root / name).exists())
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    defines = dict(re.findall(r"#define\s+(\w+)\s+(\S+)", text))
    types = dict(_C_TYPES, MUMPS_INT=ctypes.c_int64 if "MUMPS_INTSIZE64" in defines else ctypes.c_int32)
    version = defines.get("MUMPS_VERSION", "").strip('"')
    body = re.search(r"typedef\s+struct\s*\{(.*?)\}\s*DMUMPS_STRUC_C\s*;", text, re.S)
    if body is None or not version:
        raise ImportError(f"{header}: no DMUMPS_STRUC_C or MUMPS_VERSION")
    fields = []
    for declaration in body.group(1).split(";"):
        words = declaration.replace("*", " * ").split()
        if not words:
            continue
        if words[0] not in types:
            raise ImportError(f"{header}: unknown type {words[0]!r} in DMUMPS_STRUC_C")
        base = types[words[0]]
        for declarator in " ".join(words[1:]).split(","):
            pointer = "*" in declarator
            match = re.fullmatch(r"\s*\**\s*(\w+)\s*(?:\[(.*)\])?\s*", declarator.replace("*", " "))
            if match is None:
                raise ImportError(f"{header}: cannot read the declaration {declarator.strip()!r}")
            name, size = match.groups()
            ctype = ctypes.POINTER(base) if pointer else base
            if size is not None:
                expression = re.sub(r"[A-Za-z_]\w*", lambda m: defines.get(m.group(0), m.group(0)), size)
                if not re.fullmatch(r"[\d\s+*-]+", expression):
                    raise ImportError(f"{header}: cannot size the array {name}[{size}]")
                ctype = ctype * int(eval(expression))  # digits and + - * only (checked above)
            fields.append((name, ctype))
    return type("DMUMPS_STRUC_C", (ctypes.Structure,), {"_fields_": fields}), version


#: Bytes allocated past ``DMUMPS_STRUC_C`` (:class:`MumpsFactor`).
_SLACK = 1 << 16
#: ``ICNTL(1..4)``: no error, diagnostic or global output, no statistics.
_SILENT = ((1, -1), (2, -1), (3, -1), (4, 0))
#: ``comm_fortran`` of the sequential library (its MPI stub's ``MPI_COMM_WORLD``).
_COMM_WORLD = -987654


def _load():
    root = _casadi_dir()
    header = root / "include" / "coin-or" / "mumps" / "dmumps_c.h"
    if not header.exists():
        raise ImportError(f"CasADi at {root} ships no MUMPS header (include/coin-or/mumps/dmumps_c.h)")
    path = _find_library(root)
    Struct, header_version = _structure(str(header))
    try:
        entry = ctypes.CDLL(str(path)).dmumps_c
    except (OSError, AttributeError) as exc:
        raise ImportError(f"{path.name} does not load or has no dmumps_c: {exc}") from None
    entry.restype, entry.argtypes = None, [ctypes.POINTER(Struct)]
    # one instance made and freed: the library must report its header's version (a structure
    # laid out from another header would not read it back; the slack takes a larger one's writes)
    buffer = ctypes.create_string_buffer(ctypes.sizeof(Struct) + _SLACK)
    probe = Struct.from_buffer(buffer)
    probe.sym, probe.par, probe.job, probe.comm_fortran = 0, 1, -1, _COMM_WORLD
    entry(ctypes.byref(probe))
    reported = bytes(probe.version_number).split(b"\0")[0].decode(errors="replace").strip()
    if reported != header_version:
        raise ImportError(f"{path.name} reports MUMPS {reported!r}, its header {header_version!r}")
    for one_based, value in _SILENT:
        probe.icntl[one_based - 1] = value
    probe.job = -2
    entry(ctypes.byref(probe))
    return Struct, entry, header_version, path


_Struct, _dmumps_c, _HEADER_VERSION, _PATH = _load()
_INT = ctypes.c_int64 if _Struct.n.size == 8 else ctypes.c_int32
_INDEX = np.int64 if _Struct.n.size == 8 else np.int32


def library_path() -> str:
    """The MUMPS library loaded (CasADi's)."""
    return str(_PATH)


#: ``ICNTL(7)`` values, the fill-reducing orderings: approximate minimum degree and METIS's
#: nested dissection.
AMD, METIS = 0, 5
#: Stored nonzeros per row up to which a matrix is ordered by AMD, beyond by METIS
#: (:func:`ordering_for`). Measured with this library (one thread, best of 3): 2-D matrices have
#: 5-22 per row and AMD took half METIS's time (P2 Hertz stiffness of 95 266 dofs, 22.0 per row:
#: 0.59 s against 0.96 s; the DDCM projection's KKT matrix of 99 687 unknowns, 12.7: 0.39 s against
#: 0.96 s; grid Laplacian of 160 000: 0.30 s against 0.70 s); 3-D P1 stiffnesses have 33-34 and
#: METIS took a third to an eighth of AMD's time (9 030 dofs: 0.16 s against 0.44 s; 29 568:
#: 1.13 s against 5.7 s; 93 248: 10 s against 80 s). METIS costs more to compute but cuts the fill
#: of 3-D meshes, whose separators are large.
AMD_MAX_ROW_NONZEROS = 27
#: ``ICNTL(14)``, the percentage by which MUMPS enlarges its estimated working space, and how
#: many times a factorisation that ran out of it is retried with twice the percentage.
WORKSPACE_PERCENT, WORKSPACE_RETRIES = 30, 4
#: ``INFOG(1)`` codes of a working space too small for the factorisation (MUMPS user guide).
_WORKSPACE_ERRORS = {-8, -9, -11, -12, -13, -14, -15, -17, -20}


#: One call into MUMPS at a time: its instances are released from the factorising thread while
#: the main thread may solve with another (``ddcm_casadi.linalg``), and the sequential library's
#: MPI stub is not documented as thread-safe.
_LOCK = threading.Lock()


def _fresh_lock_in_child() -> None:
    global _LOCK
    _LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    # no fork in the middle of a call (a release in the factorising thread, say): the child would
    # inherit the lock held, and MUMPS's state half-changed, with no thread to finish either
    os.register_at_fork(before=lambda: _LOCK.acquire(), after_in_parent=lambda: _LOCK.release(),
                        after_in_child=_fresh_lock_in_child)


def ordering_for(A: sp.spmatrix) -> int:
    """The ordering (``ICNTL(7)``) for ``A``: :data:`AMD` up to :data:`AMD_MAX_ROW_NONZEROS`
    stored nonzeros per row (2-D meshes, saddle-point systems), else :data:`METIS` (3-D)."""
    return AMD if A.nnz <= AMD_MAX_ROW_NONZEROS * max(A.shape[0], 1) else METIS


def _pointer(array: np.ndarray, ctype):
    return array.ctypes.data_as(ctypes.POINTER(ctype))


class MumpsFactor:
    r"""One MUMPS factorisation of a square sparse ``A``, optionally with the Delassus matrix of
    a few rows ``C`` (then ``A`` must be symmetric positive definite).

    Parameters
    ----------
    A : scipy.sparse matrix
        Square. Symmetric (``symmetric`` 1 or 2): only its lower triangle is read.
    symmetric : {0, 1, 2}
        MUMPS's ``SYM``: 0 a general matrix (LU), 1 symmetric positive definite (``LDL^T``
        without pivoting), 2 general symmetric (``LDL^T`` with 1x1 and 2x2 pivots).
    C : scipy.sparse matrix, optional
        ``nc x n`` rows: the factorisation is of ``[[A, C^T], [C, 0]]`` with the last ``nc``
        variables as Schur variables, eliminated last, and :attr:`schur` is ``C A^-1 C^T``
        (from the lower triangle MUMPS returns). Solves are with ``A`` alone (``ICNTL(26) = 0``: MUMPS solves the
        interior block and sets the Schur variables to zero). Needs ``symmetric`` 1 or 2.
    ordering : int, optional
        ``ICNTL(7)``; default :func:`ordering_for` ``A``.
    icntl : dict, optional
        Further control parameters by their one-based index (``{8: 0}``: no scaling), set after
        this class's own (silent output, ``ordering``, :data:`WORKSPACE_PERCENT`, null pivot
        detection ``ICNTL(24) = 1``).

    Attributes
    ----------
    nnz : int
        Entries of the factors (``INFOG(29)``; ``L`` and ``U``, for a symmetric factor twice
        ``L``'s, as SuperLU and PARDISO count).
    null_pivots : int
        Pivots MUMPS found null (``INFOG(28)``, with null pivot detection on): a singular ``A``.
    negative_pivots : int
        Negative pivots of a symmetric factor (``INFOG(12)``): with ``symmetric = 1``, none means
        ``A`` is positive definite and the factor as backward stable as Cholesky's.
    schur : ndarray or None
        ``C A^-1 C^T`` (dense ``nc x nc``) where ``C`` was given.

    Raises
    ------
    MumpsError
        MUMPS failed (``INFOG(1) < 0``) for another reason than a singular matrix: the callers
        in :mod:`ddcm_casadi.linalg` map a singular matrix (``-10``) and null pivots to their
        ``SingularMatrix``.
    """

    def __init__(self, A: sp.spmatrix, symmetric: int = 0, C: sp.spmatrix | None = None, *,
                 ordering: int | None = None, icntl: dict[int, int] | None = None) -> None:
        n = A.shape[0]
        if C is not None and symmetric == 0:
            raise ValueError("the Delassus matrix needs a symmetric A (symmetric = 1 or 2)")
        self.n, self.nc = n, 0 if C is None else C.shape[0]
        # the entries by index arithmetic on A's CSC arrays (a symmetric A: its lower triangle),
        # then C's below them: no block matrix assembled (0.03 s of 0.45 s at 95 266 dofs)
        A = sp.csc_matrix(A)
        rows, cols, values = A.indices, np.repeat(np.arange(n, dtype=A.indices.dtype), np.diff(A.indptr)), A.data
        if symmetric:
            keep = rows >= cols
            rows, cols, values = rows[keep], cols[keep], values[keep]
        if C is not None:
            Cc = sp.coo_matrix(C)
            rows, cols = np.concatenate([rows, n + Cc.row]), np.concatenate([cols, Cc.col])
            values = np.concatenate([values, Cc.data])
        irn, jcn = (rows + 1).astype(_INDEX), (cols + 1).astype(_INDEX)
        a = np.ascontiguousarray(values, dtype=float)
        del rows, cols, values
        # slack past the structure read from the header (see _load)
        self._buffer = ctypes.create_string_buffer(ctypes.sizeof(_Struct) + _SLACK)
        self._s = s = _Struct.from_buffer(self._buffer)
        self._alive = False
        s.sym, s.par, s.comm_fortran = symmetric, 1, _COMM_WORLD
        self._call(-1)
        self._alive = True
        ordering = ordering_for(A) if ordering is None else ordering
        for one_based, value in (*_SILENT, (7, ordering), (14, WORKSPACE_PERCENT), (24, 1)):  # 24: null pivots
            s.icntl[one_based - 1] = value
        for one_based, value in (icntl or {}).items():
            s.icntl[one_based - 1] = value
        s.n, s.nz, s.nnz = n + self.nc, len(a) if len(a) < 2**31 else 0, len(a)
        s.irn, s.jcn, s.a = _pointer(irn, _INT), _pointer(jcn, _INT), _pointer(a, ctypes.c_double)
        schur = None
        if self.nc:
            listvar = np.arange(n + 1, n + self.nc + 1, dtype=_INDEX)
            schur = np.zeros(self.nc * self.nc)
            s.size_schur, s.listvar_schur, s.schur = self.nc, _pointer(listvar, _INT), _pointer(schur, ctypes.c_double)
            s.icntl[18] = 1  # ICNTL(19) = 1: the Schur complement, centralised
        for attempt in range(WORKSPACE_RETRIES + 1):
            code = self._call(4, raise_error=False)  # analysis and factorisation
            if code not in _WORKSPACE_ERRORS or attempt == WORKSPACE_RETRIES:
                break
            s.icntl[13] = max(2 * s.icntl[13], WORKSPACE_PERCENT)
        if code < 0:
            self._raise()
        # the solves need neither the matrix nor the Schur list (no refinement, no error analysis)
        s.irn = s.jcn = ctypes.POINTER(_INT)()
        s.a = ctypes.POINTER(ctypes.c_double)()
        s.listvar_schur, s.schur = ctypes.POINTER(_INT)(), ctypes.POINTER(ctypes.c_double)()
        del irn, jcn, a
        self.null_pivots = int(s.infog[27])
        self.negative_pivots = int(s.infog[11]) if symmetric else 0
        entries = int(s.infog[28])
        self.nnz = (-entries * 10**6 if entries < 0 else entries) * (2 if symmetric else 1)
        if schur is not None:
            # a symmetric factor returns the lower triangle by rows (row-major here); the strict
            # upper one holds whatever the working space held (seen at 1e6 unknowns)
            S = schur.reshape(self.nc, self.nc)
            self.schur = -(np.tril(S) + np.tril(S, -1).T)
        else:
            self.schur = None

    def _call(self, job: int, raise_error: bool = True) -> int:
        self._s.job = job
        with _LOCK:
            _dmumps_c(ctypes.byref(self._s))
        code = int(self._s.infog[0])
        if code < 0 and raise_error:
            self._raise()
        return code

    def _raise(self) -> None:
        code, detail = int(self._s.infog[0]), int(self._s.infog[1])
        raise MumpsError(f"MUMPS: INFOG(1) = {code}, INFOG(2) = {detail}"
                         + (" (a numerically singular matrix)" if code == -10 else ""), code, detail)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^-1 rhs`` for a vector or an ``n x k`` matrix of right-hand sides."""
        b, x = schur_columns(rhs, self.n, self.nc)
        s = self._s
        s.rhs, s.nrhs, s.lrhs = _pointer(x, ctypes.c_double), x.shape[1], x.shape[0]
        try:
            self._call(3)
        finally:
            s.rhs = ctypes.POINTER(ctypes.c_double)()
        return x[:self.n].reshape(b.shape)

    def __del__(self) -> None:
        if getattr(self, "_alive", False) and sys.meta_path is not None:  # at exit the memory goes with the process
            self._alive = False
            self._call(-2, raise_error=False)


def version() -> str:
    """The version of the MUMPS library loaded (its header's)."""
    return _HEADER_VERSION

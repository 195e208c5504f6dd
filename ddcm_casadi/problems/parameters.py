"""Named CasADi parameters packed into one vector: no hidden layouts (used for the problems'
parameters, the formulations' own, and the named blocks of a Newton system's unknowns)."""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np


class Parameters:
    """Named CasADi parameters, packed in order into one vector (no hidden layouts).

    >>> P = Parameters(gap0=1, f=2)
    >>> Q = P.extend(mu=1)                 # a formulation's own parameters after the problem's
    >>> Q.pack(P.pack(gap0=[0.1], f=[0, 1]), mu=0.0)
    array([0.1, 0. , 1. , 0. ])

    The ``SX`` symbols (:attr:`symbols`, :attr:`vector`) are created on first use (a million of
    them take about a second, and the sparse builds never need them); an extension shares the
    symbols of the parameters it extends.

    Parameters
    ----------
    **sizes : int
        Name and length of each parameter, in order.
    """

    def __init__(self, _base: "Parameters | None" = None, **sizes: int) -> None:
        inherited = dict(_base.sizes) if _base is not None else {}
        for name in sizes:
            if name in inherited:
                raise ValueError(f"parameter {name!r} is defined twice")
        self._base = _base
        self.sizes: dict[str, int] = {**inherited, **{name: int(n) for name, n in sizes.items()}}
        self.names = tuple(self.sizes)
        offsets = np.cumsum([0] + list(self.sizes.values()))
        self._slices = {n: slice(int(a), int(b)) for n, a, b in zip(self.names, offsets[:-1], offsets[1:])}
        self.size = int(offsets[-1])

    @cached_property
    def symbols(self) -> dict[str, ca.SX]:
        """The ``SX`` symbol of each parameter (those of the extended parameters shared)."""
        symbols = dict(self._base.symbols) if self._base is not None else {}
        for name in self.names:
            if name not in symbols:
                symbols[name] = ca.SX.sym(name, self.sizes[name])
        return symbols

    @cached_property
    def vector(self) -> ca.SX:
        """All symbols as one vector, in order."""
        return ca.vertcat(*self.symbols.values()) if self.names else ca.SX(0, 1)

    def __getitem__(self, name: str) -> ca.SX:
        return self.symbols[name]

    def slice(self, name: str) -> slice:
        """Where ``name`` sits in a packed vector."""
        return self._slices[name]

    def extend(self, **sizes: int) -> "Parameters":
        """These parameters followed by new ones (the same symbols)."""
        return Parameters(self, **sizes)

    def pack(self, _base: np.ndarray | None = None, **values) -> np.ndarray:
        """One vector (or, with 2-D values, one column per case) from values by name.

        ``_base`` is a packed vector of a prefix of these parameters (those of the problem a
        formulation extended); every other name must be given.
        """
        given = 0 if _base is None else np.asarray(_base, float).shape[0]
        names = [n for n in self.names if self._slices[n].start >= given]
        if _base is not None and given not in {self._slices[n].start for n in self.names} | {self.size}:
            raise ValueError(f"a base vector of {given} values does not end on a parameter")
        missing = [n for n in names if n not in values]
        unknown = sorted(set(values) - set(names))
        if missing or unknown:
            raise ValueError(f"parameters: missing {missing}, unknown {unknown}")
        parts = [] if _base is None else [np.asarray(_base, float)]
        cols = max((np.asarray(v).shape[1] for v in values.values() if np.ndim(v) == 2), default=None)
        for n in names:
            v = np.asarray(values[n], dtype=float)
            size = self._slices[n].stop - self._slices[n].start
            if cols is None:
                v = np.broadcast_to(v.ravel() if v.ndim else v, (size,))
            else:
                v = np.broadcast_to(v.reshape(size, -1) if v.ndim == 2 else v.reshape(size, 1), (size, cols))
            parts.append(v)
        if cols is not None and parts and parts[0].ndim == 1:
            parts[0] = np.repeat(parts[0][:, None], cols, axis=1)
        return np.concatenate(parts) if parts else np.zeros(0)

    def get(self, packed: np.ndarray, name: str) -> np.ndarray:
        """The value of ``name`` in a packed vector."""
        return np.asarray(packed)[self._slices[name]]

    def prefix(self, packed: np.ndarray, upto: "Parameters") -> np.ndarray:
        """The part of a packed vector that holds the parameters of ``upto`` (a prefix)."""
        return np.asarray(packed)[:upto.size]

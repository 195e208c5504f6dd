r"""Prescribed displacements (a "hard device"): degrees of freedom whose displacement is given
at every load step, for every model kind (bars, trusses, continua).

The unknowns ``u`` stay the free dofs. The prescribed dofs' values ``u_D`` are a *step
parameter*, ``u_prescribed`` (:meth:`~ddcm_casadi.models.base.ContactModel.step_sizes`,
:meth:`~ddcm_casadi.models.base.ContactModel.load_names`,
:meth:`~ddcm_casadi.models.base.ContactModel.step_values`), interpolated by sub-steps like the
loads. Small kinematics:

.. math::  \varepsilon = B u + B_D u_D ,\qquad g = G u + G_D u_D + g_0 ,

affine in ``u`` and in the parameters, so that every formulation takes them unchanged.
Equilibrium stays ``B^T W sigma - G^T a p = f`` on the free dofs; the force the device exerts
on the body, per prescribed dof, is

.. math::  r_D = B_D^T W \sigma - f_D - G_D^T a p

(:meth:`Prescribed.nodal_forces`), reported per support as a resultant vector
(:meth:`Prescribed.resultants`, :meth:`Prescribed.columns`). ``docs/maths.md`` states the maths.

This module holds the record a model carries (:class:`Prescribed`) and the checks every case
kind shares (:func:`displacement_path`, :func:`path_steps`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.errors import InputError

#: The step parameter of the prescribed values (a name of the problems' parameters).
PARAMETER = "u_prescribed"
#: Axis letters.
AXES = "xyz"
#: What the reaction columns and fields are called: the force the hard device exerts on the body.
FORCE_NAME = "hard_device_force"


@dataclass(frozen=True, eq=False)
class Prescribed:
    """The prescribed dofs of a model.

    Parameters
    ----------
    strain_operator : sparse (m k, nD)
        ``B_D``: the material-point strains of the prescribed values (small kinematics; at finite
        strain the derivative at the reference configuration).
    gap_operator : sparse (nc, nD)
        ``G_D``: the gaps of the prescribed values.
    values : (n_steps, nD)
        ``u_D`` per step (m).
    loads : (n_steps, nD)
        External loads on the prescribed dofs per step (N): the device carries them.
    support : (nD,) int
        The support (index into ``support_names``) each prescribed dof belongs to.
    component : (nD,) int
        The axis (0, 1, 2) of each prescribed dof.
    support_names : tuple of str
        A name per support (``"node 4"``, a boundary's name), for the reaction columns.
    dimension : int
        The model's space dimension (the length of a resultant).
    dofs : (nD,) int
        The dofs in the model kind's own numbering of every dof (node ``i``, axis ``c``: ``i d +
        c`` for trusses; the vector dofs of a continuum's discretisation), for full displacement
        fields.
    """

    strain_operator: sp.csr_matrix
    gap_operator: sp.csr_matrix
    values: np.ndarray
    loads: np.ndarray
    support: np.ndarray
    component: np.ndarray
    support_names: tuple
    dimension: int
    dofs: np.ndarray

    def __post_init__(self) -> None:
        B = sp.csr_matrix(self.strain_operator, dtype=float)
        G = sp.csr_matrix(self.gap_operator, dtype=float)
        n = B.shape[1]
        values = np.atleast_2d(np.asarray(self.values, dtype=float))
        if values.shape[1] != n or G.shape[1] != n:
            raise InputError(f"prescribed displacements: {values.shape[1]} values per step for {n} prescribed dofs")
        if not np.all(np.isfinite(values)):
            raise InputError("prescribed displacements must be finite (no NaN or infinity)")
        loads = np.broadcast_to(np.asarray(self.loads, dtype=float), values.shape).copy()
        for name, v in dict(strain_operator=B, gap_operator=G, values=values, loads=loads,
                            support=np.asarray(self.support, dtype=np.intp).ravel(),
                            component=np.asarray(self.component, dtype=np.intp).ravel(),
                            dofs=np.asarray(self.dofs, dtype=np.intp).ravel(),
                            support_names=tuple(str(s) for s in self.support_names)).items():
            object.__setattr__(self, name, v)
        if self.support.size != n or self.component.size != n or self.dofs.size != n:
            raise InputError("prescribed displacements: one support, component and dof per prescribed value")

    @property
    def size(self) -> int:
        """The number of prescribed dofs."""
        return self.strain_operator.shape[1]

    @property
    def n_steps(self) -> int:
        return self.values.shape[0]

    def nodal_forces(self, weighted_stress: np.ndarray, contact_forces: np.ndarray, step: int,
                     strain_jacobian: sp.spmatrix | None = None) -> np.ndarray:
        """``r_D = B_D^T (w sigma) - f_D - G_D^T (a p)`` (N, per prescribed dof): the force the
        device exerts on the body at step ``step``.

        Parameters
        ----------
        weighted_stress : (m k,)
            ``w sigma``, every component times its point's volume.
        contact_forces : (nc,)
            ``a p``.
        strain_jacobian : sparse (m k, nD), optional
            ``d eps / d u_D`` where it is not ``B_D`` (finite kinematics).
        """
        B = self.strain_operator if strain_jacobian is None else strain_jacobian
        r = B.T @ np.asarray(weighted_stress, float) - self.loads[step]
        if self.gap_operator.shape[0]:
            r = r - self.gap_operator.T @ np.asarray(contact_forces, float)
        return np.asarray(r, float).ravel()

    def resultants(self, nodal: np.ndarray) -> np.ndarray:
        """``(n_supports, d)``: each support's resultant device force (N) from the per-dof forces
        (zero along a component the support leaves free)."""
        out = np.zeros((len(self.support_names), self.dimension))
        np.add.at(out, (self.support, self.component), np.asarray(nodal, float))
        return out

    def prescribed_axes(self) -> list[list[int]]:
        """Per support, the axes it prescribes (sorted)."""
        return [sorted(set(self.component[self.support == s].tolist())) for s in range(len(self.support_names))]

    def column_names(self) -> list[str]:
        """The names of :meth:`columns`, in order: ``hard_device_force_<axis>(<support>)``."""
        return [f"{FORCE_NAME}_{AXES[c]}({name})" for name, axes in zip(self.support_names, self.prescribed_axes())
                for c in axes]

    def columns(self, resultants: np.ndarray) -> dict[str, float]:
        """The step's columns of ``results.csv``: the device force on the body (N; per unit
        thickness in 2-D continua) along each prescribed axis of each support."""
        r = np.asarray(resultants, float)
        names = iter(self.column_names())
        return {next(names): float(r[s, c]) for s, axes in enumerate(self.prescribed_axes()) for c in axes}

    def describe(self) -> dict:
        """The record in ``results.json``: supports, their prescribed axes, the number of dofs."""
        return dict(supports=list(self.support_names),
                    axes=["".join(AXES[c] for c in axes) for axes in self.prescribed_axes()],
                    dofs=self.size, column_names=self.column_names())


# ----------------------------------------------------------------------------------- case inputs
def path_steps(value, d: int) -> int | None:
    """The number of steps a displacement gives: ``None`` for one vector (scaled by the load
    factors), the length of a list of vectors (one per step); in 1-D a list of more than one
    number is one value per step. A value that is not numbers gives ``None``
    (:func:`displacement_path` says what is wrong with it)."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    if a.ndim == 2:
        return int(a.shape[0])
    if d == 1 and a.ndim == 1 and a.size > 1:
        return int(a.size)
    return None


def displacement_path(value, d: int, n_steps: int, factors: np.ndarray | None, where: str) -> np.ndarray:
    """The ``(n_steps, d)`` displacements of one support: one vector of ``d`` numbers scaled by
    the load ``factors`` (``None``: in full at every step), or one vector per step.

    In 1-D a bare number is one vector, ``[u1, u2, ...]`` (more than one number) one value per step,
    and ``[[u1], [u2], ...]`` too.

    Raises
    ------
    InputError
        One line naming ``where``: a vector of the wrong length, a per-step list whose length is
        not the number of steps, a value that is not a finite number.
    """
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{where} displacement must be {d} numbers or one list of {d} numbers per step, "
                         f"got {value!r}") from None
    if d == 1 and a.ndim == 1 and a.size > 1:
        a = a[:, None]  # [u1, u2, ...]: one value per step
    if a.ndim == 0 and d == 1:
        a = a.reshape(1)
    if not np.all(np.isfinite(a)):
        raise InputError(f"{where} displacement must be finite numbers, got {value!r}")
    if a.ndim == 1:
        if a.size != d:
            raise InputError(f"{where} displacement must have {d} components (one per axis), got {a.size}")
        lf = np.ones(n_steps) if factors is None else np.asarray(factors, float)
        return lf[:, None] * a[None, :]
    if a.ndim != 2 or a.shape[1] != d:
        raise InputError(f"{where} displacement per step must be lists of {d} numbers, got shape "
                         f"{'x'.join(map(str, a.shape))}")
    if a.shape[0] != n_steps:
        raise InputError(f"{where} displacement has {a.shape[0]} steps but the load path has {n_steps}")
    return a


def reconcile_steps(n_steps: int | None, given: int | None, what: str, other: str) -> int | None:
    """The number of steps of a path from two sources that must agree (``None``: not given)."""
    if given is None:
        return n_steps
    if n_steps is not None and n_steps != given:
        raise InputError(f"{what} has {given} steps but {other} has {n_steps}")
    return given


def nonzero_free_components(values: np.ndarray, axes: list[int], where: str) -> None:
    """Refuse a displacement along an axis the support does not hold (it would be ignored)."""
    d = values.shape[1]
    free = [c for c in range(d) if c not in axes]
    bad = [c for c in free if np.any(values[:, c] != 0)]
    if bad:
        raise InputError(f"{where} displacement has a {AXES[bad[0]]} component but the support does not fix "
                         f"{AXES[bad[0]]} (it fixes {''.join(AXES[c] for c in axes)!r}): add it to the fixed "
                         f"components or set it to 0")

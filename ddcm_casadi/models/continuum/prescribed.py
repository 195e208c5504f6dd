"""Prescribed displacements of a continuum (a hard device): supports with a ``displacement``.

A :class:`~ddcm_casadi.models.continuum.inputs.Support` with ``displacement`` fixes its
components to that displacement instead of zero: one vector (2 or 3 numbers) scaled by the load
factors of each step, or one vector per step. The components the support holds are prescribed;
the others stay free (a non-zero value along a free component is refused). The dofs are not
unknowns (:func:`~ddcm_casadi.models.continuum.assembly.free_dofs` leaves them out, as any
support's); their values enter the problems as a step parameter
(:class:`~ddcm_casadi.models.prescribed.Prescribed`, built here by :func:`continuum_prescribed`).

Kept apart from the builder (:func:`~ddcm_casadi.models.continuum.model.continuum_model` calls
:func:`device_step_count`, :func:`continuum_prescribed` and :func:`check_kinematics`).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.sparse as sp

from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum import fem
from ddcm_casadi.models.continuum.assembly import _components, step_count
from ddcm_casadi.models.continuum.inputs import Contact, Support
from ddcm_casadi.models.continuum.mesh import select_facets
from ddcm_casadi.models.prescribed import (AXES, Prescribed, displacement_path, nonzero_free_components, path_steps,
                                           reconcile_steps)


def _label(i: int) -> str:
    """How messages name a support: its table in the case file."""
    return f"[supports {i}]"


def support_name(i: int, support: Support) -> str:
    """The name of a support in the reaction columns: its boundary's name, else ``supports i``."""
    return support.where if isinstance(support.where, str) else f"supports {i}"


def device_steps(supports: Sequence[Support], d: int) -> int | None:
    """The number of steps the displacements given per step fix (``None``: none is)."""
    steps = None
    for i, s in enumerate(supports):
        if s.displacement is not None:
            steps = reconcile_steps(steps, path_steps(s.displacement, d), f"{_label(i)} displacement",
                                    "an earlier [[supports]] displacement")
    return steps


def device_step_count(load_factors: Sequence[float] | None, contacts: Sequence[Contact],
                      supports: Sequence[Support], d: int) -> int:
    """The number of steps of the load path: :func:`~ddcm_casadi.models.continuum.assembly.step_count`
    (load factors, else an obstacle's travel per step), else the displacements given per step;
    the sources that are given must agree.

    Raises
    ------
    InputError
        A displacement per step whose number of steps differs from the load factors', the
        obstacle travel's or another support's.
    """
    given = device_steps(supports, d)
    base = step_count(load_factors, contacts)
    if given is None:
        return base
    if load_factors is not None:
        source = "[loading] load_factors"
    elif any(np.asarray(c.travel).ndim == 1 for c in contacts):
        source = "the obstacle travel"
    else:
        return given
    if base != given:
        i = next(i for i, s in enumerate(supports) if s.displacement is not None and path_steps(s.displacement, d))
        raise InputError(f"[supports {i}] displacement has {given} steps but {source} has {base}")
    return given


def continuum_prescribed(disc: fem.Discretisation, supports: Sequence[Support], B_all: sp.spmatrix,
                         G_all: sp.spmatrix, n_steps: int, load_factors: Sequence[float] | None,
                         f_ref: np.ndarray) -> Prescribed | None:
    """The hard device of a continuum (``None`` if no support has a displacement).

    Parameters
    ----------
    disc : fem.Discretisation
    supports : sequence of Support
    B_all : sparse (m k, n_all)
        The strain operator of every dof (:func:`~ddcm_casadi.models.continuum.fem.strain_operator`).
    G_all : sparse (nc, n_all)
        The gap operator of every dof (:func:`~ddcm_casadi.models.continuum.assembly.contact_pairs`):
        ``G_D`` is its prescribed columns (an obstacle pair's normal on its own prescribed
        components; a mortar pair's weights on the slave's and the master's).
    n_steps : int
    load_factors : sequence of float, optional
        Scale a displacement given as one vector (``None``: in full at every step).
    f_ref : (n_all,)
        The reference loads (the device carries those on its dofs).

    Raises
    ------
    InputError
        A displacement of the wrong length or number of steps, along a component the support
        does not fix, or two supports prescribing different values on one dof (a support without
        a displacement fixes its components at zero).
    """
    if all(s.displacement is None for s in supports):
        return None
    d = disc.dimension
    vdofs = disc.vector_dofs()
    factors = None if load_factors is None else np.asarray(load_factors, dtype=float)
    value_of: dict[int, np.ndarray] = {}
    owner: dict[int, int] = {}
    zero_by: dict[int, int] = {}
    for i, s in enumerate(supports):
        comps = _components(s.components, d)
        nodes = fem.boundary_dofs(disc, select_facets(disc.mesh, s.where))
        if s.displacement is None:
            for c in comps:
                for dof in vdofs[c, nodes]:
                    zero_by.setdefault(int(dof), i)
            continue
        where = _label(i)
        path = displacement_path(s.displacement, d, n_steps, factors, where)
        nonzero_free_components(path, comps, where)
        for c in comps:
            for dof in vdofs[c, nodes]:
                dof = int(dof)
                if dof in value_of and not np.array_equal(value_of[dof], path[:, c]):
                    _conflict(disc, dof, vdofs, f"[supports {owner[dof]}]", where, AXES[c])
                value_of.setdefault(dof, path[:, c])
                owner.setdefault(dof, i)
    component_of = np.empty(disc.n_dofs, dtype=np.intp)
    for c in range(d):
        component_of[vdofs[c]] = c
    for dof, i in zero_by.items():  # a dof fixed at zero by one support and moved by another
        if dof in value_of and np.any(value_of[dof] != 0):
            _conflict(disc, dof, vdofs, f"[supports {i}] (fixed at 0)", f"[supports {owner[dof]}]",
                      AXES[component_of[dof]])
    dofs = np.array(sorted(value_of), dtype=np.intp)
    component = component_of[dofs]
    devices = sorted(set(owner.values()))
    lf = np.ones(n_steps) if factors is None else factors
    return Prescribed(
        strain_operator=B_all[:, dofs].tocsr(), gap_operator=sp.csr_matrix(G_all)[:, dofs].tocsr(),
        values=np.column_stack([value_of[int(dof)] for dof in dofs]),
        loads=lf[:, None] * np.asarray(f_ref, float)[dofs][None, :],
        support=np.array([devices.index(owner[int(dof)]) for dof in dofs], dtype=np.intp), component=component,
        support_names=tuple(support_name(i, supports[i]) for i in devices), dimension=d, dofs=dofs)


def _conflict(disc: fem.Discretisation, dof: int, vdofs: np.ndarray, first: str, second: str, axis: str) -> None:
    scalar = int(np.flatnonzero(vdofs == dof)[0] % vdofs.shape[1])
    at = ", ".join(f"{v:.3g}" for v in disc.dof_locations()[scalar])
    raise InputError(f"{first} and {second} prescribe different {axis} displacements at ({at}): a dof held by "
                     f"two supports takes one value")


def check_kinematics(model) -> None:
    """Refuse a hard device with finite kinematics (one line): the element-by-element assembly
    of a finite-strain continuum gathers free dofs only."""
    if model.prescribed is not None and model.kinematics == "finite":
        raise InputError("[[supports]] displacement (prescribed displacements) is not supported with "
                         "kinematics = \"finite\" yet; use kinematics = \"small\"")

"""The peer side of ``benchmarks/ddfenics_block.py``: plain DDCM on a 2-D block with ddfenics.

Run by the peer's own Python (DOLFINx 0.11 from the ``dolfinx-solver-real`` wheel, Python >= 3.12,
with ``ddfenicsx`` and ``fetricksx`` importable), never imported by the project::

    PEER_PYTHON benchmarks/peers/ddfenics_block.py PROBLEM.npz RESULT.json ASSIGNMENT.npy

``PROBLEM.npz`` is written by ``benchmarks/ddfenics_block.py``: the project's mesh (``points``,
``cells``: P1 triangles), its Dirichlet boundaries (``xmin`` fixes x, ``ymin`` fixes x and y), the
traction on ``ymax``, the data set (Mandel ``strain``, ``stress``) and the metric ``C``. ddfenics
solves the same discrete problem: one quadrature point per triangle (``DDSpace(..., 'Quadrature')``
of degree 0), the Kirchdoerfer-Ortiz scheme with one MUMPS factorisation
(``DDProblemInfinitesimalStrain``, ``is_accelerated=False``: its default moves the state halfway to the
data, another scheme), its KD-tree search (``DDSearch``, scikit-learn) from the zero state. The result
gives the iterations, the seconds of the equilibrium and data projections (ddfenics' own timers:
``seconds_per_iteration``; ``loop_seconds_per_iteration`` adds its stopping test and the first
call's form compilation), the set-up, the peak
memory of this process (``RESULT.json``) and the final data index of every cell in the project's
cell order (``ASSIGNMENT.npy``).
"""

import json
import sys
import time

import dolfinx_solver  # noqa: F401  (first: it loads the wheel's MPI and PETSc libraries)
import basix.ufl
import numpy as np
import ufl
from dolfinx import fem, mesh
from mpi4py import MPI
from petsc4py import PETSc

import ddfenicsx as dd
from process import peak_resident_bytes  # benchmarks/peers/, this script's folder


def main(problem_path: str, result_path: str, assignment_path: str) -> None:
    t0 = time.perf_counter()
    P = np.load(problem_path)
    points, cells = np.asarray(P["points"], float), np.asarray(P["cells"], np.int64)
    element = basix.ufl.element("Lagrange", "triangle", 1, shape=(2,))
    domain = mesh.create_mesh(MPI.COMM_WORLD, cells, element, points)
    tdim, fdim = domain.topology.dim, domain.topology.dim - 1
    xmin, ymin = points.min(axis=0)
    ymax = points[:, 1].max()
    tol = 1e-9 * float(np.ptp(points))

    Uh = fem.functionspace(domain, ("Lagrange", 1, (tdim,)))
    left = mesh.locate_entities_boundary(domain, fdim, lambda x: np.isclose(x[0], xmin, atol=tol))
    bottom = mesh.locate_entities_boundary(domain, fdim, lambda x: np.isclose(x[1], ymin, atol=tol))
    top = mesh.locate_entities_boundary(domain, fdim, lambda x: np.isclose(x[1], ymax, atol=tol))
    zero = PETSc.ScalarType(0.0)
    bcs = [fem.dirichletbc(zero, fem.locate_dofs_topological(Uh.sub(0), fdim, left), Uh.sub(0)),
           fem.dirichletbc(np.zeros(2, dtype=PETSc.ScalarType), fem.locate_dofs_topological(Uh, fdim, bottom), Uh)]
    tags = mesh.meshtags(domain, fdim, np.sort(top), np.full(top.size, 1, dtype=np.int32))
    ds = ufl.Measure("ds", domain=domain, subdomain_data=tags)
    T = fem.Constant(domain, np.asarray(P["traction"], dtype=PETSc.ScalarType))

    database = np.stack([P["strain"], P["stress"]], axis=1)  # (Nd, 2, 3), Mandel
    ddmat = dd.DDMaterial(database, addzero=False, shuffle=-1)
    Sh = dd.DDSpace(Uh, 3, "Quadrature")
    metric = dd.DDMetric(C=np.asarray(P["C"], float), Sh=Sh)
    problem = dd.DDProblemInfinitesimalStrain([Uh, Sh], L=lambda w: ufl.dot(T, w) * ds(1), bcs=bcs,
                                              metric=metric, is_accelerated=False)
    search = dd.DDSearch(metric, ddmat, algorithm="kd_tree", opInit="zero")
    solver = dd.DDSolver(problem, search)
    setup = time.perf_counter() - t0

    t1 = time.perf_counter()
    _, iterations, t_equilibrium, t_data = solver.solve(tol=float(P["tol"]), maxit=int(P["maxit"]))
    total = time.perf_counter() - t1

    original = np.asarray(domain.topology.original_cell_index, dtype=np.int64)
    assignment = np.empty(cells.shape[0], dtype=np.int64)
    assignment[original] = np.asarray(search.map[:, 0], dtype=np.int64)
    result = dict(iterations=int(iterations), solve_seconds=total, setup_seconds=setup,
                  equilibrium_seconds=t_equilibrium, data_seconds=t_data,
                  seconds_per_iteration=(t_equilibrium + t_data) / max(int(iterations), 1),
                  loop_seconds_per_iteration=total / max(int(iterations), 1),
                  peak_memory_bytes=peak_resident_bytes(),
                  distance=float(search.global_dist))
    np.save(assignment_path, assignment)
    with open(result_path, "w") as f:
        json.dump(result, f)


if __name__ == "__main__":
    main(*sys.argv[1:4])

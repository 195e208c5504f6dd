"""The peer side of ``benchmarks/snesvi.py``: PETSc's reduced-space active-set VI Newton
(SNES ``vinewtonrsls``) with MUMPS on the discrete Signorini problem that ddcm-casadi wrote.

    PYTHON_WITH_PETSC benchmarks/peers/snesvi_peer.py solve PROBLEM.npz SOLUTION.npz ORDERING FACTOR
    PYTHON_WITH_PETSC benchmarks/peers/snesvi_peer.py factor PROBLEM.npz REPEATS ORDERING FACTOR

Imports only numpy, scipy and petsc4py (the ``dolfinx-solver-real`` wheel ships PETSc, petsc4py
and MUMPS; it needs Python >= 3.12, so this runs in its own interpreter). ``PROBLEM.npz`` holds the
free-dof stiffness ``K``, the gap operator ``G`` (one node a row, a unit normal), the gap offsets
``gap0`` and loads ``f`` per step. Each contact node's dofs are rotated, ``u = R v`` with ``R``
orthogonal and the node's normal as the first new axis, so that the gap ``g = G u + gap0 = v_n +
gap0`` becomes the bound ``v_n >= -gap0`` and each step is the bound-constrained MCP

    lb <= v  _|_  F(v) = R^T K R v - R^T f,

whose contact pressures are ``p = F_n / a``. Steps are warm-started from the last one, as
ddcm-casadi's path is. ``ORDERING``: MUMPS's ``ICNTL(7)`` (0 AMD, 2 AMF, 5 METIS, 7 automatic);
``FACTOR``: ``lu`` or ``cholesky`` (MUMPS's LDL^T of the symmetric reduced matrix). Prints one
JSON line: seconds per step, Newton iterations, numeric factorisations, symbolic analyses and the
peak resident memory of this process. ``factor``: the seconds of one factorisation and solve of
``K`` alone.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import scipy.sparse as sp

import dolfinx_solver  # noqa: F401 - loads the wheel's MPI library before petsc4py
from petsc4py import PETSc
from process import peak_resident_bytes  # benchmarks/peers/, this script's folder


def rotation(G: sp.csr_matrix, n: int) -> sp.csr_matrix:
    """The orthogonal ``R`` (``u = R v``) whose column at a contact node's first dof is the node's
    unit normal (the gap row) and whose next column is its tangent; the identity elsewhere."""
    rows, cols, vals = [], [], []
    touched = np.zeros(n, bool)
    for c in range(G.shape[0]):
        idx, w = G.indices[G.indptr[c]:G.indptr[c + 1]], G.data[G.indptr[c]:G.indptr[c + 1]]
        if idx.size == 1:
            i = int(idx[0])
            rows.append(i), cols.append(i), vals.append(float(np.sign(w[0])))
        elif idx.size == 2:
            (i, j), (a, b) = idx, w / np.hypot(*w)
            # u_i = a v_i - b v_j, u_j = b v_i + a v_j: v_i = a u_i + b u_j is the normal component
            rows += [i, i, j, j]
            cols += [i, j, i, j]
            vals += [a, -b, b, a]
        else:
            raise ValueError("a gap row must involve one node (one or two dofs)")
        touched[idx] = True
    free = np.flatnonzero(~touched)
    rows += free.tolist()
    cols += free.tolist()
    vals += [1.0] * free.size
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def petsc_matrix(A: sp.csr_matrix) -> PETSc.Mat:
    A = sp.csr_matrix(A)
    A.sort_indices()
    return PETSc.Mat().createAIJ(size=A.shape, csr=(A.indptr.astype(PETSc.IntType),
                                                      A.indices.astype(PETSc.IntType), A.data))


def event_count(name: str) -> int:
    return int(PETSc.Log.Event(name).getPerfInfo()["count"])


def main(problem: str, solution: str, ordering: int, factor: str) -> dict:
    PETSc.Log.begin()
    d = np.load(problem)
    n = int(d["n"])
    K = sp.csr_matrix((d["K_data"], d["K_indices"], d["K_indptr"]), shape=(n, n))
    G = sp.csr_matrix((d["G_data"], d["G_indices"], d["G_indptr"]), shape=(int(d["nc"]), n))
    area, gap0, loads = d["area"], d["gap0"], d["f"]
    t0 = time.perf_counter()
    R = rotation(G, n)
    A = (R.T @ K @ R).tocsr()
    normal = np.array([G.indices[G.indptr[c]] for c in range(G.shape[0])])  # the rotated normal dofs
    J = petsc_matrix(A)
    if factor == "cholesky":
        J.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        J.setOption(PETSc.Mat.Option.SPD, False)  # the reduced matrices are SPD, MUMPS LDL^T is fine
    rhs, v, F = J.createVecRight(), J.createVecRight(), J.createVecRight()
    lower, upper = J.createVecRight(), J.createVecRight()
    upper.set(PETSc.INFINITY)

    def residual(snes, x, out):
        J.mult(x, out)
        out.axpy(-1.0, rhs)

    def jacobian(snes, x, Jm, P):
        pass  # constant: vinewtonrsls extracts the reduced block itself

    snes = PETSc.SNES().create()
    snes.setType("vinewtonrsls")
    snes.setFunction(residual, F)
    snes.setJacobian(jacobian, J, J)
    scale = float(np.max(np.abs(A.data)))
    snes.setTolerances(rtol=1e-14, atol=1e-12 * scale * float(np.max(np.abs(gap0))), stol=0.0, max_it=100)
    ksp = snes.getKSP()
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType(factor)
    pc.setFactorSolverType("mumps")
    opts = PETSc.Options()
    opts["mat_mumps_icntl_7"] = ordering
    snes.setFromOptions()
    setup = time.perf_counter() - t0
    steps = []
    u_out, p_out = [], []
    for k in range(gap0.shape[0]):
        t = time.perf_counter()
        rhs.setArray(R.T @ loads[k])
        lb = np.full(n, PETSc.NINFINITY)
        lb[normal] = -gap0[k]
        lower.setArray(lb)
        snes.setVariableBounds(lower, upper)
        snes.solve(None, v)
        steps.append(dict(seconds=time.perf_counter() - t, iterations=snes.getIterationNumber(),
                          reason=int(snes.getConvergedReason())))
        residual(snes, v, F)
        u_out.append(R @ v.getArray())
        p_out.append(F.getArray()[normal] / area)
    np.savez(solution, u=np.array(u_out), p=np.array(p_out))
    return dict(seconds=sum(s["seconds"] for s in steps), setup_seconds=setup, steps=steps,
                newton_iterations=sum(s["iterations"] for s in steps),
                numeric_factorisations=event_count("MatLUFactorNum") + event_count("MatCholFctrNum"),
                symbolic_factorisations=event_count("MatLUFactorSym") + event_count("MatCholFctrSym"),
                converged=all(s["reason"] > 0 for s in steps), ordering=ordering, factor=factor,
                peak_memory_bytes=peak_resident_bytes(),
                petsc_version=".".join(map(str, PETSc.Sys.getVersion())))


def factor_time(problem: str, repeats: int, ordering: int, factor: str) -> dict:
    """Seconds of one MUMPS factorisation (symbolic and numeric) and solve of ``K`` (median of
    ``repeats``), and the peak resident memory."""
    d = np.load(problem)
    n = int(d["n"])
    J = petsc_matrix(sp.csr_matrix((d["K_data"], d["K_indices"], d["K_indptr"]), shape=(n, n)))
    J.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    b = J.createVecRight()
    b.setArray(np.cos(np.arange(n)))
    x = b.duplicate()
    PETSc.Options()["mat_mumps_icntl_7"] = ordering
    times = []
    for _ in range(repeats):
        ksp = PETSc.KSP().create()
        ksp.setOperators(J)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType(factor)
        pc.setFactorSolverType("mumps")
        ksp.setFromOptions()
        t0 = time.perf_counter()
        ksp.setUp()
        ksp.solve(b, x)
        times.append(time.perf_counter() - t0)
        ksp.destroy()
    return dict(seconds=float(np.median(times)), ordering=ordering, factor=factor,
                peak_memory_bytes=peak_resident_bytes())


if __name__ == "__main__":
    mode, path, out, ordering, factor = sys.argv[1:6]
    if mode == "factor":
        print(json.dumps(factor_time(path, int(out), int(ordering), factor)))
    else:
        print(json.dumps(main(path, out, int(ordering), factor)))

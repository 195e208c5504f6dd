"""The loops that solve Fischer-Burmeister systems: active-set predictor, semismooth Newton,
biactive corner polish, smoothing continuation and the primal-dual active-set branch finish.

The system itself (CasADi Functions with named parameters) is built by
:class:`ddcm_casadi.formulations.ncp.FBSystem`; the maths of each stage (why a corner needs
its own branch, why the branch finish is exact, when the predictor's result is accepted) is in
that class's docstring. This module owns the iteration and its state: the cache of
factorisations per active set and the counters.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from ddcm_casadi.problems.complementarity import CONTACT, b_stationarity, free_sign, identify
from ddcm_casadi.factor_updates import ReferenceFactor, UpdatedFactor, UpdatingFactors
from ddcm_casadi.linalg import SingularMatrix
from ddcm_casadi.loops.newton import NewtonResult, newton_solve, smoothed_newton_solve


class PieceFactorCache:
    """The factors of piece systems an :class:`ActiveSetSolver` keeps, one per active set (its key),
    the least recently used going first.

    At most ``size`` factors are kept, resting on at most ``bases`` full factorisations: an
    :class:`~ddcm_casadi.factor_updates.UpdatedFactor` holds its base factor, and a full factorisation
    takes a few GB at 1e6 unknowns.

    Parameters
    ----------
    size : int
        Factors kept.
    bases : int
        Full factorisations those may rest on.
    """

    def __init__(self, size: int, bases: int) -> None:
        self.size, self.bases = int(size), int(bases)
        self._factors: OrderedDict[bytes, object] = OrderedDict()

    def take(self, key: bytes) -> object | None:
        """The factor kept for ``key``, removed from the cache (:meth:`put` it back once used), or
        ``None``."""
        return self._factors.pop(key, None)

    def put(self, key: bytes, factor: object) -> None:
        """Keep ``factor`` for ``key`` as the most recently used, then drop the least recently used
        beyond :attr:`size` factors or :attr:`bases` full factorisations."""
        self._factors[key] = factor
        bases: list[int] = []
        for k in reversed(list(self._factors)):
            lu = self._factors[k]
            base = id(lu.base if isinstance(lu, UpdatedFactor) else lu)
            if base not in bases:
                bases.append(base)
            if len(bases) > self.bases:
                del self._factors[k]
        while len(self._factors) > self.size:
            self._factors.popitem(last=False)

    def keys(self) -> list[bytes]:
        """The keys kept, least recently used first."""
        return list(self._factors)

    def clear(self) -> None:
        """Forget every factor."""
        self._factors.clear()


@dataclass
class _Walk:
    """The state of one primal-dual active-set iteration (:meth:`ActiveSetSolver._active_set`)."""

    z: np.ndarray  # the point the next piece solve starts from
    branch: np.ndarray  # 1.0 where a pair is on its contact piece
    held: np.ndarray  # pairs held at the corner (a_i = b_i = 0)
    releases: int  # holds and releases of corner pairs left
    flips: np.ndarray  # switches of each pair since the last hold or release
    seen: set = field(default_factory=set)  # the (branch, held) visited since then

    def key(self) -> bytes:
        return self.branch.tobytes() + self.held.tobytes()

    def restart(self, z: np.ndarray) -> None:
        """After pairs were held or released: from ``z``, with no piece seen and no flip counted."""
        self.z, self.seen, self.flips[:] = z, set(), 0


class ActiveSetSolver:
    """Solves one :class:`~ddcm_casadi.formulations.ncp.FBSystem` many times (state: the
    factorisations of the piece systems, one per active set, and the counters ``stats``).

    Parameters
    ----------
    system : FBSystem
    predictor : bool
        Try the active-set predictor before semismooth Newton. For a proximal system (the
        augmented Lagrangian's) an accepted prediction is a KKT point of a piece of ``Z_E``:
        ``Phi = 0`` there, so it is the exact projection whatever ``lam`` and ``rho`` (as the
        branch finish's result).
    """

    #: Factors of piece systems kept (one per active set).
    LU_CACHE = 4
    #: Full factorisations those rest on (a few GB each at 1e6 unknowns).
    FACTORS_KEPT = 2

    def __init__(self, system, *, predictor: bool = True) -> None:
        self.system = system
        self.predictor = bool(predictor)
        self.stats = {"predicted": 0, "newton": 0, "factorizations": 0, "updates": 0}
        self._pieces = PieceFactorCache(self.LU_CACHE, self.FACTORS_KEPT)
        self._factors = UpdatingFactors()  # the last piece matrix factorised itself, and its updates
        if self.predictor:
            system.branch_system()  # part of the build, not of the first solve

    def reset(self) -> None:
        """Forget the cached factorisations and the counters (for cold-start measurements)."""
        self._pieces.clear()
        self._factors.reset()
        self.stats = {"predicted": 0, "newton": 0, "factorizations": 0, "updates": 0}

    def solve(self, z0, base, opts, *, corner_tol: float = 1e-3):
        """Predictor, semismooth Newton, a corner (biactive) polish, smoothing, branch finish.

        ``base``: the values of the system's base parameters (the problem's, and ``lam``,
        ``rho`` for a proximal system). Returns ``(x, p, state, result, mu, stages)``.
        """
        system = self.system
        kw = dict(jacobian=system.jacobian, tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        spent = 0
        if self.predictor:
            predicted, spent = self._active_set(z0, base, opts, corner_tol=corner_tol, max_switches=opts.max_iter)
            if predicted is not None:
                self.stats["predicted"] += 1
                predicted.message = predicted.message.replace("active set", "active-set predictor")
                x, p, st = system.split(predicted.z)
                return x, p, st, predicted, 0.0, 0
        self.stats["newton"] += 1

        def pack(mu: float) -> np.ndarray:
            return system.pack(base, mu=mu)

        if not system.corner:
            res, mu, stages = smoothed_newton_solve(system.rj, system.r, z0, pack, smoothing=opts.smoothing, **kw)
            res.iterations += spent
            x, p, st = system.split(res.z)
            return x, p, st, res, mu, stages
        best = newton_solve(system.rj, system.r, z0, pack(0.0), **kw)
        total, mu, stages = spent + best.iterations, 0.0, 0
        if not best.converged or self._creeping(best.z, base, corner_tol):
            polished = self._corner(best.z, base, corner_tol, kw)
            if polished is not None:
                total += polished.iterations
                best = polished
        if not best.converged and system.proximal:
            # The augmented Lagrangian's inner systems: the branch finish (a few solves with kept
            # piece factors) before the smoothing continuation (up to 350 Newton steps, each a
            # factorisation; docs/performance.md, 2026-11-26). Same acceptance tests either way.
            finish, spent = self.branch_finish((best.z,), base, opts, corner_tol=corner_tol)
            total += spent
            if finish is not None:
                best = finish
        if not best.converged:
            best, mu, stages = smoothed_newton_solve(system.rj, system.r, z0, pack, smoothing=opts.smoothing,
                                                     try_plain=False, **kw)
            total += best.iterations
            polished = self._corner(best.z, base, corner_tol, kw)
            if polished is not None:
                total += polished.iterations
                best, mu = polished, 0.0
        if not best.converged:
            finish, spent = self.branch_finish((best.z, z0), base, opts, corner_tol=corner_tol)
            total += spent
            if finish is not None:
                best, mu = finish, 0.0
        best.iterations = total
        x, p, st = system.split(best.z)
        return x, p, st, best, mu, stages

    def _solve_piece(self, z, P, branch, held, kw, *, steps: int = 3) -> NewtonResult | None:
        """Newton on the piece system ``branch`` with the pairs ``held`` at the corner (``P``: the
        problem's parameter values); for a linear model with a cached factorisation. ``None`` if
        the piece system is singular. ``steps``: at most this many steps on a linear piece (1:
        the solve alone, unconfirmed: enough to choose the switches of a piece that is left)."""
        rj, r, jac, linear = self.system.branch_system()
        Pb = self.system.piece_parameters.pack(P, branch=branch, corner=held.astype(float))
        if not linear:
            return newton_solve(rj, r, z, Pb, **dict(kw, jacobian=jac))
        key = branch.tobytes() + held.tobytes()
        lu = self._pieces.take(key)
        if lu is None:
            res, J = rj(z, Pb)
            try:
                lu = self._factorize(jac(J))
            except SingularMatrix:  # singular piece (degenerate active set)
                return None
        else:
            res = r(z, Pb)
        result = self._refine(z, res, lu, r, Pb, kw, steps)
        if steps > 1 and (result is None or not result.converged) and isinstance(lu, UpdatedFactor):
            # an update that misses the tolerances (an ill-conditioned capacitance matrix):
            # factorise this piece itself
            try:
                lu = self._factorize(jac(rj(z, Pb)[1]), update=False)
            except SingularMatrix:
                return None
            result = self._refine(z, res, lu, r, Pb, kw, steps)
        # A reference is cached by its factor only: its kept update columns (up to a few GB at
        # 1e6 unknowns) serve updates while it is the reference, and go with it.
        self._pieces.put(key, lu.factor if isinstance(lu, ReferenceFactor) else lu)
        return result

    @staticmethod
    def _refine(z, res, lu, r, Pb, kw, steps: int = 3) -> NewtonResult | None:
        """Newton on a linear piece system with its exact factorised Jacobian ``lu`` from ``z``
        (residual ``res``): the first step solves it, the next ones (up to ``steps`` in all)
        refine roundoff and confirm the increment."""
        z = np.array(z, dtype=float)
        rnorm, increment, it = float(np.max(np.abs(res), initial=0.0)), np.inf, 0
        for it in range(1, min(steps, kw["max_iter"]) + 1):
            dz = -lu.solve(res)
            if not np.all(np.isfinite(dz)):
                return None
            z = z + dz
            increment = float(np.max(np.abs(dz), initial=0.0)) / max(1.0, float(np.max(np.abs(z), initial=0.0)))
            res = r(z, Pb)
            rnorm = float(np.max(np.abs(res), initial=0.0))
            if increment <= kw["tol"] and rnorm <= kw["residual_tol"]:
                return NewtonResult(z, True, it, rnorm, increment, "converged")
        return NewtonResult(z, False, it, rnorm, increment, "piece system: refinement stalled")

    def _factorize(self, A, *, update: bool = True):
        """A factor of the piece matrix ``A``: a low-rank update of the last full factorisation
        when few rows differ (a few pairs switched piece; :class:`~ddcm_casadi.factor_updates.UpdatingFactors`),
        else a factorisation of its own, which becomes the reference (``_refine`` corrects its solves)."""
        lu = self._factors.factor(A, update=update)
        self.stats["updates" if isinstance(lu, UpdatedFactor) else "factorizations"] += 1
        return lu

    def _signs(self, z, P, branch):
        """The sign each piece leaves free: ``b_i`` where ``a_i = 0`` is imposed, else ``a_i``."""
        a, b = self.system.ab(z, P)
        return free_sign(a, b, branch > 0)

    def branch_finish(self, starts, base, opts, *, corner_tol: float = 1e-3, max_switches: int | None = None):
        """Primal-dual active-set finish on the pieces of ``Z_E`` (see the class notes).

        Returns ``(result, spent)``: the converged Newton result, or ``None`` if no start leads to
        a solution whose signs hold (then the caller reports the failure), and the linear solves
        and Newton steps spent on every start.
        """
        max_switches = 2 * self.system.nc + 5 if max_switches is None else max_switches
        spent = 0
        for z in starts:
            res, work = self._active_set(z, base, opts, corner_tol=corner_tol, max_switches=max_switches)
            spent += work
            if res is not None:
                res.iterations = spent
                res.message = res.message.replace("active set", "branch finish")
                return res, spent
        return None, spent

    def _active_set(self, z, base, opts, *, corner_tol: float,
                    max_switches: int) -> tuple[NewtonResult | None, int]:
        """Primal-dual active-set iteration from ``z``: solve the piece system of the branches ``z``
        lies on, switch the pairs whose free sign is violated, until every sign holds.

        A sign-consistent result is accepted if strictly complementary; with biactive pairs (signs
        hold to 1e-12 relative) it is accepted for ``mcp`` (any sign-consistent point solves the
        pairs), and for ``mpcc`` those pairs are *held* at the corner as below. If the
        iteration cycles, the pairs that switched back and forth are the biactive candidates: they
        are held at the corner (``a_i = b_i = 0``, in the same linear piece system) while the
        others go on switching; a result with held pairs is accepted only if B-stationary, and a
        held pair whose multiplier says otherwise is released onto the piece it points to. A piece
        solve that misses its tolerance still chooses the switches but is never accepted. ``None``
        if a piece is singular, corners are held or released more than ``3 + nc`` times or
        ``max_switches`` is reached.
        Returns ``(result, spent)``, ``spent`` the linear solves and Newton steps (counted also
        when it fails).
        """
        if not np.all(np.isfinite(z)):
            return None, 0
        system = self.system
        P = system.problem_values(base)
        kw = dict(tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        a, b = system.ab(z, P)
        # Each release frees at least one held pair, so one per pair (plus a few re-holds) lets a
        # corner of many biactive pairs be unwound; max_switches still bounds the whole loop.
        w = _Walk(z=z, branch=(identify(a, b) == CONTACT).astype(float), held=np.zeros(system.nc, dtype=bool),
                  releases=3 + system.nc, flips=np.zeros(system.nc, dtype=int))
        total = 0
        linear = system.branch_system()[3]  # a nonlinear piece's Newton already ran to max_iter: no second try
        for _ in range(max_switches):
            w.seen.add(w.key())
            # One solve first: most pieces are left for another, and their switches need no
            # confirming step (a piece of the 1e5 Hertz path: 2 solves against 3, with its column).
            res = self._solve_piece(w.z, P, w.branch, w.held, kw, steps=1)
            for attempt in range(2):
                if res is None or not np.all(np.isfinite(res.z)):
                    return None, total
                total += res.iterations
                other = np.where(w.held, np.inf, self._signs(res.z, P, w.branch))
                roundoff = 1e-12 * max(1.0, float(np.max(np.abs(other[~w.held]), initial=0.0)))
                worst = -float(np.min(other, initial=np.inf))
                if attempt or res.converged or worst > roundoff or not linear:
                    break
                # The signs hold: confirm, within the piece's budget of three steps (max_iter)
                res = self._solve_piece(res.z, P, w.branch, w.held, kw, steps=min(3, kw["max_iter"]) - 1)
            if not res.converged:
                # An ill-conditioned piece (a far-off start) may miss residual_tol; its solution
                # still says which pairs to switch, but it cannot be accepted.
                if worst <= roundoff:
                    return None, total
            elif np.all(other > 0) or worst <= roundoff:
                done, message = self._signs_hold(w, res, other, roundoff)
                if not done:
                    continue
                if message is None:
                    return None, total
                res.iterations, res.message = total, message
                return res, total
            w.z = res.z
            switch = other < 0
            w.flips += switch
            w.branch = np.where(switch, 1.0 - w.branch, w.branch)
            if w.key() in w.seen:
                # Cycling between pieces: the solution is at the corner of the pairs that switch
                # back and forth, if anywhere.
                if not system.corner or w.releases == 0:
                    return None, total
                w.releases -= 1
                w.held |= w.flips >= 2
                w.seen, w.flips[:] = set(), 0
        return None, total

    def _signs_hold(self, w: _Walk, res: NewtonResult, other: np.ndarray, roundoff: float) -> tuple[bool, str | None]:
        """Every free sign of the piece solution ``res`` holds, strictly or to ``roundoff``: accept
        it, or hold (biactive to roundoff) or release (not B-stationary) corner pairs and go on.

        Returns
        -------
        done : bool
            Whether the iteration ends here: accepted if ``message``, else failed (no release
            left).
        message : str or None
            The accepted result's message.
        """
        system = self.system
        if np.all(other > 0):
            if not w.held.any():
                return True, "converged (active set)"
            wrong_theta, wrong_nu = b_stationarity(*system.corner_multipliers(res.z), w.held)
            if not (wrong_theta.any() or wrong_nu.any()):
                return True, "converged (biactive corner)"
            if w.releases == 0:
                return True, None
            # Not B-stationary: leave the corner along the piece its multipliers point to.
            w.releases -= 1
            w.held &= ~(wrong_theta | wrong_nu)
            w.branch = np.where(wrong_theta, 0.0, np.where(wrong_nu, 1.0, w.branch))
            w.restart(res.z)
            return False, None
        if not system.corner:  # mcp: signs hold to roundoff; the caller checks the residual
            return True, "converged (active set)"
        if w.releases == 0:
            return True, None
        # Biactive to roundoff: hold those pairs at the corner (accepted if B-stationary).
        w.releases -= 1
        w.held |= np.abs(other) <= roundoff
        w.restart(res.z)
        return False, None

    def polish_corner(self, z, base, opts, *, corner_tol: float = 1e-3):
        """The biactive-branch solution near ``z`` if it is B-stationary, else ``None``."""
        kw = dict(jacobian=self.system.jacobian, tol=opts.tol, residual_tol=opts.residual_tol, max_iter=opts.max_iter)
        return self._corner(z, base, corner_tol, kw) if self.system.corner else None

    def _creeping(self, z, base, corner_tol) -> bool:
        a, b = self.system.ab(z, self.system.problem_values(base))
        near = np.maximum(np.abs(a), np.abs(b)) <= corner_tol
        return bool(np.any(np.minimum(np.abs(a), np.abs(b))[near] > 1e-14))

    def _corner(self, z, base, corner_tol, kw):
        """Newton on the biactive branch of the pairs within ``corner_tol`` of a corner; ``None``
        unless it converges and is B-stationary (no ``theta_i > 0``: ``a_i`` wants to open, nor
        ``nu_i > 0``: ``b_i`` does; :func:`ddcm_casadi.problems.complementarity.b_stationarity`)."""
        if not np.all(np.isfinite(z)):
            return None
        system = self.system
        a, b = system.ab(z, system.problem_values(base))
        sel = (np.maximum(np.abs(a), np.abs(b)) <= corner_tol).astype(float)
        if not sel.any():
            return None
        res = newton_solve(system.rj, system.r, z, system.pack(base, mu=0.0, corner=sel), **kw)
        if not res.converged:
            return None
        wrong_theta, wrong_nu = b_stationarity(*system.corner_multipliers(res.z), sel > 0)
        if wrong_theta.any() or wrong_nu.any():
            return None
        res.message = "converged (biactive corner)"
        return res

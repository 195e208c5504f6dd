"""Solvers that drive the CasADi problems built by the formulations."""

from ddcm_casadi.loops.newton import NewtonResult, newton_solve

__all__ = ["NewtonResult", "newton_solve"]

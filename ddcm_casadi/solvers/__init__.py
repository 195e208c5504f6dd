"""Solvers that drive the CasADi problems built by the formulations."""

from .newton import NewtonResult, newton_solve

__all__ = ["NewtonResult", "newton_solve"]

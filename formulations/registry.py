"""Registry of contact formulations: each is a named transformation of the complementarity pairs."""

from __future__ import annotations

from typing import Any

from ddcm_casadi.errors import InputError

_REGISTRY: dict[str, type] = {}


def register(cls: type) -> type:
    """Class decorator: register a :class:`~ddcm_casadi.formulations.base.Formulation` under ``cls.name``."""
    if cls.name in _REGISTRY:
        raise ValueError(f"formulation {cls.name!r} is already registered")
    _REGISTRY[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names of the registered formulations, in registration order."""
    return list(_REGISTRY)


def get(name: str, **options: Any):
    """A new formulation instance by name, with keyword options (copied, validated)."""
    try:
        cls = _REGISTRY[name]
    except KeyError:
        raise InputError(f"unknown formulation {name!r}; available: {', '.join(_REGISTRY)}") from None
    return cls(**options)

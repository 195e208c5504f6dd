"""Registry of contact formulations: each is a named transformation of the complementarity pairs."""

from __future__ import annotations

from typing import Any

from ddcm_casadi.registry import Registry

_REGISTRY: Registry[type] = Registry("formulation", listing="available")


def register(cls: type) -> type:
    """Class decorator: register a :class:`~ddcm_casadi.formulations.base.Formulation` under ``cls.name``."""
    return _REGISTRY.add(cls.name, cls)


def available() -> list[str]:
    """Names of the registered formulations, in registration order."""
    return _REGISTRY.names()


def enforcing(contact_law: str) -> list[str]:
    """Names of the registered formulations whose ``supported_contact_laws`` include
    ``contact_law`` (a frictional case's default), in registration order."""
    return [name for name in available() if contact_law in _REGISTRY[name].supported_contact_laws]


def get(name: str, **options: Any):
    """A new formulation instance by name, with keyword options (copied, validated)."""
    return _REGISTRY[name](**options)

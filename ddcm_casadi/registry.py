"""Named registries: the one pattern behind the package's extension points (formulations, contact
laws): a name maps to one object, a name is registered once, and an unknown name is a one-line
:class:`~ddcm_casadi.errors.InputError` that lists the known ones."""

from __future__ import annotations

from typing import Generic, TypeVar

from ddcm_casadi.errors import InputError

T = TypeVar("T")


class Registry(Generic[T]):
    """Objects by name, in registration order.

    Parameters
    ----------
    what : str
        What the objects are, for messages (``"formulation"``, ``"contact law"``).
    listing : str
        The word before the known names in the unknown-name message (``"known"``, ``"available"``).
    """

    def __init__(self, what: str, listing: str = "known") -> None:
        self.what, self.listing = what, listing
        self._items: dict[str, T] = {}

    def add(self, name: str, item: T) -> T:
        """Register ``item`` under ``name``; a second registration of a name is a programming
        error (``ValueError``)."""
        if name in self._items:
            raise ValueError(f"{self.what} {name!r} is already registered")
        self._items[name] = item
        return item

    def names(self) -> list[str]:
        """The registered names, in registration order."""
        return list(self._items)

    def __getitem__(self, name: str) -> T:
        try:
            return self._items[name]
        except KeyError:
            raise InputError(f"unknown {self.what} {name!r}; {self.listing}: {', '.join(self._items)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._items

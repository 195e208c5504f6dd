"""Contact laws as kinds: what the complementarity pairs of a contact mean.

A contact carries a *block* of components (:attr:`ContactLaw.components`): the normal one for
frictionless unilateral (Signorini) contact, and tangential ones for a frictional law. A model
declares its law by name (``ContactModel.contact_law``), the problems carry it
(``ComplementarityProblem.contact_law``), and every formulation declares the laws it enforces
(``Formulation.contact_laws``), refusing the others with one line before any work
(:meth:`~ddcm_casadi.formulations.base.Formulation.check_supports`).

>>> get_contact_law("signorini").components
('normal',)
"""

from __future__ import annotations

from dataclasses import dataclass

from ddcm_casadi.registry import Registry


@dataclass(frozen=True)
class ContactLaw:
    """A kind of contact law.

    Attributes
    ----------
    name : str
        Registry name (case files, ``results.json``).
    components : tuple of str
        The components of one contact's block, normal first.
    description : str
        The law's conditions, stated once.
    """

    name: str
    components: tuple
    description: str

    @property
    def block(self) -> int:
        """Components per contact."""
        return len(self.components)


_LAWS: Registry[ContactLaw] = Registry("contact law")


def register_contact_law(law: ContactLaw) -> ContactLaw:
    """Add a contact law kind (names are unique)."""
    return _LAWS.add(law.name, law)


def contact_laws() -> list[str]:
    """Names of the registered contact laws."""
    return _LAWS.names()


def get_contact_law(name: str) -> ContactLaw:
    """A registered contact law by name; one-line :class:`InputError` otherwise."""
    return _LAWS[name]


SIGNORINI = register_contact_law(ContactLaw(
    "signorini", ("normal",),
    "frictionless unilateral contact: gap g >= 0, pressure p >= 0, g p = 0 (one pair per contact)"))

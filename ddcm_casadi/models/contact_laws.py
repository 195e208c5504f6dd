"""Contact laws as kinds: what the complementarity pairs of a contact mean.

A contact carries a *block* of components (:attr:`ContactLaw.components`): the normal one for
frictionless unilateral (Signorini) contact, and tangential ones for a frictional law. A model
declares its law by name (``ContactModel.contact_law``), the problems carry it
(``ComplementarityProblem.contact_law``), and every formulation declares the laws it enforces
(``Formulation.contact_laws``), refusing the others with one line before any work
(:meth:`~ddcm_casadi.formulations.base.Formulation.check_supports`).

>>> get_contact_law("signorini").block(3), get_contact_law("coulomb").block(3)
(1, 3)
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
        The kinds of component of one contact's block, normal first (a ``"tangential"`` kind has
        ``dimension - 1`` components: one in 2-D, two in 3-D).
    description : str
        The law's conditions, stated once.
    history : tuple of str
        The problem parameters the law takes from the last converged step (the frictional
        law's tangential tractions ``traction0``, which a penalty's stick spring starts from).
    """

    name: str
    components: tuple
    description: str
    history: tuple = ()

    def block(self, dimension: int) -> int:
        """Components per contact in ``dimension`` space dimensions."""
        return sum(dimension - 1 if c == "tangential" else 1 for c in self.components)


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

COULOMB = register_contact_law(ContactLaw(
    "coulomb", ("normal", "tangential"),
    "unilateral contact with Coulomb friction, incremental: gap g_N >= 0, pressure p_N >= 0, g_N p_N = 0; "
    "tangential traction |r_T| <= mu p_N, opposing the slip s_T (the tangential displacement relative to the "
    "obstacle since the last converged step): s_T = -lambda r_T, lambda >= 0, lambda (mu p_N - |r_T|) = 0",
    history=("traction0",)))

"""The output layer's registries: the functions that draw a model's figures and write its field files.

A model kind declares *which* figures and field files it has, as data
(:meth:`~ddcm_casadi.models.base.ContactModel.figures` gives :class:`~ddcm_casadi.models.base.FigureSpec`\\ s,
:meth:`~ddcm_casadi.models.base.ContactModel.field_outputs` writer names); the modules that draw or write
them register their functions here under those names (:mod:`ddcm_casadi.outputs.plots`,
:mod:`ddcm_casadi.outputs.continuum_results`), and :mod:`ddcm_casadi.outputs.save` looks them up. This module
imports neither matplotlib nor any model kind.

>>> @register_drawing("my_figure")
... def my_figure(cmp, *, colour="k"):
...     ...
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, TypeVar

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: ``drawing(comparison, **options)`` returns a matplotlib ``Figure``.
Drawing = Callable[..., "Figure"]
#: ``writer(comparison, out_dir)`` writes files (atomically) into ``out_dir`` and returns their paths.
FieldWriter = Callable[[Any, Path], "list[Path]"]

_F = TypeVar("_F", bound=Callable[..., Any])
_DRAWINGS: dict[str, Drawing] = {}
_FIELD_WRITERS: dict[str, FieldWriter] = {}


def _register(table: dict[str, Any], what: str, name: str) -> Callable[[_F], _F]:
    def decorate(function: _F) -> _F:
        if table.get(name, function) is not function:  # two modules claiming one name is a bug
            raise ValueError(f"{what} {name!r} is registered already")
        table[name] = function
        return function

    return decorate


def register_drawing(name: str) -> Callable[[_F], _F]:
    """Decorator: register ``function(comparison, **options) -> Figure`` as the drawing ``name``.

    Parameters
    ----------
    name : str
        The name a :class:`~ddcm_casadi.models.base.FigureSpec` refers to.

    Raises
    ------
    ValueError
        Another function is registered under ``name``.
    """
    return _register(_DRAWINGS, "drawing", name)


def register_field_writer(name: str) -> Callable[[_F], _F]:
    """Decorator: register ``function(comparison, out_dir) -> list[Path]`` as the field writer ``name``.

    Parameters
    ----------
    name : str
        The name a model's :meth:`~ddcm_casadi.models.base.ContactModel.field_outputs` refers to.

    Raises
    ------
    ValueError
        Another function is registered under ``name``.
    """
    return _register(_FIELD_WRITERS, "field writer", name)


def _lookup(table: dict[str, Any], what: str, name: str) -> Any:
    try:
        return table[name]
    except KeyError:
        raise LookupError(f"no {what} {name!r} is registered (known: {', '.join(sorted(table)) or 'none'}); "
                          "import the module that registers it") from None


def drawing(name: str) -> Drawing:
    """The drawing registered as ``name``.

    Raises
    ------
    LookupError
        None is (the message lists those that are).
    """
    return _lookup(_DRAWINGS, "drawing", name)


def field_writer(name: str) -> FieldWriter:
    """The field writer registered as ``name``.

    Raises
    ------
    LookupError
        None is (the message lists those that are).
    """
    return _lookup(_FIELD_WRITERS, "field writer", name)

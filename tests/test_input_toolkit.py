"""One validation toolkit (``ddcm_casadi.inputs``) for case files, DDCM options and formulation options.

Options dataclasses are checked from their *resolved* type hints (``Optional[float]`` and
``float | None`` alike; the old check parsed annotation strings and let ``Optional[float]``
through unchecked), with the name rules (``max_*`` an iteration limit, ``*tol`` a tolerance), and a
bad value reads the same from a case file, from ``--set`` and from the API.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, Optional

import numpy as np
import pytest

from ddcm_casadi import bar_model, formulations
from ddcm_casadi.casefiles.base import load_case
from ddcm_casadi.casefiles.config import load_case_with_overrides
from ddcm_casadi.errors import InputError
from ddcm_casadi.inputs import (
    ITERATION_LIMIT,
    TOLERANCE,
    boolean,
    check_dataclass,
    check_fields,
    check_typed,
    finite_number,
    in_range,
    integer,
    iteration_limit,
    nonempty_list,
    number_list,
    one_of,
    positive,
    table,
    tolerance,
)
from ddcm_casadi.drivers.ddcm_options import DDCMOptions

from .test_bad_input import assert_input_error, case_toml, run_cli


@dataclass(frozen=True)
class Probe:
    """Options of every kind the toolkit reads from type hints (annotations are strings here)."""

    optional: Optional[float] = None  # noqa: UP045 - the spelling under test
    union: float | None = None
    ratio: float = 0.5
    comp_tol: float = 1e-9
    max_iter: int = 50
    depth: int = 0
    flag: bool = True
    mode: Literal["fast", "exact"] = "fast"
    name: str = "probe"
    steps: tuple = (1.0, 0.0)
    indices: tuple[int, ...] | None = None
    extra: dict = field(default_factory=dict)


def _probe(**values) -> Probe:
    options = Probe(**values)
    check_dataclass(options, "probe")
    return options


def _message(call, *args, **kwargs) -> str:
    with pytest.raises(InputError) as exc:
        call(*args, **kwargs)
    text = str(exc.value)
    assert "\n" not in text
    return text


# ------------------------------------------------------------------------------------- dataclasses
@pytest.mark.parametrize("key", ["optional", "union"])
def test_optional_and_union_with_none_are_both_checked(key):
    assert getattr(_probe(**{key: None}), key) is None
    assert getattr(_probe(**{key: 3}), key) == 3.0 and isinstance(getattr(_probe(**{key: 3}), key), float)
    assert _message(_probe, **{key: "abc"}) == f"probe {key} must be a number, got 'abc'"
    assert _message(_probe, **{key: math.inf}) == f"probe {key} must be finite, got inf"


@pytest.mark.parametrize("key", ["optional", "union", "ratio"])
def test_a_boolean_is_not_a_number(key):
    assert _message(_probe, **{key: True}) == f"probe {key} must be a number, got True"


def test_name_rules_iteration_limits_and_tolerances():
    assert _message(_probe, max_iter=0) == "probe max_iter must be an integer in 1..1000000, got 0"
    assert _message(_probe, max_iter=10**6 + 1).endswith("in 1..1000000, got 1000001")
    assert _message(_probe, comp_tol=1e-20) == ("probe comp_tol must be in [1e-15, 1) (a relative tolerance below "
                                                 "a few machine epsilons cannot be met), got 1e-20")
    assert _message(_probe, comp_tol=1.0).startswith("probe comp_tol must be in [1e-15, 1)")
    assert _probe(comp_tol=1e-15).comp_tol == 1e-15
    assert _message(_probe, depth=-1) == "probe depth must be an integer (>= 0), got -1"


def test_literal_choices_are_listed():
    assert _probe(mode="exact").mode == "exact"
    assert _message(_probe, mode="quick") == "probe mode must be one of 'fast', 'exact', got 'quick'"


def test_other_types_and_normalisation():
    options = _probe(flag=np.bool_(False), steps=[0.1, 0], indices=[3, np.int64(4)], extra={"a": 1})
    assert options.flag is False and options.steps == (0.1, 0.0) and options.indices == (3, 4)
    assert options.extra == {"a": 1}
    assert _message(_probe, flag=1) == "probe flag must be true or false, got 1"
    assert _message(_probe, name=5) == "probe name must be a string, got 5"
    assert _message(_probe, steps=[1.0, -1.0]).startswith("probe steps must be a list of finite non-negative numbers")
    assert _message(_probe, indices=[1.5]).startswith("probe indices must be a list of non-negative integers")
    assert _message(_probe, extra=[1]) == "probe extra must be a table, got [1]"
    # integral floats: refused with a hint, or accepted where the caller coerces them
    assert "(write it without a decimal point or exponent: 50)" in _message(_probe, max_iter=50.0)
    options = Probe(max_iter=50.0)
    check_dataclass(options, "probe", coerce_floats=True)
    assert options.max_iter == 50 and isinstance(options.max_iter, int)


def test_fields_rules_and_labels():
    rules = {"depth": lambda v, where: integer(v, where, low=2, high=3), "indices": lambda v, where: (0,)}
    assert check_fields(Probe, {"depth": 2, "indices": None}, "[probe]", rules=rules) == {"depth": 2, "indices": None}
    assert _message(check_fields, Probe, {"depth": 0}, "[probe]", rules=rules) == \
        "[probe] depth must be an integer in 2..3, got 0"
    assert _message(check_fields, Probe, {"ratio": "x"}, lambda name: f"option {name!r}") == \
        "option 'ratio' must be a number, got 'x'"
    with pytest.raises(TypeError):
        check_fields(Probe, {"nope": 1}, "probe")
    with pytest.raises(TypeError):
        check_typed(1, set, "probe")


# ---------------------------------------------------------------------------------------- checkers
def test_scalar_checkers():
    assert finite_number(np.float32(2.5), "x") == 2.5 and finite_number(np.array(3), "x") == 3.0
    assert _message(finite_number, 10**400, "x").startswith("x must be finite, got 1000")  # beyond the float range
    assert _message(positive, 0, "x") == "x must be finite and positive, got 0.0"
    assert _message(positive, "1", "x") == "x must be a number, got '1'"
    assert in_range(1.0, "x", 0.0, 1.0) == 1.0
    assert _message(in_range, 1.0, "x", 0.0, 1.0, high_open=True) == "x must be in [0, 1), got 1.0"
    assert _message(in_range, 0.0, "x", 0.0, None, low_open=True) == "x must be in (0, inf), got 0.0"
    assert _message(in_range, math.nan, "x", None, 1.0) == "x must be in (-inf, 1], got nan"
    assert tolerance(1e-9, "x") == 1e-9 and TOLERANCE == (1e-15, 1.0)
    assert iteration_limit(np.int64(7), "x") == 7 and ITERATION_LIMIT == (1, 10**6)
    assert _message(integer, 5, "x", high=3, what="a node index") == "x must be a node index (<= 3), got 5"
    assert _message(integer, 2.5, "x", coerce_floats=True) == "x must be an integer, got 2.5"
    assert boolean(True, "x") is True
    assert one_of("a", "x", ("a", "b")) == "a"
    assert _message(one_of, 1, "x", (True, False)) == "x must be one of True, False, got 1"
    assert nonempty_list([], "x", nonempty=False) == []
    assert _message(nonempty_list, [], "x") == "x must be a non-empty list, got []"
    assert number_list(np.array([1, 2]), "x", integers=True) == (1, 2)
    assert _message(number_list, [], "x", nonempty=True).startswith("x must be a non-empty list")
    assert table({"a": 1}, "x") == {"a": 1}


# ------------------------------------------------------------------------------ the three families
def test_formulation_options_by_resolved_hints():
    """``gamma: float | None`` (a string annotation in its module) and the name rules."""
    assert formulations.get("penalty", gamma=None).options.gamma is None
    assert _message(formulations.get, "penalty", gamma="1e14") == \
        "option 'gamma' of 'penalty' must be a number, got '1e14'"
    assert _message(formulations.get, "penalty", tol=True).startswith("option 'tol' of 'penalty' must be in [1e-15, 1)")
    assert _message(formulations.get, "penalty", max_iter=0) == \
        "option 'max_iter' of 'penalty' must be an integer in 1..1000000, got 0"
    assert _message(formulations.get, "fischer_burmeister", tol=1e-20).startswith(
        "option 'tol' of 'fischer_burmeister' must be in [1e-15, 1) (a relative tolerance")
    assert _message(formulations.get, "penalty", gamma=-1.0) == \
        "option 'gamma' of 'penalty' must be finite and positive, got -1.0"
    assert formulations.get("penalty", max_iter=20.0).options.max_iter == 20  # coerced, as before


def test_ddcm_options_literal_choices():
    assert _message(DDCMOptions, start="warm") == \
        "ddcm option start must be one of 'origin', 'elastic', 'random', got 'warm'"
    assert _message(DDCMOptions.from_mapping, {"variant": "knn"}) == \
        "[ddcm] variant must be one of 'plain', 'lcdd', 'maxent', got 'knn'"
    assert DDCMOptions(initial=None).initial is None and DDCMOptions(initial=[2, 3]).initial == (2, 3)


# ------------------------------------------------------------- file, --set and API say the same
SAME = [
    # (case-file section text, --set item, API call, the message after its label)
    pytest.param("[formulations.penalty]\nmax_iter = 0\n", "formulations.penalty.max_iter=0",
                 lambda: formulations.get("penalty", max_iter=0),
                 "option 'max_iter' of 'penalty'", "option 'max_iter' of 'penalty'",
                 " must be an integer in 1..1000000, got 0", id="formulation-iteration-limit"),
    pytest.param("[formulations.fischer_burmeister]\ntol = 1e-20\n", "formulations.fischer_burmeister.tol=1e-20",
                 lambda: formulations.get("fischer_burmeister", tol=1e-20),
                 "option 'tol' of 'fischer_burmeister'", "option 'tol' of 'fischer_burmeister'",
                 " must be in [1e-15, 1) (a relative tolerance below a few machine epsilons cannot be met), "
                 "got 1e-20", id="formulation-tolerance"),
    pytest.param("[formulations.penalty]\ngamma = true\n", "formulations.penalty.gamma=true",
                 lambda: formulations.get("penalty", gamma=True),
                 "option 'gamma' of 'penalty'", "option 'gamma' of 'penalty'",
                 " must be a number, got True", id="formulation-bool-for-float"),
    pytest.param('[ddcm]\nstart = "warm"\n', 'ddcm.start="warm"', lambda: DDCMOptions(start="warm"),
                 "[ddcm] start", "ddcm option start",
                 " must be one of 'origin', 'elastic', 'random', got 'warm'", id="ddcm-literal"),
    pytest.param("[ddcm]\nmax_outer = 1\n", "ddcm.max_outer=1", lambda: DDCMOptions(max_outer=1),
                 "[ddcm] max_outer", "ddcm option max_outer",
                 " must be an integer in 2..1000000, got 1", id="ddcm-range"),
    pytest.param("", "bar.youngs_modulus=-1",
                 lambda: bar_model(length=1.0, youngs_modulus=-1, positions=[1.0]),
                 "[bar] youngs_modulus", "youngs_modulus", " must be finite and positive, got -1.0", id="case-value"),
]


def _bad_case(extra: str) -> str:
    """The bar case with ``extra`` added (merged into ``[ddcm]`` when it is that section), or with
    ``youngs_modulus = -1`` when ``extra`` is empty."""
    if not extra:
        return case_toml(youngs_modulus="-1")
    if extra.startswith("[ddcm]"):
        return case_toml().replace("[ddcm]\n", extra, 1)
    return case_toml(extra=extra)


@pytest.mark.parametrize("extra, item, api, file_label, api_label, tail", SAME)
def test_the_same_bad_value_reads_the_same_everywhere(tmp_path, capsys, extra, item, api, file_label, api_label,
                                                      tail):
    base = tmp_path / "base.toml"
    base.write_text(case_toml())
    bad = tmp_path / "bad.toml"
    bad.write_text(_bad_case(extra))
    from_file = _message(load_case, bad)
    from_set = _message(load_case_with_overrides, base, [item])
    from_api = _message(api)
    assert from_file == from_set == file_label + tail
    assert from_api == api_label + tail
    code, _, err = run_cli(["--config", str(base), "--set", item, "--out", str(tmp_path / "out")], capsys)
    assert_input_error(code, err, file_label + tail)
    assert not (tmp_path / "out").exists()

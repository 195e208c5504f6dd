"""Sweep specifications: a base case, a grid of dotted keys, seeds, and what to run.

A spec is a TOML (or JSON) file::

    base = "paper_bar.toml"             # the base case, relative to this file (required)
    description = "..."                 # optional
    variants = ["ddcm"]                 # optional: default, the variants the case supports
    formulations = ["fischer_burmeister"]   # optional: default, every formulation
    seeds = 20                          # optional: seeds 0..19 (or a list) of the generated data

    [set]                               # optional: fixed overrides of the base case
    "ddcm.max_outer" = 50

    [generate]                          # optional: generated data (ddcm_casadi.sweep.generators)
    law = "hookean"
    youngs_modulus = 200e9
    noise_kind = "multiplicative"

    [grid]                              # dotted keys -> lists of values (the Cartesian product)
    "generate.noise" = [0.0, 0.01, 0.02]
    "formulations.penalty.gamma" = [1e13, 1e14]

    [[figures]]                         # optional
    kind = "band"                       # "rate": log-log with fitted slope; "band": median, 5-95 %
    x = "generate.noise"
    y = "max_error_p"

Grid keys are dotted keys into the case document, exactly as ``ddcm-compare --set`` takes them
(:mod:`ddcm_casadi.casefiles.overrides`), or ``generate.KEY`` for the data generator; unquoted dotted keys
(``generate.noise = [...]``) are the same key. Each combination of grid values and seeds is one
case, identified by a hash of its resolved parameters: the case document after the overrides,
the generator's resolved fields, the variants and the formulations.

The cases are not materialised: :class:`CaseGrid` computes case ``k`` from its index (the grid
is a mixed-radix number, seeds innermost), so a spec of 10^6 cases costs no memory until a case
is asked for, and the runner submits them in batches.

Everything that can be checked without solving is checked when the spec is loaded, for every
case, before any work: unknown keys, an empty grid, a missing base case, keys that do not resolve
in the document, the generator, and every distinct case built in full exactly as a case file
(types, ranges, unknown keys: everything :func:`~ddcm_casadi.casefiles.config.case_from_dict`
checks before solving; seeds share one build, since a seed changes only the drawn data). A bad
value is refused in one line naming its case, wherever it is in the grid. Only what appears when
a case runs (a solve that fails, a refusal computed from the solved state) fails that case,
recorded, without stopping the sweep.
"""

from __future__ import annotations

import hashlib
import math
import json
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ddcm_casadi import formulations as registry
from ddcm_casadi.casefiles.base import read_document
from ddcm_casadi.casefiles.config import case_from_dict
from ddcm_casadi.errors import DDCMError, InputError, one_line
from ddcm_casadi.drivers.harness import VARIANTS
from ddcm_casadi.inputs import input_file
from ddcm_casadi.casefiles.overrides import apply_overrides, split_key
from ddcm_casadi.sweep.generators import DataGenerator, attach, generator_from_dict
from ddcm_casadi.sweep.table import METRICS

#: Top-level keys of a spec.
SPEC_KEYS = ("base", "description", "variants", "formulations", "seeds", "set", "generate", "grid", "figures")
FIGURE_KINDS = ("rate", "band")
FIGURE_KEYS = ("kind", "x", "y", "file", "title", "logy")
SEED = "seed"


@dataclass(frozen=True)
class FigureSpec:
    """One ``[[figures]]`` table: ``y`` against ``x``, one line per variant and formulation."""

    kind: str
    x: str
    y: str
    file: str
    title: str | None = None
    logy: bool = True


@dataclass(frozen=True)
class SweepCase:
    """One case of a sweep: its swept values and its resolved parameters."""

    id: str
    index: int
    params: dict
    doc: dict
    generate: dict | None


class CaseGrid(Sequence):
    """The cases of a sweep, in grid order (seeds innermost), computed on demand from their index.

    A sequence (``len``, indexing, iteration) that holds only the grid: case ``k`` is built when
    it is asked for (its document, generator and id), so a large grid costs no memory.
    """

    def __init__(self, grid: tuple[tuple[str, tuple], ...], seeds: tuple[int, ...] | None, base_doc: dict,
                 generate: dict | None, variants: tuple[str, ...] | None,
                 formulations: tuple[str, ...] | None) -> None:
        self.grid, self.seeds, self.base_doc, self.generate = grid, seeds, base_doc, generate
        self.variants, self.formulations = variants, formulations
        self._sizes = [len(values) for _, values in grid]
        self._n_seeds = len(seeds) if seeds is not None else 1
        self._len = math.prod(self._sizes) * self._n_seeds

    def __len__(self) -> int:
        return self._len

    def combination(self, index: int) -> tuple[tuple, int | None]:
        """The grid values and the seed of case ``index``."""
        rest, s = divmod(index, self._n_seeds)
        combo = []
        for size, (_, values) in zip(reversed(self._sizes), reversed(self.grid)):
            rest, k = divmod(rest, size)
            combo.append(values[k])
        return tuple(reversed(combo)), (self.seeds[s] if self.seeds is not None else None)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[k] for k in range(*index.indices(self._len))]
        if not isinstance(index, int) or isinstance(index, bool):
            raise TypeError(f"case indices are integers, got {index!r}")
        k = index + self._len if index < 0 else index
        if not 0 <= k < self._len:
            raise IndexError(f"case index {index} out of range ({self._len} cases)")
        combo, seed = self.combination(k)
        return _make_case(k, combo, seed, self.grid, self.base_doc, self.generate, self.variants, self.formulations)

    def __iter__(self) -> Iterator[SweepCase]:
        for k in range(self._len):
            yield self[k]


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep specification with its cases, in grid order (seeds innermost)."""

    path: Path
    document: dict
    base: Path
    grid: tuple[tuple[str, tuple], ...]
    seeds: tuple[int, ...] | None
    variants: tuple[str, ...] | None
    formulations: tuple[str, ...] | None
    figures: tuple[FigureSpec, ...]
    cases: CaseGrid = field(repr=False)

    @property
    def columns(self) -> list[str]:
        """The swept parameters: the grid keys, then ``seed`` when the spec has seeds."""
        return [k for k, _ in self.grid] + ([SEED] if self.seeds is not None else [])


def flatten(table: dict, prefix: str = "") -> list[tuple[str, Any]]:
    """``{a: {b: v}}`` as ``[("a.b", v)]``: nested tables (unquoted dotted keys) become dotted keys."""
    out = []
    for key, value in table.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.extend(flatten(value, name + "."))
        else:
            out.append((name, value))
    return out


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def case_id(doc: dict, generate: dict | None, variants, formulations) -> str:
    """The hash that names a case: SHA-256 of its resolved parameters (16 hex digits)."""
    resolved = dict(case=doc, generate=generate, variants=variants, formulations=formulations)
    return hashlib.sha256(_canonical(resolved).encode()).hexdigest()[:16]


def _names(spec: dict, key: str, known: list[str] | tuple[str, ...]) -> tuple[str, ...] | None:
    if key not in spec:
        return None
    value = spec[key]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise InputError(f"{key} must be a non-empty list of names, got {value!r}")
    for v in value:
        if v not in known:
            raise InputError(f"unknown {key[:-1]} {v!r} in the spec; choose from {', '.join(known)}")
    return tuple(dict.fromkeys(value))


def _seeds(value: Any) -> tuple[int, ...]:
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 1:
            raise InputError(f"seeds must be a positive count or a list of seeds, got {value!r}")
        return tuple(range(value))
    if (not isinstance(value, list) or not value
            or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value)):
        raise InputError(f"seeds must be a positive count or a non-empty list of integers >= 0, got {value!r}")
    if len(set(value)) != len(value):
        raise InputError("seeds lists a seed twice")
    return tuple(value)


def _grid(table: Any, has_generate: bool) -> tuple[tuple[str, tuple], ...]:
    if not isinstance(table, dict):
        raise InputError("[grid] must be a table of dotted keys to lists of values")
    grid = []
    for key, values in flatten(table):
        split_key(key, what="grid key")
        if key == SEED or key == f"generate.{SEED}":
            raise InputError(f"grid key {key!r}: give the seeds with seeds = N or seeds = [...]")
        if key.startswith("generate.") and not has_generate:
            raise InputError(f"grid key {key!r} needs a [generate] table in the spec")
        if not isinstance(values, list) or not values:
            raise InputError(f"grid key {key!r} must be a non-empty list of values, got {values!r}")
        if len({_canonical(v) for v in values}) != len(values):
            raise InputError(f"grid key {key!r} lists a value twice")
        grid.append((key, tuple(values)))
    keys = [k for k, _ in grid]
    for a in keys:
        for b in keys:
            if a != b and b.startswith(a + "."):
                raise InputError(f"grid keys {a!r} and {b!r} overlap")
    return tuple(grid)


def _figures(value: Any, columns: list[str]) -> tuple[FigureSpec, ...]:
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise InputError("[[figures]] must be an array of tables")
    out = []
    for k, fig in enumerate(value):
        where = f"figures {k}"
        unknown = sorted(set(fig) - set(FIGURE_KEYS))
        if unknown:
            raise InputError(f"unknown key {unknown[0]!r} in [{where}]; known: {', '.join(FIGURE_KEYS)}")
        for key in ("kind", "x", "y"):
            if key not in fig:
                raise InputError(f"missing key {key!r} in [{where}]")
        if fig["kind"] not in FIGURE_KINDS:
            raise InputError(f"[{where}] kind must be one of {', '.join(FIGURE_KINDS)}, got {fig['kind']!r}")
        if fig["x"] not in columns:
            raise InputError(f"[{where}] x must be a swept parameter ({', '.join(columns)}), got {fig['x']!r}")
        if fig["y"] not in METRICS:
            raise InputError(f"[{where}] y must be a metric of sweep.csv ({', '.join(METRICS)}), got {fig['y']!r}")
        name = fig.get("file", f"{fig['kind']}_{fig['y']}_vs_{fig['x'].replace('.', '_')}.png")
        if not isinstance(name, str) or not name.endswith(".png") or Path(name).name != name:
            raise InputError(f"[{where}] file must be a file name ending in .png, got {name!r}")
        logy = fig.get("logy", True)
        if not isinstance(logy, bool):
            raise InputError(f"[{where}] logy must be true or false, got {logy!r}")
        title = fig.get("title")
        if title is not None and not isinstance(title, str):
            raise InputError(f"[{where}] title must be a string, got {title!r}")
        out.append(FigureSpec(kind=fig["kind"], x=fig["x"], y=fig["y"], file=name, title=title, logy=logy))
    if len({f.file for f in out}) != len(out):
        raise InputError("[[figures]] name the same file twice")
    return tuple(out)


#: The most cases a spec may have without ``max_cases`` (``ddcm-sweep --max-cases``): every case
#: is validated before the sweep starts, and a grid this large is more often a typo.
MAX_CASES = 10_000


def case_count(grid: tuple[tuple[str, tuple], ...], seeds: tuple[int, ...] | None) -> int:
    """The number of cases of a grid and seeds, without expanding them."""
    return math.prod(len(values) for _, values in grid) * (len(seeds) if seeds is not None else 1)


def load_spec(path: str | Path, *, check: bool = True, max_cases: int | None = None) -> SweepSpec:
    """Read and validate a sweep spec and expand its cases.

    Parameters
    ----------
    path : str or Path
        The spec (``.toml`` or ``.json``); ``base`` is relative to its folder.
    check : bool
        Validate every case before any work (:func:`validate_cases`): its overrides and generator,
        and every distinct case built in full (data and model), so that the case file's own
        validation runs. Without it the cases are only counted (they are built when asked for).
    max_cases : int, optional
        The most cases (default :data:`MAX_CASES`); a larger grid is refused before any case is
        built.

    Raises
    ------
    InputError
        Missing or malformed spec, unknown key, empty grid, missing base case, or a key or value
        that cannot be applied, more cases than ``max_cases``, a case that its case file would
        refuse (one line, naming the case).
    """
    path = input_file(path, "sweep spec")
    spec = read_document(path)
    unknown = sorted(set(spec) - set(SPEC_KEYS))
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} in the sweep spec {path}; known: {', '.join(SPEC_KEYS)}")
    if "base" not in spec:
        raise InputError(f"the sweep spec {path} needs base = \"CASE.toml\" (the base case, relative to the spec)")
    if not isinstance(spec["base"], str) or not spec["base"]:
        raise InputError(f"base must be the path of a case file, got {spec['base']!r}")
    base = input_file(path.parent / spec["base"], "base case")
    base_doc = read_document(base)

    variants = _names(spec, "variants", VARIANTS)
    formulations = _names(spec, "formulations", registry.available())
    fixed = spec.get("set", {})
    if not isinstance(fixed, dict):
        raise InputError("[set] must be a table of dotted keys to values")
    base_doc = apply_overrides(base_doc, flatten(fixed), what="[set]")
    generate = spec.get("generate")
    if generate is not None and not isinstance(generate, dict):
        raise InputError("[generate] must be a table")
    grid = _grid(spec.get("grid", {}), generate is not None)
    seeds = None
    if "seeds" in spec:
        if generate is None:
            raise InputError("seeds need a [generate] table in the spec (the seeds of the generated data)")
        seeds = _seeds(spec["seeds"])
    if not grid and seeds is None:
        raise InputError(f"empty grid in {path}: [grid] needs at least one dotted key with a list of values "
                         "(or give seeds)")
    count, limit = case_count(grid, seeds), MAX_CASES if max_cases is None else int(max_cases)
    if count > limit:
        raise InputError(f"the sweep spec {path} has {count} cases, more than {limit}; pass --max-cases {count} "
                         "to run them all (or use a coarser grid)")
    cases = CaseGrid(grid, seeds, base_doc, generate, variants, formulations)
    columns = [k for k, _ in grid] + ([SEED] if seeds is not None else [])
    figures = _figures(spec.get("figures", []), columns)
    out = SweepSpec(path=path, document=spec, base=base, grid=grid, seeds=seeds, variants=variants,
                    formulations=formulations, figures=figures, cases=cases)
    if check:
        validate_cases(out)
    return out


def describe_case(case: SweepCase) -> str:
    """How a message names a case: its number and its swept values."""
    values = ", ".join(f"{k} = {_canonical(v)}" for k, v in case.params.items())
    return f"case {case.index + 1}" + (f" ({values})" if values else "")


def validate_cases(spec: SweepSpec) -> int:
    """Check every case of ``spec`` before any work; returns how many distinct cases were built.

    Every case's overrides and generator are applied, and every distinct case (its document and
    its generator without the seed: a seed changes only the drawn data) is built in full as a
    case file (:func:`build_case`), so a value its case file refuses is refused here, whatever
    its place in the grid.

    Raises
    ------
    InputError
        The first case that cannot be built, named (:func:`describe_case`), with its reason.
    """
    built: set[str] = set()
    grid = spec.cases
    for k in range(len(grid)):
        combo, seed = grid.combination(k)
        if seed is not None and spec.seeds is not None and seed != spec.seeds[0]:
            continue  # the same document and generator as the first seed's case, checked there
        try:
            case = grid[k]
        except DDCMError as exc:
            raise InputError(f"{_name(k, combo, seed, spec)}: {one_line(exc)}") from None
        key = _canonical([case.doc, {n: v for n, v in (case.generate or {}).items() if n != SEED}])
        if key in built:
            continue
        try:
            build_case(case, spec)
        except DDCMError as exc:
            raise InputError(f"{describe_case(case)}: {one_line(exc)}") from None
        built.add(key)
    return len(built)


def _name(index: int, combo: tuple, seed: int | None, spec: SweepSpec) -> str:
    pairs = [(k, v) for (k, _), v in zip(spec.grid, combo)] + ([(SEED, seed)] if seed is not None else [])
    values = ", ".join(f"{k} = {_canonical(v)}" for k, v in pairs)
    return f"case {index + 1}" + (f" ({values})" if values else "")


def _make_case(index: int, combo: tuple, seed: int | None, grid, base_doc, generate, variants,
               formulations) -> SweepCase:
    params = dict(zip((k for k, _ in grid), combo))
    doc = apply_overrides(base_doc, [(k, v) for k, v in params.items() if not k.startswith("generate.")],
                          what="grid key")
    gen = None
    if generate is not None:
        table = apply_overrides(generate, [(k[len("generate."):], v) for k, v in params.items()
                                           if k.startswith("generate.")], what="grid key generate")
        if seed is not None:
            table[SEED] = seed
            params[SEED] = seed
        gen = generator_from_dict(table, doc).describe()
    cid = case_id(doc, gen, list(variants) if variants else None, list(formulations) if formulations else None)
    return SweepCase(id=cid, index=index, params=params, doc=doc, generate=gen)


def build_case(case: SweepCase, spec_or_base: SweepSpec | Path):
    """The :class:`~ddcm_casadi.casefiles.base.Case` of a sweep case: generated data written to a
    temporary CSV file, then the document validated and built exactly as a case file."""
    base = spec_or_base.base if isinstance(spec_or_base, SweepSpec) else Path(spec_or_base)
    doc = case.doc
    with tempfile.TemporaryDirectory(prefix="ddcm-sweep-") as tmp:
        if case.generate is None:
            return case_from_dict(doc, base_dir=base.parent, source=str(base))
        gen = DataGenerator(**case.generate)
        csv = gen.write_csv(Path(tmp) / "data.csv")
        doc = attach(doc, gen, csv)
        try:
            # The data are read eagerly, so the temporary file may go once the case is built.
            return case_from_dict(doc, base_dir=base.parent, source=str(base))
        except InputError as exc:  # a message names the generated data, not a file that is gone
            raise InputError(one_line(exc).replace(f"data file {csv}", "the generated data ([generate])")
                             .replace(str(csv), "the generated data ([generate])")) from None

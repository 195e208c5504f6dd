"""Material data generated for studies: a law, a strain range, a size, noise and a seed.

A sweep's ``[generate]`` table describes one data set of the base case, regenerated for every
case (so a noise Monte Carlo or a data-size study needs no files):

- ``law``: ``"hookean"`` (``stress = E strain``), ``"tanh"`` (``stress = s tanh(E strain / s)``,
  saturating at the stress scale ``s = stress_scale``) or ``"cubic"``
  (``stress = E strain (1 + beta strain^2)``); ``youngs_modulus`` ``E`` is the initial tangent;
- ``strain_min``, ``strain_max``, ``points``: the strain range and the size ``n``;
  ``sampling = "grid"`` (equally spaced, as the paper's data) or ``"random"`` (uniform, sorted);
- ``noise`` ``eta >= 0`` and ``noise_kind``: ``"multiplicative"`` (``stress_i = stress(strain_i)
  (1 + eta xi_i)``) or ``"additive"`` (``stress_i = stress(strain_i) + eta S xi_i``, ``S`` the
  largest ``|stress|`` of the noiseless data), ``xi_i`` independent standard normal draws;
  ``noise_on = "both"`` perturbs the strains the same way (additive: scaled by the largest
  ``|strain|`` of the range);
- ``seed``: the seed of the draws (``numpy.random.default_rng``); the same seed gives the same data;
- ``table``: which ``[[data]]`` table of the case is replaced (default 0); its metric ``c`` is kept.

Missing ``strain_min``, ``strain_max``, ``points`` and ``youngs_modulus`` are taken from that
table's ``hookean`` entry when it has one. The data reach the case as a CSV file (written to a
temporary folder on the worker, read back by the case file's own ``path`` reader), so they are
validated exactly as any data file.

A continuum case (one with a ``[mesh]``) gets Mandel data, ``k = 3`` components in plane strain
and 6 in 3-D (the dimension of its generated shape, or ``components`` for a mesh file): the
isotropic Hookean law ``stress = C(E, nu) strain`` (``law = "hookean"`` only) on the grid of
``points^k`` strains (``grading`` as in ``[data] hookean``, denser towards zero) or ``points^k``
uniform samples, noise on every component as above. ``poisson_ratio`` and ``grading`` default to
the table's ``hookean`` entry, then to ``[material]``.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ddcm_casadi.casefiles.common import HOOKEAN_KEYS, integer, number, positive
from ddcm_casadi.data.dataset import graded_axis
from ddcm_casadi.data.limits import MAX_DATA_POINTS
from ddcm_casadi.data.metric import isotropic_elasticity
from ddcm_casadi.errors import InputError

LAWS = ("hookean", "tanh", "cubic")
SAMPLINGS = ("grid", "random")
NOISE_KINDS = ("multiplicative", "additive")
NOISE_ON = ("stress", "both")
#: Keys of ``[generate]``.
KEYS = ("law", "youngs_modulus", "strain_min", "strain_max", "points", "sampling", "noise", "noise_kind",
        "noise_on", "seed", "stress_scale", "beta", "table", "components", "poisson_ratio", "grading")
#: Mandel components of a continuum's data by the dimension of its generated shape.
_SHAPE_COMPONENTS = {"rectangle": 3, "disc": 3, "half_disc": 3, "box": 6, "ball": 6}
_FROM_HOOKEAN = tuple(sorted(HOOKEAN_KEYS))


@dataclass(frozen=True)
class DataGenerator:
    """A validated ``[generate]`` table (see the module docstring for the meaning of each field)."""

    law: str
    youngs_modulus: float
    strain_min: float
    strain_max: float
    points: int
    sampling: str = "grid"
    noise: float = 0.0
    noise_kind: str = "multiplicative"
    noise_on: str = "stress"
    seed: int = 0
    stress_scale: float | None = None
    beta: float | None = None
    table: int = 0
    components: int = 1
    poisson_ratio: float | None = None
    grading: float = 1.0

    def _stiffness(self) -> np.ndarray:
        """``C``: ``E`` for one component, the isotropic Mandel matrix for 3 or 6."""
        if self.components == 1:
            return np.array([[self.youngs_modulus]])
        return isotropic_elasticity(self.youngs_modulus, self.poisson_ratio, {3: 2, 6: 3}[self.components])[0]

    def law_stress(self, strain: np.ndarray) -> np.ndarray:
        """The noiseless stress of the law at ``strain``."""
        E = self.youngs_modulus
        if self.law == "tanh":
            return self.stress_scale * np.tanh(E * strain / self.stress_scale)
        if self.law == "cubic":
            return E * strain * (1.0 + self.beta * strain**2)
        return E * strain

    def sample(self) -> tuple[np.ndarray, np.ndarray]:
        """The data ``(strain, stress)``: sampled strains, the law, then the noise (``points``
        values, or ``points^k`` rows of ``k`` Mandel components for a continuum)."""
        if self.components > 1:
            return self._sample_mandel()
        rng = np.random.default_rng(self.seed)
        n = self.points
        if self.sampling == "random":
            strain = np.sort(rng.uniform(self.strain_min, self.strain_max, n))
        else:
            strain = np.linspace(self.strain_min, self.strain_max, n)
        return self._noisy(rng, strain, self.law_stress(strain))

    def _sample_mandel(self) -> tuple[np.ndarray, np.ndarray]:
        rng = np.random.default_rng(self.seed)
        k, n = self.components, self.points
        if self.sampling == "random":
            strain = rng.uniform(self.strain_min, self.strain_max, (n**k, k))
        else:
            axis = graded_axis(self.strain_min, self.strain_max, n, self.grading)
            strain = np.stack(np.meshgrid(*([axis] * k), indexing="ij"), axis=-1).reshape(-1, k)
        return self._noisy(rng, strain, strain @ self._stiffness().T)

    def _noisy(self, rng, strain: np.ndarray, stress: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noise on the stresses (and the strains with ``noise_on = "both"``), every component."""
        if self.noise > 0:
            stress_scale = float(np.max(np.abs(stress))) or 1.0
            stress = self._perturb(stress, rng.standard_normal(stress.shape), stress_scale)
            if self.noise_on == "both":
                strain_scale = max(abs(self.strain_min), abs(self.strain_max)) or 1.0
                strain = self._perturb(strain, rng.standard_normal(strain.shape), strain_scale)
        return strain, stress

    def _perturb(self, values: np.ndarray, xi: np.ndarray, scale: float) -> np.ndarray:
        if self.noise_kind == "additive":
            return values + self.noise * scale * xi
        return values * (1.0 + self.noise * xi)

    def write_csv(self, path: Path) -> Path:
        """The data as a CSV file with header ``strain,stress`` (``strain_1..k,stress_1..k`` for
        Mandel data; 17 significant digits: exact)."""
        strain, stress = self.sample()
        k = self.components
        header = "strain,stress" if k == 1 else ",".join([f"strain_{i}" for i in range(1, k + 1)]
                                                          + [f"stress_{i}" for i in range(1, k + 1)])
        np.savetxt(path, np.column_stack([strain, stress]), delimiter=",", header=header, comments="", fmt="%.17g")
        return path

    def describe(self) -> dict:
        """The resolved fields (for hashing and ``case.json``)."""
        return asdict(self)


def _choice(key: str, value: Any, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise InputError(f"[generate] {key} must be one of {', '.join(choices)}, got {value!r}")
    return value


def data_table(doc: dict, index: int) -> dict | None:
    """Table ``index`` of the case's ``[data]`` / ``[[data]]`` (``None`` if there is no such table)."""
    data = doc.get("data")
    tables = data if isinstance(data, list) else [data] if isinstance(data, dict) else []
    return tables[index] if 0 <= index < len(tables) and isinstance(tables[index], dict) else None


def generator_from_dict(table: Any, case_doc: dict) -> DataGenerator:
    """Validate a ``[generate]`` table against the case document it will feed.

    Parameters
    ----------
    table : dict
        The ``[generate]`` table with the case's grid values applied.
    case_doc : dict
        The case document (for the defaults of the ``hookean`` entry of the target table).

    Raises
    ------
    InputError
        Unknown key, missing or invalid value (one line, naming the key).
    """
    if not isinstance(table, dict):
        raise InputError("[generate] must be a table")
    unknown = sorted(set(table) - set(KEYS))
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} in [generate]; known: {', '.join(sorted(KEYS))}")
    g = dict(table)
    index = integer("generate", "table", g.get("table", 0), low=0)
    target = data_table(case_doc, index)
    if target is None and index > 0:
        raise InputError(f"[generate] table = {index}, but the case has no data table {index}")
    hookean = target.get("hookean") if target is not None else None
    for key in _FROM_HOOKEAN:
        if key not in g and isinstance(hookean, dict) and key in hookean:
            g[key] = hookean[key]
    material = case_doc.get("material")
    if "youngs_modulus" not in g and isinstance(material, dict) and "youngs_modulus" in material:
        g["youngs_modulus"] = material["youngs_modulus"]  # a continuum's [material]
    missing = [k for k in _FROM_HOOKEAN if k not in g]
    if missing:
        raise InputError(f"missing key {missing[0]!r} in [generate] (and in the case's data hookean table)")
    law = _choice("law", g.get("law", "hookean"), LAWS)
    E = positive("generate", "youngs_modulus", g["youngs_modulus"])
    lo, hi = number("generate", "strain_min", g["strain_min"]), number("generate", "strain_max", g["strain_max"])
    if lo > hi:
        raise InputError(f"[generate] strain_min must be <= strain_max, got [{lo}, {hi}]")
    points = g["points"]
    if isinstance(points, float) and points.is_integer():
        points = int(points)  # 1e5 in a grid of sizes
    points = integer("generate", "points", points, low=1, high=MAX_DATA_POINTS)
    noise = number("generate", "noise", g.get("noise", 0.0))
    if noise < 0:
        raise InputError(f"[generate] noise must be >= 0, got {g['noise']!r}")
    stress_scale = beta = None
    if law == "tanh":
        if "stress_scale" not in g:
            raise InputError("[generate] law = \"tanh\" needs stress_scale (Pa)")
        stress_scale = positive("generate", "stress_scale", g["stress_scale"])
    if law == "cubic":
        if "beta" not in g:
            raise InputError("[generate] law = \"cubic\" needs beta")
        beta = number("generate", "beta", g["beta"])
    for key, needed_by in (("stress_scale", "tanh"), ("beta", "cubic")):
        if key in g and law != needed_by:
            raise InputError(f"[generate] {key} applies to law = \"{needed_by}\" only, the law is {law!r}")
    mandel = _mandel_fields(g, case_doc, hookean, law, points)
    return DataGenerator(**mandel,law=law, youngs_modulus=E, strain_min=lo, strain_max=hi, points=points,
                         sampling=_choice("sampling", g.get("sampling", "grid"), SAMPLINGS), noise=noise,
                         noise_kind=_choice("noise_kind", g.get("noise_kind", "multiplicative"), NOISE_KINDS),
                         noise_on=_choice("noise_on", g.get("noise_on", "stress"), NOISE_ON),
                         seed=integer("generate", "seed", g.get("seed", 0), low=0), stress_scale=stress_scale, beta=beta,
                         table=index)


def attach(case_doc: dict, generator: DataGenerator, csv_path: Path) -> dict:
    """A copy of ``case_doc`` whose target data table reads ``csv_path`` (its metric ``c`` kept)."""
    doc = copy.deepcopy(case_doc)
    table = {"path": str(csv_path)}
    old = data_table(doc, generator.table)
    if old is not None and "c" in old:
        table["c"] = old["c"]
    if isinstance(doc.get("data"), list):
        doc["data"][generator.table] = table
    else:
        doc["data"] = table
    return doc


def _mandel_fields(g: dict, case_doc: dict, hookean: dict | None, law: str, points: int) -> dict:
    """``components``, ``poisson_ratio`` and ``grading`` of the data of a continuum case (empty for
    a bar or a truss: one component)."""
    mesh = case_doc.get("mesh")
    if not isinstance(mesh, dict):
        for key in ("components", "poisson_ratio", "grading"):
            if key in g:
                raise InputError(f"[generate] {key} applies to continuum cases ([mesh]) only")
        return {}
    if "components" in g:
        k = integer("generate", "components", g["components"], low=3, high=6)
        if k not in (3, 6):
            raise InputError(f"[generate] components must be 3 (plane strain) or 6 (3-D), got {k}")
    elif mesh.get("shape") in _SHAPE_COMPONENTS:
        k = _SHAPE_COMPONENTS[mesh["shape"]]
    else:
        raise InputError("[generate] on a mesh file needs components = 3 (plane strain) or 6 (3-D)")
    if law != "hookean":
        raise InputError(f"[generate] law = {law!r} makes one-component data; a continuum's Mandel data use "
                         "law = \"hookean\" (the isotropic law of youngs_modulus and poisson_ratio)")
    material = case_doc.get("material") if isinstance(case_doc.get("material"), dict) else {}
    hk = hookean if isinstance(hookean, dict) else {}
    nu = g.get("poisson_ratio", hk.get("poisson_ratio", material.get("poisson_ratio")))
    if nu is None:
        raise InputError("[generate] needs poisson_ratio (or the case's hookean or [material] one) for Mandel data")
    nu = number("generate", "poisson_ratio", nu)
    if not -1.0 < nu < 0.5:
        raise InputError(f"[generate] poisson_ratio must be in (-1, 0.5), got {nu!r}")
    grading = number("generate", "grading", g.get("grading", hk.get("grading", 1.0)))
    graded_axis(0.0, 1.0, 2, grading)  # checks the range of grading
    if float(points) ** k > MAX_DATA_POINTS:
        raise InputError(f"[generate] points = {points} makes {points}^{k} Mandel data points, more than "
                         f"{MAX_DATA_POINTS}")
    return dict(components=k, poisson_ratio=nu, grading=float(grading))

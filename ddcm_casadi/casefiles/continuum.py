"""The ``[mesh]`` case files: continua pressed against rigid obstacles (registered case kind)."""

from __future__ import annotations

import logging
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ddcm_casadi.casefiles import common as casefile
from ddcm_casadi.casefiles.base import Case, register_case_kind
from ddcm_casadi.casefiles.common import integer, nonempty_list, number, positive, show, vector
from ddcm_casadi.data import hyperelastic
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.errors import InputError, PhysicsWarning
from ddcm_casadi.data.metric import COMPONENTS, Metric, isotropic_elasticity
from ddcm_casadi.models.continuum.hertz import BodyHertzReference, HertzReference
from ddcm_casadi.models.continuum.obstacles import Ball, Cylinder, FlatPunch, Plane, moving

# scikit-fem and meshio are imported when a [mesh] case is parsed, not when the kind registers:
# the paper's example does not pay for them.

#: The ``[mesh]`` case-file format (also part of :mod:`ddcm_casadi.casefiles.config`'s documentation).
CASE_FORMAT = """
Continua
--------
::

    [mesh]                       # a generated shape, or path = "body.msh" (.msh, .vtu, .xdmf)
    shape = "rectangle"          # rectangle, box, disc, half_disc, ball
    size = [0.02, 0.01]          # rectangle/box: the edge lengths (m)
    divisions = [8, 4]           # rectangle/box: elements per edge
    origin = [0.0, -0.01]        # rectangle/box: the lower corner (default 0)
    # radius = 0.01, center = [0, 0], refine = 3          (disc, half_disc, ball)
    refine_near = { point = [0.0, 0.0], radius = 0.004, levels = 4 }   # optional grading: the
                                 # radius shrinks by shrink (0.5) per level, plus buffer elements
    degree = 1                   # Lagrange elements: 1 (P1) or 2 (P2; no contact on P2 tetrahedra)
    symmetry_factor = 1          # the full body's force over the modelled part's (a half: 2, a
                                 # quarter: 4): the full-body forces of the results and Hertz's

    [material]                   # or [[material]] tables with region = "<subdomain name>"
    youngs_modulus = 200e9       # Pa; with poisson_ratio the classical law (optional if DDCM only)
    poisson_ratio = 0.3
    law = "linear"               # small kinematics; with the top-level kinematics = "finite":
                                 # "saint_venant_kirchhoff" or "neo_hookean" (docs/maths.md)
    data = 0                     # optional: the [[data]] set of this material (default 0 if data)

    [[supports]]                 # fixed displacement components on a boundary
    boundary = "ymin"            # generated shapes: xmin, xmax, ymin, ymax (zmin, zmax); arc, flat; surface
    fix = "xy"                   # mesh files: a Gmsh physical group's name, or its tag (boundary = 3),
                                 # or by position: boundary = { min = [x0, y0], max = [x1, y1] } (a box)
                                 # or { point = [..], normal = [..], tolerance = 1e-9 } (a plane);
                                 # docs/meshes.md
    # displacement = [1e-4, 0.0] # optional: a hard device: the fixed components move by this (m),
                                 # scaled by the load factors, or one vector per step
                                 # ([[0, 0], [1e-4, 0], ...]); 0 along components not fixed

    [[loads]]                    # optional, scaled by [loading] load_factors
    boundary = "ymax"            # a traction (Pa) on a boundary, or
    traction = [0.0, -1e6]       # body_force = [0, -8e4] (N/m^3) with optional region = "..."

    # several bodies instead of one shape: [mesh] keeps degree, each [[mesh.body]] table takes
    # the keys above plus name; its boundaries are then "<name>/<boundary>", its region "<name>"
    # [[mesh.body]]
    # name = "cylinder"
    # shape = "quarter_disc"     # also: ball_octant (signs = [1, 1, -1]: the octant)

    [[contact]]                  # a rigid obstacle and the boundary that may touch it
    boundary = "ymax"
    obstacle = "circle"          # plane, circle (2-D), sphere (3-D), cylinder (3-D), punch
    radius = 0.05                # circle/sphere/cylinder; center = [..] (circle/sphere)
    center = [0.0, 0.05]         # plane: point, normal; cylinder: point, axis;
                                 # punch: center (of its face), normal, half_width, edge_radius
    direction = [0.0, -1.0]      # direction of travel
    travel = [0.0, 1e-5, 2e-5]   # m, one value per step (or one number: standing still)
    # motion = [[0.0, -1e-5], [2e-6, -1e-5]]   # or any path: the displacement per step
    # friction = 0.3             # Coulomb friction (mu >= 0; absent: frictionless)

    # [[contact]]                # or two bodies: mortar pairs of the slave's nodes against the
    # slave = "cylinder/arc"     # master's facets (P1; choose as slave the surface that stays
    # master = "block/ymax"      # within the other), found within search_distance (m; default
    # search_distance = 0.01     # 5 % of the size) at the reference configuration

    [loading]
    load_factors = [0.0, 1.0]    # optional: one per step (default: loads in full)

    [hertz]                      # optional: validate against Hertz (one isotropic material)
    obstacle = 0                 # the [[contact]] table of the indenter
                                 # (its force is the full body's: [mesh] symmetry_factor; an older
                                 # force_factor here must equal it)
    # contact = 0               # or two round bodies: the [[contact]] between them and
    # radius = 0.05              # R* (1/R* = 1/R1 + 1/R2); E* from the two sides' materials
    # direction = [0.0, -1.0]    # the line of centres, slave to master (default: the normal of
                                 # the first point of contact; give it on a symmetry plane)

    [data]                       # strain_1..k,stress_1..k CSV (Mandel: k = 3 in 2-D, 6 in 3-D),
    hookean = { strain_min = -0.01, strain_max = 0.01, points = 21 }    # or a linear law on a
    # law = "neo_hookean"        # or (E, S) pairs of a hyperelastic law (Green-Lagrange strain,
    # grid = { strain_min = -0.3, strain_max = 0.3, points = 21 }   # second Piola-Kirchhoff
    # samples = { strain_min = -0.3, strain_max = 0.3, count = 10000, seed = 0 }   # stress;
    #                            the range bounds the principal strains)
    c = "isotropic"              # grid of points^k states (grading = 2: denser towards zero);
                                 # c: "isotropic" (from the material),
                                 # "estimated" (from the data), a number (c I) or a k x k matrix

Strains and stresses are in Mandel notation: 2-D ``[e11, e22, sqrt(2) e12]``, 3-D ``[e11, e22,
e33, sqrt(2) e23, sqrt(2) e13, sqrt(2) e12]``. The result is
:func:`~ddcm_casadi.models.continuum.model.continuum_model`.
"""

#: The logger that announces a large build (``ddcm-compare`` prints its INFO lines unless ``-q``).
BUILD_LOG = logging.getLogger("ddcm_casadi.build")
#: A build of this many displacement or stress unknowns, or data points, takes long enough (tens
#: of seconds and more) to be announced before it starts.
ANNOUNCE_UNKNOWNS = 20_000
ANNOUNCE_DATA_POINTS = 200_000
#: Share of the machine's physical memory above which a case is warned about (it may swap, or
#: not fit beside other programs); above all of it, it is refused.
MEMORY_WARNING_SHARE = 0.5

_MESH = {"shape", "size", "divisions", "origin", "radius", "center", "refine", "path", "degree", "refine_near",
         "signs", "body", "symmetry_factor"}
#: The [mesh] keys of the whole model, not of one body.
_WHOLE_MESH = {"degree", "body", "symmetry_factor"}
_HOOKEAN = {"strain_min", "strain_max", "points", "youngs_modulus", "poisson_ratio", "grading"}
_GRID = _HOOKEAN
_SAMPLES = {"strain_min", "strain_max", "count", "seed", "youngs_modulus", "poisson_ratio"}
_SHAPES = ("rectangle", "box", "disc", "half_disc", "quarter_disc", "ball", "ball_octant")
_OBSTACLES = ("plane", "circle", "sphere", "cylinder", "punch")


def _symmetry_factor(doc: dict) -> float:
    """``[mesh] symmetry_factor`` (default 1), the one symmetry setting of a case: ``[hertz]
    force_factor`` (its older place) is taken when it is alone and must equal it when both are given."""
    given = {}
    if "symmetry_factor" in doc["mesh"]:
        given["[mesh] symmetry_factor"] = number("mesh", "symmetry_factor", doc["mesh"]["symmetry_factor"])
    if "force_factor" in doc.get("hertz", {}):
        given["[hertz] force_factor"] = number("hertz", "force_factor", doc["hertz"]["force_factor"])
    values = set(given.values())
    if len(values) > 1:
        raise InputError(f"{' and '.join(f'{k} = {v:g}' for k, v in given.items())} differ: give one symmetry "
                         "factor, [mesh] symmetry_factor")
    factor = values.pop() if values else 1.0
    if not factor >= 1:
        raise InputError(f"{next(iter(given))} must be >= 1 (the full body's force over the modelled part's: "
                         f"a half 2, a quarter 4), got {factor:g}")
    return factor


def _keys(label: str, table: dict, known: set) -> None:
    unknown = sorted(set(table) - known)
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} in [{label}]; known: {', '.join(sorted(known))}")


def _shape_mesh(doc: dict, base_dir: Path):
    """The mesh of ``[mesh]`` and its element degree: one shape or file, or the bodies of
    ``[[mesh.body]]`` tables joined (:func:`~ddcm_casadi.models.continuum.bodies.join`)."""
    m = doc["mesh"]
    if "body" in m:
        from ddcm_casadi.models.continuum.bodies import join

        extra = sorted(set(m) & (_MESH - _WHOLE_MESH))
        if extra:
            raise InputError(f"[mesh] with [[mesh.body]] tables takes only {', '.join(sorted(_WHOLE_MESH - {'body'}))}; "
                             f"{extra[0]!r} goes in a body")
        bodies = {}
        for i, table in enumerate(_tables(m, "body")):
            label = f"mesh.body {i}"
            if not isinstance(table, dict):
                raise InputError(f"[{label}] must be a table")
            _keys(label, table, (_MESH - _WHOLE_MESH) | {"name"})
            name = table.get("name")
            if not isinstance(name, str) or not name or name in bodies:
                raise InputError(f"[{label}] needs a unique 'name' (a string), got {show(name)}")
            bodies[name] = _one_mesh(label, table, base_dir)
        mesh = join(bodies)
    else:
        mesh = _one_mesh("mesh", m, base_dir)
    degree = m.get("degree", 1)
    if isinstance(degree, bool) or not isinstance(degree, int) or degree not in (1, 2):
        raise InputError(f"[mesh] degree must be 1 (P1) or 2 (P2), got {show(degree)}")
    return mesh, degree


def _one_mesh(label: str, m: dict, base_dir: Path):
    """One generated shape or mesh file, graded by ``refine_near`` if asked."""
    from ddcm_casadi.models.continuum import mesh as meshes

    if ("path" in m) == ("shape" in m):
        raise InputError(f"[{label}] needs exactly one of 'shape' or 'path'")
    if "path" in m:
        if not isinstance(m["path"], str):
            raise InputError(f"[{label}] path must be a string, got {show(m['path'])}")
        mesh = meshes.read_mesh(base_dir / m["path"])
    else:
        shape = m["shape"]
        if shape not in _SHAPES:
            raise InputError(f"[{label}] shape must be one of {', '.join(_SHAPES)}, got {show(shape)}")
        if shape in ("rectangle", "box"):
            d = 2 if shape == "rectangle" else 3
            for key in ("size", "divisions"):
                if key not in m:
                    raise InputError(f"[{label}] a {shape} needs {key!r}")
            size = [positive(label, "size", v) for v in vector(label, "size", m["size"], d)]
            div = nonempty_list(label, "divisions", m["divisions"])
            if len(div) != d:
                raise InputError(f"[{label}] divisions must be a list of {d} integers, got {show(div)}")
            div = [integer(label, "divisions", v, low=1, high=10**4, what="a positive integer") for v in div]
            origin = vector(label, "origin", m.get("origin", [0.0] * d), d)
            if d == 2:
                mesh = meshes.rectangle(*size, nx=div[0], ny=div[1], origin=tuple(origin))
            else:
                mesh = meshes.box(*size, nx=div[0], ny=div[1], nz=div[2], origin=tuple(origin))
        else:
            d = 3 if shape.startswith("ball") else 2
            if "radius" not in m:
                raise InputError(f"[{label}] a {shape} needs 'radius'")
            if "signs" in m and shape != "ball_octant":
                raise InputError(f"[{label}] signs is for shape = \"ball_octant\" only")
            radius = positive(label, "radius", m["radius"])
            center = vector(label, "center", m.get("center", [0.0] * d), d)
            refine = integer(label, "refine", m.get("refine", 3 if d == 2 else 2), low=0, high=8,
                             what="an integer")
            build = dict(disc=meshes.disc, half_disc=meshes.half_disc, quarter_disc=meshes.quarter_disc,
                         ball=meshes.ball, ball_octant=meshes.ball_octant)[shape]
            extra = {"signs": tuple(vector(label, "signs", m.get("signs", [1, 1, -1]), 3))} if shape == "ball_octant" else {}
            mesh = build(radius, center=tuple(center), refine=refine, **extra)
    if "refine_near" in m:
        r = m["refine_near"]
        if not isinstance(r, dict):
            raise InputError(f"[{label}] refine_near must be a table {{point, radius, levels}}")
        _keys(f"{label}.refine_near", r, {"point", "radius", "levels", "shrink", "buffer"})
        d = mesh.p.shape[0]
        if "point" not in r or "radius" not in r:
            raise InputError(f"[{label}] refine_near needs 'point' and 'radius'")
        point = vector(label, "refine_near.point", r["point"], d)
        radius = positive(label, "refine_near.radius", r["radius"])
        levels = integer(label, "refine_near.levels", r.get("levels", 1), low=1, high=12, what="an integer")
        shrink = number(label, "refine_near.shrink", r.get("shrink", 0.5))
        buffer = number(label, "refine_near.buffer", r.get("buffer", 0.0))
        try:
            mesh = meshes.refine_near(mesh, point, radius, levels=levels, shrink=shrink, buffer=buffer)
        except InputError as err:  # name the table: the function's own message names its argument
            raise InputError(f"[{label}] refine_near: {err}") from None
    return mesh


def _tables(doc: dict, name: str) -> list[dict]:
    value = doc.get(name, [])
    return value if isinstance(value, list) else [value]


def _boundary(label: str, table: dict, d: int):
    """The boundary of a table: a name of the mesh, a Gmsh physical tag (an integer: a group
    without a name is named by its tag), or a geometric test on the boundary facets' midpoints,
    ``{ min = [..], max = [..] }`` (a box, bounds included) or ``{ point = [..], normal = [..] }``
    (a plane, with an optional ``tolerance`` in m): for mesh files without named boundaries."""
    from ddcm_casadi.models.continuum.mesh import FacetBox, FacetPlane

    if "boundary" not in table:
        raise InputError(f"[{label}] needs 'boundary' (a boundary name or tag of the mesh, or a box or plane)")
    b = table["boundary"]
    if isinstance(b, str):
        return b
    if isinstance(b, int) and not isinstance(b, bool):
        return str(b)  # read_mesh names an unnamed Gmsh physical group by its tag
    if isinstance(b, dict):
        if set(b) == {"min", "max"}:
            return FacetBox(tuple(vector(label, "boundary.min", b["min"], d)),
                            tuple(vector(label, "boundary.max", b["max"], d)))
        if set(b) in ({"point", "normal"}, {"point", "normal", "tolerance"}):
            tol = positive(label, "boundary.tolerance", b["tolerance"]) if "tolerance" in b else None
            return FacetPlane(tuple(vector(label, "boundary.point", b["point"], d)),
                              tuple(vector(label, "boundary.normal", b["normal"], d)), tol)
        raise InputError(f"[{label}] boundary as a table is a box {{min, max}} or a plane {{point, normal[, tolerance]}}, "
                         f"got keys {', '.join(sorted(b)) or 'none'}")
    raise InputError(f"[{label}] boundary must be a name, a tag, a box or a plane, got {show(b)}")


def _obstacle(label: str, t: dict, d: int):
    kind = t.get("obstacle")
    if kind not in _OBSTACLES:
        raise InputError(f"[{label}] obstacle must be one of {', '.join(_OBSTACLES)}, got {show(kind)}")
    need = {"plane": ("point", "normal"), "circle": ("center", "radius"), "sphere": ("center", "radius"),
            "cylinder": ("point", "axis", "radius"), "punch": ("center", "normal", "half_width")}[kind]
    for key in need:
        if key not in t:
            raise InputError(f"[{label}] a {kind} needs {key!r}")
    allowed = set(need) | {"boundary", "obstacle", "direction", "travel", "name", "motion", "friction"} | (
        {"edge_radius"} if kind == "punch" else set())
    extra = sorted(set(t) - allowed)
    if extra:
        raise InputError(f"[{label}] a {kind} takes no {extra[0]!r}")
    if kind in ("circle", "sphere") and d != (2 if kind == "circle" else 3):
        raise InputError(f"[{label}] a {kind} needs a {2 if kind == 'circle' else 3}-D mesh, this one is {d}-D")
    if kind == "cylinder" and d != 3:
        raise InputError(f"[{label}] a cylinder obstacle needs a 3-D mesh (in 2-D use a circle)")
    direction = vector(label, "direction", t.get("direction", [0.0] * (d - 1) + [-1.0]), d)
    if not np.any(direction):
        raise InputError(f"[{label}] direction must be a non-zero vector")
    travel = t.get("travel", 0.0)
    if isinstance(travel, list):  # its length against the load path: Obstacle.travels
        nonempty_list(label, "travel", travel)
        travel = np.array([number(label, "travel", v) for v in travel])
    else:
        travel = number(label, "travel", travel)
    common = dict(direction=tuple(direction), travel=travel, name=str(t.get("name", f"{kind} {label.split()[-1]}")))
    if kind == "plane":
        ob = Plane(point=vector(label, "point", t["point"], d), normal=vector(label, "normal", t["normal"], d),
                   **common)
    elif kind == "punch":
        ob = FlatPunch(center=vector(label, "center", t["center"], d), normal=vector(label, "normal", t["normal"], d),
                       half_width=positive(label, "half_width", t["half_width"]),
                       edge_radius=number(label, "edge_radius", t.get("edge_radius", 0.0)), **common)
    elif kind == "cylinder":
        ob = Cylinder(point=vector(label, "point", t["point"], 3), axis=vector(label, "axis", t["axis"], 3),
                      radius=positive(label, "radius", t["radius"]), **common)
    else:
        ob = Ball(center=vector(label, "center", t["center"], d), radius=positive(label, "radius", t["radius"]),
                  **common)
    if "motion" not in t:
        return ob
    if "travel" in t or "direction" in t:
        raise InputError(f"[{label}] give either motion or direction and travel, not both")
    motion = nonempty_list(label, "motion", t["motion"])
    return moving(ob, [vector(label, f"motion[{i}]", v, d) for i, v in enumerate(motion)])


def _friction(label: str, t: dict) -> float | None:
    """A ``[[contact]]`` table's Coulomb coefficient (``None``: frictionless)."""
    if "friction" not in t:
        return None
    mu = number(label, "friction", t["friction"])
    if mu < 0:
        raise InputError(f"[{label}] friction must be >= 0, got {mu:g}")
    return mu


def _body_contact(label: str, t: dict, d: int):
    """A ``[[contact]]`` between two bodies: ``slave`` and ``master`` boundaries (names, tags,
    boxes or planes, as ``boundary`` elsewhere), ``name``, ``search_distance``."""
    from ddcm_casadi.models.continuum.inputs import BodyContact

    extra = sorted(set(t) - {"slave", "master", "name", "search_distance"})
    if extra:
        raise InputError(f"[{label}] a contact between bodies (slave, master) takes no {extra[0]!r}")
    for key in ("slave", "master"):
        if key not in t:
            raise InputError(f"[{label}] a contact between bodies needs {key!r} (a boundary of the mesh)")
    reach = positive(label, "search_distance", t["search_distance"]) if "search_distance" in t else None
    return BodyContact(_boundary(label, {"boundary": t["slave"]}, d), _boundary(label, {"boundary": t["master"]}, d),
                       name=str(t.get("name", f"contact {label.split()[-1]}")), search_distance=reach)


def _metric(label: str, value: Any, k: int, material) -> Metric | str:
    if isinstance(value, str):
        if value == "isotropic":
            if material is None or material.youngs_modulus is None:
                raise InputError(f"[{label}] c = \"isotropic\" needs youngs_modulus and poisson_ratio in [material]")
            return Metric(isotropic_elasticity(material.youngs_modulus, material.poisson_ratio,
                                               {3: 2, 6: 3}[k])[0])
        if value == "estimated":
            return "estimated"
        raise InputError(f"[{label}] c must be \"isotropic\", \"estimated\", a number or a matrix, got {show(value)}")
    if isinstance(value, list):
        if len(value) != k or not all(isinstance(r, list) and len(r) == k for r in value):
            raise InputError(f"[{label}] c must be a {k} x {k} matrix (list of {k} rows), got {show(value)}")
        return Metric([[number(label, "c", v) for v in row] for row in value])
    return Metric(positive(label, "c", value) * np.eye(k))


def _datasets(doc: dict, base_dir: Path, k: int, materials: list) -> list[MaterialDataset]:
    tables = _tables(doc, "data")
    ddcm_c = doc.get("ddcm", {}).get("c")
    out = []
    for i, table in enumerate(tables):
        label = "data" if len(tables) == 1 else f"data {i}"
        users = [m for m in materials if m.data == i] or [None]
        if "c" not in table and ddcm_c is None:
            raise InputError(f"[{label}] needs the metric c (\"isotropic\", \"estimated\", a number or a matrix)")
        c = _metric(label, table.get("c", ddcm_c), k, users[0])
        sources = [key for key in ("path", "hookean", "law") if key in table]
        if len(sources) != 1:
            raise InputError(f"[{label}] needs exactly one of 'path', 'hookean' or 'law'")
        # "estimated": fitted to the data before they are checked against it (MaterialDataset)
        if "path" in table:
            if not isinstance(table["path"], str):
                raise InputError(f"[{label}] path must be a string")
            ds = MaterialDataset.from_file(base_dir / table["path"], c=c, components=k)
        elif "law" in table:
            ds = _law_data(label, table, k, c, users[0])
        else:
            hk = casefile.hookean_table(label, table["hookean"], _HOOKEAN)
            mat = users[0]
            E = hk.get("youngs_modulus", None if mat is None else mat.youngs_modulus)
            nu = hk.get("poisson_ratio", None if mat is None else mat.poisson_ratio)
            if E is None or nu is None:
                raise InputError(f"[{label}] hookean needs youngs_modulus and poisson_ratio "
                                 "(here or in the [material] that uses it)")
            D = isotropic_elasticity(positive(label, "hookean.youngs_modulus", E),
                                     number(label, "hookean.poisson_ratio", nu), {3: 2, 6: 3}[k])[0]
            points = integer(label, "hookean.points", hk["points"], low=1, what="a positive integer (per axis)")
            lo = number(label, "hookean.strain_min", hk["strain_min"])
            hi = number(label, "hookean.strain_max", hk["strain_max"])
            grading = number(label, "hookean.grading", hk.get("grading", 1.0))  # range: graded_axis
            ds = MaterialDataset.hookean_grid(D, lo, hi, points, c=c, grading=grading)
        out.append(ds)
    return out


def _law_data(label: str, table: dict, k: int, c, material) -> MaterialDataset:
    """``[data] law = "neo_hookean"`` with ``grid = {...}`` or ``samples = {...}``: the
    ``(E, S)`` pairs of a hyperelastic law (:mod:`ddcm_casadi.data.hyperelastic`)."""
    law = hyperelastic.get_law(table["law"]).name
    if ("grid" in table) == ("samples" in table):
        raise InputError(f"[{label}] law = {law!r} needs exactly one of 'grid' or 'samples'")
    key = "grid" if "grid" in table else "samples"
    known = _GRID if key == "grid" else _SAMPLES
    t = table[key]
    if not isinstance(t, dict):
        raise InputError(f"[{label}] {key} must be a table {{{', '.join(sorted(known))}}}")
    unknown = sorted(set(t) - known)
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} in [{label}] {key}; known: {', '.join(sorted(known))}")
    need = ("strain_min", "strain_max", "points" if key == "grid" else "count")
    missing = [name for name in need if name not in t]
    if missing:
        raise InputError(f"missing key {missing[0]!r} in [{label}] {key}")
    E = t.get("youngs_modulus", None if material is None else material.youngs_modulus)
    nu = t.get("poisson_ratio", None if material is None else material.poisson_ratio)
    if E is None or nu is None:
        raise InputError(f"[{label}] law needs youngs_modulus and poisson_ratio (in {key} or the [material] that uses it)")
    d = {3: 2, 6: 3}[k]
    isotropic_elasticity(positive(label, f"{key}.youngs_modulus", E), number(label, f"{key}.poisson_ratio", nu), d)
    lo = number(label, f"{key}.strain_min", t["strain_min"])
    hi = number(label, f"{key}.strain_max", t["strain_max"])
    stress = hyperelastic.law_of(law, float(E), float(nu), d)
    # the range bounds the principal strains (a Mandel box would reach det C = 0)
    keep = lambda strain: hyperelastic.principal_strains_within(strain, d, lo, hi)  # noqa: E731
    if key == "grid":
        points = integer(label, "grid.points", t["points"], low=1, what="a positive integer (per axis)")
        return MaterialDataset.from_law(stress, k, lo, hi, points, c=c, keep=keep,
                                        grading=number(label, "grid.grading", t.get("grading", 1.0)))
    count = integer(label, "samples.count", t["count"], low=1, what="a positive integer")
    seed = integer(label, "samples.seed", t.get("seed", 0), low=0, what="a non-negative integer")
    return MaterialDataset.from_law(stress, k, lo, hi, 1, c=c, samples=count, seed=seed, keep=keep)


def _data_points(doc: dict, base_dir: Path, k: int) -> int:
    """The data points the ``[data]`` tables will hold, counted before any is built: ``points^k``
    of a Hookean grid, the lines of a file (0 for what cannot be read: its parser says why)."""
    total = 0
    for table in _tables(doc, "data"):
        hookean = table.get("hookean") if isinstance(table, dict) else None
        grid = table.get("grid") if isinstance(table, dict) else None
        samples = table.get("samples") if isinstance(table, dict) else None
        if isinstance(hookean, dict) and isinstance(hookean.get("points"), int) and hookean["points"] > 0:
            total += int(hookean["points"]) ** k
        elif isinstance(grid, dict) and isinstance(grid.get("points"), int) and grid["points"] > 0:
            total += int(grid["points"]) ** k
        elif isinstance(samples, dict) and isinstance(samples.get("count"), int) and samples["count"] > 0:
            total += int(samples["count"])
        elif isinstance(table, dict) and isinstance(table.get("path"), str):
            try:
                with open(base_dir / table["path"], "rb") as f:
                    total += sum(block.count(b"\n") for block in iter(lambda: f.read(1 << 20), b""))
            except OSError:
                pass
    return total


def check_size(size, *, source: str) -> None:
    """Announce, warn about or refuse a continuum before it is built, from its estimated size.

    Parameters
    ----------
    size : BuildSize
        :func:`~ddcm_casadi.models.continuum.fem.estimate_size` of the case.
    source : str
        The case file, named in the messages.

    Raises
    ------
    InputError
        The estimate exceeds the machine's physical memory (one line: what, how big, what to reduce).

    Warns
    -----
    PhysicsWarning
        The estimate exceeds :data:`MEMORY_WARNING_SHARE` of the machine's memory.
    """
    from ddcm_casadi import parallel

    have = parallel.physical_memory()
    gib = size.bytes / 2**30
    if have is not None and size.bytes > have:
        raise InputError(f"{source}: this case needs about {gib:.3g} GiB ({size.describe()}) but the machine has "
                         f"{have / 2**30:.3g} GiB of memory: use a coarser mesh (divisions, refine, refine_near) "
                         "or fewer data points")
    if have is not None and size.bytes > MEMORY_WARNING_SHARE * have:
        warnings.warn(f"{source}: this case needs about {gib:.3g} GiB, more than half of the machine's "
                      f"{have / 2**30:.3g} GiB: it may swap; a coarser mesh or fewer data points would fit",
                      PhysicsWarning, stacklevel=2)
    if (max(size.dofs, size.stress_unknowns if size.data_points else 0) >= ANNOUNCE_UNKNOWNS
            or size.data_points >= ANNOUNCE_DATA_POINTS):
        BUILD_LOG.info("building %s", size.describe())


def parse_case(doc: dict, *, base_dir: Path, source: str, name: str) -> Case:
    """Validate a ``[mesh]`` document and build its :class:`Case`."""
    from ddcm_casadi.models.continuum.model import BodyForce, Contact, Material, Support, Traction, continuum_model

    from ddcm_casadi.models.continuum.fem import estimate_size

    mesh, degree = _shape_mesh(doc, base_dir)
    d = mesh.p.shape[0]
    k = COMPONENTS[d]
    n_data = len(_tables(doc, "data"))
    # before the data and the model are built: what cannot fit is refused, what is big announced
    check_size(estimate_size(mesh, degree, _data_points(doc, base_dir, k)), source=source)

    materials = []
    mats = _tables(doc, "material")
    if not mats:
        raise InputError("missing section [material] (youngs_modulus, poisson_ratio, and/or data)")
    for i, t in enumerate(mats):
        label = "material" if len(mats) == 1 else f"material {i}"
        region = t.get("region")
        if region is not None and not isinstance(region, str):
            raise InputError(f"[{label}] region must be a subdomain name, got {show(region)}")
        E = positive(label, "youngs_modulus", t["youngs_modulus"]) if "youngs_modulus" in t else None
        nu = number(label, "poisson_ratio", t["poisson_ratio"]) if "poisson_ratio" in t else None
        if (E is None) != (nu is None):
            raise InputError(f"[{label}] give youngs_modulus and poisson_ratio together")
        data = t.get("data", 0 if n_data else None)
        if data is not None:
            data = integer(label, "data", data, low=0, high=max(n_data - 1, 0), what="a data-set index")
            if not n_data:
                raise InputError(f"[{label}] data = {data} but the case has no [data]")
        law = t.get("law", "linear")
        if not isinstance(law, str):
            raise InputError(f"[{label}] law must be a string, got {show(law)}")
        materials.append(Material(region=region, youngs_modulus=E, poisson_ratio=nu, data=data,
                                  law=hyperelastic.get_law(law).name))

    supports = []
    for i, t in enumerate(_tables(doc, "supports")):
        label = f"supports {i}"
        if "fix" not in t:
            raise InputError(f"[{label}] needs 'fix' (components, e.g. \"xy\")")
        supports.append(Support(_boundary(label, t, d), t["fix"], t.get("displacement")))  # a hard device
    if not supports:
        raise InputError("missing [[supports]]: a continuum must be held")

    tractions, body_forces = [], []
    for i, t in enumerate(_tables(doc, "loads")):
        label = f"loads {i}"
        if ("traction" in t) == ("body_force" in t):
            raise InputError(f"[{label}] needs exactly one of 'traction' or 'body_force'")
        if "traction" in t:
            tractions.append(Traction(_boundary(label, t, d), tuple(vector(label, "traction", t["traction"], d))))
        else:
            region = t.get("region")
            if "boundary" in t:
                raise InputError(f"[{label}] a body force acts on a region, not a boundary")
            body_forces.append(BodyForce(tuple(vector(label, "body_force", t["body_force"], d)), region))

    load_factors = None
    if "loading" in doc and "load_factors" in doc["loading"]:
        lf = nonempty_list("loading", "load_factors", doc["loading"]["load_factors"])
        load_factors = [number("loading", "load_factors", v) for v in lf]
    contacts = []
    for i, t in enumerate(_tables(doc, "contact")):
        label = f"contact {i}"
        contacts.append(_body_contact(label, t, d) if "slave" in t or "master" in t
                        else Contact(_obstacle(label, t, d), _boundary(label, t, d), friction=_friction(label, t)))

    symmetry = _symmetry_factor(doc)
    reference = None
    if "hertz" in doc:
        h = doc["hertz"]
        key = "contact" if "contact" in h else "obstacle"
        index = integer("hertz", key, h.get(key, 0), low=0, high=max(len(contacts) - 1, 0), what="a [[contact]] index")
        if key == "contact":  # between two bodies: R* given, E* from the two sides' materials
            if "radius" not in h or contacts[index].kind != "bodies":
                raise InputError("[hertz] contact = <index> needs a [[contact]] between bodies (slave, master) and "
                                 "radius (the effective radius 1/R* = 1/R1 + 1/R2)")
            direction = tuple(vector("hertz", "direction", h["direction"], d)) if "direction" in h else None
            reference = BodyHertzReference(positive("hertz", "radius", h["radius"]), contact=index,
                                           force_factor=symmetry, direction_of_centres=direction)
        else:
            if len(materials) != 1 or materials[0].youngs_modulus is None:
                raise InputError("[hertz] needs one material with youngs_modulus and poisson_ratio")
            if not contacts or getattr(getattr(contacts[index], "obstacle", None), "kind", None) != "ball":
                raise InputError("[hertz] needs a circle (2-D) or sphere (3-D) obstacle")
            reference = HertzReference(materials[0].youngs_modulus, materials[0].poisson_ratio, obstacle=index,
                                       force_factor=symmetry)

    datasets = _datasets(doc, base_dir, k, materials) if n_data else []
    max_outer, options = casefile.run_options(doc)
    model = continuum_model(mesh, materials=materials, supports=supports, contacts=contacts, degree=degree,
                            tractions=tractions, body_forces=body_forces, load_factors=load_factors,
                            datasets=datasets, name=name, reference=reference, symmetry_factor=symmetry,
                            # the case's top-level kinematics replaces this; built to fit the laws
                            # so that the model checks the pair (law, kinematics) the user wrote
                            kinematics="finite" if any(hyperelastic.get_law(m.law).finite for m in materials)
                            else "small")
    return Case(model=model, formulation_options=options, ddcm_max_outer=max_outer, source=source)


register_case_kind(
    "mesh",
    sections={"mesh": _MESH, "material": {"region", "youngs_modulus", "poisson_ratio", "data", "law"},
              "supports": {"boundary", "fix", "displacement"}, "loads": {"boundary", "traction", "body_force", "region"},
              "contact": {"boundary", "obstacle", "radius", "center", "point", "normal", "axis", "half_width",
                          "edge_radius", "direction", "travel", "name", "slave", "master", "search_distance",
                          "motion", "friction"},
              "loading": {"load_factors"}, "hertz": {"obstacle", "force_factor", "contact", "radius", "direction"}},
    arrays={"supports", "loads", "contact"}, tables={"material"}, parse=parse_case,
    uses="[material], [[supports]] and [[contact]]", default_name="continuum", kinematics=("small", "finite"))

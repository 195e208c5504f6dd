"""Hyperelastic laws, finite-strain kinematics and exact gaps of continua, checked against
closed forms written independently of the package's code."""

from __future__ import annotations

import numpy as np
import pytest

from ddcm_casadi.casefiles.config import case_from_dict
from ddcm_casadi.data import hyperelastic
from ddcm_casadi.data.dataset import MaterialDataset
from ddcm_casadi.data.metric import Metric, isotropic_elasticity, mandel_to_tensor
from ddcm_casadi.errors import InputError
from ddcm_casadi.models.continuum.finite import green_lagrange
from ddcm_casadi.models.continuum.inputs import Contact, Material, Support
from ddcm_casadi.models.continuum.mesh import rectangle
from ddcm_casadi.models.continuum.model import continuum_model
from ddcm_casadi.models.continuum.obstacles import Ball, Plane

K = {2: 3, 3: 6}
# Round-off of a law evaluated at O(0.1) strains with O(1) moduli: a few ulps per operation.
ROUNDOFF = 1e-13


@pytest.mark.parametrize("d", [2, 3])
def test_neo_hookean_derivative_equals_its_closed_form(d):
    """``S = dW/dE`` by automatic differentiation against ``mu (I - C^-1) + lambda ln J C^-1``."""
    E = 0.1 * np.random.default_rng(d).standard_normal((20, K[d]))
    S = hyperelastic.second_piola("neo_hookean", E, 3.0, 0.3, d)
    assert np.max(np.abs(S - hyperelastic.neo_hookean_stress(E, 3.0, 0.3, d))) < ROUNDOFF


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("law", ["saint_venant_kirchhoff", "linear"])
def test_quadratic_laws_are_the_isotropic_matrix(d, law):
    E = 0.1 * np.random.default_rng(d).standard_normal((20, K[d]))
    D = isotropic_elasticity(3.0, 0.3, d)[0]
    assert np.max(np.abs(hyperelastic.second_piola(law, E, 3.0, 0.3, d) - E @ D.T)) < ROUNDOFF


def test_green_lagrange_of_a_rigid_rotation_is_zero_and_of_a_stretch_exact():
    c, s = np.cos(0.7), np.sin(0.7)
    H = np.array([[[c - 1, -s], [s, c - 1]], [[0.5, 0.0], [0.0, -0.3]]])
    E = green_lagrange(H)
    assert np.max(np.abs(E[0])) < 1e-15
    assert np.allclose(E[1], [(1.5**2 - 1) / 2, (0.7**2 - 1) / 2, 0.0], rtol=0, atol=1e-15)


def test_law_data_leave_out_undefined_states():
    law = hyperelastic.law_of("neo_hookean", 1.0, 0.3, 2)
    ds = MaterialDataset.from_law(law, 3, -0.45, 0.45, 7, c=Metric(np.eye(3)))
    assert 0 < len(ds) < 7**3
    C = np.eye(3)[None] + 2 * mandel_to_tensor(ds.strain, 2)
    assert np.all(np.linalg.det(C[:, :2, :2]) > 0)


def _block(law="neo_hookean", kinematics="finite", obstacle=None, travel=(0.0, 0.1)):
    obstacle = obstacle or Plane(point=(0.0, 1.0), normal=(0.0, -1.0), direction=(0.0, -1.0), travel=list(travel))
    return continuum_model(rectangle(1.0, 1.0, nx=2, ny=2),
                           materials=[Material(youngs_modulus=1.0, poisson_ratio=0.3, law=law)],
                           supports=[Support("ymin", "y"), Support("xmin", "x")],
                           contacts=[Contact(obstacle, "ymax")], kinematics=kinematics)


@pytest.mark.parametrize("law,kinematics", [("linear", "finite"), ("neo_hookean", "small")])
def test_a_law_that_does_not_fit_the_kinematics_is_refused(law, kinematics):
    with pytest.raises(InputError, match="does not fit kinematics"):
        _block(law, kinematics)


def test_unknown_law_is_one_line():
    with pytest.raises(InputError, match="unknown material law 'rubber'"):
        _block("rubber")


def test_exact_gap_of_a_ball_at_the_current_configuration():
    """``phi(X + u - s d)`` for a circle: moved nodes against ``|x - c| - R`` computed here."""
    ball = Ball(center=(0.5, 3.0), radius=2.0, direction=(0.0, -1.0), travel=[0.0, 0.25])
    m = _block(obstacle=ball)
    u = 0.05 * np.random.default_rng(1).standard_normal(m.n_dofs)
    x = m.contact_points + m.dof_displacement(u)[m.contact_dofs] - np.array([0.0, -0.25])
    expected = np.linalg.norm(x - [0.5, 3.0], axis=1) - 2.0
    assert np.max(np.abs(m.gap(u, 1) - expected)) < 1e-14


def test_inverted_point_is_inadmissible():
    m = _block()
    u = np.zeros(m.n_dofs)
    assert m.inadmissible(u) is None
    # every node mirrored through y = 0.5 ... only the free components move: flip y of free y dofs
    vd = m.discretisation.vector_dofs()
    y = m.discretisation.dof_locations()[:, 1]
    full = np.zeros(m.discretisation.n_dofs)
    full[vd[1]] = -2.0 * y
    assert "inverted" in m.inadmissible(full[m.free_dofs])


def test_case_file_law_keys_and_errors():
    doc = {"kinematics": "finite",
           "mesh": {"shape": "rectangle", "size": [1.0, 1.0], "divisions": [1, 1]},
           "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3, "law": "neo_hookean"},
           "supports": [{"boundary": "ymin", "fix": "xy"}],
           "data": {"law": "neo_hookean", "grid": {"strain_min": -0.1, "strain_max": 0.1, "points": 3},
                    "c": "isotropic"}}
    case = case_from_dict(doc)
    assert case.model.kinematics == "finite" and case.model.laws == ("neo_hookean",)
    # the range bounds the principal strains: of the 3^3 grid, the states whose 2x2 tensor has
    # both eigenvalues within [-0.1, 0.1] (counted here from the closed-form eigenvalues)
    grid = np.array(np.meshgrid(*[[-0.1, 0.0, 0.1]] * 3, indexing="ij")).reshape(3, -1).T
    mean, radius = (grid[:, 0] + grid[:, 1]) / 2, np.hypot((grid[:, 0] - grid[:, 1]) / 2, grid[:, 2] / np.sqrt(2))
    inside = (mean + radius <= 0.1 + 1e-15) & (mean - radius >= -0.1 - 1e-15)
    assert len(case.model.dataset) == int(inside.sum()) < 27
    bad = dict(doc, data=dict(doc["data"], samples={"strain_min": 0, "strain_max": 1, "count": 2}))
    with pytest.raises(InputError, match="exactly one of 'grid' or 'samples'"):
        case_from_dict(bad)
    small = {k: v for k, v in doc.items() if k != "kinematics"}
    with pytest.raises(InputError, match="does not fit kinematics = 'small'"):
        case_from_dict(small)


def _whole_expression(model):
    """The same model built as one expression of every point (no element-by-element assembly)."""
    import dataclasses

    from ddcm_casadi.models.continuum.model import ContinuumModel

    whole = type("WholeExpression", (ContinuumModel,), {"local_kinematics": lambda self: None})
    return whole(**{f.name: getattr(model, f.name) for f in dataclasses.fields(model) if f.init})


# Both builds sum the same terms in another order: roundoff of the terms that cancel in a row,
# the Newton loop's own allowance (64 ulps, ddcm_casadi.loops.newton.ROUNDOFF_ULPS).
ASSEMBLY_ULPS = 64 * np.finfo(float).eps


@pytest.mark.parametrize("degree", [1, 2])
def test_element_assembly_equals_the_whole_expression(degree):
    """LocalTerms against the one-expression builder, on a curved obstacle with data: residuals,
    gaps, objective and the Fischer-Burmeister Newton matrix at a random state."""
    from ddcm_casadi import formulations
    from ddcm_casadi.problems.build import build_problems

    ds = MaterialDataset.from_law(hyperelastic.law_of("neo_hookean", 1.0, 0.3, 2), 3, -0.2, 0.2, 5,
                                  c=Metric(isotropic_elasticity(1.0, 0.3, 2)[0]))
    ball = Ball(center=(0.5, 3.0), radius=2.0, direction=(0.0, -1.0), travel=[0.0, 0.05])
    model = continuum_model(rectangle(1.0, 1.0, nx=2, ny=2), degree=degree, datasets=[ds],
                            materials=[Material(youngs_modulus=1.0, poisson_ratio=0.3, law="neo_hookean", data=0)],
                            supports=[Support("ymin", "y"), Support("xmin", "x")],
                            contacts=[Contact(ball, "ymax")], kinematics="finite")
    rng = np.random.default_rng(degree)
    pairs = [build_problems(model), build_problems(_whole_expression(model))]
    for kind in ("classical", "projection"):
        a, b = (getattr(p, kind) for p in pairs)
        x, p = 0.02 * rng.standard_normal(a.n_x), np.abs(rng.standard_normal(a.n_pairs))
        P = rng.standard_normal(a.parameters.size) * 0.05
        (ra, ta, ga, fa), (rb, tb, gb, fb) = a.evaluate(x, p, P), b.evaluate(x, p, P)
        assert np.all(np.abs(ra - rb) <= ASSEMBLY_ULPS * np.maximum(ta, 1.0))
        assert np.allclose(ta, tb, rtol=ASSEMBLY_ULPS, atol=0)
        assert np.max(np.abs(ga - gb)) <= ASSEMBLY_ULPS * max(1.0, np.max(np.abs(ga)))
        assert abs(fa - fb) <= ASSEMBLY_ULPS * max(1.0, abs(fa))
        built = [formulations.get("fischer_burmeister").build(q) for q in (a, b)]
        z, Pz = built[0].newton_point(P, x, p)
        Ja, Jb = (f.newton_system().matrix(z, Pz) for f in built)
        scale = max(float(abs(Ja).max()), 1.0)
        assert abs(Ja - Jb).max() <= ASSEMBLY_ULPS * scale

import pytest

from ddcm_casadi import formulations
from ddcm_casadi import compare, paper_bar

ALL = formulations.available()
EXACT = [n for n in ALL if formulations.get(n).exact]


@pytest.fixture(scope="session")
def paper():
    return paper_bar()


@pytest.fixture(scope="session")
def paper_comparison(paper):
    """Every formulation x variant on the paper's example, computed once per test session."""
    return compare(paper)

"""Parameter sweeps and Monte Carlo studies over data, on ``dask.distributed`` (``ddcm-sweep``).

- :mod:`~ddcm_casadi.sweep.spec`: the spec (a base case, a grid of dotted keys, seeds) and its cases;
- :mod:`~ddcm_casadi.sweep.generators`: material data generated per case (law, size, noise, seed);
- :mod:`~ddcm_casadi.sweep.runner`: one Dask task per case, one folder per finished case, resumable;
- :mod:`~ddcm_casadi.sweep.table`: the rows of ``sweep.csv`` and the fitted rates;
- :mod:`~ddcm_casadi.sweep.figures`: error against data size and against noise (matplotlib);
- :mod:`~ddcm_casadi.commands.sweep`: the command ``ddcm-sweep``.

Dask is imported only when a sweep runs (``pip install 'ddcm-casadi[sweep]'``).
"""

from ddcm_casadi.sweep.generators import DataGenerator, generator_from_dict
from ddcm_casadi.sweep.runner import SweepReport, run_case, run_sweep
from ddcm_casadi.sweep.spec import SweepCase, SweepSpec, load_spec

__all__ = ["DataGenerator", "SweepCase", "SweepReport", "SweepSpec", "generator_from_dict", "load_spec", "run_case",
           "run_sweep"]

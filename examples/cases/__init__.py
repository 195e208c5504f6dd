"""The example case files (TOML, JSON), installed with the package as ``ddcm_casadi.cases``.

``ddcm-validate`` and the benchmarks read the Hertz example from here, so a regular (not editable)
install has them too. Run one with ``ddcm-compare --config examples/cases/<file> --out DIR``.
"""

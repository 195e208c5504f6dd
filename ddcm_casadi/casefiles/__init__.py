"""Case files (TOML or JSON): the registry of case kinds (:mod:`~ddcm_casadi.casefiles.base`) and the
shared pieces (:mod:`~ddcm_casadi.casefiles.common`), one parser per model kind (:mod:`~ddcm_casadi.casefiles.bar`,
:mod:`~ddcm_casadi.casefiles.truss`, :mod:`~ddcm_casadi.casefiles.continuum`), ``--set`` overrides
and the loader (:mod:`~ddcm_casadi.casefiles.config`)."""

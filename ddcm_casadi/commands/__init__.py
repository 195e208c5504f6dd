"""The command-line tools: ``ddcm-compare`` (:mod:`~ddcm_casadi.commands.compare`),
``ddcm-validate`` (:mod:`~ddcm_casadi.commands.validate`) and ``ddcm-sweep``
(:mod:`~ddcm_casadi.commands.sweep`), with their shared pieces (:mod:`~ddcm_casadi.commands.base`)."""

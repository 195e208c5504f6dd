"""The verification ladder of ``ddcm-validate`` (:mod:`~ddcm_casadi.validation.ladder`): checks
against closed forms and independent references (:mod:`~ddcm_casadi.validation.reference`), with
tolerances derived from each method (:mod:`~ddcm_casadi.validation.verification`)."""

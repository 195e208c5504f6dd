"""Material data: data sets and their metric, the nearest-datum search backends, and the check of
states beyond the data (:mod:`~ddcm_casadi.data.dataset`, :mod:`~ddcm_casadi.data.metric`,
:mod:`~ddcm_casadi.data.search`, :mod:`~ddcm_casadi.data.extrapolation`); the data files' readers
(:mod:`~ddcm_casadi.data.files`) and what a data set may hold (:mod:`~ddcm_casadi.data.limits`)."""

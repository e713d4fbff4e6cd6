"""The studies built on the co-simulation core: the Table I/II report (tables), the claims check,
the step study, the regression against reference results, mutation testing, the in-process oracle,
parameter sweeps and the tuning of the controller's design parameters.  They import
 the core (harness/*.py), never a host runner (harness/hosts/)."""

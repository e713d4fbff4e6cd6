"""The studies built on the co-simulation core: the Table I/II report (tables), the claims check,
the step study, the regression against reference results, mutation testing, the in-process oracle,
and parameter sweeps.  They import the core (harness/*.py), never a host runner (harness/hosts/)."""

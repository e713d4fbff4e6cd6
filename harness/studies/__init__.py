"""Studies built on the co-simulation core (harness/): each one a subcommand of ``python -m harness``."""

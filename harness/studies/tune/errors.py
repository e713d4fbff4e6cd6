"""The tune command's usage error."""
from __future__ import annotations

from ... import cli_args


class TuneError(cli_args.UsageError):
    """A mistake in the tune command's input (exit 2, nothing written)."""

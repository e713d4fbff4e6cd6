"""The controller-variant registry: one row per variant of the controller FMU.

A variant is a value of the controller FMU's ``variant`` parameter (fmu_src/afc_math.py,
``VARIANT_*``; docs/model.md section 6 (the three controllers)).  Everything in the harness that
lists the controllers (the command-line choices, the step study, the regression's cases, sweeps,
the engines) takes them from here, so a new variant is its row below plus its math in the FMU
(Python and C).  The paper's comparison (Table I/II and its figures, the claims, the scenarios'
communication step, the tuning comparison) takes the rows marked ``paper`` only: a variant beyond
the paper (an ablation) runs everywhere else but changes no verdict of the paper's claims.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Variant:
    name: str  # on the command line and in file names: --controller NAME
    code: int  # the controller FMU's ``variant`` parameter
    label: str  # what it is, in the paper's terms
    colour: str  # in the report's figures (matplotlib colour)
    paper: bool = False  # one of the paper's three controllers (Table I/II, its claims); else beyond the paper


VARIANTS = (
    Variant("vud", 1, "proposed AFC (variable universes)", "tab:red", paper=True),
    Variant("fixed", 2, "stand-in for [46] (fixed universes)", "tab:blue", paper=True),
    Variant("fae", 3, "stand-in for [28] (fixed universes + error estimator)", "tab:green", paper=True),
)
PROPOSED = "vud"  # the paper's controller: the claims compare it with every other variant of the paper; the default
CONTROLLER_VARIANTS = {v.name: v.code for v in VARIANTS}  # {"vud": 1, "fixed": 2, "fae": 3}
NAMES = tuple(CONTROLLER_VARIANTS)
PAPER = tuple(v.name for v in VARIANTS if v.paper)  # the paper's comparison: vud, fixed, fae
COMPARISONS = tuple(name for name in PAPER if name != PROPOSED)  # what the proposed controller is compared with
COLOURS = {v.name: v.colour for v in VARIANTS}


def name_of(code: int, default: str = PROPOSED) -> str:
    """The variant whose ``variant`` parameter is ``code`` (``default`` when none is)."""
    return next((v.name for v in VARIANTS if v.code == code), default)

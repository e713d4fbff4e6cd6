"""The controller-variant registry (harness/variants.py) agrees with the controller FMU it names."""
import re
from pathlib import Path

from fmu_src import afc_math

from harness.fmu_build import catalog as fmu_catalog
from harness import variants
from harness.studies import claims, step_study, tables

ROOT = Path(__file__).resolve().parents[1]


def test_each_row_is_a_value_of_the_fmus_variant_parameter():
    declared = next(v for v in fmu_catalog.model_class("AdaptiveFuzzyController").VARIABLES if v.name == "variant")
    codes = [row.code for row in variants.VARIANTS]
    assert sorted(codes) == list(range(int(declared.minimum), int(declared.maximum) + 1))  # every value, once
    # every VARIANT_<NAME> constant of the math has the row named <name> (fmu_src/afc_math.py, and the C header)
    constants = {key[len("VARIANT_"):].lower(): value for key, value in vars(afc_math).items()
                 if key.startswith("VARIANT_")}
    assert variants.CONTROLLER_VARIANTS == constants
    header = (ROOT / "fmu_src" / "afc_math.h").read_text()
    assert {name: int(code) for name, code in re.findall(r"(?m)^#define VARIANT_(\w+) (\d+)", header)} == \
        {name.upper(): code for name, code in constants.items()}


def test_the_proposed_controller_is_compared_with_every_other_variant_of_the_paper():
    assert variants.PROPOSED == "vud" and variants.PROPOSED in variants.NAMES
    assert variants.PAPER == ("vud", "fixed", "fae")  # the paper's three (docs/model.md section 6)
    assert variants.PAPER == tuple(row.name for row in variants.VARIANTS if row.paper)
    assert set(variants.COMPARISONS) == set(variants.PAPER) - {variants.PROPOSED}
    # Table I/II and the claims are the paper's comparison: a row beyond the paper (paper=False) is in neither
    assert claims.CONTROLLERS == tables.CONTROLLERS == variants.PAPER
    assert len(set(variants.COLOURS.values())) == len(variants.VARIANTS)  # one colour each in the figures
    assert [variants.name_of(row.code) for row in variants.VARIANTS] == list(variants.NAMES)
    assert variants.name_of(99) == variants.PROPOSED  # a code no row has: the default


def test_a_variant_beyond_the_paper_sets_no_scenarios_step():
    def result(feedthrough):
        return {"validated_step": {"feedthrough": feedthrough, "jacobi": None}}

    entry = {"start_step": 1e-3, "controllers": {"vud": result(4e-4), "fixed": result(1e-3), "fae": result(5e-4)}}
    assert step_study.chosen_step(entry) == (4e-4, None)
    entry["controllers"]["ablation"] = result(1e-5)  # a row without paper=True: studied, but not the step
    assert step_study.chosen_step(entry) == (4e-4, None)
    entry["controllers"]["fixed"] = result(None)
    assert step_study.chosen_step(entry)[0] == 1e-3 and "fallback" in step_study.chosen_step(entry)[1]

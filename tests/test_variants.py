"""The controller-variant registry (harness/variants.py) agrees with the controller FMU it names."""
from fmu_src import afc_math

import fmu_catalog
from harness import variants


def test_each_row_is_a_value_of_the_fmus_variant_parameter():
    declared = next(v for v in fmu_catalog.model_class("AdaptiveFuzzyController").VARIABLES if v.name == "variant")
    codes = [row.code for row in variants.VARIANTS]
    assert sorted(codes) == list(range(int(declared.minimum), int(declared.maximum) + 1))  # every value, once
    assert variants.CONTROLLER_VARIANTS == {"vud": afc_math.VARIANT_VUD, "fixed": afc_math.VARIANT_FIXED,
                                            "fae": afc_math.VARIANT_FAE}


def test_the_proposed_controller_is_compared_with_every_other_variant():
    assert variants.PROPOSED == "vud" and variants.PROPOSED in variants.NAMES
    assert set(variants.COMPARISONS) == set(variants.NAMES) - {variants.PROPOSED}
    assert len(set(variants.COLOURS.values())) == len(variants.VARIANTS)  # one colour each in the figures
    assert [variants.name_of(row.code) for row in variants.VARIANTS] == list(variants.NAMES)
    assert variants.name_of(99) == variants.PROPOSED  # a code no row has: the default

"""tests/message_meaning.py: what a log message says, read from either edition's text."""
import math

from tests.message_meaning import meaning, parameter_error, written_as_c_does


def test_numbers_written_by_repr_and_by_c_s_17g_say_the_same():
    values = [1.0, -1.0, 0.1, 1e-05, 2.0 ** 0.5, 1e308, -0.0, 5e-324, 12345678901234567.0, math.inf, -math.inf]
    for value in values:
        python, c = f"x = {value!r}; valid range: > 0", f"x = {value:.17g}; valid range: > 0"
        assert meaning(python) == meaning(c), (python, c)
        assert written_as_c_does(meaning(c).texts[0])
        assert written_as_c_does(meaning(python).texts[0]) == (repr(value) == f"{value:.17g}")


def test_a_different_last_bit_a_different_word_or_another_count_of_numbers_is_another_meaning():
    assert meaning("t = 0.1") != meaning(f"t = {math.nextafter(0.1, 1.0)!r}")
    assert meaning("t = 0.0") != meaning("t = -0.0")
    assert meaning("t = 0.1 refused") != meaning("t = 0.1 accepted")
    assert meaning("E = (0.1, 0.2)") != meaning("E = (0.1,)")


def test_names_are_words_and_numbers_stand_alone():
    said = meaning("fmi2SetReal: k1..k2 = (3.0, 2.0) for x1=0.5 at t = 3.0. e(0) = 1e-05, s^2 + 2 s")
    assert said.texts == ("3.0", "2.0", "0.5", "3.0", "0", "1e-05", "2", "2")
    assert said.words == "fmi2SetReal: k1..k2 = (#, #) for x1=# at t = #. e(#) = #, s^# + # s"


def test_every_way_a_c_library_writes_a_nan_is_a_nan():
    assert meaning("u = nan") == meaning("u = -nan") == meaning("u = -nan(ind)")
    assert meaning("u = nan") != meaning("u = inf") and meaning("u = inf") != meaning("u = -inf")
    assert all(written_as_c_does(text) for text in ("nan", "-nan", "-nan(ind)", "inf", "-inf"))
    assert not written_as_c_does("0.1") and written_as_c_does("0.10000000000000001")


def test_a_parameter_error_gives_the_variable_its_value_and_its_valid_range():
    assert parameter_error("parameter k1 = -1 is invalid; valid range: > 0") == ("k1", -1.0, "> 0")
    name, value, valid = parameter_error("parameter gamma = nan is invalid; valid range: > 0")
    assert (name, valid) == ("gamma", "> 0") and math.isnan(value)
    assert parameter_error("input e = nan is not finite") is None

"""The mutation command (harness/studies/mutation.py) itself: one mutant killed, one survivor reported,
patterns applied inside their function only, a pattern that no longer matches reported.

The full mutation run (every mutant) is ``python -m harness mutate``, not part of this suite."""
from harness.studies import mutation
from harness.cli import main as cli_main


def test_every_mutation_pattern_matches_its_function_once():
    """When a source is rewritten, this names the mutations to update (they are not skipped)."""
    problems = {m.name: mutation.check_pattern(m) for m in mutation.MUTATIONS}
    assert {name: p for name, p in problems.items() if p} == {}
    assert len({m.name for m in mutation.MUTATIONS}) == len(mutation.MUTATIONS)


def test_a_pattern_is_applied_inside_its_function_only():
    source = "def a(x):\n    return x + 1\n\n\ndef b(x):\n    return x + 1\n"
    edit = mutation.Mutation("m", "f.py", "b", "x + 1", "x - 1", ())
    assert mutation.mutated_source(source, edit) == "def a(x):\n    return x + 1\n\n\ndef b(x):\n    return x - 1\n"
    for bad in (mutation.Mutation("m", "f.py", "c", "x + 1", "x - 1", ()),  # no such function
                mutation.Mutation("m", "f.py", "b", "x + 2", "x - 1", ())):  # no such text
        try:
            mutation.mutated_source(source, bad)
        except mutation.PatternNotFound:
            continue
        raise AssertionError(f"{bad} applied")


def test_a_pattern_that_no_longer_matches_is_reported_clearly(monkeypatch, capsys):
    stale = mutation.Mutation("stale", "fmu_src/afc_math.py", "adaptation_signal", "no such text", "x", ())
    monkeypatch.setattr(mutation, "MUTATIONS", (stale,))
    assert cli_main(["mutate", "--list"]) == 2
    assert "PATTERN NOT FOUND" in capsys.readouterr().out
    assert cli_main(["mutate"]) == 2
    captured = capsys.readouterr()
    assert "mutation score: 0/0" in captured.out
    assert "error: mutation stale: pattern not found: fmu_src/afc_math.py: 'no such text' occurs 0 times" in captured.err


def test_the_command_kills_a_mutant_and_reports_a_survivor(fmu_paths, capsys):
    assert cli_main(["mutate", "--only", "tau_p12_p22_swap", "--tests", "tests/test_adaptive_law_fmu.py"]) == 0
    out = capsys.readouterr().out
    assert "KILLED            tau_p12_p22_swap" in out and "by tests/test_adaptive_law_fmu.py::" in out
    assert "mutation score: 1/1 killed" in out
    # the same mutant against tests that do not look at tau survives, and is named
    assert cli_main(["mutate", "--only", "tau_p12_p22_swap", "--tests", "tests/test_scores.py"]) == 1
    out = capsys.readouterr().out
    assert "SURVIVED" in out and "mutation score: 0/1 killed" in out
    assert "survived: tau_p12_p22_swap (tau = [E, dE] P B with p12 and p22 swapped (31)" in out


def test_a_test_selection_that_does_not_run_is_an_error_not_a_kill(fmu_paths, capsys):
    assert cli_main(["mutate", "--only", "tau_p12_p22_swap", "--tests", "tests/no_such_test_file.py"]) == 2
    captured = capsys.readouterr()
    assert "mutation score: 0/0" in captured.out and "ERROR" in captured.out
    assert "error: mutation tau_p12_p22_swap: error: pytest exit status 4" in captured.err

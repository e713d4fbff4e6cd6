"""Every +- of the claims (harness/studies/claims.py on the ladders of harness/studies/ladders.py) bounds the
distance of its value to the continuous-time value of the model, per scenario and controller, every score.

The continuous-time reference is Model Exchange (harness/me_master.py: the controller without a hold, the
manipulator's friction with its stuck mode, CVODE at rtol 1e-10, its change from 1e-9 counted against it),
itself held to an independent event-located solution in tests/test_continuous_reference.py. The ladders are
those `tables` runs (the case at h, at h/2 with the plant's step halved with it and, on the manipulator, whose
friction switches, at h with another plant step), over the scenarios' 20 s, in the native edition (the same numbers
as the pythonfmu edition's). On the smooth pendulum the plant-axis run the ladder leaves out is run here too: the RK4
error it shows at the table's plant step (fourth order) stays below SMOOTH_PLANT_SHARE of the printed error.
"""
from __future__ import annotations

import math

import pytest

from harness.fmu_build import native as build_native

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")

SCENARIOS = ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator")
CONTROLLERS = ("vud", "fixed", "fae")
REFERENCE_RTOL = 1e-10
#: on a smooth plant the RK4 error the plant axis (left out of its ladder) shows is at most this share of the +-
SMOOTH_PLANT_SHARE = 0.25


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as patch:
        yield patch


@pytest.fixture(scope="module")
def native(fmu_paths, monkeypatch_module):
    monkeypatch_module.setenv("AFC_EDITION", "native")
    from harness.fmu_build import builder
    return builder.ensure_built()


def ladder_and_reference(name: str, fmu_paths: dict) -> dict:
    """{controller: (ladder rows, Model Exchange at REFERENCE_RTOL, at 10 x REFERENCE_RTOL, the plant-axis row
    the ladder leaves out on a smooth plant or None)}."""
    from harness.cases import Case, run_cases
    from harness.studies import ladders

    runs, references, omitted = {}, {}, {}
    for controller in CONTROLLERS:
        case = Case(name, controller)
        runs[controller] = [case, *ladders.ladder_cases(case)]
        references[controller] = [Case(name, controller, algorithm="me", rtol=r)
                                  for r in (REFERENCE_RTOL, 10 * REFERENCE_RTOL)]
        smooth = not ladders.needs_plant_axis(case.build())
        omitted[controller] = [ladders.plant_step_case(case, smooth_too=True)] if smooth else []
    flat = [c for controller in CONTROLLERS for c in (*runs[controller], *references[controller],
                                                      *omitted[controller])]
    outcomes = dict(zip(flat, run_cases(flat, jobs=2, progress=False, fmu_paths=fmu_paths)))
    return {controller: ([ladders.ladder_row(c, outcomes[c]) for c in runs[controller]],
                         *(outcomes[c] for c in references[controller]),
                         *([ladders.ladder_row(c, outcomes[c]) for c in omitted[controller]] or [None]))
            for controller in CONTROLLERS}


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_printed_error_bounds_the_distance_to_the_continuous_time_value(native, name):
    from harness.scores import SCORE_KEYS
    from harness.studies import claims

    found = ladder_and_reference(name, native)
    worst, shares = [], []
    for controller, (ladder, reference, looser, omitted) in found.items():
        assert reference["status"] == "ok" and all(row["status"] == "ok" for row in ladder), controller
        for metric in SCORE_KEYS:
            if reference[metric] is None:  # ts of a run not settled within the horizon
                assert all(row[metric] is None for row in ladder), (controller, metric)
                continue
            estimate = claims.estimate(ladder, metric)
            # the reference's own error: its change from a 10 x looser rtol; ts is read off its output grid
            slack = reference["step"] if metric == "ts" else abs(reference[metric] - looser[metric])
            distance = abs(estimate.value - reference[metric])
            worst.append((max(0.0, distance - slack) / estimate.error, controller, metric, estimate.text(),
                          reference[metric]))
            assert distance <= estimate.error + slack, (
                f"{name}/{controller} {metric}: {estimate.text()} ({estimate.where()}) is {distance:.3g} from the "
                f"continuous-time value {reference[metric]:.10g} (its own error {slack:.2g})")
            if omitted is not None and metric not in claims.GRID_QUANTISED and math.isfinite(estimate.error):
                # a smooth plant's ladder has no plant axis: the RK4 error (fourth order in h_p) the left-out run
                # shows at the table's plant step stays a small part of the printed error
                table = next(row for row in ladder if row["step"] == omitted["step"])
                h, other = table["plant_step"], omitted["plant_step"]
                rk4 = abs(omitted[metric] - table[metric]) * h ** 4 / abs(other ** 4 - h ** 4)
                shares.append(claims.SAFETY_FACTOR * rk4 / estimate.error)
                assert claims.SAFETY_FACTOR * rk4 <= SMOOTH_PLANT_SHARE * estimate.error + 1e-12 * abs(estimate.value), (
                    f"{name}/{controller} {metric}: the plant axis shows an RK4 error {rk4:.3g} beside "
                    f"{estimate.text()}")
    worst.sort(reverse=True)
    print(f"\n{name}: the largest distances to the continuous-time value, as a fraction of the printed error:")
    for ratio, controller, metric, text, value in worst[:5]:
        print(f"  {ratio:.2f} {controller} {metric}: {text} against {value:.10g}")
    if shares:
        print(f"  the left-out plant axis' RK4 error: at most {max(shares):.3f} of the printed error")

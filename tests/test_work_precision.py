"""harness/studies/work_precision.py: every point of every ladder measured, the verdict at 0.01 %, the figure."""
from __future__ import annotations

import json
import math

import pytest

from harness.fmu_build import native as build_native
from harness import cli
from harness.studies import work_precision as wp

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")


def point(series, cpu, error, step=1e-4, rtol=None):
    return {"scenario": "s", "series": series, "status": "ok", "cpu_s": cpu, "error": error, "step": step,
            "rtol": rtol, "rows": 10}


def test_the_verdict_takes_the_cheapest_point_within_the_target():
    points = [point("feedthrough", 0.3, 2e-4), point("feedthrough", 0.5, 5e-5), point("jacobi", 0.4, 3e-4),
              point("me", 0.6, 1e-6, rtol=1e-8), point("me", 0.2, 5e-4, rtol=1e-6), point("me-1ms", 0.1, 2e-5, rtol=1e-8)]
    verdict = wp.verdicts({"points": points, "target": 1e-4})["s"]
    assert verdict["best"]["feedthrough"]["cpu_s"] == 0.5 and verdict["best"]["jacobi"] is None
    assert verdict["cheapest_co_simulation_s"] == 0.5
    assert verdict["met"] == {"me": False, "me-1ms": True}


def test_a_short_run_measures_every_point_and_draws_the_figure(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(wp, "RTOLS", (1e-5, 1e-8))
    monkeypatch.setitem(wp.LADDERS, "pendulum_case1", {"feedthrough": (5e-4, 2.5e-4), "jacobi": (1e-4,)})
    assert cli.main(["work-precision", "pendulum_case1", "--stop", "0.1", "--repeat", "1", "--edition", "native",
                     "--out", str(tmp_path)]) == 0
    study = json.loads((tmp_path / "work_precision.json").read_text())
    assert len(study["points"]) == 2 + 1 + 2 + 2
    assert all(p["status"] == "ok" and p["cpu_s"] > 0 and math.isfinite(p["ITAE"]) for p in study["points"])
    assert {p["step"] for p in study["points"] if p["series"] == "me-1ms"} == {1e-3}
    assert (tmp_path / "work_precision.png").stat().st_size > 10_000
    assert "## At 0.01 % accuracy" in (tmp_path / "work_precision.md").read_text()

"""A host written in C (tests/c_host/host.c) runs the controller FMU as fmpy does, and gets an error
status and the FMU's message for a bad parameter."""
from __future__ import annotations

import math
import os
import pathlib
import shutil
import subprocess
import sys
import sysconfig

import numpy as np
import pytest
from fmpy import read_model_description

from tests.fmu_variables import driven

ROOT = pathlib.Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------- C host
def libpython_path():
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    path = pathlib.Path(sysconfig.get_config_var("LIBDIR") or "", sysconfig.get_config_var("LDLIBRARY") or "")
    return path if path.is_file() else None


def host_inputs(steps, h):
    rows = []
    for n in range(steps):
        t = n * h
        rows.append((0.3 * math.cos(1.7 * t) + 0.1 * math.sin(5 * t), -0.51 * math.sin(1.7 * t) + 0.5 * math.cos(5 * t),
                     math.pi / 6 * math.sin(t), math.pi / 6 * math.cos(t)))
    return rows


@pytest.fixture(scope="module")
def c_host(tmp_path_factory):
    library = libpython_path()
    if library is None:
        pytest.skip("this Python is statically linked (no shared libpython to LD_PRELOAD for the C host)")
    compiler = shutil.which("cc")
    if compiler is None:
        pytest.skip("no C compiler `cc` on PATH")
    binary = tmp_path_factory.mktemp("c_host") / "host"
    subprocess.run([compiler, "-O2", "-Wall", "-Werror", "-o", str(binary), str(ROOT / "tests" / "c_host" / "host.c"),
                    "-ldl"], check=True, capture_output=True, text=True)
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    environment.update(LD_PRELOAD=str(library), PYTHONHOME=sys.base_prefix, PYTHONNOUSERSITE="1")
    return binary, environment


def run_c_host(c_host, fmu_path, unzip_dir, h, rows, parameters=()):
    binary, environment = c_host
    md = read_model_description(str(fmu_path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    kinds = {v.name: v.type for v in md.modelVariables}
    arguments = [f"{'i' if kinds[n] == 'Integer' else 'r'}:{vr[n]}={value!r}" for n, value in parameters]
    command = [str(binary), str(pathlib.Path(unzip_dir, "binaries", "linux64", f"{md.coSimulation.modelIdentifier}.so")),
               pathlib.Path(unzip_dir, "resources").as_uri(), md.guid, repr(h),
               ",".join(str(vr[n]) for n in ("e", "de", "ym", "dym")), str(vr["u"]), *arguments]
    stdin = "".join(" ".join(repr(x) for x in row) + "\n" for row in rows)
    return subprocess.run(command, input=stdin, capture_output=True, text=True, env=environment, timeout=120,
                          cwd=str(unzip_dir))


@pytest.mark.parametrize("variant", [1, 3])
def test_a_c_host_runs_the_controller_fmu_like_fmpy(fmu_paths, unzipped, c_host, variant):
    h, steps = 0.01, 200
    rows = host_inputs(steps, h)
    completed = run_c_host(c_host, fmu_paths["AdaptiveFuzzyController"], unzipped["AdaptiveFuzzyController"],
                           h, rows, [("variant", variant), ("gamma", 250.0)])
    assert completed.returncode == 0, completed.stderr
    from_c = np.array([float(line) for line in completed.stdout.split()])
    python = driven(fmu_paths, unzipped, "AdaptiveFuzzyController", "python")
    python.initialize(variant=variant, gamma=250.0, **dict(zip(("e", "de", "ym", "dym"), rows[0])))
    expected = []
    for n, row in enumerate(rows):
        python.set(**dict(zip(("e", "de", "ym", "dym"), row)))
        expected.append(python.get("u"))
        python.slave.doStep(n * h, h)
    python.free()
    assert len(from_c) == steps and np.max(np.abs(expected)) > 1.0
    np.testing.assert_allclose(from_c, expected, rtol=0, atol=1e-12)


def test_a_c_host_gets_an_error_status_and_message_for_a_bad_parameter(fmu_paths, unzipped, c_host):
    completed = run_c_host(c_host, fmu_paths["AdaptiveFuzzyController"], unzipped["AdaptiveFuzzyController"],
                           0.01, host_inputs(3, 0.01), [("lambda_ce", 1.0)])
    assert completed.returncode == 3, completed.stderr  # an FMI call returned error or fatal
    assert "parameter lambda_ce = 1.0 is invalid; valid range: (0, 1)" in completed.stderr
    assert "fmi2ExitInitializationMode returned" in completed.stderr
    assert "instance freed after the error" in completed.stderr  # the host survived the error path



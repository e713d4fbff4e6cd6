"""OpenModelica's OMSimulator as a host of the host matrix (harness/hosts/matrix.py).

OMSimulator (3.0) is not on PyPI for these machines (its source package downloads a binary at
build time); where it is installed (``import OMSimulator`` works: for example after sourcing the
env.sh of a build of it), the matrix runs our SSP packages (harness/hosts/ssp.py) in it three ways:

* its Python API (``SSP``, ``instantiate``), weakly coupled: the co-simulation FMUs under its
  co-simulation master, which respects direct feedthrough.  This API reads no step annotation of the
  SSP (neither ours, libcosim's, nor OMSimulator's own ``FixedStepMaster``): with none set it runs at
  1 ms, so the step is set by hand, ``setFixedStepSize`` (docs/hosts.md);
* its C API's ``oms_importFile`` (what its older Python API and tools wrap), weakly coupled: it takes
  the master's step from the package's ``org.openmodelica`` annotation (``oms:FixedStepMaster``),
  which export-ssp writes: nothing is set by hand;
* its Python API on an ``--algorithm me`` package: the SSP declares one CVODE solver with a
  relative tolerance and assigns every component to it, so OMSimulator builds one strongly coupled
  system and integrates the FMUs' Model Exchange interface with its CVODE (the native edition);
  nothing is set by hand but the output grid (its CVODE's maximum step, which is also where it writes
  results).

Each run writes its result file (CSV) into a private temporary folder; OMSimulator's own temporary
folders (its Python API makes them with ``tempfile.mkdtemp``) go there too and are removed with it.
"""
from __future__ import annotations

import contextlib
import csv
import ctypes
import importlib.util
from pathlib import Path

import numpy as np

from .. import unpack

MODULE = "OMSimulator"


def unavailable() -> str | None:
    """None if OMSimulator can be imported here, else why not (and how to get it)."""
    if importlib.util.find_spec(MODULE) is None:
        return ("OMSimulator is not importable (pip cannot install it on these machines; build it or source the "
                "env.sh of a build, then run again)")
    return None


@contextlib.contextmanager
def private_temp_dir():
    """A temporary folder that OMSimulator's folders also go into (``tempfile.tempdir``), removed afterwards;
    OMSimulator's count of warnings and errors is printed before it is (:func:`flush_log_counts`)."""
    with unpack.private_temporary_folder("oms") as folder:
        try:
            yield Path(folder)
        finally:
            flush_log_counts(Path(folder))


def flush_log_counts(folder: Path) -> None:
    """Have OMSimulator print its count of logged warnings and errors now, and start counting from 0.

    It prints the count ("info:    0 warnings", "info:    1 errors") when its log target changes, and
    at process exit when the count is not 0: after the caller (a test session, a command) has printed its
    last line.  Switching the log to a file of ``folder`` and back to the console prints it here, where
    the caller captures the console."""
    from OMSimulator.capi import Capi  # optional: see unavailable(); loaded by the run this follows

    library = Capi.obj
    library.oms_setLogFile(str(folder / "omsimulator.log").encode())
    library.oms_setLogFile(b"")


def read_result(path: Path, names: list) -> tuple:
    """(time, {instance.variable: values}) from OMSimulator's CSV result: its columns are named
    ``[model.]system.instance.variable``; of rows with the same time (it writes one before and one after
    each communication point) the last is kept."""
    with open(path, newline="") as stream:
        rows = list(csv.reader(stream))
    header = rows[0]
    table = np.array([[float(v) for v in row] for row in rows[1:] if row], dtype=float)
    time = table[:, 0]
    keep = np.r_[time[1:] != time[:-1], True]
    table = table[keep]
    columns = {}
    for name in names:
        matches = [k for k, column in enumerate(header) if column.endswith("." + name)]
        if not matches:
            raise RuntimeError(f"OMSimulator's result has no column for {name}")
        columns[name] = table[:, matches[0]]
    return table[:, 0], columns


def run_python_api(package: Path, stop: float, names: list, fixed_step: float | None = None,
                   output_step: float | None = None) -> tuple:
    """The package through OMSimulator's Python API; ``fixed_step``: its co-simulation master's step (set by
    hand); ``output_step``: a strongly coupled system's maximum step (its output grid)."""
    from OMSimulator import SSP, Settings  # optional: see unavailable()

    Settings.suppressPath = True
    with private_temp_dir() as folder:
        model = SSP(str(package), temp_dir=str(folder))
        instance = model.instantiate()
        result = folder / "result.csv"
        instance.setResultFile(str(result))
        instance.setStopTime(stop)
        if fixed_step is not None:
            instance.setFixedStepSize(fixed_step)
        if output_step is not None:
            instance.setVariableStepSize(1e-6 * output_step, 1e-12, output_step)
        instance.initialize()
        instance.simulate()
        instance.terminate()
        instance.delete()
        del model
        return read_result(result, names)


def run_c_api(package: Path, stop: float, names: list) -> tuple:
    """The package through OMSimulator's C API (``oms_importFile``): the step from the package's annotation."""
    from OMSimulator.capi import Capi  # optional: see unavailable(); the library its Python API loaded

    library = Capi.obj
    library.oms_importFile.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_char_p)]
    library.oms_importFile.restype = ctypes.c_int
    with private_temp_dir() as folder:
        library.oms_setTempDirectory(str(folder).encode())
        model = ctypes.c_char_p()
        status = library.oms_importFile(str(package).encode(), ctypes.byref(model))
        if status != 0 or not model.value:
            raise RuntimeError(f"oms_importFile returned status {status}")
        cref = model.value
        try:
            result = folder / "result.csv"
            calls = [("oms_setResultFile", lambda: library.oms_setResultFile(cref, str(result).encode(), 1)),
                     ("oms_setStopTime", lambda: library.oms_setStopTime(cref, ctypes.c_double(stop))),
                     ("oms_instantiate", lambda: library.oms_instantiate(cref)),
                     ("oms_initialize", lambda: library.oms_initialize(cref)),
                     ("oms_simulate", lambda: library.oms_simulate(cref))]
            for function, call in calls:
                status = call()
                if status != 0:
                    raise RuntimeError(f"{function} returned status {status}")
            library.oms_terminate(cref)
        finally:
            library.oms_delete(cref)
        return read_result(result, names)


__all__ = ["unavailable", "run_python_api", "run_c_api", "read_result", "MODULE"]

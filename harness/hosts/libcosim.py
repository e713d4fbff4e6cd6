"""Run an exported SSP in libcosim (``pip install libcosimpy``), with a chosen number of worker threads.

libcosim's fixed-step algorithm starts hardware_concurrency - 1 worker threads unless the
SSD says otherwise; its Python API has no knob.  :func:`with_algorithm` adds the
annotation that sets it (``osp:FixedStepAlgorithm numWorkerThreads``, with the ``osp``
namespace declared on the ``ssc:Annotation`` element, as libcosim requires) to a copy of
the package.  :func:`run_libcosim` then runs it and returns the last values of the
requested variables and the cost per step of libcosim's own loop.
"""
from __future__ import annotations

import time as clock
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

NS_OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations"


class LibcosimUnavailable(RuntimeError):
    """libcosimpy is not installed or cannot load."""


@dataclass
class LibcosimRun:
    steps: int
    loop_us_per_step: float  # libcosim's stepping alone
    last_values: dict  # "instance.variable" -> value at the stop time
    recorded_samples: int = 0  # samples of each ``record`` variable the time-series observer holds
    recorded_last_values: dict = field(default_factory=dict)  # its last sample of each


def with_algorithm(ssp_path, out_dir, step: float, workers: int = 0) -> Path:
    """A copy of the SSP package (as a folder) whose SSD fixes libcosim's step and worker threads."""
    out_dir = Path(out_dir)
    with zipfile.ZipFile(ssp_path) as archive:
        archive.extractall(out_dir)
    ssd = out_dir / "SystemStructure.ssd"
    text = ssd.read_text(encoding="utf-8")
    annotation = (f'      <ssc:Annotation type="com.opensimulationplatform" xmlns:osp="{NS_OSP}">\n'
                  f'        <osp:Algorithm><osp:FixedStepAlgorithm baseStepSize="{step!r}" '
                  f'numWorkerThreads="{int(workers)}"/></osp:Algorithm>\n'
                  "      </ssc:Annotation>\n")
    marker = "    </ssd:Annotations>\n  </ssd:DefaultExperiment>"
    if marker not in text:
        raise ValueError(f"{ssd}: no DefaultExperiment annotations to extend (not exported by harness/hosts/ssp.py?)")
    ssd.write_text(text.replace(marker, annotation + marker, 1), encoding="utf-8")
    return out_dir


def run_libcosim(package_dir, stop: float, step: float, variables=(), record=()) -> LibcosimRun:
    """Run the package folder made by :func:`with_algorithm` to ``stop``; read ``variables`` at the end.

    ``record``: "instance.variable" names that a time-series observer records at every step (what
    our master records; libcosim then reads only those and the connected outputs).  ``variables``
    uses a last-value observer, which makes libcosim read every variable of every FMU at every step
    (on the pendulum loop with native FMUs: 2.3 us per step instead of 1.1 with no observer).
    """
    try:  # optional (the hosts and test extras): imported here, where a missing package is one clear error
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimObserver import CosimObserver
    except ImportError as error:  # pragma: no cover - depends on the machine
        raise LibcosimUnavailable(f"libcosim needs libcosimpy, in the hosts extra: pip install -e '.[hosts]' "
                                  f"({error})") from error
    log_output_level(CosimLogLevel.WARNING)
    execution = CosimExecution.from_ssp_file(str(package_dir), step_size=None)
    steps = round(stop / step)
    if variables:
        observer = CosimObserver.create_last_value()
        execution.add_observer(observer)
    if record:
        series = CosimObserver.create_time_series(buffer_size=steps + 1)
        execution.add_observer(series)
        observed = []
        for dotted in record:
            slave, reference = _reference(execution, dotted)
            if not series.start_time_series(slave, reference, CosimVariableType.REAL):
                raise RuntimeError(f"libcosim: cannot observe {dotted} with a time-series observer")
            observed.append((slave, reference))
    indices = {dotted: _reference(execution, dotted) for dotted in variables}
    started = clock.perf_counter()
    execution.step(steps)
    elapsed = clock.perf_counter() - started
    last = {dotted: observer.last_real_values(slave, [reference])[0]
            for dotted, (slave, reference) in indices.items()}
    recorded, recorded_last = 0, {}
    if record:  # what the observer holds: a sample of each variable at each step
        series_of = {dotted: series.time_series_real_samples(slave, reference, 1, steps + 1)[2]
                     for dotted, (slave, reference) in zip(record, observed)}  # [2]: (times, steps, values)
        recorded = min(len(values) for values in series_of.values())
        recorded_last = {dotted: values[-1] for dotted, values in series_of.items() if values}
    return LibcosimRun(steps=steps, loop_us_per_step=1e6 * elapsed / steps, last_values=last,
                       recorded_samples=recorded, recorded_last_values=recorded_last)


def _reference(execution, dotted: str) -> tuple[int, int]:
    """(slave index, value reference) of "instance.variable"."""
    instance, _, name = dotted.partition(".")
    slave = execution.slave_index_from_instance_name(instance)
    return slave, next(v.reference for v in execution.slave_variables(slave) if v.name.decode() == name)

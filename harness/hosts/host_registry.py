"""The host registry of the host matrix: one :class:`Host` row per host, with the runner that runs it
(harness/hosts/host_runners.py), what it needs, and whether it can run here."""
from __future__ import annotations

import functools
import importlib.util
from dataclasses import dataclass
from itertools import permutations
from typing import Callable

from harness.fmu_build import native as build_native

from ..me_master import DEFAULT_RTOL
from . import omsimulator
from .host_runners import (COMPONENT_ORDER, run_container, run_ecos, run_fmpy_ssp, run_libcosim_api,
                           run_libcosim_ssp, run_omsimulator, run_ours, run_ours_me, run_plain_fmpy)


@dataclass(frozen=True)
class Host:
    """One row of the host registry (``HOSTS`` below; its runner is in harness/hosts/host_runners.py)."""

    key: str
    name: str
    settings: str
    family: str  # "feedthrough": our master's validated step applies; "jacobi": the Jacobi one
    run: Callable  # (scenario, fmu_paths, package) -> (Trajectory, warnings, where the warnings come from)
    package: str | None = None  # the PyPI distribution it needs beyond the project's dependencies
    module: str | None = None  # that distribution's import name (checked before the host runs)
    needs_ssp: bool = False  # runs the scenario exported as an SSP package (handed to ``run`` as ``package``)
    ssp_rtol: float | None = None  # the package is an --algorithm me one with this CVODE tolerance
    unavailable: Callable | None = None  # () -> why the host cannot run here, or None (instead of ``module``)
    edition: str | None = None  # "native": the native FMUs (FMI 2.0) whatever edition the matrix runs
    max_steps: int | None = None  # the longest run it is given, in communication steps (its memory grows per step)

    @property
    def model_exchange(self) -> bool:
        return self.family == "me"

    def horizon(self, stop: float, step: float) -> float:
        """The stop time of its run: ``stop``, or the last whole step within ``max_steps``."""
        if self.max_steps is None or stop <= self.max_steps * step:
            return stop
        return round(self.max_steps * step, 12)


def host_available(host: Host) -> str | None:
    """None if the host can run here, else the reason."""
    if host.module and importlib.util.find_spec(host.module) is None:
        return f"{host.package} is not installed (pip install -e '.[hosts]')"
    if host.unavailable is not None and host.unavailable():
        return host.unavailable()
    if host.edition == "native" and not build_native.compiler_available():
        return "it runs the native edition's FMUs, and zig's C compiler is not installed (pip install -e .)"
    return None


#: OMSimulator keeps what it simulates in memory, more with every step (docs/other_hosts.md has the
#: figure): its runs stop after this many steps
OMSIMULATOR_MAX_STEPS = 40_000


#: one row per host: a new host is its runner (harness/hosts/host_runners.py) and its row here
HOSTS = [
    Host("ours-feedthrough", "our master", "feedthrough-aware; consistent initial values", "feedthrough",
         functools.partial(run_ours, algorithm="feedthrough")),
    Host("ours-jacobi", "our master", "--algorithm jacobi; consistent initial values", "jacobi",
         functools.partial(run_ours, algorithm="jacobi")),
    Host("fmpy-jacobi", "plain fmpy script (FMU2Slave)", "Jacobi; no initial-value propagation", "jacobi",
         run_plain_fmpy),
    *(Host(f"fmpy-gs-{'-'.join(order)}", "plain fmpy script (FMU2Slave)",
           f"Gauss-Seidel {' > '.join(order)}; no initial-value propagation", "jacobi",
           functools.partial(run_plain_fmpy, order=order)) for order in permutations(COMPONENT_ORDER)),
    Host("fmpy-ssp", "fmpy.ssp (simulate_ssp)", "exported SSP with start values of the inputs; Jacobi", "jacobi",
         run_fmpy_ssp, needs_ssp=True),
    Host("ecos", "Ecos (ecospy)", "exported SSP; Jacobi; propagates initial values", "jacobi", run_ecos,
         "ecospy", "ecospy", needs_ssp=True),
    Host("libcosim-ssp", "libcosim (libcosimpy)", "exported SSP, OSP annotation numWorkerThreads=0; Jacobi",
         "jacobi", run_libcosim_ssp, "libcosimpy", "libcosimpy", needs_ssp=True),
    Host("libcosim-api", "libcosim (libcosimpy)", "FMUs wired through its API, default worker threads; Jacobi",
         "jacobi", run_libcosim_api, "libcosimpy", "libcosimpy"),
    Host("fmutool-parallel", "fmu-manipulation-toolbox container", "parallel (Jacobi); run by fmpy", "jacobi",
         functools.partial(run_container, mode="parallel"), "fmu-manipulation-toolbox", "fmu_manipulation_toolbox"),
    Host("fmutool-seq-forward", "fmu-manipulation-toolbox container",
         "sequential plant > reference > controller; run by fmpy", "jacobi",
         functools.partial(run_container, mode="seq-forward"), "fmu-manipulation-toolbox", "fmu_manipulation_toolbox"),
    Host("fmutool-seq-reverse", "fmu-manipulation-toolbox container",
         "sequential controller > reference > plant; run by fmpy", "jacobi",
         functools.partial(run_container, mode="seq-reverse"), "fmu-manipulation-toolbox", "fmu_manipulation_toolbox"),
    Host("ours-me", "our master", f"--algorithm me: Model Exchange, CVODE rtol {DEFAULT_RTOL:g}; native edition", "me",
         run_ours_me, edition="native"),
    Host("omsimulator-wc", "OMSimulator 3 (Python API)", "exported SSP; its co-simulation master, step set by hand "
         "(setFixedStepSize: this API reads no step annotation)", "feedthrough",
         functools.partial(run_omsimulator, api="python"), needs_ssp=True, unavailable=omsimulator.unavailable,
         edition="native", max_steps=OMSIMULATOR_MAX_STEPS),
    Host("omsimulator-wc-capi", "OMSimulator 3 (C API oms_importFile)", "exported SSP; its co-simulation master, "
         "step from the SSP's org.openmodelica annotation", "feedthrough",
         functools.partial(run_omsimulator, api="capi"), needs_ssp=True, unavailable=omsimulator.unavailable,
         edition="native", max_steps=OMSIMULATOR_MAX_STEPS),
    Host("omsimulator-sc", "OMSimulator 3 (Python API)", "export-ssp --algorithm me --rtol 1e-8: strongly coupled, "
         "its CVODE over the Model Exchange FMUs; native edition", "me",
         functools.partial(run_omsimulator, api="sc"), needs_ssp=True, ssp_rtol=1e-8,
         unavailable=omsimulator.unavailable, edition="native", max_steps=OMSIMULATOR_MAX_STEPS),
]
HOSTS_BY_KEY = {h.key: h for h in HOSTS}

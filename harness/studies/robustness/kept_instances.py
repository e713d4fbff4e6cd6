"""A master that keeps its FMU instances from one run to the next (:class:`KeptInstancesMaster`), for a
study of thousands of short runs of one scenario whose runs differ in parameter values only.

Each FMU is read and extracted once per process (harness/fmi.py, ``extracted_fmu``) and instantiated
once; before every later run its instance is reset with fmi2Reset (fmi3Reset for FMI 3.0), which
puts it back in the instantiated state with its start values (FMI 2.0 section 2.1.6, FMI 3.0 section
2.3.1), and the run then sets up, sets the run's parameters and initialises it as a new one.  An
instance whose run did not complete, or whose reset fails, is freed and a new one instantiated:
reuse never carries an error over.  FMUs built by pythonfmu implement no fmi2Reset: they are
instantiated for every run.
"""
from __future__ import annotations

from ...fmi import PYTHONFMU, Component, FmiError, extracted_fmu
from ...master import Master
from ...scenario_checks import resolve_fmu


class KeptInstancesMaster(Master):
    """``run_scenario(scenario)`` runs a scenario of the same components, connections and FMUs as the
    one given here, with the FMU instances of the previous run reset rather than made anew."""

    def __init__(self, scenario, algorithm: str = "feedthrough", fmu_paths: dict | None = None):
        prepared = {}
        for spec in scenario.components.values():
            path = resolve_fmu(spec.fmu, scenario, fmu_paths)
            prepared[path] = extracted_fmu(path)
        super().__init__(scenario, algorithm, fmu_paths, prepared=prepared)
        self.kept: dict = {}  # instance name -> its Component, between two runs
        self.reused = self.made = 0  # instances reset, instances made (for the study's figures)

    def run_scenario(self, scenario, progress=None):
        """One run; without ``progress``, the whole loop in one call of the compiled loop."""
        self.scenario = scenario
        return self.run(progress=progress, progress_every=0 if progress is not None else max(1, scenario.steps))

    def _reusable(self, name: str) -> bool:
        return not self.infos[name].generation_tool.startswith(PYTHONFMU)

    def _instantiate(self, name: str) -> Component:
        component = self.kept.pop(name, None)
        if component is not None:
            try:
                component._call("fmi3Reset" if component.fmi3 else "fmi2Reset", component.slave.reset)
            except FmiError:
                component.free()
            else:
                component.log = []  # the new run's messages only (the logger appends to this list)
                self.reused += 1
                return component
        self.made += 1
        return super()._instantiate(name)

    def _release_components(self, completed: bool):
        for name, component in self.components.items():
            if completed and self._reusable(name):
                self.kept[name] = component
            else:
                component.free()

    def close(self):
        """Free the kept instances (the process's extracted FMUs stay until it ends)."""
        while self.kept:
            _, component = self.kept.popitem()
            try:
                component.free()
            except Exception:  # noqa: BLE001 - freeing at the end: what cannot be freed goes with the process
                pass


__all__ = ["KeptInstancesMaster"]

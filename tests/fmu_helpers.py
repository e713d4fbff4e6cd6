"""Small helpers for driving one FMU through fmpy's low-level API in tests."""
import shutil
import weakref

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi2 import defaultCallbacks


class Driven:
    """An instantiated FMU with name-based set/get and captured log messages."""

    def __init__(self, path, instance_name="instance", unzip_dir=None, logging_on=True):
        self.md = read_model_description(str(path))
        self.unzip_dir = unzip_dir or extract(str(path))
        # an extraction of its own is removed by free(), else when the helper is forgotten or at exit
        self._remove_extraction = (weakref.finalize(self, shutil.rmtree, self.unzip_dir, True)
                                   if unzip_dir is None else None)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.messages = []
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip_dir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier,
                               instanceName=instance_name)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        callbacks.allocateMemory = defaultCallbacks.allocateMemory
        callbacks.freeMemory = defaultCallbacks.freeMemory
        self._callbacks = callbacks
        self.slave.instantiate(callbacks=callbacks, loggingOn=logging_on)

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, message.decode("utf-8", "replace")))

    def enter(self, start_time=0.0, **values):
        """setupExperiment, enterInitializationMode, then set ``values``."""
        self.slave.setupExperiment(startTime=start_time)
        self.slave.enterInitializationMode()
        self.set(**values)
        return self

    def initialize(self, start_time=0.0, **values):
        self.enter(start_time, **values)
        self.slave.exitInitializationMode()
        return self

    def set(self, **values):
        for name, value in values.items():
            if self.types[name] == "Integer":
                self.slave.setInteger([self.vr[name]], [int(value)])
            else:
                self.slave.setReal([self.vr[name]], [float(value)])

    def get(self, *names):
        values = self.slave.getReal([self.vr[n] for n in names])
        return values[0] if len(names) == 1 else values

    def free(self):
        try:
            self.slave.terminate()
        except Exception:
            pass
        self.slave.freeInstance()
        if self._remove_extraction is not None:
            self._remove_extraction()

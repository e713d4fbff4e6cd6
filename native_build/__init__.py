"""The native edition's build, one module per stage (build_native.py runs them in order).

* :mod:`native_build.targets`: the platforms and zig targets;
* :mod:`native_build.model_exchange`: each model's Model Exchange declaration and its XML;
* :mod:`native_build.description`: the FMI 2.0 and 3.0 modelDescription.xml and the GUID;
* :mod:`native_build.header`: ``model_variables.h``, the declaration table for the C layer;
* :mod:`native_build.compiler`: one cached shared library per model, FMI version and target;
* :mod:`native_build.sources`: what compiles the FMU from its ``sources/`` (FMI 2.0 ``<SourceFiles>`` and
  the ``fmi2_layer.c`` unit, FMI 3.0 ``buildDescription.xml``);
* :mod:`native_build.ls_ref`: the FMI-LS-REF files (manifest, stimuli, reference) of the stored experiment;
* :mod:`native_build.package`: the FMU archives (sources, binaries, the fat Mach-O, FMI-LS-REF), written atomically.
"""
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYER = (ROOT / "fmu_src" / "fmi_layer.c", ROOT / "fmu_src" / "fmi_layer.h")  # the FMI layer every model links

"""The native edition's build, one module per stage (harness/fmu_build/native.py runs them in order).

* :mod:`harness.fmu_build.native_stages.targets`: the platforms and zig targets;
* :mod:`harness.fmu_build.native_stages.model_exchange`: each model's Model Exchange declaration and its XML;
* :mod:`harness.fmu_build.native_stages.description`: the FMI 2.0 and 3.0 modelDescription.xml and the GUID;
* :mod:`harness.fmu_build.native_stages.header`: ``model_variables.h``, the declaration table for the C layer;
* :mod:`harness.fmu_build.native_stages.compiler`: one cached shared library per model, FMI version and target;
* :mod:`harness.fmu_build.native_stages.sources`: what compiles the FMU from its ``sources/`` (FMI 2.0 ``<SourceFiles>`` and
  the ``fmi2_layer.c`` unit, FMI 3.0 ``buildDescription.xml``);
* :mod:`harness.fmu_build.native_stages.ls_ref`: the FMI-LS-REF files (manifest, stimuli, reference) of the stored experiment;
* :mod:`harness.fmu_build.native_stages.package`: the FMU archives (sources, binaries, the fat Mach-O, FMI-LS-REF), written atomically.
"""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]  # the repository
LAYER = (ROOT / "fmu_src" / "fmi_layer.c", ROOT / "fmu_src" / "fmi_layer.h")  # the FMI layer every model links

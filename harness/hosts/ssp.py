"""Export a scenario as an SSP 1.0 package: ``python -m harness export-ssp SCENARIO --controller C --out F.ssp``.

The package is a zip file holding

* ``SystemStructure.ssd``: one ``ssd:Component`` per instance with
  ``source="resources/<ModelIdentifier>.fmu"``, its connectors (the connected
  inputs, the connected and recorded outputs, all Real), the connections,
  a ``ssd:DefaultExperiment`` (start, stop) and, per component, a
  ``ssd:ParameterBinding`` to ``resources/<instance>.ssv``;
* the communication step in every annotation the SSP engines we know read (SSP 1.0 has no
  attribute for it; docs/hosts.md says which engine takes which): ours
  (``org.afc-fmi.experiment`` in the DefaultExperiment), libcosim's
  (``com.opensimulationplatform``: ``osp:FixedStepAlgorithm`` with 0 worker threads, in the
  DefaultExperiment) and OpenModelica's (``org.openmodelica`` on the System:
  ``oms:SimulationInformation`` / ``oms:FixedStepMaster stepSize``, which OMSimulator's C API
  ``oms_importFile`` reads; its 3.0 Python API reads no step annotation: ``setFixedStepSize``);
* with ``--algorithm me`` (native FMUs, which carry Model Exchange) the System's
  ``org.openmodelica`` annotation instead declares one CVODE solver with the relative tolerance
  ``--rtol`` and every component is assigned to it: OMSimulator's Python API then runs the
  loop strongly coupled, integrating the FMUs' Model Exchange interface with CVODE (no step);
* ``resources/<instance>.ssv``: an ``ssv:ParameterSet`` named
  ``initialValues`` with the scenario's parameter values of that instance
  (and the controller variant), written with full precision;
* ``resources/<ModelIdentifier>.fmu``: the FMUs, unchanged.

Start values of the connected inputs (``--start-inputs``, on by default)
----------------------------------------------------------------------
An engine that does not propagate values along the connections before
``fmi2ExitInitializationMode`` (fmpy's SSP simulator starts every connector
at 0) would hand the controller e(0) = de(0) = 0, and the controller latches
those for the modified error of Remark 3 (docs/model.md section 5 (the modified
tracking error)): the modification is then off.  With ``--start-inputs`` each connected input also gets, in its
instance's parameter set, the consistent start value that our master
propagates at the start time (e.g. ``controller.e = ym(0) - y(0)``).  SSP
parameter bindings may set the start values of inputs (they are applied
before initialisation); an engine that does propagate (Ecos, our master)
overwrites them with the same values, so they are harmless there.

Both namespace prefixes and element names are the literal ones Ecos's
parser looks for (``ssd:``, ``ssc:``, ``ssv:``), and the files validate
against the SSP 1.0 schemas that fmpy ships.
"""
from __future__ import annotations

import argparse
import copy
import datetime
import sys
import zipfile
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from harness.fmu_build import builder as build_fmu

from .. import atomic_files, cli_args, variants
from .. import scenario as scenarios
from ..fmi import ModelInfo
from ..master import simulate
from ..me_master import DEFAULT_RTOL, check_tolerances, model_exchange_info
from ..scenario import Scenario, ScenarioError
from ..scenario_checks import resolve_fmu, validate
from ..studies.step_study import load_convergence, validated_step

NS_SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
NS_SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
NS_SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
NS_AFC = "https://afc-fmi.invalid/ssp/experiment"  # our annotation (step size), ignored by other tools
NS_OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations"  # libcosim's algorithm annotation
NS_OMS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"  # OMSimulator's
OMS_SOLVER = "cvode"  # the name of the one solver of an --algorithm me package
PARAMETER_SET = "initialValues"
ANNOTATION_TYPE = "org.afc-fmi.experiment"


def _number(value) -> str:
    """Full precision: repr of a float round-trips exactly."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def _ssv(name: str, parameters: dict, infos: ModelInfo, description: str) -> str:
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<ssv:ParameterSet xmlns:ssv="{NS_SSV}" version="1.0" name="{PARAMETER_SET}" '
             f'description={quoteattr(description)}>',
             "  <ssv:Parameters>"]
    for parameter, value in parameters.items():
        variable = infos.variables[parameter]
        kind = {"Integer": "Integer", "Boolean": "Boolean", "Enumeration": "Integer"}.get(variable.type, "Real")
        if kind == "Integer":
            text = str(int(value))
        elif kind == "Boolean":
            text = "true" if value else "false"
        else:
            text = _number(float(value))
        lines.append(f'    <ssv:Parameter name={quoteattr(parameter)}><ssv:{kind} value="{text}"/></ssv:Parameter>')
    lines += ["  </ssv:Parameters>", "</ssv:ParameterSet>", ""]
    return "\n".join(lines)


def initial_inputs(scenario: Scenario, fmu_paths: dict | None = None) -> dict:
    """{"instance.input": value}: what our master propagates to each connected input at the start time."""
    probe = copy.deepcopy(scenario)
    probe.record = list(dict.fromkeys([*scenario.record, *(c.source for c in scenario.connections)]))
    probe.stop = probe.start + probe.step
    result = simulate(probe, fmu_paths=fmu_paths)
    return {c.target: float(result.signal(c.source)[0]) for c in scenario.connections}


def connectors(scenario: Scenario, infos: dict) -> dict:
    """{instance: [(variable, kind)]}: connected inputs, connected or recorded outputs."""
    result = {name: [] for name in scenario.components}
    for name in scenario.components:
        wanted = {c.target_variable for c in scenario.connections if c.target_instance == name}
        wanted |= {c.source_variable for c in scenario.connections if c.source_instance == name}
        wanted |= {d.split(".", 1)[1] for d in scenario.record if d.split(".", 1)[0] == name}
        for variable in infos[name].variables.values():  # model description order
            if variable.name in wanted:
                if variable.type != "Real":
                    raise ScenarioError(f"{name}.{variable.name} is {variable.type}: the export handles Real connectors")
                result[name].append((variable.name, variable.causality))
    return result


def _oms_annotation(indent: str, body: list) -> list:
    return [f'{indent}<ssd:Annotations>', f'{indent}  <ssc:Annotation type="org.openmodelica">',
            f'{indent}    <oms:Annotations xmlns:oms="{NS_OMS}">', *(f"{indent}      {line}" for line in body),
            f"{indent}    </oms:Annotations>", f"{indent}  </ssc:Annotation>", f"{indent}</ssd:Annotations>"]


def system_structure(scenario: Scenario, infos: dict, sources: dict, name: str, rtol: float | None = None) -> str:
    """The text of SystemStructure.ssd; ``rtol``: an --algorithm me package (OMSimulator's CVODE solver)."""
    now = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<ssd:SystemStructureDescription xmlns:ssd="{NS_SSD}" xmlns:ssc="{NS_SSC}" xmlns:ssv="{NS_SSV}" '
             f'version="1.0" name={quoteattr(name)} generationTool="afc-fmi harness (python -m harness export-ssp)" '
             f'generationDateAndTime="{now}">',
             f'  <ssd:System name={quoteattr(scenario.name)} description={quoteattr(scenario.description)}>',
             "    <ssd:Elements>"]
    for instance, kinds in connectors(scenario, infos).items():
        lines.append(f'      <ssd:Component name={quoteattr(instance)} type="application/x-fmu-sharedlibrary" '
                     f'source={quoteattr(sources[instance])}>')
        lines.append("        <ssd:Connectors>")
        for variable, kind in kinds:
            lines.append(f'          <ssd:Connector name={quoteattr(variable)} kind="{kind}"><ssc:Real/></ssd:Connector>')
        lines.append("        </ssd:Connectors>")
        lines.append("        <ssd:ParameterBindings>")
        lines.append(f'          <ssd:ParameterBinding type="application/x-ssp-parameter-set" '
                     f'source="resources/{escape(instance)}.ssv"/>')
        lines.append("        </ssd:ParameterBindings>")
        if rtol is not None:  # OMSimulator: this component is integrated by the system's CVODE solver
            lines += _oms_annotation("        ", [f'<oms:SimulationInformation name="{OMS_SOLVER}"/>'])
        lines.append("      </ssd:Component>")
    lines.append("    </ssd:Elements>")
    lines.append("    <ssd:Connections>")
    for c in scenario.connections:
        lines.append(f'      <ssd:Connection startElement={quoteattr(c.source_instance)} '
                     f'startConnector={quoteattr(c.source_variable)} endElement={quoteattr(c.target_instance)} '
                     f'endConnector={quoteattr(c.target_variable)}/>')
    lines.append("    </ssd:Connections>")
    if rtol is None:  # OMSimulator's C API (oms_importFile) takes its co-simulation master's step from here
        lines += _oms_annotation("    ", ["<oms:SimulationInformation>",
                                        f'  <oms:FixedStepMaster description="oms-ma" '
                                        f'stepSize="{_number(scenario.step)}"/>',
                                        "</oms:SimulationInformation>"])
    else:  # OMSimulator's Python API: one strongly coupled system, CVODE over the Model Exchange FMUs
        lines += _oms_annotation("    ", [f'<oms:SimulationInformation name="{OMS_SOLVER}" method="cvode" '
                                        f'tolerance="{_number(rtol)}"/>'])
    lines.append("  </ssd:System>")
    lines.append(f'  <ssd:DefaultExperiment startTime="{_number(scenario.start)}" stopTime="{_number(scenario.stop)}">')
    lines.append("    <ssd:Annotations>")
    lines.append(f'      <ssc:Annotation type="{ANNOTATION_TYPE}">')
    lines.append(f'        <afc:Experiment xmlns:afc="{NS_AFC}" stepSize="{_number(scenario.step)}" '
                 f'parameterSet="{PARAMETER_SET}"/>')
    lines.append("      </ssc:Annotation>")
    # libcosim reads its algorithm from here; 0 worker threads: pythonfmu FMUs hold the GIL, threads only cost
    lines.append(f'      <ssc:Annotation type="com.opensimulationplatform" xmlns:osp="{NS_OSP}">')
    lines.append("        <osp:Algorithm>")
    lines.append(f'          <osp:FixedStepAlgorithm baseStepSize="{_number(scenario.step)}" numWorkerThreads="0"/>')
    lines.append("        </osp:Algorithm>")
    lines.append("      </ssc:Annotation>")
    lines.append("    </ssd:Annotations>")
    lines.append("  </ssd:DefaultExperiment>")
    lines.append("</ssd:SystemStructureDescription>")
    lines.append("")
    return "\n".join(lines)


def export_ssp(scenario: Scenario, out, fmu_paths: dict | None = None, start_inputs: bool = True,
               rtol: float | None = None) -> Path:
    """Write ``scenario`` (controller variant already set) as an SSP 1.0 package to ``out``; with ``rtol``
    an --algorithm me package (every FMU must carry Model Exchange: one clear error names one that does not)."""
    if fmu_paths is None:
        fmu_paths = build_fmu.ensure_built()
    out = Path(out)
    paths = {name: resolve_fmu(spec.fmu, scenario, fmu_paths) for name, spec in scenario.components.items()}
    infos = {name: ModelInfo.read(path) for name, path in paths.items()}
    if rtol is not None:
        check_tolerances(rtol, None)
        for name, path in paths.items():
            model_exchange_info(name, path)
    validate(scenario, infos)
    sources = {name: f"resources/{infos[name].model_identifier}.fmu" for name in scenario.components}
    parameters = {name: dict(spec.parameters) for name, spec in scenario.components.items()}
    if start_inputs:
        for dotted, value in initial_inputs(scenario, fmu_paths).items():
            instance, variable = dotted.split(".", 1)
            parameters[instance][variable] = value
    variant = scenario.components[scenario.controller_instance].parameters.get("variant")
    controller = variants.name_of(variant)
    name = f"{scenario.name}_{controller}"
    with atomic_files.replacing(out, "wb") as stream, \
            zipfile.ZipFile(stream, "w", compression=zipfile.ZIP_DEFLATED) as package:  # whole or not at all
        package.writestr("SystemStructure.ssd", system_structure(scenario, infos, sources, name, rtol))
        for instance in scenario.components:
            description = f"{scenario.name}: parameters of {instance}"
            if start_inputs:
                description += " and consistent start values of its connected inputs"
            package.writestr(f"resources/{instance}.ssv",
                             _ssv(instance, parameters[instance], infos[instance], description))
        for source in dict.fromkeys(sources.values()):
            instance = next(n for n, s in sources.items() if s == source)
            package.write(paths[instance], source)
    return out


def export_command(args) -> int:
    overrides = list(args.set or [])
    cli_args.check_assignments(scenarios.load(args.scenario), overrides)
    step, note = args.step, ""
    me = args.algorithm == "me"
    if me:  # no communication step: the scenario's step is the output interval
        note = f"; Model Exchange: OMSimulator's CVODE at rtol {args.rtol:g} over every FMU"
    elif step is None:  # the step a host that delays every link (Jacobi) needs for 1 %
        step = validated_step(load_convergence(), scenarios.load(args.scenario).name, args.controller, "jacobi")
        note = (f"; step {step:g} s, the Jacobi validated step (1 %) of docs/convergence.md" if step else
                "; no Jacobi validated step in the study: the scenario's step")
    scenario = scenarios.configure(args.scenario, args.controller, step, args.stop, overrides)
    out = args.out or str(Path("results") / f"{scenario.name}_{args.controller}.ssp")
    for scenario_note in scenario.notes:  # e.g. the stop moved to a whole number of steps
        print(f"note: {scenario_note}", file=sys.stderr)
    path = export_ssp(scenario, out, start_inputs=args.start_inputs, rtol=args.rtol if me else None)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB): {', '.join(scenario.components)}; "
          f"parameter set '{PARAMETER_SET}'"
          + ("; connected inputs start at their consistent initial values" if args.start_inputs else "") + note)
    return 0


def register(commands):
    export = commands.add_parser("export-ssp", help="export a scenario as an SSP 1.0 package (SystemStructure.ssd, "
                                                    "parameter sets, FMUs)")
    export.add_argument("scenario", type=cli_args.scenario, help=cli_args.scenario_help())
    export.add_argument("--controller", choices=variants.NAMES, default=variants.PROPOSED)
    export.add_argument("--out", help="the .ssp file to write (default: results/SCENARIO_CONTROLLER.ssp)")
    export.add_argument("--step", type=cli_args.positive_float,
                        help="communication step written to the package (default: the Jacobi validated step (1 %%) "
                             "of the scenario and controller, docs/convergence.md)")
    export.add_argument("--stop", type=cli_args.positive_float, help="stop time of the default experiment (default: the scenario's)")
    export.add_argument("--set", action="append", metavar="INSTANCE.PARAMETER=VALUE", type=cli_args.assignment,
                        help="override a parameter value (repeatable), e.g. controller.gamma=290")
    export.add_argument("--algorithm", choices=("co-simulation", "me"), default="co-simulation",
                        help="co-simulation (default): the step in every engine's annotation; me: the native FMUs' "
                             "Model Exchange, integrated by OMSimulator's CVODE (its org.openmodelica solver "
                             "annotation; --edition native)")
    export.add_argument("--rtol", type=cli_args.positive_float, default=DEFAULT_RTOL,
                        help=f"--algorithm me: CVODE's relative tolerance (default {DEFAULT_RTOL:g})")
    export.add_argument("--start-inputs", action=argparse.BooleanOptionalAction, default=True,
                        help="also set the start values of the connected inputs to the consistent initial values "
                             "(needed by engines that start connectors at 0, e.g. fmpy's SSP simulator; default on)")
    export.set_defaults(handler=export_command)

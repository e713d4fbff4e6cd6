"""docs/hosts.md from a matrix (``python -m harness hosts``, ``--from-json``): the prose of
harness/hosts/matrix_prose.py, the validated steps, one table row per matrix row, and where each
host's warnings come from."""
from __future__ import annotations

import re

from .. import scenario as scenarios
from ..studies.step_study import CONTROLLERS, load_convergence, validated_step
from .host_registry import HOSTS, HOSTS_BY_KEY
from .matrix_prose import (EXAMPLES_INTRO, INTRO, MATRIX_HEADING, MATRIX_INTRO, STEPS_HEADING, STEPS_INTRO, TITLE,
                           USAGE, USER_NOTES)
from .matrix_row import within


def warning_kind(text: str) -> str:
    """A warning in a few words for the table (hosts.json keeps the whole text)."""
    chatter = re.search(r"u chatters with communication step (\S+) s", text)
    if chatter:
        return f"u chatters (step {chatter.group(1)} s)"
    if "initial error re-latched" in text:
        return "initial error re-latched"
    return text.replace("|", "/")[:100]


def percent(value: float) -> str:
    """A relative error as the table shows it."""
    return f"{100 * value:+.3g} %"


def steps_for_hosts(convergence: dict) -> list:
    """The validated steps a user of another host needs, per scenario (smallest over the three controllers)."""
    lines = [STEPS_HEADING, "", STEPS_INTRO, "",
             "| scenario | Jacobi host (s) | feedthrough-aware master (s) |", "|---|---|---|"]
    for name in convergence.get("scenarios", {}):
        jacobi = [validated_step(convergence, name, c, "jacobi") for c in CONTROLLERS]
        ours = [validated_step(convergence, name, c, "feedthrough") for c in CONTROLLERS]
        smallest = [f"{min(s for s in steps if s):g}" if any(steps) else "n/a" for steps in (jacobi, ours)]
        lines.append(f"| {name} | {smallest[0]} | {smallest[1]} |")
    return lines


def matrix_markdown(matrix: dict) -> str:
    """The text of docs/hosts.md for ``matrix`` (what hosts_matrix returns, or its hosts.json)."""
    convergence = load_convergence()
    horizon = ", ".join(f"{name} {stop:g} s" if stop else f"{name} 20 s" for name, stop in matrix["stops"].items())
    lines = [TITLE, "", INTRO.format(wall_s=matrix["wall_s"], horizon=horizon), "", *USAGE, ""]
    lines += [USER_NOTES, ""] + steps_for_hosts(convergence) + [""]
    for host in HOSTS:
        if host.key in matrix.get("skipped", {}):
            lines.append(f"- `{host.key}` not run: {matrix['skipped'][host.key]}")
    lines += ["", MATRIX_HEADING, "", MATRIX_INTRO, "",
              "| scenario | host | settings | step (s) | ITAE | IAE | Ec | verdict | FMU warnings |",
              "|---|---|---|---|---|---|---|---|---|"]
    for row in matrix["rows"]:
        host = HOSTS_BY_KEY[row["host"]]
        limit = validated_step(convergence, row["scenario"], row["controller"], host.family)
        step = f"{row['step']:g} ({row['step_kind']})"
        full = matrix["stops"].get(row["scenario"]) or scenarios.load(row["scenario"]).stop
        if host.max_steps and row["stop"] is not None and row["stop"] < full - 1e-12:
            step += f", over {row['stop']:g} s ({host.max_steps} steps: its memory)"
        if row["status"] != "ok":
            lines.append(f"| {row['scenario']} | {host.name} (`{host.key}`) | {host.settings} | {step} | "
                         f"{row['status']}: {row.get('reason', '')} |||||")
            continue
        error = row["error"]
        verdict = "**ok**" if within(row) else ("off" + (f" (step > validated {limit:g})"
                                                         if limit and row["step"] > limit * (1 + 1e-9) else ""))
        warnings = "; ".join(warning_kind(w) for w in row["warnings"]) or "none"
        lines.append(f"| {row['scenario']} | {host.name} (`{host.key}`) | {host.settings} | {step} | "
                     f"{percent(error['ITAE'])} | {percent(error['IAE'])} | {percent(error['Ec'])} | {verdict} | "
                     f"{warnings} |")
    examples = {}
    for row in matrix["rows"]:
        for text in row["warnings"]:
            examples.setdefault(warning_kind(text).split(" (")[0], (row["host"], text))
    if examples:
        lines += ["", EXAMPLES_INTRO, ""]
        lines += [f"- `{host}`: {text}" for host, text in examples.values()]
    lines += ["", "Where the warnings come from: " + "; ".join(sorted({f"`{r['host']}`: {r['warnings_from']}"
                                                                     for r in matrix["rows"]
                                                                     if r.get("warnings_from")})) + ".", ""]
    return "\n".join(lines)

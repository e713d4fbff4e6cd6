"""The report: ``report.md`` of an output folder (a table of its studies, the equal-effort comparison if
it was run, one section per study) and each study's two figures (best so far; the Pareto fronts ITAE
vs Ec and vs TV(u)), drawn from the summaries and comparison written there as JSON."""
from __future__ import annotations

import json
import math
from pathlib import Path

from ... import cli_args, variants
from ...scores import SCORE_KEYS
from .summary import pareto_front

REPORT_NAME = "report.md"  # the folder's report, every study of the folder in it


def number_text(value, digits: int = 6) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}g}"


def first_better_text(first_better) -> str:
    """Which trial first beat the starting parameters, or that none did."""
    if first_better is None:
        return "no trial beat the starting parameters"
    return f"first better than the start at trial #{first_better}"


def study_markdown(summary: dict, folder: Path) -> str:
    """The report section of one study."""
    objective = summary["objective"]
    name = summary["study"]
    lines = [f"## Study `{name}`", ""]
    horizon = f"{summary['stop']:g} s"
    grid = summary["grid"]
    lines.append(f"Scenario `{summary['scenario']}`, controller `{summary['controller']}`, objective {objective}"
                 + (f" (worst case over {len(grid)} plant variations)" if len(grid) > 1 else "")
                 + (f", constraints {', '.join(summary['constraints'])}" if summary["constraints"] else "")
                 + f"; horizon {horizon}, step {summary['step']:g} s, {summary['edition']} edition, sampler "
                 f"{summary['sampler']}, seed {summary['seed']}; database `{summary['storage']}` "
                 f"(`optuna-dashboard {summary.get('dashboard', summary['storage'])}` shows it live).")
    counts = ", ".join(f"{count} {status}" for status, count in sorted(summary["counts"].items()))
    lines += ["", f"**Trials**: {summary['finished']} finished of {summary['trials']} ({counts})."]
    run = summary.get("run")
    if run and run.get("ran"):
        lines.append(f"This run: {run['ran']} trials in {run['wall_s']:.1f} s wall on {run.get('jobs', 1)} "
                     f"process(es) ({run['ran'] / run['wall_s']:.2f} trials/s; {run['simulated_s']:.1f} s in the "
                     "co-simulations).")
    if len(grid) > 1:
        lines.append("Plant variations: " + "; ".join(", ".join(f"{d}={v:g}" for d, v in point) for point in grid)
                     + ".")
    start, best = summary.get("start"), summary.get("best")
    lines += ["", "### Best parameters", ""]
    if best is None:
        lines.append("No trial finished complete, feasible and verified at half the step: nothing to report "
                     "as best.")
    else:
        improvement = ""
        if start is not None:
            improvement = (f" against {number_text(start['value'])} for the starting parameters "
                           f"(trial #{start['number']}); {first_better_text(summary['first_better'])}")
        half = best["half_step"]
        lines.append(f"Trial #{best['number']}: {objective} = {number_text(best['value'])}{improvement}. "
                     f"Re-run at half the step ({half['step']:g} s): {objective} "
                     f"{number_text(half['scores'][objective])} ({100 * half['change']:.3g} % change; limit {100 * summary['tolerance']:g} %). Scenario "
                     f"file: `{summary['study_file']}`.")
        lines += ["", "| parameter | searched | start | tuned |", "|---|---|---|---|"]
        for dimension in summary["space"]:
            tuned = best["parameters"].get(dimension["parameter"])
            lines.append(f"| `{dimension['parameter']}` | {dimension['range']} | {number_text(dimension['start'])} | "
                         f"{number_text(tuned)} |")
        lines += ["", "| score | start | tuned at h | tuned at h/2 | Richardson 2 f(h/2) - f(h) | "
                  "error estimate of tuned at h |", "|---|---|---|---|---|---|"]
        for key in SCORE_KEYS:
            lines.append(f"| {key} | {number_text(start['scores'][key]) if start else 'n/a'} | "
                         f"{number_text(best['scores'][key])} | {number_text(half['scores'][key])} | "
                         f"{number_text(half['richardson'].get(key))} | {number_text(half['error'].get(key), 3)} |")
    lines += ["", f"![best so far]({name}_progress.png)", "",
              f"![Pareto fronts]({name}_pareto.png)", ""]
    lines += ["### Parameter importances", ""]
    if summary["importances"]:
        lines.append(f"{summary['importance_evaluator']}, over the complete trials:")
        lines += ["", "| parameter | importance |", "|---|---|"]
        lines += [f"| `{k}` | {v:.3f} |" for k, v in sorted(summary["importances"].items(), key=lambda kv: -kv[1])]
    else:
        lines.append(f"None: {summary['importance_evaluator']}.")
    held = summary.get("held_out") or []
    if held:
        lines += ["", "### Tuned against starting parameters on held-out scenarios", "",
                  f"Tuned on `{summary['scenario']}` only; the same controller parameters on scenarios the search "
                  "never saw:", "", "| scenario | controller | " + " | ".join(SCORE_KEYS) + " |",
                  "|---|---|" + "---|" * len(SCORE_KEYS)]
        for row in held:
            for label in ("start", "tuned"):
                result = row.get(label, {})
                if result.get("scores") and result.get("status") == "ok":
                    cells = " | ".join(number_text(result["scores"][k], 4) for k in SCORE_KEYS)
                else:
                    cells = f"{result.get('status')}: {result.get('reason', '')}" + " |" * (len(SCORE_KEYS) - 1)
                lines.append(f"| {row['scenario']} | {label} | {cells} |")
    return "\n".join(lines) + "\n"


def figure_progress(summary: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(7, 4), layout="constrained")
    values = summary["trial_values"]
    if values:
        axes.scatter([v[0] for v in values], [v[1] for v in values], s=8, color="0.6", label="complete trials")
    curve = [(n, b) for n, b in summary["best_so_far"] if math.isfinite(b)]
    if curve:
        axes.step([c[0] for c in curve], [c[1] for c in curve], where="post", color="C0", label="best so far")
    if summary.get("start"):
        axes.axhline(summary["start"]["scores"][summary["objective"]], color="C3", linestyle="--",
                     label="starting parameters")
    axes.set_yscale("log")
    axes.set_xlabel("trial")
    axes.set_ylabel(summary["objective"])
    axes.set_title(f"{summary['study']}: best so far")
    axes.legend(loc="upper right", fontsize=8)
    figure.savefig(path, dpi=110)
    plt.close(figure)


def figure_pareto(summary: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, panels = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    points = summary["pareto_points"]
    for panel, (key, label) in zip(panels, (("Ec", "Ec = int u^2 dt"), ("tv_u", "TV(u) per second"))):
        xy = [(p["ITAE"], p[key]) for p in points]
        if xy:
            panel.scatter([p[0] for p in xy], [p[1] for p in xy], s=8, color="0.65", label="complete trials")
            front = [xy[i] for i in pareto_front(xy)]
            panel.plot([p[0] for p in front], [p[1] for p in front], "o-", color="C0", markersize=4,
                       label="Pareto front")
        for which, marker, color in (("start", "s", "C3"), ("best", "*", "C2")):
            if summary.get(which):
                scores = summary[which]["scores"]
                panel.scatter([scores["ITAE"]], [scores[key]], marker=marker, s=80, color=color, zorder=5,
                              label=f"{which} (#{summary[which]['number']})")
        panel.set_xscale("log")
        panel.set_yscale("log")
        panel.set_xlabel("ITAE")
        panel.set_ylabel(label)
        panel.legend(fontsize=8)
    figure.suptitle(f"{summary['study']}: ITAE against control effort and smoothness")
    figure.savefig(path, dpi=110)
    plt.close(figure)


def comparison_markdown(comparison: dict) -> str:
    seeds = comparison["seeds"]
    key = comparison["objective"]
    lines = ["## The paper's comparison under equal tuning effort", "",
             f"Every controller tuned with the same budget ({comparison['trials']} trials per study, sampler "
             f"{comparison['sampler']}, objective {key}"
             + (f", constraints {', '.join(comparison['constraints'])}" if comparison.get("constraints") else "")
             + ") over the same search space where they share parameters "
             "(lambda_ce and kappa_i act in vud only, gamma_w in fae only: the FMU's table), "
             f"{len(seeds)} time(s) with seeds {', '.join(map(str, seeds))}: an optimiser's result varies with "
             "its seed, and that spread is part of the answer. Trial 0 of every study is the scenario's own "
             "parameters (the paper's values). Each value is at the scenario's step h, +- the estimated "
             "numerical error |f(h) - (2 f(h/2) - f(h))| from the re-run at half the step (Richardson, as in the "
             "step study).", ""]

    def cell(entry, score):
        if not entry:
            return "n/a"
        error = (entry.get("error") or {}).get(score)
        return number_text(entry["scores"][score], 5) + (f" +- {error:.2g}" if error is not None else "")

    for scenario, block in comparison["scenarios"].items():
        lines += [f"### {scenario}", "", f"| controller | seed | {key}, paper's parameters | {key}, tuned | "
                  "Ec, tuned | TV(u)/s, tuned | umax, tuned | best trial | finished trials (pruned) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for repeat in block["repeats"]:
            for row in repeat["rows"]:
                start, best = row.get("start"), row.get("best")
                pruned = row.get("states", {}).get("PRUNED", 0)
                lines.append(f"| {row['controller']} | {repeat['seed']} | {cell(start, key)} | {cell(best, key)} | "
                             f"{cell(best, 'Ec')} | {cell(best, 'tv_u')} | {cell(best, 'umax')} | "
                             f"{'#' + str(best['number']) if best else 'n/a'} | {row['finished']} ({pruned}) |")
        lines.append("")
        for repeat in block["repeats"]:
            for verdict in repeat["verdicts"]:
                lines.append(f"- seed {repeat['seed']}: **{verdict['question']}** {verdict['answer']}")
        for verdict in block.get("overall", ()):
            lines.append(f"- **{verdict['question']}** {verdict['answer']}")
        lines.append("")
    return "\n".join(lines)


def write_report(out: Path) -> Path:
    """report.md of the folder: the comparison (if run) and every study whose <study>.json is there."""
    out = Path(out)
    summaries = []
    for path in sorted(out.glob("*.json")):
        if path.name == "comparison.json":
            continue
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and "study" in data and "best_so_far" in data:
            summaries.append(data)
    parts = ["# Tuning report", "",
             "Generated by `python -m harness tune` (docs/tuning.md) from the studies in this folder. Every "
             "best value was re-run at half the communication step; candidates that diverged, failed, made u "
             "chatter (the controller FMU's warning) or moved by more than the tolerance at half the step are "
             "pruned and counted, never reported as best.", ""]
    order = list(variants.NAMES)
    summaries.sort(key=lambda m: (m["scenario"], m["seed"], order.index(m["controller"])
                                  if m["controller"] in order else 9, m["study"]))
    if summaries:
        parts += ["| study | seed | trials (pruned) | best | start | scenario file |", "|---|---|---|---|---|---|"]
        for m in summaries:
            best, start = m.get("best"), m.get("start")
            pruned = m.get("states", {}).get("PRUNED", 0)
            link = f"[`{m['study']}`](#study-{m['study'].lower()})"
            parts.append(f"| {link} | {m['seed']} | {m['finished']} ({pruned}) | "
                         f"{m['objective']} {number_text(best['value'], 5) if best else 'n/a'} | "
                         f"{number_text(start['value'], 5) if start else 'n/a'} | "
                         f"{'`' + Path(m['study_file']).name + '`' if m.get('study_file') else 'none'} |")
        parts.append("")
    comparison_path = out / "comparison.json"
    if comparison_path.exists():
        try:
            parts.append(comparison_markdown(json.loads(comparison_path.read_text())))
        except (KeyError, TypeError, ValueError) as error:  # written by another version of this module
            parts.append(f"(comparison.json not shown: {cli_args.one_line(error)}; run `tune --compare` again)\n")
    for summary in summaries:
        parts.append(study_markdown(summary, out))
    path = out / REPORT_NAME
    path.write_text("\n".join(parts))
    return path

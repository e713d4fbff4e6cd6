"""The regression's reports: report.md, report.html with the figures of failing signals, JUnit XML.

Written by ``python -m harness regress`` (:mod:`.command`) from its comparisons:

* ``report.md``: the summary table and every signal (pass/fail, largest excursion and where);
* ``report.html``: a static page (no server, no script: it opens from a CI artifact) with the
  failing signals first, each with its plot (reference, tube, new result, the largest excursion
  marked), then the passing ones; every link and image is a file beside it;
* JUnit XML (``--junit FILE``): one test case per scenario x controller, a failure naming the
  signal, its largest excursion and its time, the report's path in the case's output, the wall
  time of the run and of the reference's run (and a flag when the run is more than
  ``SLOW_FACTOR`` times slower), as GitHub Actions, GitLab CI and Jenkins read it.
"""
from __future__ import annotations

import datetime
import html
import platform
import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path

from ... import atomic_files
from .comparison import code_span
from .figures import draw_failing_signals, slug
from .references import DEFAULT_TOLERANCES, REFERENCE_DIR, relative
from .runs import POINTS

SLOW_FACTOR = 2.0  # a case whose run takes more than this times its reference's run is flagged
SUMMARY_HEADER = ["case", "result", "signals in tube", "worst signal", "max outside tube", "at t [s]",
                  "max abs deviation", "run [s]", "reference run [s]", "notes"]


def _format_tolerances(tolerances: dict) -> str:
    return ", ".join(f"{key} = {value:g}" for key, value in tolerances.items())


def slowness(comparison) -> str:
    """'' or 'N.Nx slower than the reference run' when the run took more than SLOW_FACTOR times as long."""
    ratio = comparison.slowdown
    return f"{ratio:.1f}x slower than the reference run" if ratio is not None and ratio > SLOW_FACTOR else ""


# --------------------------------------------------------------- markdown
class Markdown(str):
    """Text that is Markdown already (``**FAIL**``, an image): written as it is."""


#: a code span of CommonMark: a run of backticks, the text, the same run (``a`b`` holds a backtick)
CODE_SPAN = re.compile(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)")
#: Markdown's punctuation that could make a name a link, an image, emphasis or a table cell's end
_MARKDOWN_PUNCTUATION = re.compile(r"([\\`*\[\]|~])")


def markdown_text(text) -> str:
    """Text for Markdown (a table cell): raw HTML and Markdown syntax in file, instance and signal names show
    as written (``<`` ``>`` ``&`` as entities, the punctuation backslash-escaped, ``|`` too); the text's own
    code spans stay code spans."""
    if isinstance(text, Markdown):
        return str(text)
    text, parts, last = str(text), [], 0
    for span in CODE_SPAN.finditer(text):
        parts.append(_MARKDOWN_PUNCTUATION.sub(r"\\\1", html.escape(text[last:span.start()], quote=False)))
        parts.append(span.group(0).replace("|", "\\|"))
        last = span.end()
    parts.append(_MARKDOWN_PUNCTUATION.sub(r"\\\1", html.escape(text[last:], quote=False)))
    return "".join(parts)


def markdown_table(rows, header, escape: bool = True) -> list[str]:
    """A Markdown table; ``escape=False``: the cells as they are (the summary printed on a terminal)."""
    shown = markdown_text if escape else str
    lines = ["| " + " | ".join(shown(cell) for cell in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(shown(cell) for cell in row) + " |" for row in rows]
    return lines


def worst_signal(comparison):
    return max(comparison.signals, key=lambda s: (s.max_error, s.max_deviation), default=None)


def summary_rows(comparisons) -> list:
    rows = []
    for comparison in comparisons:
        failed = [s for s in comparison.signals if not s.passed]
        worst = worst_signal(comparison)
        notes = [comparison.message or ", ".join(s.signal for s in failed), slowness(comparison), *comparison.notes]
        rows.append([comparison.case.label, "pass" if comparison.passed else Markdown("**FAIL**"),
                     f"{len(comparison.signals) - len(failed)}/{len(comparison.signals)}",
                     worst.signal if worst else "-",
                     f"{worst.max_error:.3g}" if worst else "-",
                     f"{worst.t_max_error:.4g}" if worst and worst.t_max_error is not None else "-",
                     f"{worst.max_deviation:.3g}" if worst else "-",
                     f"{comparison.wall_s:.2f}",
                     f"{comparison.reference_wall_s:.2f}" if comparison.reference_wall_s else "-",
                     "; ".join(note for note in notes if note)])
    return rows


def _header_lines(comparisons, reference_dir, tolerances: dict, points: int) -> tuple:
    passed = sum(c.passed for c in comparisons)
    title = f"Regression report ({passed}/{len(comparisons)} cases pass)"
    generated = (f"Generated {datetime.datetime.now().replace(microsecond=0).isoformat()} by "
                 f"`python -m harness regress` on {platform.node() or 'this machine'}; references in "
                 f"{code_span(str(reference_dir))}.")
    tolerance = (f"Tolerances (pyfunnel): {_format_tolerances(tolerances)}, unless a reference's metadata sets its "
                 f"own (per case or per signal: listed with the signal); signals resampled to {points} points "
                 f"over each scenario's horizon. A run more than {SLOW_FACTOR:g}x slower than its reference's "
                 "run is flagged.")
    return title, generated, tolerance


def write_markdown(comparisons, path: Path, reference_dir, tolerances: dict, points: int) -> Path:
    title, generated, tolerance = _header_lines(comparisons, reference_dir, tolerances, points)
    lines = [f"# {title}", "", markdown_text(generated), "", markdown_text(tolerance), "",
             "Also as a web page: [report.html](report.html).", "", "## Summary", ""]
    lines += markdown_table(summary_rows(comparisons), SUMMARY_HEADER)
    lines += ["", "## Signals", ""]
    rows = []
    for comparison in comparisons:
        for s in comparison.signals:
            plot = Markdown(f"![]({s.plot.name})") if s.plot else ""
            rows.append([comparison.case.label, s.signal, "pass" if s.passed else Markdown("**FAIL**"),
                         f"{s.max_error:.3g}",
                         f"{s.t_max_error:.4g}" if s.t_max_error is not None else "-", f"{s.max_deviation:.3g}",
                         f"{s.t_max_deviation:.4g}" if s.t_max_deviation is not None else "-",
                         _own_tolerances(comparison, s), s.message, plot])
    lines += markdown_table(rows, ["case", "signal", "result", "max outside tube", "at t [s]", "max abs deviation",
                           "at t [s]", "own tolerances", "message", "plot"])
    atomic_files.write_text(path, "\n".join(lines) + "\n")
    return path


def _own_tolerances(comparison, signal) -> str:
    """The signal's tolerances where they differ from the report's (set in its reference's metadata)."""
    own = {key: value for key, value in signal.tolerances.items() if comparison.run_tolerances.get(key) != value}
    return _format_tolerances(own)


# ------------------------------------------------------------------- HTML
STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 72em; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.5em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
.fail { color: #b00020; font-weight: bold; }
.pass { color: #1b5e20; }
.slow { color: #8a4b00; font-weight: bold; }
section.failure { border-left: 4px solid #b00020; padding-left: 1em; margin-bottom: 2em; }
img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; }
"""


def _inline(text: str) -> str:
    """Escaped text with `code` spans as <code>."""
    return CODE_SPAN.sub(lambda span: f"<code>{span.group(2).strip() if span.group(1) != '`' else span.group(2)}"
                                      "</code>", html.escape(text))


def _cell(text, css: str = "") -> str:
    attribute = f' class="{css}"' if css else ""
    return f"<td{attribute}>{html.escape(str(text))}</td>"


def _html_table(header, rows) -> list:
    lines = ["<table>", "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    lines += ["<tr>" + "".join(row) + "</tr>" for row in rows]
    return lines + ["</table>"]


def anchor(comparison, signal=None) -> str:
    return "case-" + slug(comparison.case.label) + (f"--{slug(signal.signal)}" if signal is not None else "")


def write_html(comparisons, path: Path, reference_dir, tolerances: dict, points: int) -> Path:
    """report.html: the summary, the failing signals with their plots, then the passing signals."""
    title, generated, tolerance = _header_lines(comparisons, reference_dir, tolerances, points)
    lines = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>{html.escape(title)}</title>", f"<style>{STYLE}</style>", "</head>", "<body>",
             f"<h1>{html.escape(title)}</h1>",
             f"<p>{_inline(generated)} {_inline(tolerance)} The same as Markdown: "
             '<a href="report.md">report.md</a>.</p>',
             '<h2 id="cases">Cases</h2>']
    rows = []
    for comparison, row in zip(comparisons, summary_rows(comparisons)):
        failing = [s for s in comparison.signals if not s.passed]
        target = anchor(comparison, failing[0]) if failing else anchor(comparison) if not comparison.passed else ""
        label = (f'<td><a href="#{target}">{html.escape(comparison.case.label)}</a></td>' if target
                 else _cell(comparison.case.label))
        cells = [label, _cell("pass" if comparison.passed else "FAIL", "pass" if comparison.passed else "fail")]
        cells += [_cell(value) for value in row[2:9]]
        cells.append(_cell(row[9], "slow" if slowness(comparison) else ""))
        rows.append(cells)
    lines += _html_table(SUMMARY_HEADER, rows)

    failures = [(c, s) for c in comparisons for s in c.signals if not s.passed]
    case_failures = [c for c in comparisons if c.message]
    lines.append(f'<h2 id="failures">Failing ({len(failures)} signals, {len(case_failures)} cases with a failure '
                 "of their own)</h2>")
    if not failures and not case_failures:
        lines.append("<p>None: every signal of every case lies inside its tube.</p>")
    for comparison in case_failures:
        lines += [f'<section class="failure" id="{anchor(comparison)}">',
                  f"<h3>{html.escape(comparison.case.label)}</h3>",
                  f'<p class="fail">{html.escape(comparison.message)}</p>', "</section>"]
    for comparison, signal in failures:
        lines += [f'<section class="failure" id="{anchor(comparison, signal)}">',
                  f"<h3>{html.escape(comparison.case.label)}: {html.escape(signal.signal)}</h3>",
                  f'<p class="fail">{html.escape(signal.message)}</p>']
        lines += _html_table(["max outside tube", "at t [s]", "max abs deviation", "at t [s]", "tolerances"], [[
            _cell(f"{signal.max_error:.3g}"),
            _cell(f"{signal.t_max_error:.6g}" if signal.t_max_error is not None else "-"),
            _cell(f"{signal.max_deviation:.3g}"),
            _cell(f"{signal.t_max_deviation:.6g}" if signal.t_max_deviation is not None else "-"),
            _cell(_format_tolerances(signal.tolerances))]])
        if signal.plot is not None:
            alt = f"{comparison.case.label}: {signal.signal}, reference, tube and new result"
            lines += ["<figure>", f'<img src="{html.escape(signal.plot.name)}" alt="{html.escape(alt)}">',
                      "<figcaption>Reference (black), tube (grey), new result (red), the largest excursion "
                      "circled; middle: a zoom around it; bottom: how far the result lies outside the tube."
                      "</figcaption>", "</figure>"]
        else:
            lines.append("<p>No plot: the signal is missing from the reference or the run.</p>")
        lines.append("</section>")

    passing = [(c, s) for c in comparisons for s in c.signals if s.passed]
    lines.append(f'<h2 id="passing">Passing signals ({len(passing)})</h2>')
    rows = [[_cell(c.case.label), _cell(s.signal), _cell(f"{s.max_deviation:.3g}"),
             _cell(f"{s.t_max_deviation:.6g}" if s.t_max_deviation is not None else "-"),
             _cell(_own_tolerances(c, s))] for c, s in passing]
    lines += _html_table(["case", "signal", "max abs deviation", "at t [s]", "own tolerances"], rows)
    lines += ["</body>", "</html>"]
    atomic_files.write_text(path, "\n".join(lines) + "\n")
    return path


# ------------------------------------------------------------------ JUnit
def failure_text(comparison) -> tuple[str, str]:
    """(message, details) of a failing case: the first failing signal named, with its largest excursion."""
    failing = [s for s in comparison.signals if not s.passed]
    details = []
    if comparison.message:
        details.append(comparison.message)
    for signal in failing:
        details.append(f"{signal.signal}: {signal.message} (largest |new - reference| {signal.max_deviation:.3g}"
                       + (f" at t = {signal.t_max_deviation:.6g} s)" if signal.t_max_deviation is not None else ")"))
    if failing:
        first = failing[0]
        message = f"{first.signal}: {first.message}"
        if len(failing) > 1:
            message += f" (and {len(failing) - 1} more: {', '.join(s.signal for s in failing[1:])})"
        if comparison.message:
            message = f"{comparison.message}; {message}"
    else:
        message = comparison.message
    return message, "\n".join(details)


def write_junit(comparisons, path: Path, report: Path | None, suite: str = "afc-fmi regress") -> Path:
    """JUnit XML: one test case per scenario x controller; failures name the signal, excursion and time."""
    failures = sum(not c.passed for c in comparisons)
    total_time = sum(c.wall_s for c in comparisons)
    stamp = datetime.datetime.now().replace(microsecond=0).isoformat()
    root = ElementTree.Element("testsuites", name=suite, tests=str(len(comparisons)), failures=str(failures),
                               errors="0", time=f"{total_time:.3f}")
    testsuite = ElementTree.SubElement(root, "testsuite", name=suite, tests=str(len(comparisons)),
                                       failures=str(failures), errors="0", skipped="0", time=f"{total_time:.3f}",
                                       timestamp=stamp, hostname=platform.node() or "localhost")
    if report is not None:
        properties = ElementTree.SubElement(testsuite, "properties")
        ElementTree.SubElement(properties, "property", name="report", value=str(report))
    for comparison in comparisons:
        case = comparison.case
        testcase = ElementTree.SubElement(testsuite, "testcase", classname=f"regress.{case.scenario_name}",
                                          name=case.label, time=f"{comparison.wall_s:.3f}")
        properties = ElementTree.SubElement(testcase, "properties")
        ElementTree.SubElement(properties, "property", name="wall_s", value=f"{comparison.wall_s:.3f}")
        if comparison.reference_wall_s:
            ElementTree.SubElement(properties, "property", name="reference_wall_s",
                                   value=f"{comparison.reference_wall_s:.3f}")
        if slowness(comparison):
            ElementTree.SubElement(properties, "property", name="slow", value=slowness(comparison))
        if not comparison.passed:
            message, details = failure_text(comparison)
            failure = ElementTree.SubElement(testcase, "failure", message=message, type="RegressionFailure")
            failure.text = details
        output = [f"report: {report}" if report is not None else "report: not written (no --report)",
                  f"run {comparison.wall_s:.2f} s"
                  + (f", reference run {comparison.reference_wall_s:.2f} s" if comparison.reference_wall_s else "")
                  + (f" ({slowness(comparison)})" if slowness(comparison) else "")]
        output += comparison.notes
        ElementTree.SubElement(testcase, "system-out").text = "\n".join(output)
    ElementTree.indent(root)
    path = Path(path)
    with atomic_files.replacing(path, "wb") as stream:
        ElementTree.ElementTree(root).write(stream, encoding="utf-8", xml_declaration=True)
    return path


# ----------------------------------------------------------- both reports
def write_report(comparisons, runs, references, directory: Path, tolerances: dict,
                 reference_dir: Path = REFERENCE_DIR) -> Path:
    """report.md and report.html (with a PNG of every failing signal) in ``directory``; returns report.md."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    draw_failing_signals(comparisons, runs, references, directory)
    shown = relative(reference_dir) + "/"
    tolerances = {**DEFAULT_TOLERANCES, **(tolerances or {})}
    write_html(comparisons, directory / "report.html", shown, tolerances, POINTS)
    return write_markdown(comparisons, directory / "report.md", shown, tolerances, POINTS)

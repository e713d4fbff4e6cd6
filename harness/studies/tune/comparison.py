"""The paper's comparison under equal tuning effort (``--compare``): vud, fixed and fae tuned with
the same budget; one row per study, and the verdicts on the paper's claims beyond the numerical
errors (harness/studies/tune/report.py renders them)."""
from __future__ import annotations

import math

from .report import number_text


def compare_rows(summaries: list) -> list:
    """One row per study of the comparison: start and tuned objective with their error estimates."""
    rows = []
    for summary in summaries:
        objective = summary["objective"]
        row = {"scenario": summary["scenario"], "controller": summary["controller"], "study": summary["study"],
               "objective": objective, "finished": summary["finished"], "counts": summary["counts"],
               "states": summary.get("states", {})}
        for which in ("start", "best"):
            entry = summary.get(which)
            half = (entry or {}).get("half_step")
            row[which] = None if entry is None else {
                "number": entry["number"], "value": entry["value"], "scores": entry["scores"],
                "error": half["error"] if half else None, "parameters": entry.get("parameters")}
        rows.append(row)
    return rows


def smallest(rows: list, which: str, key: str) -> dict:
    """Which controller has the smallest ``key`` (start or best), and is it apart beyond the numerical errors?"""
    present = [r for r in rows if r.get(which)]
    if not present:
        return {"controller": None, "separated": False, "text": "no result"}
    ranked = sorted(present, key=lambda r: r[which]["scores"][key])
    winner = ranked[0]

    def error(row):
        errors = row[which].get("error")
        return errors[key] if errors else math.nan

    high = winner[which]["scores"][key] + (error(winner) if math.isfinite(error(winner)) else 0.0)
    separated = all(high < r[which]["scores"][key] - (error(r) if math.isfinite(error(r)) else 0.0)
                    for r in ranked[1:]) and all(math.isfinite(error(r)) for r in ranked)
    return {"controller": winner["controller"], "separated": separated,
            "values": {r["controller"]: (r[which]["scores"][key], error(r)) for r in ranked}}


def beats(rows: list, which: str, key: str, first: str, second: str) -> dict:
    """Does ``first`` have a smaller ``key`` than ``second`` beyond their numerical errors?"""
    by = {r["controller"]: r for r in rows if r.get(which)}
    if first not in by or second not in by:
        return {"answer": "no result"}
    a, b = by[first][which], by[second][which]
    ea = (a.get("error") or {}).get(key, math.nan)
    eb = (b.get("error") or {}).get(key, math.nan)
    va, vb = a["scores"][key], b["scores"][key]
    if not (math.isfinite(ea) and math.isfinite(eb)):
        answer = "yes" if va < vb else "no"
        answer += " (no error estimate)"
    elif va + ea < vb - eb:
        answer = "yes"
    elif vb + eb < va - ea:
        answer = "no"
    else:
        answer = "undecided: the difference is within the numerical errors"
    return {"answer": answer, first: (va, ea), second: (vb, eb)}


def overall_verdicts(scenario_name: str, order: int, repeats: list, key: str) -> list:
    """The claims over every seed: in how many repetitions does each answer come out?"""
    found = []
    count = len(repeats)
    if scenario_name.startswith("pendulum"):
        winners = [smallest(r["rows"], "best", key) for r in repeats]
        vud = sum(w["controller"] == "vud" for w in winners)
        apart = sum(w["controller"] == "vud" and w["separated"] for w in winners)
        others = ", ".join(f"{w['controller']} (seed {r['seed']})" for w, r in zip(winners, repeats)
                           if w["controller"] != "vud")
        found.append({"question": f"Over all seeds: does vud give the smallest {key} on the pendulum when every "
                                  "controller is tuned?",
                      "answer": f"in {vud} of {count} repetition(s) ({apart} apart beyond the numerical errors)"
                                + (f"; otherwise {others}" if others else "") + "."})
    if order >= 3:
        answers = [beats(r["rows"], "best", key, "fae", "vud")["answer"] for r in repeats]
        yes = sum(a == "yes" for a in answers)
        no = sum(a == "no" for a in answers)
        found.append({"question": "Over all seeds: does fae beat vud on the third-order plant when both are tuned?",
                      "answer": f"yes in {yes}, no in {no}, undecided in {count - yes - no} of {count} "
                                "repetition(s)."})
    return found


def verdicts_for(scenario_name: str, order: int, rows: list, key: str) -> list:
    """The paper's claims re-checked on one scenario: the smallest score before and after tuning;
    on the pendulum: is vud still the smallest; on a plant of order 3 or more: does fae still beat vud?"""
    found = []

    def describe(result):
        if result["controller"] is None:
            return "no result"
        values = ", ".join(f"{c} {number_text(v, 5)}" + (f" +- {e:.2g}" if math.isfinite(e) else "")
                           for c, (v, e) in result["values"].items())
        apart = "apart beyond the numerical errors" if result["separated"] else \
            "not apart beyond the numerical errors"
        return f"{result['controller']} ({values}; {apart})"

    before, after = smallest(rows, "start", key), smallest(rows, "best", key)
    if scenario_name.startswith("pendulum"):
        answer = ("yes" if after["controller"] == "vud" and after["separated"] else
                  "yes, but within the numerical errors" if after["controller"] == "vud" else
                  f"no: {after['controller']} has it")
        found.append({"question": f"Does vud still give the smallest {key} on the pendulum when every controller "
                                  "is tuned?", "answer": f"{answer}. Tuned: {describe(after)}. With the paper's "
                                                          f"parameters: {describe(before)}."})
    if order >= 3:
        for which, label in (("start", "with the pendulum's (paper's) parameters"), ("best", "all tuned")):
            result = beats(rows, which, key, "fae", "vud")
            if result["answer"] == "no result":
                continue
            va, ea = result["fae"]
            vb, eb = result["vud"]
            found.append({"question": f"Does fae beat vud on the third-order plant ({label})?",
                          "answer": f"{result['answer']} (fae {number_text(va, 5)} +- {ea:.2g}, "
                                    f"vud {number_text(vb, 5)} +- {eb:.2g})."})
    if not found:
        found.append({"question": f"Smallest {key} when every controller is tuned:", "answer": describe(after)})
    return found

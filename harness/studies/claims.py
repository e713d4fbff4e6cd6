"""The paper's claims on the scores of docs/model.md section 9 (scores), each decided only where the
numbers can carry it.

Every score comes from a ladder of runs of the same case that refines what its error depends on
(docs/verification.md): the communication step h and the plant's internal RK4 step h_p.

* the communication axis: the case at h and at h/2 with the plant's internal step halved with it
  (the same h_p / h), and finer where a comparison needs it (``--refine``);
* the plant axis: the case at h with the plant's internal step halved (h_p / 2), which shows what the
  plant's fixed-step integration leaves in the score (the Coulomb friction's stuck phases: RK4 of
  sgn(x2) is only first order in h_p there, and their chatter is set by h_p / h, not by h).

A score's value is the one at the finest communication step run and its numerical error, an
estimate of its distance to the continuous-time value of the model, is

    SAFETY_FACTOR x (communication change + plant error)

* the communication change: ``|s(h') - s(h'/2)|`` over the last halving (the sampled-data loop is first
  order in the step: u held, theta by explicit Euler, so the change estimates the error left in the
  finer value); with three or more halvings the ladder must show convergence (the last change smaller
  than the one before, the error then scaled by their ratio q as ``q / (1 - q)`` when q > 1/2),
  otherwise the error is infinite: *undecided at this step*;
* the plant error: the value's plant step is the table run's h_p / h (the communication axis keeps it), and
  the plant axis runs the case at h with another plant step h_p' (2 h_p where h holds two plant steps or
  more, else h_p / 2): a first-order integration leaves ``|s(h, h_p) - s(h, h_p')| h_p / |h_p' - h_p|`` at
  h_p (the change itself from 2 h_p, twice the change to h_p / 2; RK4 is first order where the Coulomb
  friction switches, so this bounds it).  A smooth plant (rows with ``plant_axis`` False) has no plant
  axis and no plant error of its own: RK4 is fourth order in h_p there and the communication axis, which
  halves h_p with h, counts it (harness/studies/ladders.py);
* SAFETY_FACTOR: the factor of safety of Roache's grid convergence index for a ladder of a known order.

``ts`` is quantised to the communication grid: its error is at least the step of its run, and its
changes are steps of the grid, so only its last halving counts (no convergence test).  A ladder that
needs the plant axis and has no run on it (or whose needed run failed) has an infinite error.

A comparison "vud below other" is decided only when the gap exceeds the combined
error (the sum of both errors: discretisation errors are systematic, not random,
so they are added, not added in quadrature):

* ``vud + err_vud < other - err_other``  -> vud clearly below,
* ``vud - err_vud > other + err_other``  -> vud clearly above,
* otherwise "not decided at this accuracy".

A claim over several scenarios is *reproduced* when every comparison is decided in
its favour, *not reproduced* when at least one is clearly decided against it, and
otherwise *not decided at this accuracy*.  ``undecided_cases`` names the runs a
finer step could decide, for the claims whose verdict is still open.

A comparison decided by a gap of less than ``CLOSE_MARGIN`` of the values (e.g. 0.02 %) is
numerically sound but says *close*, and a claim that such comparisons decide says so beside its
verdict.  A score a run cannot give (harness/scores.py: es1, es2 on a horizon shorter than one
reference period) decides nothing: the comparison is open, with the reason, and no finer step is
asked for it.  A run that has not settled within its horizon (ts None: the error does not stay in
the band for one reference period before T) settles later than any run that has: its ts counts as
beyond the horizon, so a settled vud is below it and two unsettled runs are not decided.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .. import variants
from ..scores import SETTLING_DWELL, why_none

REPRODUCED = "reproduced"
NOT_REPRODUCED = "not reproduced"
UNDECIDED = "not decided at this accuracy"

CONTROLLERS = variants.PAPER  # the paper's: vud, fixed, fae (a variant beyond the paper decides no claim)
PROPOSED = variants.PROPOSED  # vud: each claim compares it with every other variant of the paper
PENDULUM = ("pendulum_case1", "pendulum_case2", "pendulum_case3")
ALL_SCENARIOS = (*PENDULUM, "manipulator")
DISTURBANCE_TOLERANCE = 0.10  # "barely changes": ITAE and IAE within 10 % of case 1
SMOOTHNESS_TOLERANCE = 1.10  # "smooth": tv_u at most 10 % above the smoothest comparison controller
GRID_QUANTISED = ("ts",)  # scores read off the communication grid: error at least one step
#: the factor of safety of Roache's grid convergence index for a ladder of a known order (first)
SAFETY_FACTOR = 1.25
#: relative slack when matching steps and plant-step ratios of the runs of one ladder
STEP_MATCH = 1e-6
TOLERANCE_FACTOR = 10.0  # --algorithm me: the ladder's rungs are rtol and 10 rtol (no step to halve)
CLOSE_MARGIN = 0.01  # a comparison decided by a gap under 1 % of the values is reported as close

BELOW, ABOVE, OPEN = "below", "above", "open"


@dataclass(frozen=True)
class Estimate:
    """A score at the finest step run, with its numerical error (its distance to the continuous-time value)."""

    value: float
    error: float  # math.inf when the ladder cannot bound it (``note`` says why)
    step: float
    plant_step: float | None = None  # the plant's internal RK4 step of the run the value comes from
    note: str = ""  # why the error is infinite: the ladder shows no convergence, a run is missing

    def scaled(self, factor: float) -> "Estimate":
        return Estimate(factor * self.value, abs(factor) * self.error, self.step, self.plant_step, self.note)

    def text(self) -> str:
        if self.value == math.inf:
            return "not settled within the horizon"
        return plus_minus(self.value, self.error)

    def where(self) -> str:
        """``h = 2.5e-05 s, plant step 3.12e-06 s``: the run the value comes from."""
        return f"h = {self.step:g} s" + (f", plant step {self.plant_step:.3g} s" if self.plant_step else "")


def plus_minus(value: float, error: float) -> str:
    """``418.222 ± 0.012``: the value to the digits its error leaves meaningful (two of the error)."""
    if value is None or not math.isfinite(value):
        return "n/a"
    if not math.isfinite(error):
        return f"{value:.6g} ± ?"
    if error == 0.0:
        return f"{value:.6g} ± 0"
    decimals = min(12, max(0, 1 - math.floor(math.log10(error))))
    return f"{value:.{decimals}f} ± {error:.2g}"


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=STEP_MATCH)


def _ratio(row: dict) -> float | None:
    """h_p / h of a co-simulation run (None when the run does not say its plant step)."""
    return row["plant_step"] / row["step"] if row.get("plant_step") else None


def communication_error(values: list) -> tuple[float, str]:
    """(the error left in the last of ``values``, a note when the chain shows no convergence): the values of
    one case at halving steps, coarsest first (see the module's doc)."""
    if len(values) < 2:
        return math.inf, "no run at half the step"
    last = abs(values[-1] - values[-2])
    if len(values) == 2:
        return last, ""
    previous = abs(values[-2] - values[-3])
    if last == 0.0:
        return 0.0, ""
    if last >= previous:
        return math.inf, (f"no convergence shown: the last halving changed it by {last:.2g}, the one before by "
                          f"{previous:.2g}")
    q = last / previous
    return last * max(1.0, q / (1.0 - q)), ""


def _tolerance_estimate(runs: list, metric: str) -> Estimate | None:
    """Model Exchange rows (each with an ``rtol``): the tightest run, its error the change from a
    TOLERANCE_FACTOR looser one."""
    runs = sorted(runs, key=lambda o: o["rtol"])
    finest = runs[0]
    if finest["status"] != "ok" or finest.get(metric) is None:
        return None
    coarser = next((o for o in runs[1:] if math.isclose(o["rtol"], TOLERANCE_FACTOR * finest["rtol"],
                                                        rel_tol=1e-9)), None)
    if coarser is None or coarser["status"] != "ok" or coarser.get(metric) is None:
        error = math.inf
    else:
        error = abs(coarser[metric] - finest[metric])
    if metric in GRID_QUANTISED:
        error = max(error, finest["step"])
    return Estimate(float(finest[metric]), error, float(finest["step"]))


def estimate(ladder: list, metric: str) -> Estimate | None:
    """The score ``metric`` of one (scenario, controller) from its ladder (see the module's doc), or (Model
    Exchange rows with an ``rtol``) from its runs at tolerances TOLERANCE_FACTOR apart.

    ``ladder`` holds outcome rows (``step``, ``plant_step``, ``status`` and the scores), in any order.
    None when the finest run failed or gives no value; an infinite error (with its note) when the ladder
    cannot bound it.  A ts the finest run does not reach (not settled within the horizon) is +inf.
    """
    if not ladder:
        return None
    if all(o.get("rtol") for o in ladder):  # a Model Exchange ladder (--algorithm me)
        return _tolerance_estimate(ladder, metric)
    runs = sorted(ladder, key=lambda o: (-o["step"], -(o.get("plant_step") or 0.0)))
    finer_steps = [o for o in runs if o["step"] < runs[0]["step"] * (1 - STEP_MATCH)]
    chain_ratio = _ratio(finer_steps[0]) if finer_steps else None  # h_p / h of the communication axis
    top = [o for o in runs if _same(o["step"], runs[0]["step"])]
    # the table's run: the coarsest step at the communication axis's h_p / h (the others there: the plant axis)
    table = next((o for o in top if chain_ratio is not None and _ratio(o) is not None
                  and _same(_ratio(o), chain_ratio)), top[0])
    chain = [o for o in runs if _ratio(o) is None or _ratio(table) is None or _same(_ratio(o), _ratio(table))]
    chain = [o for o in chain if o is table or o["step"] < table["step"] * (1 - STEP_MATCH)]
    finest = chain[-1]
    value = _value(finest, metric)
    if value is None:
        return None
    plant_step = finest.get("plant_step")
    if any(o["status"] != "ok" or _value(o, metric) is None for o in chain):
        error, note = math.inf, "a run of the ladder failed or gives no value"
    else:
        values = [_value(o, metric) for o in chain]
        if any(v == math.inf for v in values):
            error, note = (0.0, "") if all(v == math.inf for v in values) else (
                math.inf, "settles at one step of the ladder and not at another")
        elif metric in GRID_QUANTISED:  # read off the grid: its changes are steps of the grid, not a series
            error, note = communication_error(values[-2:])
        else:
            error, note = communication_error(values)
    plant = [o for o in top if o is not table and _ratio(o) is not None and _ratio(table) is not None
             and not _same(_ratio(o), _ratio(table))]
    if not plant and not any(o.get("plant_axis", True) for o in ladder):
        plant_error = 0.0  # a smooth plant: the communication axis counts its RK4 error (ladders.py)
    elif not plant:
        plant_error, note = math.inf, note or "no run at another plant step"
    elif plant[0]["status"] != "ok" or _value(plant[0], metric) is None or _value(table, metric) is None:
        plant_error, note = math.inf, note or "the run at another plant step failed or gives no value"
    else:
        other, own = _value(plant[0], metric), _value(table, metric)
        change = 0.0 if other == own else abs(other - own)  # inf - inf: unsettled at both
        if math.isnan(change) or (math.inf in (other, own) and other != own):
            plant_error, note = math.inf, note or "settles at one plant step and not at the other"
        else:  # first order in h_p: the error left at the table's h_p, from the change to the other h_p
            plant_error = change * _ratio(table) / abs(_ratio(plant[0]) - _ratio(table))
    error = SAFETY_FACTOR * (error + plant_error)
    if value == math.inf:  # not settled within the horizon at every step of the ladder
        error = 0.0 if math.isfinite(error) else error
    elif metric in GRID_QUANTISED:
        error = max(error, finest["step"])
    return Estimate(float(value), error, float(finest["step"]), plant_step, note if not math.isfinite(error) else "")


def _value(row: dict, metric: str):
    """The row's score; a ts the run does not reach (not settled within its horizon, which could show it) is
    +inf; None when the run failed or the horizon does not define the score."""
    if row.get("status") != "ok":
        return None
    value = row.get(metric)
    if value is None and metric == "ts" and row.get("stop", 0.0) - row.get("start", 0.0) >= SETTLING_DWELL:
        return math.inf  # the horizon could have shown settling: the run settles later, if ever
    return value


def missing_reason(ladder: list, metric: str) -> str:
    """Why a (scenario, controller) has no estimate of ``metric`` (:func:`estimate` gave None)."""
    runs = sorted(ladder, key=lambda o: o["step"])
    if not runs:
        return "not run"
    finest = runs[0]
    if finest["status"] != "ok":
        return f"run {finest['status']}"
    return why_none(metric, finest.get("start", 0.0), finest.get("stop", math.nan))


def relative_gap(low: Estimate, high: Estimate) -> float:
    """|high - low| over the larger magnitude: how far apart two scores are, as a fraction."""
    scale = max(abs(low.value), abs(high.value))
    return abs(high.value - low.value) / scale if scale > 0 else 0.0


def compare(low: Estimate, high: Estimate) -> tuple[str, float, float]:
    """(BELOW | ABOVE | OPEN, gap, combined error): is ``low`` clearly below ``high``?"""
    gap = high.value - low.value
    combined = low.error + high.error
    if gap > combined:
        return BELOW, gap, combined
    if -gap > combined:
        return ABOVE, gap, combined
    return OPEN, gap, combined


def gap_text(gap: float, combined: float, decided: bool, other: str) -> str:
    """``gap 0.104 > error 0.0993``, or which run does not settle within the horizon (ts)."""
    if math.isnan(gap):
        return f"neither {PROPOSED} nor {other} settles within the horizon"
    if math.isinf(gap):
        return f"{other if gap > 0 else PROPOSED} does not settle within the horizon"
    return f"gap {abs(gap):.3g} {'>' if decided else '<='} error {combined:.3g}"


def combine(verdicts: list) -> str:
    """All in favour: reproduced; one clearly against: not reproduced; else not decided."""
    if any(v == NOT_REPRODUCED for v in verdicts):
        return NOT_REPRODUCED
    if verdicts and all(v == REPRODUCED for v in verdicts):
        return REPRODUCED
    return UNDECIDED


@dataclass
class Claim:
    label: str
    verdict: str
    details: list = field(default_factory=list)  # one line per scenario (or controller)
    open_cases: set = field(default_factory=set)  # (scenario, controller) a finer step could decide
    close: list = field(default_factory=list)  # "scenario (metric vud vs other: 0.02 %)": decided by a small margin


def _comparisons(name: str, metric: str, ladders: dict, factor: float = 1.0):
    """vud's ``metric`` against ``factor`` x each comparison controller in one scenario:
    (verdict, detail line, cases a finer step could decide, close comparisons that decide the verdict)."""
    estimates = {c: estimate(ladders.get((name, c), []), metric) for c in CONTROLLERS}
    missing = {c: missing_reason(ladders.get((name, c), []), metric) for c, e in estimates.items() if e is None}
    if missing:
        reasons = {}
        for controller, reason in missing.items():
            reasons.setdefault(reason, []).append(controller)
        text = "; ".join(f"{', '.join(names)}: {reason}" for reason, names in reasons.items())
        return UNDECIDED, f"{name}: no {metric} ({text})", set(), []
    vud = estimates[PROPOSED]
    outcomes, parts, open_cases, close = [], [], set(), {}
    for other in variants.COMPARISONS:
        limit = estimates[other].scaled(factor)
        outcome, gap, combined = compare(vud, limit)
        outcomes.append(outcome)
        margin = relative_gap(vud, limit)
        is_close = outcome != OPEN and margin < CLOSE_MARGIN
        relation = {BELOW: "below", ABOVE: "above", OPEN: "undecided"}[outcome]
        if outcome != OPEN:
            relation = f"just {relation} (close: by {100 * margin:.2g} %)" if is_close else f"clearly {relation}"
        elif not math.isfinite(combined):  # a ladder that cannot bound its error: no verdict with a too-small one
            notes = [e.note for e in (vud, limit) if e.note]
            relation = "undecided at this step" + (f" ({'; '.join(dict.fromkeys(notes))})" if notes else "")
        scaled = f"{factor:g} x " if factor != 1.0 else ""
        parts.append(f"{scaled}{other} {limit.text()} ({estimates[other].where()}; {PROPOSED} {relation}: "
                     f"{gap_text(gap, combined, outcome != OPEN, other)})")
        if outcome == OPEN and not math.isnan(gap):  # two runs unsettled within the horizon: no step decides
            open_cases |= {(name, PROPOSED), (name, other)}
        if is_close:
            close[outcome] = close.get(outcome, []) + [f"{name} ({metric}: {PROPOSED} vs {scaled}{other} by "
                                                       f"{100 * margin:.2g} %)"]
    if all(o == BELOW for o in outcomes):
        verdict, deciding = REPRODUCED, close.get(BELOW, [])
    elif any(o == ABOVE for o in outcomes):
        verdict, deciding = NOT_REPRODUCED, close.get(ABOVE, [])
        if len(deciding) < outcomes.count(ABOVE):  # a clear comparison decides it too
            deciding = []
    else:
        verdict, deciding = UNDECIDED, []
    line = f"{name}: {PROPOSED} {vud.text()} ({vud.where()}) vs " + ", ".join(parts) + f": {verdict}"
    return verdict, line, open_cases, deciding


def best_claim(label: str, metric: str, scenario_list, ladders: dict, factor: float = 1.0) -> Claim:
    verdicts, details, open_cases, close = [], [], set(), []
    for name in scenario_list:
        verdict, line, cases, deciding = _comparisons(name, metric, ladders, factor)
        verdicts.append(verdict)
        details.append(line)
        open_cases |= cases
        close.append((verdict, deciding))
    verdict = combine(verdicts)
    # close when every comparison that decides the verdict is close (not reproduced: those against it)
    if verdict == REPRODUCED:
        deciding = [d for _, found in close for d in found] if all(found for _, found in close) else []
    elif verdict == NOT_REPRODUCED:
        against = [found for v, found in close if v == NOT_REPRODUCED]
        deciding = [d for found in against for d in found] if all(against) else []
    else:
        deciding = []
    return Claim(label, verdict, details, open_cases if verdict == UNDECIDED else set(), deciding)


def relative_change(two: Estimate, one: Estimate) -> tuple[float, float]:
    """r = two / one - 1 and its error from both errors (first order, added)."""
    ratio = two.value / one.value
    error = (two.error + abs(ratio) * one.error) / abs(one.value)
    return ratio - 1.0, error


def disturbance_claim(ladders: dict) -> Claim:
    label = (f"The disturbance barely changes the proposed AFC's tracking (case 2 vs case 1: "
             f"ITAE and IAE within {100 * DISTURBANCE_TOLERANCE:.0f} %)")
    verdicts, details, open_cases = [], [], set()
    for controller in CONTROLLERS:
        changes = []
        for metric in ("ITAE", "IAE"):
            one = estimate(ladders.get(("pendulum_case1", controller), []), metric)
            two = estimate(ladders.get(("pendulum_case2", controller), []), metric)
            if one is None or two is None or one.value == 0.0:
                changes.append(f"{metric} n/a (run failed)")
                if controller == PROPOSED:
                    verdicts.append(UNDECIDED)
                continue
            change, error = relative_change(two, one)
            changes.append(f"{metric} {100 * change:+.3g} % ± {100 * error:.2g} % "
                           f"({two.text()} vs {one.text()})")
            if controller != PROPOSED:
                continue
            if abs(change) + error < DISTURBANCE_TOLERANCE:
                verdicts.append(REPRODUCED)
            elif abs(change) - error > DISTURBANCE_TOLERANCE:
                verdicts.append(NOT_REPRODUCED)
            else:
                verdicts.append(UNDECIDED)
                open_cases |= {("pendulum_case1", PROPOSED), ("pendulum_case2", PROPOSED)}
        details.append(f"{controller}: case 2 vs case 1: {', '.join(changes)}")
    verdict = combine(verdicts)
    return Claim(label, verdict, details, open_cases if verdict == UNDECIDED else set())


def claims_check(ladders: dict) -> list:
    """Every claim of the paper with its verdict, the numbers with their errors, and what is open.

    ``ladders`` maps (scenario, controller) to that case's ladder rows (harness/studies/ladders.py: at least h,
    h/2 and h with another plant step for a finite error; each row with ``step``, ``plant_step``, ``status`` and
    the scores).
    """
    claims = [
        best_claim("The proposed AFC has the shortest settling time ts in all four scenarios",
                   "ts", ALL_SCENARIOS, ladders),
        best_claim("The proposed AFC has the smallest steady-state error es1 in all four scenarios",
                   "es1_pct", ALL_SCENARIOS, ladders),
        best_claim("The proposed AFC has the smallest steady-state error es2 in all four scenarios",
                   "es2_pct", ALL_SCENARIOS, ladders),
        best_claim("The proposed AFC has the smallest ITAE in all four scenarios", "ITAE", ALL_SCENARIOS, ladders),
        best_claim("The proposed AFC has the smallest IAE in all four scenarios", "IAE", ALL_SCENARIOS, ladders),
        best_claim("The proposed AFC needs the least control energy Ec for the pendulum (cases 1-3)",
                   "Ec", PENDULUM, ladders),
        disturbance_claim(ladders),
        best_claim(f"The proposed AFC's control input is smooth (total variation of u per second at most "
                   f"{100 * (SMOOTHNESS_TOLERANCE - 1):.0f} % above the smoother comparison controller)",
                   "tv_u", ALL_SCENARIOS, ladders, factor=SMOOTHNESS_TOLERANCE),
    ]
    return claims


def undecided_cases(claims: list) -> set:
    """(scenario, controller) pairs whose finer run could decide a claim still open."""
    cases = set()
    for claim in claims:
        cases |= claim.open_cases
    return cases


def ladders_from_rows(rows: list) -> dict:
    """Outcome rows (any steps, any order) grouped by (scenario, controller)."""
    ladders: dict = {}
    for row in rows:
        ladders.setdefault((row["scenario"], row["controller"]), []).append(row)
    return ladders


def claims_markdown(claims: list) -> list:
    """Report lines: one bullet per claim with its verdict (and "close" when comparisons decided by
    a margin under CLOSE_MARGIN decide it), one sub-bullet per comparison."""
    lines = []
    for claim in claims:
        close = ""
        if claim.close:
            close = (f" (close: decided by a margin under {100 * CLOSE_MARGIN:g} % of the values, beyond the "
                     f"numerical error: {'; '.join(claim.close)})")
        lines.append(f"- **{claim.verdict}**: {claim.label}.{close}")
        lines += [f"  - {d}" for d in claim.details]
    return lines

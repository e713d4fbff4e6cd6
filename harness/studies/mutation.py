"""``python -m harness mutate``: mutation testing of the FMU sources (fmu_src/, plants/).

Each mutation is a small wrong-math edit a reviewer would worry about (a swapped
coefficient, a sign, a weight), defined robustly as *file + function + exact
substring -> replacement*.  For each mutation the command copies the repository to a
temporary folder, applies the edit there (the working tree is never touched), rebuilds
the FMUs built from the mutated file (the others are copied built), runs a fast
selection of tests with ``-x`` and reports the mutant *killed* (a test failed, the
build failed, or the tests timed out) or *survived*.  A mutation whose pattern no
longer matches its function (the source was rewritten) is reported as
*pattern not found*, never skipped: update its pattern.  A test selection that does
not run (pytest usage or internal error) is an *error*, never counted as a kill.
Exit status: 0 all killed, 1 survivors, 2 a pattern not found or an error.

The selection is deliberately not the regression references (tests/test_regression.py,
which this same code produced) but the tests that check the math against the paper.

    python -m harness mutate                 # every mutation, score and survivors
    python -m harness mutate --list          # the mutations and whether each pattern matches
    python -m harness mutate --only tau_p12_p22_swap --tests tests/test_adaptive_law_fmu.py
"""
from __future__ import annotations

import ast
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time as clock
from dataclasses import dataclass
from pathlib import Path

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import catalog as fmu_catalog

from .. import cli_args
from ..cases import parallel_map

ROOT = Path(__file__).resolve().parents[2]
CONTROLLER_TESTS = ("tests/test_adaptive_law_fmu.py", "tests/test_independent_loop.py",
                    "tests/test_afc_math.py", "tests/test_adaptive_fuzzy_controller_fmu.py")
PLANT_TESTS = ("tests/test_plants.py", "tests/test_independent_loop.py")
REFERENCE_TESTS = ("tests/test_plants.py", "tests/test_independent_loop.py")
GENERAL_TESTS = ("tests/test_general_order.py", "tests/test_afc_math.py")  # order n, m sets (docs/general_order.md)
MOTOR_TESTS = ("tests/test_dc_motor_arm.py",)  # the third-order plant and its closed loop
TIMEOUT_S = 600
SKIPPED_IN_COPY = {".git", ".venv", "build", "results", "__pycache__", ".pytest_cache"}


@dataclass(frozen=True)
class Mutation:
    name: str
    path: str  # relative to the repository root
    function: str  # the def whose source holds the pattern
    find: str  # exact substring, expected exactly once in that function
    replace: str
    tests: tuple  # the fast test selection (pytest arguments)
    why: str = ""  # what the mutation breaks, in the paper's terms


M = Mutation
MUTATIONS = (
    # --- the controller (fmu_src/)
    M("tau_p12_p22_swap", "fmu_src/afc_math.py", "adaptation_signal", "error[0] * p_b[0] + error[1] * p_b[1]",
      "error[0] * p_b[1] + error[1] * p_b[0]", CONTROLLER_TESTS, "tau = [E, dE] P B with p12 and p22 swapped (31)"),
    M("projection_upper_sign", "fmu_src/afc_math.py", "projected_rate", "(1.0 + (m_theta - theta_j) / delta)",
      "(1.0 - (m_theta - theta_j) / delta)", CONTROLLER_TESTS, "upper branch of the projection (31)"),
    M("projection_lower_sign", "fmu_src/afc_math.py", "projected_rate", "(1.0 + (m_theta + theta_j) / delta)",
      "(1.0 - (m_theta + theta_j) / delta)", CONTROLLER_TESTS, "lower branch of the projection (31)"),
    M("projection_lower_theta_sign", "fmu_src/afc_math.py", "projected_rate", "(1.0 + (m_theta + theta_j) / delta)",
      "(1.0 + (m_theta - theta_j) / delta)", CONTROLLER_TESTS, "lower branch of (31) with the upper branch's term"),
    M("projection_lower_tau_condition", "fmu_src/afc_math.py", "projected_rate", "theta_j < -m_theta and tau < 0.0",
      "theta_j < -m_theta and tau > 0.0", CONTROLLER_TESTS, "lower branch of (31) active for the wrong sign of tau"),
    M("contraction_factor_sign", "fmu_src/afc_math.py", "contraction_factor", "1.0 - lambda_ce",
      "1.0 + lambda_ce", CONTROLLER_TESTS, "alpha = 1 + lambda exp(-kappa x^2) instead of (23)"),
    M("contraction_exponent_sign", "fmu_src/afc_math.py", "contraction_factor", "math.exp(-kappa * x * x)",
      "math.exp(-kappa * x)", CONTROLLER_TESTS, "alpha with exp(-kappa x) instead of exp(-kappa x^2) (23)"),
    M("normalisation_inverted", "fmu_src/afc_math.py", "normalized_input", "z = x / alpha\n", "z = x * alpha\n",
      CONTROLLER_TESTS, "z = x alpha instead of x / alpha (7)"),
    M("membership_swap", "fmu_src/afc_math.py", "memberships", "return sigmoid(slope * (first - z)), sigmoid(",
      "return sigmoid(slope * (z - first)), sigmoid(", CONTROLLER_TESTS, "mu_1 = mu_2: the low set is the high set"),
    M("rule_order_swap", "fmu_src/afc_math.py", "fuzzy_basis", "mu1[0] * mu2[1], mu1[1] * mu2[0]",
      "mu1[1] * mu2[0], mu1[0] * mu2[1]", CONTROLLER_TESTS, "rules (1,2) and (2,1) swapped in xi (8)"),
    M("sigmoid_slope_dropped", "fmu_src/afc_math.py", "memberships",
      "return sigmoid(slope * (first - z)), sigmoid(slope * (z - first))", "return sigmoid(first - z), sigmoid(z - first)",
      CONTROLLER_TESTS, "membership slope s ignored"),
    M("remark3_a1_coefficient", "fmu_src/afc_math.py", "remark3_coefficients", "(lambda_e ** (k - j)",
      "((-lambda_e) ** (k - j)", CONTROLLER_TESTS, "a1 = de(0) - lambda e(0): E(0) = 0 but dE(0) != 0 (Remark 3, (36))"),
    M("remark3_rate_sign", "fmu_src/afc_math.py", "remark3_offset", "((0.0 * t + b1) - lambda_e * value)",
      "((0.0 * t + b1) + lambda_e * value)", CONTROLLER_TESTS, "wrong derivative of the offset in dE (Remark 3)"),
    M("lyapunov_k_reversed", "fmu_src/afc_math.py", "lyapunov_p", "row[unknown[n - 1, j]] -= k[n - 1 - i]",
      "row[unknown[n - 1, j]] -= k[i]", CONTROLLER_TESTS, "companion matrix with k reversed: k1 and k2 swapped (30)"),
    M("lyapunov_q_reversed", "fmu_src/afc_math.py", "lyapunov_p", "row[size] = -q[i] if i == j",
      "row[size] = -q[n - 1 - i] if i == j", CONTROLLER_TESTS, "Q = diag(q2, q1) instead of diag(q1, q2) (30)"),
    M("gamma_for_gamma_w", "fmu_src/adaptive_fuzzy_controller_fmu.py", "step", "step_size * self.gamma_w * tau",
      "step_size * self.gamma * tau", CONTROLLER_TESTS, "w_hat learns with gamma instead of gamma_w"),
    M("fae_w_hat_sign", "fmu_src/afc_math.py", "controller_output", "u += w_hat",
      "u -= w_hat", CONTROLLER_TESTS, "u = theta^T xi - w_hat for fae"),
    M("fae_w_hat_dropped", "fmu_src/afc_math.py", "controller_output", "u += w_hat",
      "u += 0.0 * w_hat", CONTROLLER_TESTS, "fae without its estimator in u"),
    M("kappa2_for_kappa1", "fmu_src/afc_math.py", "contraction_factors",
      "contraction_factor(x[1], lambda_ce, kappa[1])", "contraction_factor(x[1], lambda_ce, kappa[0])",
      CONTROLLER_TESTS, "alpha_2 with kappa_1 (23)"),
    M("universe_e1_for_e2", "fmu_src/afc_math.py", "normalized_inputs",
      "normalized_input(x[1], alpha[1], universe[1])", "normalized_input(x[1], alpha[1], universe[0])",
      CONTROLLER_TESTS, "input 2 saturated to E1 (7)"),
    M("theta_euler_sign", "fmu_src/afc_math.py", "adapted_weights", "value + step_size * (rate * basis)",
      "value - step_size * (rate * basis)", CONTROLLER_TESTS, "theta integrated against its law (31)"),
    M("fls_state_input_sign", "fmu_src/afc_math.py", "fls_inputs", "tuple(map(sub, reference, error))",
      "tuple(map(sub, error, reference))", CONTROLLER_TESTS, "state input x = e - ym for fls_input = 2 (Remark 4)"),
    M("saturation_lower_bound", "fmu_src/afc_math.py", "normalized_input", "if z < -universe:\n        return -universe",
      "if z < -universe:\n        return universe", CONTROLLER_TESTS, "z below -E saturated to +E (7)"),
    M("fixed_gets_variable_universes", "fmu_src/afc_math.py", "controller_output",
      "if variant == VARIANT_VUD:", "if variant != VARIANT_FAE:", CONTROLLER_TESTS,
      "the fixed-universe stand-in contracts its universes"),
    M("latch_de0", "fmu_src/initial_error_latch.py", "start",
      "state[LATCHED + i] = state[LATCHED + n + i] = state[LATCHED + 2 * n + i] = float(sample[i])",
      "state[LATCHED + i] = state[LATCHED + n + i] = state[LATCHED + 2 * n + i] = float(sample[0])",
      CONTROLLER_TESTS, "de(0) latched as e(0) (Remark 3)"),
    # --- the general controller: n inputs, m sets (docs/general_order.md)
    M("membership_middle_sign", "fmu_src/afc_math.py", "memberships", "result.append(previous - rising)",
      "result.append(rising - previous)", GENERAL_TESTS, "middle sets sig(c_l) - sig(c_(l-1)): negative"),
    M("boundaries_spacing", "fmu_src/afc_math.py", "membership_boundaries", "-universe + 2.0 * universe * l / sets",
      "-universe + universe * l / sets", GENERAL_TESTS, "boundaries c_l = -E + E l / m: crowded on the left"),
    M("basis_order_general", "fmu_src/afc_math.py", "fuzzy_basis", "xi = [a * b for a in xi for b in mu]",
      "xi = [a * b for b in mu for a in xi]", GENERAL_TESTS, "l1 fastest instead of slowest for n >= 3 (8)"),
    M("remark3_recursion_sign", "fmu_src/afc_math.py", "remark3_offset",
      "values = [values[j + 1] - lambda_e * values[j]", "values = [values[j + 1] + lambda_e * values[j]",
      GENERAL_TESTS, "r_i = r_(i-1)' + lambda r_(i-1): E^(i)(t0) != 0 for n >= 3 (36)"),
    # --- the plants and the reference (plants/)
    M("pendulum_denominator_sign", "plants/inverted_pendulum/model.py", "pendulum_derivative",
      "FOUR_THIRDS - mp_over_mt * c * c", "FOUR_THIRDS + mp_over_mt * c * c", PLANT_TESTS,
      "den = lp (4/3 + mp cos^2 x1 / (mc + mp)) (37)"),
    M("pendulum_centripetal_sign", "plants/inverted_pendulum/model.py", "pendulum_derivative",
      "gv * s - mp_lp_over_mt * x2 * x2 * c * s", "gv * s + mp_lp_over_mt * x2 * x2 * c * s", PLANT_TESTS,
      "sign of the mp lp x2^2 cos sin term (37)"),
    M("pendulum_input_gain", "plants/inverted_pendulum/model.py", "pendulum_derivative", "c * inv_mt * u",
      "inv_mt * u", PLANT_TESTS, "input gain without cos x1 (37)"),
    M("pendulum_params_factor", "plants/inverted_pendulum/model.py", "pendulum_params", "mp * lp / mt",
      "mp / mt", PLANT_TESTS, "mp lp / (mc + mp) without lp (37)"),
    M("pendulum_disturbance_frequency", "plants/inverted_pendulum/model.py", "pendulum_derivative",
      "3.0 * _cos(2.0 * t)", "3.0 * _cos(t)", PLANT_TESTS, "d(t) = 3 cos t + ... instead of 3 cos 2t"),
    M("manipulator_coulomb_sign", "plants/manipulator/model.py", "manipulator_derivative", "torque -= cr",
      "torque += cr", PLANT_TESTS, "Coulomb friction pushes instead of opposing (39)"),
    M("manipulator_gravity_cos", "plants/manipulator/model.py", "manipulator_derivative",
      "mr * gv_lr * _cos(x1)", "mr * gv_lr * _sin(x1)", PLANT_TESTS, "gravity torque with sin x1 (38)"),
    M("manipulator_damping_sign", "plants/manipulator/model.py", "manipulator_derivative",
      "u - dr_plus_vr * x2", "u + dr_plus_vr * x2", PLANT_TESTS, "damping and viscous friction sign (38, 39)"),
    M("manipulator_payload_sign", "plants/manipulator/model.py", "manipulator_derivative", "mr0 + mr1 * _sin(t)",
      "mr0 - mr1 * _sin(t)", PLANT_TESTS, "payload 5 - 4 sin t (39)"),
    M("manipulator_inertia_factor", "plants/manipulator/model.py", "manipulator_params",
      "INERTIA_COEFFICIENT * lr * lr", "INERTIA_COEFFICIENT * lr", PLANT_TESTS, "J = 1.33 mr lr (39)"),
    M("rk4_weights_x1", "plants/plant_integration.py", "rk4_advance", "sixth * (a1 + 2.0 * (a2 + a3) + a4)",
      "sixth * (2.0 * a1 + (a2 + a3) + 2.0 * a4)", PLANT_TESTS, "RK4 weights (1, 2, 2, 1) -> (2, 1, 1, 2) in x1"),
    M("rk4_weights_x2", "plants/plant_integration.py", "rk4_advance", "sixth * (b1 + 2.0 * (b2 + b3) + b4)",
      "sixth * (b1 + 2.0 * (b2 + b3) + 2.0 * b4)", PLANT_TESTS, "RK4 weight of k4 doubled in x2"),
    M("rk4_stage3_half", "plants/plant_integration.py", "rk4_advance", "x2 + half * b2, u, params)",
      "x2 + h * b2, u, params)", PLANT_TESTS, "RK4 third stage at a full step"),
    M("rk4_stage_time", "plants/plant_integration.py", "rk4_advance", "tm = ti + half", "tm = ti", PLANT_TESTS,
      "RK4 middle stages at the start time (d(t), mr(t) sampled wrong)"),
    M("internal_step_floor", "plants/plant_integration.py", "internal_step_count",
      "math.ceil(step_size / max_internal_step - SPLIT_TOLERANCE)",
      "math.floor(step_size / max_internal_step - SPLIT_TOLERANCE)", PLANT_TESTS,
      "internal steps larger than max_internal_step"),
    M("friction_output_sign", "plants/manipulator/model.py", "manipulator_friction", "-(sgn(x2) * cr + vr * x2)",
      "-(sgn(x2) * cr - vr * x2)", PLANT_TESTS, "the d output's viscous term (39)"),
    M("reference_phase_omega", "plants/tracking_reference/fmu.py", "compute_outputs", "phase = omega * self.time",
      "phase = self.time", REFERENCE_TESTS, "ym = A sin t whatever omega"),
    M("reference_derivative_omega", "plants/tracking_reference/fmu.py", "compute_outputs",
      "dym = amplitude * omega * _cos(phase)", "dym = amplitude * _cos(phase)", REFERENCE_TESTS,
      "dym without omega"),
    M("reference_error_sign", "plants/tracking_reference/fmu.py", "compute_outputs", "self.de = dym - self.dy",
      "self.de = self.dy - dym", REFERENCE_TESTS, "de = dy - dym"),
    M("reference_acceleration_sign", "plants/tracking_reference/fmu.py", "compute_outputs",
      "-amplitude * omega * omega * s", "amplitude * omega * omega * s", REFERENCE_TESTS, "ddym sign"),
    M("reference_d2e_sign", "plants/tracking_reference/fmu.py", "compute_outputs", "self.d2e = ddym - self.d2y",
      "self.d2e = self.d2y - ddym", MOTOR_TESTS, "d2e = d2y - ddym"),
    M("motor_back_emf_sign", "plants/dc_motor_arm/model.py", "motor_arm_derivative",
      "(u - resistance * x3 - ke * x2) * inv_l", "(u - resistance * x3 + ke * x2) * inv_l", MOTOR_TESTS,
      "back-emf adds to the armature voltage"),
    M("rk4_states_weights", "plants/plant_integration.py", "rk4_advance_states", "sixth * (b1 + 2.0 * (b2 + b3) + b4)",
      "sixth * (b1 + 2.0 * (b2 + b3) + 2.0 * b4)", MOTOR_TESTS, "n-state RK4 weight of k4 doubled"),
)


class PatternNotFound(ValueError):
    """A mutation's pattern does not occur exactly once in its function."""


def function_span(source: str, function: str) -> tuple[int, int]:
    """(start, end) character offsets of ``def function`` (the first with that name)."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == function:
            lines = source.splitlines(keepends=True)
            start = sum(len(line) for line in lines[:node.lineno - 1])
            end = sum(len(line) for line in lines[:node.end_lineno])
            return start, end
    raise PatternNotFound(f"no function {function!r}")


def mutated_source(source: str, mutation: Mutation) -> str:
    """``source`` with the mutation applied; PatternNotFound when its pattern does not match once."""
    start, end = function_span(source, mutation.function)
    body = source[start:end]
    count = body.count(mutation.find)
    if count != 1:
        raise PatternNotFound(f"{mutation.find!r} occurs {count} times in {mutation.function}(), expected once")
    return source[:start] + body.replace(mutation.find, mutation.replace) + source[end:]


def check_pattern(mutation: Mutation, root: Path = ROOT) -> str | None:
    """None when the mutation applies to the sources in ``root``, else why not."""
    path = root / mutation.path
    if not path.exists():
        return f"{mutation.path} does not exist"
    try:
        mutated_source(path.read_text(), mutation)
    except PatternNotFound as error:
        return f"{mutation.path}: {error}"
    return None


def repository_files(root: Path) -> list[Path]:
    """The files a clone holds (tracked plus new, not ignored), relative to ``root``."""
    try:
        listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=root, capture_output=True,
                                text=True, check=True).stdout.splitlines()
        return [Path(name) for name in listed if (root / name).is_file()]
    except (OSError, subprocess.CalledProcessError):
        return [p.relative_to(root) for p in root.rglob("*")
                if p.is_file() and not SKIPPED_IN_COPY & set(p.relative_to(root).parts)]


def copy_repository(root: Path, target: Path, built: dict):
    """Copy the sources (mtimes kept) and the built FMUs into ``target``."""
    for relative in repository_files(root):
        destination = target / relative
        destination.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / relative, destination)
    fmu_dir = target / "build" / "fmus"
    fmu_dir.mkdir(parents=True, exist_ok=True)
    for path in built.values():
        shutil.copy2(path, fmu_dir / Path(path).name)


def stale_fmus(mutation: Mutation, target: Path) -> list[Path]:
    """The copied FMUs built from the mutated file: removed so the tests rebuild them."""
    mutated = (ROOT / mutation.path).resolve()
    return [target / "build" / "fmus" / f"{f.model_identifier}.fmu" for f in fmu_catalog.FMUS
            if any(Path(source).resolve() == mutated for source in f.sources)]


@dataclass
class Outcome:
    mutation: Mutation
    status: str  # killed, survived, pattern not found, error (the tests did not run)
    detail: str
    seconds: float


def run_mutant(mutation: Mutation, built: dict, tests: tuple | None = None, timeout: float = TIMEOUT_S) -> Outcome:
    started = clock.perf_counter()
    problem = check_pattern(mutation)
    if problem:
        return Outcome(mutation, "pattern not found", problem, 0.0)
    with tempfile.TemporaryDirectory(prefix="afc_mutant_") as folder:
        target = Path(folder)
        copy_repository(ROOT, target, built)
        path = target / mutation.path
        path.write_text(mutated_source(path.read_text(), mutation))
        for fmu in stale_fmus(mutation, target):
            fmu.unlink(missing_ok=True)
        environment = dict(os.environ, PYTHONPATH=str(target), PYTHONDONTWRITEBYTECODE="1")
        command = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-rf",
                   *(tests or mutation.tests)]
        try:
            completed = subprocess.run(command, cwd=target, env=environment, capture_output=True, text=True,
                                       timeout=timeout)
        except subprocess.TimeoutExpired:
            return Outcome(mutation, "killed", f"tests timed out after {timeout:g} s",
                           clock.perf_counter() - started)
    seconds = clock.perf_counter() - started
    output = completed.stdout + completed.stderr
    if completed.returncode == 0:
        return Outcome(mutation, "survived", _last_line(output), seconds)
    if completed.returncode == 5:  # pytest: no tests collected
        return Outcome(mutation, "survived", "no test ran: " + _last_line(output), seconds)
    if completed.returncode != 1:  # 2 interrupted, 3 internal error, 4 usage error: no verdict
        return Outcome(mutation, "error", f"pytest exit status {completed.returncode}: {_last_line(output)}",
                       seconds)
    failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", output, re.M)
    detail = f"by {failed[0]}" if failed else _last_line(output)
    return Outcome(mutation, "killed", detail, seconds)


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else ""


def select(names) -> list:
    if not names:
        return list(MUTATIONS)
    known = {m.name: m for m in MUTATIONS}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise cli_args.UsageError(f"unknown mutation {', '.join(unknown)}; valid: {', '.join(known)}")
    return [known[n] for n in names]


def mutate_command(args) -> int:
    mutations = select(args.only)
    if args.list:
        missing = 0
        for mutation in mutations:
            problem = check_pattern(mutation)
            missing += problem is not None
            print(f"{mutation.name:32s} {mutation.path}:{mutation.function}  "
                  f"{'PATTERN NOT FOUND: ' + problem if problem else 'ok'}")
        return 2 if missing else 0
    if importlib.util.find_spec("pytest") is None:  # each mutant is judged by the test suite
        raise cli_args.UsageError("mutate runs the tests on every mutant: it needs pytest, in the test extra: "
                                  "pip install -e '.[test]'")
    built = build_fmu.ensure_built()
    tests = tuple(args.tests) if args.tests else None
    started = clock.perf_counter()
    outcomes = parallel_map(_run_one, [(m, built, tests, args.timeout) for m in mutations], args.jobs or 1,
                            "mutants", progress=None)
    for outcome in outcomes:
        print(f"{outcome.status.upper():17s} {outcome.mutation.name:32s} {outcome.seconds:6.1f} s  {outcome.detail}")
    missing = [o for o in outcomes if o.status in ("pattern not found", "error")]
    tried = [o for o in outcomes if o.status in ("killed", "survived")]
    killed = [o for o in tried if o.status == "killed"]
    survivors = [o for o in tried if o.status == "survived"]
    print(f"\nmutation score: {len(killed)}/{len(tried)} killed in {clock.perf_counter() - started:.0f} s")
    for outcome in survivors:
        print(f"  survived: {outcome.mutation.name} ({outcome.mutation.why}; {outcome.mutation.path}:"
              f"{outcome.mutation.function})")
    for outcome in missing:
        advice = ("update its pattern in harness/studies/mutation.py" if outcome.status == "pattern not found"
                  else "the test selection did not run")
        print(f"error: mutation {outcome.mutation.name}: {outcome.status}: {outcome.detail}; {advice}",
              file=sys.stderr)
    return 2 if missing else (1 if survivors else 0)


def _run_one(arguments: tuple) -> Outcome:
    return run_mutant(*arguments)


def register(commands):
    parser = commands.add_parser("mutate", help="mutation testing of fmu_src/ and plants/: score and survivors")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="these mutations (default: all)")
    parser.add_argument("--list", action="store_true", help="list the mutations and check their patterns")
    parser.add_argument("--tests", nargs="+", help="pytest selection for every mutant (default: each mutation's own)")
    parser.add_argument("--jobs", type=cli_args.positive_int, default=1, help="mutants in parallel (default 1)")
    parser.add_argument("--timeout", type=cli_args.positive_float, default=TIMEOUT_S, help="seconds per mutant's tests")
    parser.set_defaults(handler=mutate_command)

"""The controller's math in C (fmu_src/afc_math.c) through ctypes: P against scipy, the
memberships and basis, Remark 3 for every order n = 1..4 and m = 2..5 (docs/general_order.md), and every
C function against its Python twin in fmu_src/afc_math.py, bit for bit."""
import ctypes
import math
import platform
import random
import struct

import numpy as np
import pytest

from harness.fmu_build import native as build_native
from harness.fmu_build.native_stages import compiler
from fmu_src import afc_math, chatter_monitor
from harness import variants

MAX_ORDER = 4
MAX_SETS = 5
MAX_BOUNDARIES = MAX_SETS - 1
MAX_RULES = 625
Matrix = (ctypes.c_double * MAX_ORDER) * MAX_ORDER
Boundaries = (ctypes.c_double * MAX_BOUNDARIES) * MAX_ORDER
double_p = ctypes.POINTER(ctypes.c_double)


class ControllerParameters(ctypes.Structure):
    """afc_math.h's ControllerParameters: the C form of afc_math.controller_parameters' dict."""
    _fields_ = [("lambda_e", ctypes.c_double), ("lambda_ce", ctypes.c_double), ("mf_slope", ctypes.c_double),
                ("kappa", ctypes.c_double * MAX_ORDER), ("universe", ctypes.c_double * MAX_ORDER),
                ("boundaries", Boundaries), ("p_b", ctypes.c_double * MAX_ORDER),
                ("error0", ctypes.c_double * MAX_ORDER), ("t0", ctypes.c_double), ("remark3", Matrix),
                ("order", ctypes.c_int), ("sets", ctypes.c_int), ("rules", ctypes.c_int),
                ("variant", ctypes.c_int), ("fls_input", ctypes.c_int), ("alpha_min", ctypes.c_double)]

pytestmark = [
    pytest.mark.skipif(not build_native.compiler_available(), reason="zig's C compiler is not installed"),
    pytest.mark.skipif(platform.system() != "Linux" or platform.machine() != "x86_64",
                       reason="the test library is built for Linux x86-64"),
]


SIGNATURES = {  # name: (restype, argtypes)
    "lyapunov_p": (ctypes.c_int, [ctypes.c_int, double_p, double_p, ctypes.POINTER(Matrix)]),
    "is_positive_definite": (ctypes.c_int, [ctypes.c_int, ctypes.POINTER(Matrix)]),
    "contraction_factor": (ctypes.c_double, [ctypes.c_double] * 3),
    "normalized_input": (ctypes.c_double, [ctypes.c_double] * 3),
    "sigmoid": (ctypes.c_double, [ctypes.c_double]),
    "membership_high": (ctypes.c_double, [ctypes.c_double] * 2),
    "membership_low": (ctypes.c_double, [ctypes.c_double] * 2),
    "membership_boundaries": (None, [ctypes.c_double, ctypes.c_int, double_p]),
    "memberships": (None, [ctypes.c_int, ctypes.c_double, ctypes.c_double, double_p, double_p]),
    "fuzzy_basis": (ctypes.c_int, [ctypes.c_int, ctypes.c_int, double_p, ctypes.c_double, ctypes.POINTER(Boundaries),
                                   double_p]),
    "remark3_coefficients": (None, [ctypes.c_int, double_p, ctypes.c_double, double_p]),
    "remark3_polynomials": (None, [ctypes.c_int, double_p, ctypes.POINTER(Matrix)]),
    "remark3_offset": (None, [ctypes.c_int, ctypes.POINTER(Matrix), ctypes.c_double, ctypes.c_double, double_p]),
    "modified_error": (None, [ctypes.c_int, double_p, ctypes.c_double, double_p, ctypes.c_double, ctypes.c_double,
                              ctypes.POINTER(Matrix), double_p]),
    "adaptation_signal": (ctypes.c_double, [ctypes.c_int, double_p, double_p]),
    "projected_rate": (ctypes.c_double, [ctypes.c_double] * 6),
    "adapted_weights": (None, [ctypes.c_int, double_p, ctypes.c_double, double_p, ctypes.c_double, ctypes.c_double,
                               ctypes.c_double, ctypes.c_double, double_p]),
    "fls_inputs": (None, [ctypes.c_int, double_p, double_p, double_p, ctypes.c_int, double_p]),
    "contraction_factors": (None, [ctypes.c_int, double_p, ctypes.c_double, double_p, double_p]),
    "normalized_inputs": (None, [ctypes.c_int, double_p, double_p, double_p, double_p]),
    "latch_error": (None, [ctypes.POINTER(ControllerParameters), double_p, ctypes.c_double]),
    "floored_contraction_factors": (None, [ctypes.c_int, double_p, ctypes.c_double, double_p]),
    "dead_zone_signal": (ctypes.c_double, [ctypes.c_double] * 2),
    "leaky_weights": (None, [ctypes.c_int, double_p, double_p, ctypes.c_double, ctypes.c_double, double_p]),
    "leaky_rates": (None, [ctypes.c_int, double_p, double_p, ctypes.c_double, double_p]),
    "measurement_filter_gain": (ctypes.c_double, [ctypes.c_double] * 2),
    "filtered_measurements": (None, [ctypes.c_int, double_p, double_p, ctypes.c_double, double_p]),
    "controller_output": (ctypes.c_double, [double_p, double_p, ctypes.c_double, double_p, ctypes.c_double,
                                            ctypes.POINTER(ControllerParameters), double_p, double_p, double_p]),
}


@pytest.fixture(scope="module")
def afc():
    library = ctypes.CDLL(str(compiler.math_library()))
    for name, (restype, argtypes) in SIGNATURES.items():
        function = getattr(library, name)
        function.restype, function.argtypes = restype, argtypes
    return library


def vector(values, size=MAX_ORDER):
    return (ctypes.c_double * size)(*values)


def c_lyapunov(afc, k, q):
    p = Matrix()
    status = afc.lyapunov_p(len(k), vector(k), vector(q), ctypes.byref(p))
    n = len(k)
    return status, np.array([[p[i][j] for j in range(n)] for i in range(n)])


def companion(k):
    n = len(k)
    a = np.zeros((n, n))
    a[np.arange(n - 1), np.arange(1, n)] = 1.0
    a[n - 1, :] = [-k[n - 1 - j] for j in range(n)]
    return a


@pytest.mark.parametrize("k,q", [
    ((3.0,), (2.0,)),
    ((2.0, 1.0), (10.0, 10.0)),
    ((3.0, 2.0), (7.0, 4.0)),
    ((2.0, 1.0, 0.5), (10.0, 10.0, 10.0)),
    ((3.0, 3.0, 1.0), (1.0, 5.0, 2.0)),
    ((4.0, 6.0, 4.0, 1.0), (10.0, 1.0, 3.0, 7.0)),
    ((2.0, 1.0, 0.5, 0.1), (10.0, 10.0, 10.0, 10.0)),
])
def test_p_solves_the_lyapunov_equation_as_scipy_does(afc, k, q):
    from scipy.linalg import solve_continuous_lyapunov

    status, p = c_lyapunov(afc, k, q)
    a = companion(k)
    expected = solve_continuous_lyapunov(a.T, -np.diag(q))  # A^T P + P A = -Q  (30)
    assert status == 0
    np.testing.assert_allclose(p, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(p, p.T, rtol=0, atol=0)


def test_a_singular_lyapunov_equation_is_reported(afc):
    status, _ = c_lyapunov(afc, (0.0, 1.0, 0.0), (1.0, 1.0, 1.0))  # s^3 + s: eigenvalues +-i, 0
    assert status == -1


def c_boundaries(afc, universe, sets):
    boundaries = vector([0.0] * MAX_BOUNDARIES, MAX_BOUNDARIES)
    afc.membership_boundaries(universe, sets, boundaries)
    return boundaries


@pytest.mark.parametrize("sets", [2, 3, 4, 5])
def test_memberships_are_a_partition_of_unity(afc, sets):
    mu = vector([0.0] * 5, 5)
    boundaries = c_boundaries(afc, 1.0, sets)
    for z in np.linspace(-1.2, 1.2, 41):
        afc.memberships(sets, z, 7.0, boundaries, mu)
        values = list(mu)[:sets]
        assert math.isclose(sum(values), 1.0, rel_tol=0, abs_tol=1e-15)
        assert min(values) >= 0.0


def test_two_sets_are_the_papers_pair(afc):
    mu = vector([0.0] * 5, 5)
    for z in (-0.7, -0.1, 0.0, 0.3, 1.0):
        afc.memberships(2, z, 7.0, c_boundaries(afc, math.pi / 3, 2), mu)
        assert mu[1] == 1.0 / (1.0 + math.exp(-7.0 * z)) or mu[1] == math.exp(7.0 * z) / (1.0 + math.exp(7.0 * z))
        assert mu[0] + mu[1] == pytest.approx(1.0, abs=1e-16)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("sets", [2, 3, 5])
def test_the_basis_has_m_to_the_n_rules_summing_to_one(afc, order, sets):
    z = vector([0.3, -0.2, 0.05, -0.9][:order])
    universe = vector([1.0, 0.8, 1.2, 1.0])
    boundaries = Boundaries()
    for i in range(MAX_ORDER):
        afc.membership_boundaries(universe[i], sets, boundaries[i])
    xi = (ctypes.c_double * MAX_RULES)()
    rules = afc.fuzzy_basis(order, sets, z, 7.0, ctypes.byref(boundaries), xi)
    assert rules == sets ** order
    assert math.isclose(sum(xi[:rules]), 1.0, abs_tol=1e-14)
    # l1 slowest: the first rule is mu_1(z1) ... mu_1(zn), the second changes only the last input
    mu = [vector([0.0] * 5, 5) for _ in range(order)]
    for i in range(order):
        afc.memberships(sets, z[i], 7.0, boundaries[i], mu[i])
    assert xi[0] == pytest.approx(math.prod(mu[i][0] for i in range(order)), rel=1e-15)
    assert xi[1] == pytest.approx(math.prod(mu[i][0] for i in range(order - 1)) * mu[order - 1][1], rel=1e-15)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_remark3_modified_error_starts_at_zero_with_all_its_derivatives(afc, order):
    """E^(i)(0) = 0 for i < n  (36); checked on a smooth e(t) by finite differences too."""
    lam = 5.0

    def e_vector(t):  # e(t) = 0.4 cos 3t + 0.1 t: derivatives in closed form
        return [0.4 * math.cos(3 * t) + 0.1 * t, -1.2 * math.sin(3 * t) + 0.1, -3.6 * math.cos(3 * t),
                10.8 * math.sin(3 * t)][:order]

    e0 = vector(e_vector(0.0))
    out = vector([0.0] * 4)
    afc.modified_error(order, e0, 0.0, e0, 0.0, lam, None, out)
    assert all(abs(out[i]) <= 1e-15 for i in range(order))
    # E^(i+1) is the time derivative of E^(i) (central differences)
    h = 1e-5
    for t in (0.05, 0.4):
        values = []
        for s in (t - h, t + h, t):
            result = vector([0.0] * 4)
            afc.modified_error(order, vector(e_vector(s)), s, e0, 0.0, lam, None, result)
            values.append(list(result)[:order])
        for i in range(order - 1):
            derivative = (values[1][i] - values[0][i]) / (2 * h)
            assert derivative == pytest.approx(values[2][i + 1], rel=1e-6, abs=1e-8)


def test_tau_is_the_last_column_of_p_times_e(afc):
    status, p = c_lyapunov(afc, (2.0, 1.0, 0.5), (10.0, 10.0, 10.0))
    error = [0.3, -0.2, 0.1]
    assert afc.adaptation_signal(3, vector(error), vector(p[:, 2])) == pytest.approx(float(np.dot(error, p[:, 2])))


# ------------------------------------------- host robustness in C
class Latch(ctypes.Structure):
    _fields_ = [(name, ctypes.c_double) for name in
                ("open", "origin", "previous_time", "rejected_time", "relatches", "confirmed")] + [
        ("latched", ctypes.c_double * MAX_ORDER), ("previous", ctypes.c_double * MAX_ORDER),
        ("rejected", ctypes.c_double * MAX_ORDER), ("order", ctypes.c_double)]


class Chatter(ctypes.Structure):
    _fields_ = [(name, ctypes.c_double) for name in
                ("previous_u", "variation_rate", "magnitude", "elapsed", "samples", "warned")]


RELATCHED, DECIDED = 1, 2


def test_the_latch_keeps_a_consistent_start_and_decides_on_the_first_informative_pair(afc):
    latch = Latch()
    afc.latch_start(ctypes.byref(latch), 2, ctypes.c_double(0.0), vector([0.3, 0.0]))
    h = 1e-3
    # e(t) = 0.3 cos 3t, de = -0.9 sin 3t: the same-time sample at t = 0 agrees, then a consistent pair
    assert afc.latch_observe(ctypes.byref(latch), ctypes.c_double(0.0), vector([0.3, -0.0])) == 0
    events = afc.latch_observe(ctypes.byref(latch), ctypes.c_double(h),
                               vector([0.3 * math.cos(3 * h), -0.9 * math.sin(3 * h)]))
    assert events == DECIDED and latch.open == 0.0 and latch.relatches == 0.0
    assert list(latch.latched[:2]) == [0.3, 0.0] and latch.origin == 0.0
    message = ctypes.create_string_buffer(2048)
    assert afc.latch_warning(ctypes.byref(latch), (ctypes.c_char_p * 4)(b"e", b"de", b"d2e", b"d3e"),
                             message, 2048) == 0


def test_the_latch_rejects_placeholders_and_warns_with_values_and_times(afc):
    """A Jacobi host without propagation: placeholders at init and at the first doStep, the
    true values from the second doStep on."""
    latch = Latch()
    afc.latch_start(ctypes.byref(latch), 2, ctypes.c_double(0.0), vector([0.0, 0.0]))  # placeholders
    true = lambda t: [0.3 * math.cos(3 * t), -0.9 * math.sin(3 * t)]  # noqa: E731
    h = 1e-3
    assert afc.latch_observe(ctypes.byref(latch), ctypes.c_double(0.0), vector([0.0, 0.0])) == 0
    assert afc.latch_observe(ctypes.byref(latch), ctypes.c_double(h), vector(true(h))) == RELATCHED
    assert afc.latch_observe(ctypes.byref(latch), ctypes.c_double(2 * h), vector(true(2 * h))) == DECIDED
    assert latch.origin == h and list(latch.latched[:2]) == true(h) and latch.relatches == 1.0
    message = ctypes.create_string_buffer(2048)
    assert afc.latch_warning(ctypes.byref(latch), (ctypes.c_char_p * 4)(b"e", b"de", b"d2e", b"d3e"),
                             message, 2048) == 1
    assert message.value.decode().startswith(
        "initial error re-latched: rejected e = 0, de = 0 at t = 0 as placeholders (the host did not propagate "
        f"initial values); kept e = {true(h)[0]:.9g}, de = {true(h)[1]:.9g} at t = 0.001 as e(0)")


def test_a_pinned_latch_never_moves(afc):
    latch = Latch()
    afc.latch_pin(ctypes.byref(latch), 2, ctypes.c_double(0.0), vector([0.1, 0.2]))
    assert afc.latch_observe(ctypes.byref(latch), ctypes.c_double(0.0), vector([5.0, 5.0])) == 0
    assert list(latch.latched[:2]) == [0.1, 0.2]


@pytest.mark.parametrize("hertz,warnings", [(2.0, 0), (10.0, 0), (30.0, 1), (300.0, 1)])
def test_the_chatter_monitor_reads_a_sines_frequency_and_warns_once_above_20_hz(afc, hertz, warnings):
    """The statistic of u = 5 sin(2 pi f t) is f: no warning at 2 and 10 Hz, one at 30 and 300 Hz."""
    afc.chatter_update.restype = ctypes.c_int
    afc.chatter_frequency.restype = ctypes.c_double
    h = 1e-4
    state = Chatter()
    afc.chatter_start(ctypes.byref(state))
    seen = 0
    for k in range(int(3.0 / h)):
        seen += afc.chatter_update(ctypes.byref(state), ctypes.c_double(5.0 * math.sin(2 * math.pi * hertz * k * h)),
                                   ctypes.c_double(h))
    assert seen == warnings
    assert afc.chatter_frequency(ctypes.byref(state)) == pytest.approx(hertz, rel=0.1)
    if warnings:
        message = ctypes.create_string_buffer(2048)
        afc.chatter_warning(ctypes.byref(state), ctypes.c_double(h), message, 2048)
        assert message.value.decode().startswith("u chatters with communication step 0.0001 s: over the last ~1 s")
        twin = [getattr(state, name) for name, _ in Chatter._fields_]  # chatter_monitor.py's layout
        assert message.value.decode() == chatter_monitor.warning(twin, h)  # word for word


# ------------------------------------- every C function against its Python twin, bit for bit
def bits(values):
    """The IEEE bytes of each number (-0.0 != 0.0, NaN == NaN of the same payload)."""
    if isinstance(values, float):
        values = (values,)
    return [struct.pack("<d", value) for value in values]


def _c_table(kind, rows):
    """A 2-D ctypes array of ``kind`` filled from nested sequences (the rest stays 0)."""
    table = kind()
    for i, row in enumerate(rows):
        for j, value in enumerate(row):
            table[i][j] = value
    return table


def c_boundary_table(boundaries):
    return _c_table(Boundaries, boundaries)


SHAPES = [(n, m) for n in (1, 2, 3, 4) for m in (2, 3, 4, 5) if m ** n <= afc_math.RULES_MAX]
ARGUMENTS = (0.0, -0.0, 1e-300, -2.5e-17, 0.3, -0.7, 1.0471975511965976, -3.0, 40.0, -800.0, 1e300)


def test_scalar_twins_give_the_same_bits(afc):
    """sigmoid, membership_high/low, contraction_factor, normalized_input, projected_rate."""
    rng = random.Random(16)
    samples = list(ARGUMENTS) + [rng.uniform(-50.0, 50.0) for _ in range(200)]
    for a in samples:
        assert bits(afc.sigmoid(a)) == bits(afc_math.sigmoid(a)), a
        for slope in (7.0, 1.5):
            assert bits(afc.membership_high(a, slope)) == bits(afc_math.membership_high(a, slope)), a
            assert bits(afc.membership_low(a, slope)) == bits(afc_math.membership_low(a, slope)), a
        for lambda_ce, kappa in ((0.99, 10.0), (0.4, 0.3)):
            alpha = afc_math.contraction_factor(a, lambda_ce, kappa)
            assert bits(afc.contraction_factor(a, lambda_ce, kappa)) == bits(alpha), a
            for universe in (math.pi / 3, 0.25):
                assert bits(afc.normalized_input(a, alpha, universe)) == bits(afc_math.normalized_input(a, alpha,
                                                                                                           universe))


def test_projected_rate_is_the_python_one_on_both_sides_of_the_bound(afc):
    rng = random.Random(31)
    for theta in (-260.0, -203.0, -200.0, -12.5, 0.0, 150.0, 200.0, 201.5, 330.0):
        for tau in (-0.8, -0.0, 0.0, 1e-3, 2.2):
            xi = rng.uniform(0.0, 1.0)
            args = (theta, tau, xi, 300.0, 200.0, 5.0)
            assert bits(afc.projected_rate(*args)) == bits(afc_math.projected_rate(*args)), args


@pytest.mark.parametrize("sets", [2, 3, 4, 5])
def test_boundaries_and_memberships_are_the_python_ones(afc, sets):
    rng = random.Random(sets)
    for universe in (math.pi / 3, 0.9, 2.5):
        expected = afc_math.membership_boundaries(universe, sets)
        boundaries = c_boundaries(afc, universe, sets)
        assert bits(list(boundaries)[:sets - 1]) == bits(expected)
        mu = vector([0.0] * MAX_SETS, MAX_SETS)
        for z in [rng.uniform(-1.3 * universe, 1.3 * universe) for _ in range(40)] + list(expected):
            afc.memberships(sets, z, 7.0, boundaries, mu)
            assert bits(list(mu)[:sets]) == bits(afc_math.memberships(z, 7.0, expected)), (universe, z)


@pytest.mark.parametrize("order,sets", SHAPES)
def test_the_basis_is_the_python_one(afc, order, sets):
    rng = random.Random(order * 10 + sets)
    universe = (1.2, math.pi / 3, 0.7, 2.0)[:order]  # a different universe per input
    boundaries = tuple(afc_math.membership_boundaries(e, sets) for e in universe)
    table = c_boundary_table(boundaries)
    xi = (ctypes.c_double * MAX_RULES)()
    for _ in range(10):
        z = tuple(rng.uniform(-e, e) for e in universe)
        slope = rng.choice((7.0, 2.5))
        assert afc.fuzzy_basis(order, sets, vector(z), slope, ctypes.byref(table), xi) == sets ** order
        assert bits(xi[:sets ** order]) == bits(afc_math.fuzzy_basis(z, slope, boundaries))


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_remark3_is_the_python_one(afc, order):
    """remark3_coefficients, remark3_polynomials, remark3_offset and modified_error (with the
    per-latch polynomials and without them), asymmetric e(t0), t0 != 0, lambda_e = 0 too."""
    rng = random.Random(order)
    for lambda_e in (5.0, 0.7, 13.0, 0.0):
        error0 = tuple(rng.uniform(-1.0, 1.0) for _ in range(order))
        t0 = rng.choice((0.0, 0.0123))
        coefficients = afc_math.remark3_coefficients(error0, lambda_e)
        c_coefficients = vector([0.0] * MAX_ORDER)
        afc.remark3_coefficients(order, vector(error0), lambda_e, c_coefficients)
        assert bits(c_coefficients[:order]) == bits(coefficients)
        polynomials = afc_math.remark3_polynomials(coefficients)
        c_polynomials = Matrix()
        afc.remark3_polynomials(order, c_coefficients, ctypes.byref(c_polynomials))
        for j in range(order):
            assert bits(c_polynomials[j][:order - j]) == bits(polynomials[j]), j
        out = vector([0.0] * MAX_ORDER)
        for elapsed in (0.0, 1e-4, 0.37, 2.0, 30.0):
            afc.remark3_offset(order, ctypes.byref(c_polynomials), elapsed, lambda_e, out)
            assert bits(out[:order]) == bits(afc_math.remark3_offset(polynomials, elapsed, lambda_e)), elapsed
            error = tuple(rng.uniform(-1.0, 1.0) for _ in range(order))
            t = t0 + elapsed
            expected = bits(afc_math.modified_error(error, t, error0, t0, lambda_e, polynomials))
            assert bits(afc_math.modified_error(error, t, error0, t0, lambda_e)) == expected
            afc.modified_error(order, vector(error), t, vector(error0), t0, lambda_e, ctypes.byref(c_polynomials), out)
            assert bits(out[:order]) == expected
            afc.modified_error(order, vector(error), t, vector(error0), t0, lambda_e, None, out)
            assert bits(out[:order]) == expected


THETA_POOL = (203.0, -240.0, 199.9, -200.0, 450.0, 0.0, -203.0, 200.0, -12.0, 240.0, -450.0, 12.0, -0.0)  # M_theta 200


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_the_adaptation_is_the_python_one(afc, order):
    """tau = E^T P B with p12 != p22, and the Euler step of theta with theta beyond +-M_theta
    (the projection active and inactive), M = 2..625 rules."""
    rng = random.Random(100 + order)
    k = ((3.0,), (3.0, 2.0), (3.0, 3.0, 1.0), (4.0, 6.0, 4.0, 1.0))[order - 1]
    q = (7.0, 4.0, 2.0, 9.0)[:order]
    p_b = tuple(row[order - 1] for row in afc_math.lyapunov_p(k, q))
    assert len(set(p_b)) == order  # asymmetric
    for error in [tuple(rng.uniform(-1.0, 1.0) for _ in range(order)) for _ in range(20)] + [(-0.0,) * order]:
        tau = afc_math.adaptation_signal(error, p_b)
        assert bits(afc.adaptation_signal(order, vector(error), vector(p_b))) == bits(tau), error
    for rules in sorted({2, 4, 5 ** order if order < 4 else 625, 3 ** order}):
        theta = [THETA_POOL[j % len(THETA_POOL)] for j in range(rules)]
        xi = [rng.uniform(0.0, 1.0) for _ in range(rules)]
        adapted = (ctypes.c_double * MAX_RULES)()
        for tau in (-0.9, 0.0, 0.45):
            expected = afc_math.adapted_weights(theta, tau, xi, 300.0, 200.0, 5.0, 1e-3)
            afc.adapted_weights(rules, vector(theta, rules), tau, vector(xi, rules), 300.0, 200.0, 5.0, 1e-3, adapted)
            assert bits(adapted[:rules]) == bits(expected), (rules, tau)
        assert any(abs(value) > 200.0 for value in theta)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_the_fls_input_vector_alpha_and_z_are_the_python_ones(afc, order):
    rng = random.Random(200 + order)
    kappa = (10.0, 3.0, 0.5, 22.0)[:order]
    universe = (1.2, math.pi / 3, 0.7, 2.0)[:order]
    x, alpha, z = (vector([0.0] * MAX_ORDER) for _ in range(3))
    for _ in range(20):
        error, reference, modified = (tuple(rng.uniform(-2.0, 2.0) for _ in range(order)) for _ in range(3))
        for fls_input in (afc_math.FLS_INPUT_ERROR, afc_math.FLS_INPUT_STATE):
            expected = afc_math.fls_inputs(error, reference, modified, fls_input)
            afc.fls_inputs(order, vector(error), vector(reference), vector(modified), fls_input, x)
            assert bits(x[:order]) == bits(expected)
            factors = afc_math.contraction_factors(expected, 0.99, kappa)
            afc.contraction_factors(order, x, 0.99, vector(kappa), alpha)
            assert bits(alpha[:order]) == bits(factors)
            afc.normalized_inputs(order, x, alpha, vector(universe), z)
            assert bits(z[:order]) == bits(afc_math.normalized_inputs(expected, factors, universe))


def parameter_values(**changes):
    from harness.fmu_build import builder as build_fmu

    values = {v.name: v.start for v in build_fmu.model_class("AdaptiveFuzzyController").VARIABLES
              if v.causality == "parameter"}
    values.update(changes)
    return values


def c_parameters(p):
    """The C struct of the Python dict p (the constants the FMU's configure sets; latch_error's
    fields are left to the C latch_error)."""
    c = ControllerParameters(lambda_e=p["lambda_e"], lambda_ce=p["lambda_ce"], mf_slope=p["mf_slope"],
                             order=p["order"], sets=p["sets"], rules=p["rules"], variant=p["variant"],
                             fls_input=p["fls_input"], alpha_min=p["alpha_min"])
    n = p["order"]
    c.kappa[:n], c.universe[:n], c.p_b[:n] = p["kappa"], p["universe"], p["p_b"]
    c.boundaries = c_boundary_table(p["boundaries"])
    return c


@pytest.mark.parametrize("order,sets", SHAPES)
def test_latch_error_and_the_control_law_are_the_python_ones(afc, order, sets):
    """latch_error (e(t0), t0, the Remark 3 polynomials) and controller_output (u, E, alpha, xi)
    for every variant of the registry (harness/variants.py) and both FLS inputs, theta beyond +-M_theta,
    w_hat != 0."""
    rng = random.Random(300 + 10 * order + sets)
    for variant in variants.CONTROLLER_VARIANTS.values():
        fls_input = afc_math.FLS_INPUT_STATE if variant == afc_math.VARIANT_FIXED else afc_math.FLS_INPUT_ERROR
        values = parameter_values(order=order, sets=sets, variant=variant, fls_input=fls_input, k1=4.0, k2=6.0,
                                  k3=4.0, k4=1.0, q1=7.0, q2=4.0, q3=2.0, q4=9.0, kappa1=10.0, kappa2=3.0,
                                  kappa3=0.5, kappa4=22.0, E1=1.2, E2=math.pi / 3, E3=0.7, E4=2.0, lambda_e=3.5)
        error0 = tuple(rng.uniform(-0.5, 0.5) for _ in range(order))
        p = afc_math.controller_parameters(values, error0, 0.02)
        c = c_parameters(p)
        afc.latch_error(ctypes.byref(c), vector(error0), 0.02)
        assert bits(c.error0[:order]) == bits(p["error0"]) and c.t0 == p["t0"]
        for j in range(order):
            assert bits(c.remark3[j][:order - j]) == bits(p["remark3"][j])
        rules = p["rules"]
        modified, alpha, xi = vector([0.0] * MAX_ORDER), vector([0.0] * MAX_ORDER), (ctypes.c_double * MAX_RULES)()
        for _ in range(5):
            theta = [rng.uniform(-450.0, 450.0) for _ in range(rules)]
            error, reference = (tuple(rng.uniform(-0.6, 0.6) for _ in range(order)) for _ in range(2))
            t, w_hat = rng.uniform(0.02, 3.0), rng.uniform(-2.0, 2.0)
            u, expected_modified, expected_alpha, expected_xi = afc_math.controller_output(
                error, reference, t, theta, w_hat, p)
            got = afc.controller_output(vector(error), vector(reference), t, vector(theta, rules), w_hat,
                                        ctypes.byref(c), modified, alpha, xi)
            assert bits(got) == bits(u), (variant, t)
            assert bits(modified[:order]) == bits(expected_modified)
            assert bits(alpha[:order]) == bits(expected_alpha)
            assert bits(xi[:rules]) == bits(expected_xi)


# --------------------------- the native controller FMU runs these functions
NATIVE_SHAPES = [(1, 5, 1), (2, 2, 3), (2, 4, 1), (3, 3, 2), (4, 2, 3), (4, 3, 1)]  # (order, sets, variant)


@pytest.fixture(scope="module")
def native_controller():
    return build_native.ensure_built()["AdaptiveFuzzyController"][2]


@pytest.mark.parametrize("order,sets,variant", NATIVE_SHAPES)
def test_the_native_controller_fmu_is_the_python_one_at_any_order(fmu_paths, native_controller, order, sets,
                                                                  variant):
    """Both editions of the controller FMU, driven alike for 80 steps with the inputs latched
    from the inputs (host-robust latch, a re-latch at the first doStep): u, E.., alpha..,
    every theta_j and w_hat, bit for bit."""
    from tests.fmu_helpers import Driven

    inputs = ("e", "de", "d2e", "d3e")[:order]
    references = ("ym", "dym", "d2ym", "d3ym")[:order]
    outputs = ["u", "w_hat", *("E", "dE", "d2E", "d3E")[:order], *(f"alpha{i + 1}" for i in range(order)),
               *(f"theta{j + 1}" for j in range(sets ** order))]
    h = 1e-3
    traces = []
    for path in (fmu_paths["AdaptiveFuzzyController"], native_controller):
        c = Driven(path, f"shape_{order}_{sets}")
        try:
            c.initialize(order=order, sets=sets, variant=variant, fls_input=2 if variant == 2 else 1, k1=4.0, k2=6.0,
                         k3=4.0, k4=1.0, q1=7.0, q2=4.0, gamma=900.0, m_theta=0.75, theta0=0.7,
                         **dict.fromkeys(inputs, 0.0))  # placeholders at initialisation: re-latched
            trace = []
            for n in range(80):
                t = n * h
                c.set(**{name: 0.3 * math.cos(1.7 * t + i) for i, name in enumerate(inputs)},
                      **{name: 0.5 * math.sin(t + i) for i, name in enumerate(references)})
                trace.append(bits(c.get(*outputs)))
                c.slave.doStep(t, h)
            trace.append(bits(c.get(*outputs)))
            traces.append(trace)
        finally:
            c.free()
    assert traces[0] == traces[1]
    assert traces[0][-1] != traces[0][1]  # theta learned


def test_the_robust_cures_are_the_python_ones(afc):
    """floored_contraction_factors (23a), dead_zone_signal (31a), leaky_weights and leaky_rates (31b),
    measurement_filter_gain and filtered_measurements (F1), bit for bit; docs/model.md section 14 (robust cures)."""
    rng = random.Random(1414)
    for _ in range(200):
        n = rng.randint(1, MAX_ORDER)
        alpha = [rng.uniform(0.0, 1.0) for _ in range(n)]
        floor = rng.choice([0.0, rng.uniform(0.0, 1.0), 1.0])
        out = vector([0.0] * n)
        afc.floored_contraction_factors(n, vector(alpha), floor, out)
        assert bits(out[:n]) == bits(afc_math.floored_contraction_factors(tuple(alpha), floor))
        tau, width = rng.uniform(-2.0, 2.0), rng.choice([0.0, rng.uniform(0.0, 1.5)])
        assert bits(afc.dead_zone_signal(tau, width)) == bits(afc_math.dead_zone_signal(tau, width))
        rules = rng.randint(1, 30)
        theta = [rng.uniform(-250.0, 250.0) for _ in range(rules)]
        rates = [rng.uniform(-50.0, 50.0) for _ in range(rules)]
        sigma, h = rng.uniform(0.0, 5.0), rng.uniform(1e-5, 1e-2)
        out = vector([0.0] * rules, rules)
        afc.leaky_weights(rules, vector(theta, rules), vector(rates, rules), sigma, h, out)
        assert bits(out[:rules]) == bits(afc_math.leaky_weights(theta, rates, sigma, h))
        afc.leaky_rates(rules, vector(theta, rules), vector(rates, rules), sigma, out)
        assert bits(out[:rules]) == bits(afc_math.leaky_rates(theta, rates, sigma))
        elapsed, time_constant = rng.uniform(0.0, 0.01), rng.uniform(1e-4, 1.0)
        gain = afc.measurement_filter_gain(elapsed, time_constant)
        assert bits(gain) == bits(afc_math.measurement_filter_gain(elapsed, time_constant))
        previous, sample = [rng.uniform(-1, 1) for _ in range(n)], [rng.uniform(-1, 1) for _ in range(n)]
        out = vector([0.0] * n)
        afc.filtered_measurements(n, vector(previous), vector(sample), gain, out)
        assert bits(out[:n]) == bits(afc_math.filtered_measurements(previous, sample, gain))


def test_the_control_law_with_a_floor_on_alpha_is_the_python_one(afc):
    """controller_output with alpha_min > 0 (23a): u, E, alpha, xi bit for bit, alpha never below the floor."""
    rng = random.Random(2323)
    values = parameter_values(alpha_min=0.2, kappa1=10.0, kappa2=3.0)
    p = afc_math.controller_parameters(values, (0.1, -0.2), 0.0)
    c = c_parameters(p)
    afc.latch_error(ctypes.byref(c), vector(p["error0"]), 0.0)
    for _ in range(100):
        error, reference = [rng.uniform(-1, 1) for _ in range(2)], [rng.uniform(-1, 1) for _ in range(2)]
        theta, t = [rng.uniform(-10, 10) for _ in range(4)], rng.uniform(0.0, 3.0)
        modified, alpha, xi = vector([0.0] * 2), vector([0.0] * 2), vector([0.0] * 4)
        u = afc.controller_output(vector(error), vector(reference), t, vector(theta), 0.0, ctypes.byref(c), modified,
                                  alpha, xi)
        expected = afc_math.controller_output(tuple(error), tuple(reference), t, theta, 0.0, p)
        assert bits(u) == bits(expected[0]) and bits(alpha[:2]) == bits(expected[2]) and min(alpha[:2]) >= 0.2
        assert bits(xi[:4]) == bits(expected[3])


def test_the_chatter_verdict_next_to_the_threshold_is_the_python_editions(afc):
    """States whose statistic lies within a relative 1e-8 of 20 Hz, on both sides (where the C test first compares
    the averages without dividing): the C twin warns exactly when chatter_monitor.update does."""
    afc.chatter_update.restype = ctypes.c_int
    h, u = 1e-4, 3.0  # u = the previous u = the magnitude: only the variation rate moves, by the factor 1 - h
    line = chatter_monitor.THRESHOLD_HZ * 2.0 * math.pi * u / (1.0 - h)
    verdicts = set()
    for relative in np.linspace(-1e-8, 1e-8, 401):
        python = [u, line * (1.0 + relative), u, 2.0, 1.0, 0.0]  # PREVIOUS_U, VARIATION_RATE, MAGNITUDE, ...
        c = Chatter(*python)
        expected = chatter_monitor.update(python, u, h)
        assert afc.chatter_update(ctypes.byref(c), ctypes.c_double(u), ctypes.c_double(h)) == expected, relative
        assert (c.variation_rate, c.magnitude, c.warned) == (python[1], python[2], python[5])
        verdicts.add(expected)
    assert verdicts == {True, False}  # the threshold was crossed inside the window

"""The controller's math in C (fmu_src/afc_math.c) through ctypes: P against scipy, the
memberships and basis, Remark 3 for every order n = 1..4 and m = 2..5 (issue 17)."""
import ctypes
import math
import platform

import numpy as np
import pytest

import build_native

MAX_ORDER = 4
Matrix = (ctypes.c_double * MAX_ORDER) * MAX_ORDER

pytestmark = [
    pytest.mark.skipif(not build_native.compiler_available(), reason="zig's C compiler is not installed"),
    pytest.mark.skipif(platform.system() != "Linux" or platform.machine() != "x86_64",
                       reason="the test library is built for Linux x86-64"),
]


@pytest.fixture(scope="module")
def afc():
    library = ctypes.CDLL(str(build_native.math_library()))
    double_p = ctypes.POINTER(ctypes.c_double)
    library.lyapunov_p.argtypes = [ctypes.c_int, double_p, double_p, ctypes.POINTER(Matrix)]
    library.lyapunov_p.restype = ctypes.c_int
    library.fuzzy_basis.argtypes = [ctypes.c_int, ctypes.c_int, double_p, double_p, ctypes.c_double, double_p]
    library.fuzzy_basis.restype = ctypes.c_int
    library.memberships.argtypes = [ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int, double_p]
    library.modified_error.argtypes = [ctypes.c_int, double_p, ctypes.c_double, double_p, ctypes.c_double, double_p]
    library.adaptation_signal.argtypes = [ctypes.c_int, double_p, ctypes.POINTER(Matrix)]
    library.adaptation_signal.restype = ctypes.c_double
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


@pytest.mark.parametrize("sets", [2, 3, 4, 5])
def test_memberships_are_a_partition_of_unity(afc, sets):
    mu = vector([0.0] * 5, 5)
    for z in np.linspace(-1.2, 1.2, 41):
        afc.memberships(z, 7.0, 1.0, sets, mu)
        values = list(mu)[:sets]
        assert math.isclose(sum(values), 1.0, rel_tol=0, abs_tol=1e-15)
        assert min(values) >= 0.0


def test_two_sets_are_the_papers_pair(afc):
    mu = vector([0.0] * 5, 5)
    for z in (-0.7, -0.1, 0.0, 0.3, 1.0):
        afc.memberships(z, 7.0, math.pi / 3, 2, mu)
        assert mu[1] == 1.0 / (1.0 + math.exp(-7.0 * z)) or mu[1] == math.exp(7.0 * z) / (1.0 + math.exp(7.0 * z))
        assert mu[0] + mu[1] == pytest.approx(1.0, abs=1e-16)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("sets", [2, 3, 5])
def test_the_basis_has_m_to_the_n_rules_summing_to_one(afc, order, sets):
    z = vector([0.3, -0.2, 0.05, -0.9][:order])
    universe = vector([1.0, 0.8, 1.2, 1.0])
    xi = (ctypes.c_double * 625)()
    rules = afc.fuzzy_basis(order, sets, z, universe, 7.0, xi)
    assert rules == sets ** order
    assert math.isclose(sum(xi[:rules]), 1.0, abs_tol=1e-14)
    # l1 slowest: the first rule is mu_1(z1) ... mu_1(zn), the second changes only the last input
    mu = [vector([0.0] * 5, 5) for _ in range(order)]
    for i in range(order):
        afc.memberships(z[i], 7.0, universe[i], sets, mu[i])
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
    afc.modified_error(order, e0, 0.0, e0, lam, out)
    assert all(abs(out[i]) <= 1e-15 for i in range(order))
    # E^(i+1) is the time derivative of E^(i) (central differences)
    h = 1e-5
    for t in (0.05, 0.4):
        values = []
        for s in (t - h, t + h, t):
            result = vector([0.0] * 4)
            afc.modified_error(order, vector(e_vector(s)), s, e0, lam, result)
            values.append(list(result)[:order])
        for i in range(order - 1):
            derivative = (values[1][i] - values[0][i]) / (2 * h)
            assert derivative == pytest.approx(values[2][i + 1], rel=1e-6, abs=1e-8)


def test_tau_is_the_last_column_of_p_times_e(afc):
    status, p = c_lyapunov(afc, (2.0, 1.0, 0.5), (10.0, 10.0, 10.0))
    matrix = Matrix()
    for i in range(3):
        for j in range(3):
            matrix[i][j] = p[i, j]
    error = [0.3, -0.2, 0.1]
    assert afc.adaptation_signal(3, vector(error), ctypes.byref(matrix)) == pytest.approx(float(np.dot(error, p[:, 2])))


# ------------------------------------------- host robustness (issue 13) in C
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

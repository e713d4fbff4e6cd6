"""The controller for plants of order n = 1..4 with m = 2..5 fuzzy sets per input (docs/general_order.md)."""
import math
import random

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from scipy.linalg import solve_continuous_lyapunov

from harness.fmu_build import catalog
from fmu_src import afc_math
from tests.fmu_helpers import Driven

SHAPES = [(n, m) for n in range(1, afc_math.ORDER_MAX + 1) for m in range(2, afc_math.SETS_MAX + 1)
          if m ** n <= afc_math.RULES_MAX]


def companion(k):
    """The companion matrix of s^n + k1 s^(n-1) + ... + kn, written here from its definition."""
    n = len(k)
    a = np.zeros((n, n))
    a[:-1, 1:] = np.eye(n - 1)
    a[-1, :] = -np.array(k[::-1], dtype=float)
    return a


# ------------------------------------------------------------------ memberships
@pytest.mark.parametrize("sets", range(2, afc_math.SETS_MAX + 1))
@pytest.mark.parametrize("slope", [1.5, 7.0, 40.0])
def test_memberships_are_a_partition_of_unity(sets, slope):
    universe = 1.3
    boundaries = afc_math.membership_boundaries(universe, sets)
    assert len(boundaries) == sets - 1
    assert boundaries == pytest.approx([-universe + 2 * universe * l / sets for l in range(1, sets)])
    for z in [-1e6, -universe, -0.77, -1e-9, 0.0, 0.3, universe, 5.0, 1e6, *np.linspace(-2, 2, 41)]:
        mu = afc_math.memberships(z, slope, boundaries)
        assert len(mu) == sets
        assert all(0.0 <= value <= 1.0 for value in mu), mu
        assert sum(mu) == pytest.approx(1.0, abs=1e-14)


@pytest.mark.parametrize("sets", range(2, afc_math.SETS_MAX + 1))
def test_each_set_peaks_in_its_own_part_of_the_universe(sets):
    universe, slope = 1.0, 30.0
    boundaries = afc_math.membership_boundaries(universe, sets)
    centres = [-universe + universe * (2 * l - 1) / sets for l in range(1, sets + 1)]
    for l, centre in enumerate(centres):
        mu = afc_math.memberships(centre, slope, boundaries)
        assert max(range(sets), key=lambda j: mu[j]) == l


@pytest.mark.parametrize("z", [-1e6, -50.0, -1.0, -1e-9, 0.0, -0.0, 1e-12, 0.3, 2.0, 1e6])
@pytest.mark.parametrize("slope", [1.5, 7.0])
def test_two_sets_are_the_papers_pair_bit_for_bit(z, slope):
    def old_high(z, slope):  # the paper's pair as the project computed it before the general form
        a = slope * z
        if a >= 0.0:
            return 1.0 / (1.0 + math.exp(-a))
        ea = math.exp(a)
        return ea / (1.0 + ea)

    pair = afc_math.memberships(z, slope, afc_math.membership_boundaries(math.pi / 3, 2))
    assert pair == (old_high(-z, slope), old_high(z, slope))
    assert pair == (afc_math.membership_low(z, slope), afc_math.membership_high(z, slope))


# ------------------------------------------------------------------ basis  [8]
@pytest.mark.parametrize("order,sets", SHAPES)
def test_basis_sums_to_one_and_has_m_to_the_n_rules(order, sets):
    rng = random.Random(order * 10 + sets)
    boundaries = tuple(afc_math.membership_boundaries(u, sets) for u in (1.0, 0.7, 2.0, 1.3)[:order])
    for _ in range(30):
        z = tuple(rng.uniform(-2.5, 2.5) for _ in range(order))
        xi = afc_math.fuzzy_basis(z, rng.choice([1.5, 7.0]), boundaries)
        assert len(xi) == sets ** order
        assert min(xi) >= 0.0
        assert sum(xi) == pytest.approx(1.0, abs=1e-13)


@pytest.mark.parametrize("order,sets", [(2, 2), (2, 3), (3, 2), (3, 3), (4, 3), (1, 5)])
def test_basis_is_the_kronecker_product_l1_slowest(order, sets):
    rng = random.Random(5)
    boundaries = tuple(afc_math.membership_boundaries(u, sets) for u in (1.0, 0.7, 2.0, 1.3)[:order])
    z = tuple(rng.uniform(-1, 1) for _ in range(order))
    expected = np.array([1.0])
    for value, bounds in zip(z, boundaries):
        expected = np.kron(expected, afc_math.memberships(value, 7.0, bounds))
    assert np.array_equal(afc_math.fuzzy_basis(z, 7.0, boundaries), expected)
    # input 1 far in its top set, the others in their lowest: rule j - 1 = (m - 1) m^(n-1)
    corner = (5.0,) + (-5.0,) * (order - 1)
    xi = afc_math.fuzzy_basis(corner, 7.0, boundaries)
    assert max(range(len(xi)), key=lambda j: xi[j]) == (sets - 1) * sets ** (order - 1)


# ------------------------------------------------------------ modified error [36]
@pytest.mark.parametrize("order", range(1, afc_math.ORDER_MAX + 1))
@pytest.mark.parametrize("t0", [0.0, 1.3])
def test_modified_error_and_its_derivatives_vanish_at_the_latch(order, t0):
    error0 = (0.4, -1.1, 2.3, -0.7)[:order]
    modified = afc_math.modified_error(error0, t0, error0, t0, 5.0)
    assert len(modified) == order
    assert modified == pytest.approx((0.0,) * order, abs=1e-14)
    # a later time: E differs from e, and the offset decays
    later = afc_math.modified_error(error0, t0 + 0.2, error0, t0, 5.0)
    assert later[0] != 0.0
    far = afc_math.modified_error(error0, t0 + 20.0, error0, t0, 5.0)
    assert far == pytest.approx(error0, abs=1e-30 + 1e-9)


@pytest.mark.parametrize("order", range(2, afc_math.ORDER_MAX + 1))
def test_modified_error_returns_the_derivative_chain(order):
    """With e held at 0, E = -offset: d/dt E^(i) must equal E^(i+1) (central differences)."""
    error0, lambda_e, t0 = (0.4, -1.1, 2.3, -0.7)[:order], 3.0, 0.5
    zero = (0.0,) * order
    h = 1e-5
    for t in (0.5, 0.61, 1.2, 2.0):
        here = afc_math.modified_error(zero, t, error0, t0, lambda_e)
        ahead = afc_math.modified_error(zero, t + h, error0, t0, lambda_e)
        behind = afc_math.modified_error(zero, t - h, error0, t0, lambda_e)
        for i in range(order - 1):
            assert (ahead[i] - behind[i]) / (2 * h) == pytest.approx(here[i + 1], rel=1e-6, abs=1e-7)


def test_modified_error_of_order_two_is_the_papers_formula_bit_for_bit():
    e0, de0, lam = 0.37, -0.21, 5.0
    for t in (0.0, 0.013, 0.4, 3.7):
        a0, a1 = e0, de0 + lam * e0  # the paper's choice (Remark 3) as computed before the general form
        decay = math.exp(-lam * t)
        offset = (a0 + a1 * t) * decay
        offset_rate = (a1 - lam * (a0 + a1 * t)) * decay
        assert afc_math.modified_error((0.1, 0.2), t, (e0, de0), 0.0, lam) == (0.1 - offset, 0.2 - offset_rate)


def test_remark3_coefficients_of_order_two_and_three():
    assert afc_math.remark3_coefficients((0.3, -0.2), 5.0) == (0.3, -0.2 + 5.0 * 0.3)
    a = afc_math.remark3_coefficients((0.3, -0.2, 0.7), 2.0)
    assert a == pytest.approx((0.3, -0.2 + 0.6, 0.7 / 2 - 0.2 * 2.0 + 0.3 * 2.0 ** 2 / 2))


# ------------------------------------------------------------------ P  [30]
LYAPUNOV_CASES = [
    ((3.0,), (2.0,)),
    ((2.0, 1.0), (10.0, 10.0)),
    ((3.5, 0.7), (2.0, 9.0)),
    ((6.0, 11.0, 6.0), (1.0, 2.0, 3.0)),
    ((3.7, 2.9, 0.6), (10.0, 0.5, 4.0)),
    ((3.0, 3.0, 1.0), (10.0, 10.0, 10.0)),
    ((10.0, 35.0, 50.0, 24.0), (1.0, 5.0, 2.0, 7.0)),
    ((2.3, 4.1, 3.2, 0.9), (3.0, 1.0, 8.0, 0.2)),
]


@pytest.mark.parametrize("k,q", LYAPUNOV_CASES)
def test_lyapunov_p_against_scipy(k, q):
    expected = solve_continuous_lyapunov(companion(k).T, -np.diag(q))
    p = np.array(afc_math.lyapunov_p(k, q))
    assert p.shape == (len(k), len(k))
    np.testing.assert_allclose(p, expected, rtol=1e-10, atol=1e-12)
    assert np.array_equal(p, p.T)
    assert afc_math.is_positive_definite(afc_math.lyapunov_p(k, q))


def test_lyapunov_cases_are_not_symmetric_looking():
    p = afc_math.lyapunov_p((3.5, 0.7), (2.0, 9.0))
    assert p[0][1] != p[1][1] and p[0][0] != p[1][1]
    p3 = afc_math.lyapunov_p((3.7, 2.9, 0.6), (10.0, 0.5, 4.0))
    assert len({p3[0][2], p3[1][2], p3[2][2], p3[0][1]}) == 4


def test_not_hurwitz_gives_no_positive_definite_p():
    # s^3 + s^2 + s + 2: k1 k2 = 1 < k3 = 2, unstable
    assert not afc_math.is_positive_definite(afc_math.lyapunov_p((1.0, 1.0, 2.0), (1.0, 1.0, 1.0)))


def test_adaptation_signal_is_e_transpose_p_b():
    k, q = (3.7, 2.9, 0.6), (10.0, 0.5, 4.0)
    p = np.array(afc_math.lyapunov_p(k, q))
    error = (0.3, -0.8, 1.7)
    p_b = tuple(p[:, -1])
    assert afc_math.adaptation_signal(error, p_b) == pytest.approx(float(np.array(error) @ p @ [0, 0, 1]),
                                                                   rel=1e-14)


def test_adapted_weights_apply_the_projection_only_beyond_the_bound():
    theta, xi = [10.0, 150.0, -150.0, 199.0], (0.1, 0.2, 0.3, 0.4)
    inside = afc_math.adapted_weights(theta, 2.0, xi, 300.0, 200.0, 5.0, 1e-3)
    assert inside == [t + 1e-3 * (300.0 * 2.0 * x) for t, x in zip(theta, xi)]
    outside = afc_math.adapted_weights([205.0, 0.0], 2.0, (0.5, 0.5), 300.0, 200.0, 5.0, 1e-3)
    assert outside[0] == 205.0  # at the outer edge of the layer: frozen
    assert outside[1] == 1e-3 * 300.0


# --------------------------------------------------------- the FMU: interface
def test_new_variables_are_appended_and_old_references_kept(fmu_paths):
    from fmpy import read_model_description

    md = read_model_description(str(fmu_paths["AdaptiveFuzzyController"]))
    names = [v.name for v in md.modelVariables]
    old = ["variant", "fls_input", "k1", "k2", "q1", "q2", "gamma", "gamma_w", "m_theta", "delta", "lambda_e",
           "lambda_ce", "kappa1", "kappa2", "mf_slope", "E1", "E2", "theta0", "e", "de", "ym", "dym", "u", "E",
           "dE", "alpha1", "alpha2", "theta1", "theta2", "theta3", "theta4", "w_hat"]
    assert names[:len(old)] == old
    assert {v.name: v.valueReference for v in md.modelVariables}["w_hat"] == len(old) - 1
    latch = ["initial_error", "e0", "de0", "d2e0", "d3e0"]  # appended before (host-robust latch)
    assert names[len(old):len(old) + len(latch)] == latch
    assert names[len(old) + len(latch):len(old) + len(latch) + 2] == ["order", "sets"]
    assert f"theta{afc_math.RULES_MAX}" in names and f"theta{afc_math.RULES_MAX + 1}" not in names
    deps = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md.outputs}
    assert deps["u"] == sorted(["e", "de", "d2e", "d3e", "ym", "dym", "d2ym", "d3ym"])
    assert deps["d2E"] == ["d2e"] and deps["theta27"] == []


BAD_SHAPES = [
    (dict(order=0), "parameter order = 0", "{1, 2, 3, 4}"),
    (dict(order=5), "parameter order = 5", "{1, 2, 3, 4}"),
    (dict(sets=1), "parameter sets = 1", "{2, 3, 4, 5}"),
    (dict(sets=6), "parameter sets = 6", "{2, 3, 4, 5}"),
    (dict(order=4, sets=4), "order = 4, sets = 4 give m^n = 256", f"<= {afc_math.RULES_MAX}"),
    (dict(order=4, sets=5), "order = 4, sets = 5 give m^n = 625", f"<= {afc_math.RULES_MAX}"),
    (dict(order=3, k1=1.0, k2=1.0, k3=2.0), "k1..k3 = (1.0, 1.0, 2.0)", "not Hurwitz"),
]


@pytest.mark.parametrize("values,culprit,valid", BAD_SHAPES)
def test_bad_order_or_sets_is_rejected_naming_the_valid_range(fmu_paths, values, culprit, valid):
    c = Driven(fmu_paths["AdaptiveFuzzyController"], "bad_shape")
    c.enter(**values)
    with pytest.raises(FMICallException):
        c.slave.exitInitializationMode()
    errors = [m for s, m in c.messages if s >= 3]
    assert any(culprit in m and valid in m and "\n" not in m for m in errors), errors
    c.slave.freeInstance()


@pytest.mark.parametrize("order,sets", [(1, 2), (3, 3), (4, 3), (3, 5)])
def test_fmu_matches_the_pure_math_at_any_order(fmu_paths, order, sets):
    """u, E^(i), alpha_i and every theta_j of the FMU against afc_math, step by step."""
    c = Driven(fmu_paths["AdaptiveFuzzyController"], f"shape_{order}_{sets}")
    inputs = ("e", "de", "d2e", "d3e")[:order]
    references = ("ym", "dym", "d2ym", "d3ym")[:order]
    start = {name: 0.1 * (i + 1) for i, name in enumerate(inputs)}
    # the inputs below are no derivative chain: pin e(0), de(0), ... (no host-robust re-latch)
    pinned = dict(zip(("e0", "de0", "d2e0", "d3e0"), start.values()))
    c.initialize(order=order, sets=sets, variant=1, k1=4.0, k2=6.0, k3=4.0, k4=1.0, initial_error=2, **pinned)
    values = {v.name: v.start for v in catalog.model_class("AdaptiveFuzzyController").VARIABLES
              if v.causality == "parameter"}
    values.update(order=order, sets=sets, variant=1, k1=4.0, k2=6.0, k3=4.0, k4=1.0)
    p = afc_math.controller_parameters(values, tuple(start.values()), 0.0)
    theta = [0.0] * sets ** order
    h = 1e-3
    for n in range(60):
        t = n * h
        error = tuple(0.3 * math.cos(1.7 * t + i) for i in range(order))
        reference = tuple(0.5 * math.sin(t + i) for i in range(order))
        c.set(**dict(zip(inputs, error)), **dict(zip(references, reference)))
        model_time = (n - 1) * h + h if n else 0.0  # the FMU's clock: t_(n-1) + h after each doStep
        u, modified, alpha, xi = afc_math.controller_output(error, reference, model_time, theta, 0.0, p)
        assert c.get("u") == u
        assert c.get(*("E", "dE", "d2E", "d3E")[:order]) == (list(modified) if order > 1 else modified[0])
        assert c.get("alpha1") == alpha[0]
        c.slave.doStep(t, h)
        theta = afc_math.adapted_weights(theta, afc_math.adaptation_signal(modified, p["p_b"]), xi,
                                         p["gamma"], p["m_theta"], p["delta"], h)
    names = [f"theta{j}" for j in range(1, len(theta) + 1)]
    assert c.get(*names) == theta
    assert max(abs(v) for v in theta) > 0.01  # it learned
    unused = c.get(f"theta{len(theta) + 1}") if len(theta) < afc_math.RULES_MAX else 0.0
    assert unused == 0.0
    c.free()


def test_state_round_trip_at_order_three(fmu_paths):
    c = Driven(fmu_paths["AdaptiveFuzzyController"], "state3")
    c.initialize(order=3, sets=3, k1=3.0, k2=3.0, k3=1.0, e=0.2, de=-0.1, d2e=0.4)

    def run(start, count):
        out = []
        for n in range(count):
            t = start + n * 1e-3
            c.set(e=0.2 * math.cos(t), de=-0.2 * math.sin(t), d2e=-0.2 * math.cos(t))
            out.append(c.get("u"))
            c.slave.doStep(t, 1e-3)
        return out + c.get(*[f"theta{j}" for j in range(1, 28)])

    run(0.0, 50)
    state = c.slave.getFMUstate()
    first = run(0.05, 50)
    c.slave.setFMUstate(state)
    assert run(0.05, 50) == first
    c.free()

"""The controller of Pan, Er, Huang and Wang (IEEE TFS 19(5), 2011) as pure functions.

For a plant of order n, x^(n) = f(x) + g(x) u  [1], with m fuzzy sets per
FLS input (n = 1..ORDER_MAX, m = 2..SETS_MAX, M = m^n <= RULES_MAX rules).
Equation numbers in brackets are the paper's; docs/model.md sections 1-6 (the
controller) and docs/general_order.md restate them.  With n = 2, m = 2 every function gives,
bit for bit, the paper's two-input, two-set controller.

Vectors are tuples (or lists) indexed from 0: error[i] = e^(i), the i-th
time derivative of the tracking error e = ym - y, i = 0..n-1.

Standard library only: this module travels inside the FMU.  A C edition
mirrors these functions one for one, with the same names.
"""
from __future__ import annotations

import math
from itertools import repeat
from operator import sub

VARIANT_VUD = 1  # variable universes of discourse: the paper's proposed AFC
VARIANT_FIXED = 2  # alpha = 1: stand-in for the direct AFC of [46]
VARIANT_FAE = 3  # alpha = 1 plus approximation-error estimate w_hat: stand-in for [28]
FLS_INPUT_ERROR = 1  # FLS input [E, dE, ..., E^(n-1)] (the paper)
FLS_INPUT_STATE = 2  # FLS input x = [ym - e, dym - de, ...] (the ablation of Remark 4)
ORDER_MAX = 4  # largest plant order n
SETS_MAX = 5  # largest number m of fuzzy sets per input
RULES_MAX = 125  # largest rule count M = m^n: every m for n <= 3, m <= 3 for n = 4
RULE_COUNT = 4  # M of the default controller (n = 2, m = 2)


# ------------------------------------------------------------------ P  [30]
def lyapunov_p(k, q) -> tuple:
    """P solving A^T P + P A = -Q  [30], as a tuple of n rows.

    A is the n x n companion matrix of s^n + k1 s^(n-1) + ... + kn:
    A[i][i+1] = 1 (i < n-1), A[n-1][j] = -k_(n-j) (so A = [[0, 1], [-k2, -k1]]
    for n = 2), Hurwitz for a suitable k; Q = diag(q1, ..., qn).
    ``k`` = (k1, ..., kn), ``q`` = (q1, ..., qn).

    The n (n + 1) / 2 unknowns p_ij (i <= j) solve the linear equations
    (A^T P + P A)_ij = -q_i [i = j] by Gaussian elimination with partial
    pivoting (standard library only).  Element (i, j) of A^T P + P A is
    p_(i-1)j [i >= 1] + p_i(j-1) [j >= 1] - k_(n-i) p_(n-1)j - k_(n-j) p_i(n-1).
    Raises ValueError when the equations are singular (A has eigenvalues
    lambda_a + lambda_b = 0: then no unique P exists).
    """
    n = len(k)
    if n < 1 or len(q) != n:
        raise ValueError(f"lyapunov_p needs k and q of the same length n >= 1, got {len(k)} and {len(q)}")
    pairs = [(i, j) for i in range(n) for j in range(i, n)]
    unknown = {}
    for index, (i, j) in enumerate(pairs):
        unknown[i, j] = unknown[j, i] = index
    size = len(pairs)
    rows = []
    for i, j in pairs:
        row = [0.0] * (size + 1)
        if i >= 1:
            row[unknown[i - 1, j]] += 1.0
        if j >= 1:
            row[unknown[i, j - 1]] += 1.0
        row[unknown[n - 1, j]] -= k[n - 1 - i]  # A[n-1][i] = -k_(n-i)
        row[unknown[i, n - 1]] -= k[n - 1 - j]
        row[size] = -q[i] if i == j else 0.0
        rows.append(row)
    solution = _solve(rows, size)
    return tuple(tuple(solution[unknown[i, j]] for j in range(n)) for i in range(n))


def is_positive_definite(matrix) -> bool:
    """True when the symmetric ``matrix`` (tuple of rows) is positive definite (Cholesky)."""
    n = len(matrix)
    lower = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            total = matrix[i][j] - sum(lower[i][c] * lower[j][c] for c in range(j))
            if i == j:
                if not total > 0.0:
                    return False
                lower[i][i] = math.sqrt(total)
            else:
                lower[i][j] = total / lower[j][j]
    return True


def _solve(rows: list, size: int) -> list:
    """x of the augmented system ``rows`` (size x (size + 1)): Gauss with partial pivoting."""
    for column in range(size):
        pivot = max(range(column, size), key=lambda r: abs(rows[r][column]))
        if rows[pivot][column] == 0.0:
            raise ValueError("singular Lyapunov equation: the companion matrix of k has "
                             "eigenvalues summing to zero (k is not Hurwitz)")
        rows[column], rows[pivot] = rows[pivot], rows[column]
        head = rows[column]
        for r in range(column + 1, size):
            factor = rows[r][column] / head[column]
            if factor != 0.0:
                target = rows[r]
                for c in range(column, size + 1):
                    target[c] -= factor * head[c]
    x = [0.0] * size
    for r in range(size - 1, -1, -1):
        total = rows[r][size]
        for c in range(r + 1, size):
            total -= rows[r][c] * x[c]
        x[r] = total / rows[r][r]
    return x


# ----------------------------------------------------- contraction  [23]
def contraction_factor(x: float, lambda_ce: float, kappa: float) -> float:
    """alpha(x) = 1 - lambda_ce exp(-kappa x^2)  [23]; alpha(0) = 1 - lambda_ce."""
    return 1.0 - lambda_ce * math.exp(-kappa * x * x)


def normalized_input(x: float, alpha: float, universe: float) -> float:
    """z = x / alpha(x)  [7], saturated to the universe [-E, E]
    (docs/model.md section 10, choice 1 (saturated))."""
    z = x / alpha
    if z > universe:
        return universe
    if z < -universe:
        return -universe
    return z


# ------------------------------------------------------- memberships
def sigmoid(a: float) -> float:
    """1 / (1 + exp(-a)), evaluated without overflow."""
    if a >= 0.0:
        return 1.0 / (1.0 + math.exp(-a))
    ea = math.exp(a)
    return ea / (1.0 + ea)


def membership_high(z: float, slope: float) -> float:
    """mu_2(z) = 1 / (1 + exp(-s z)) of the paper's pair (m = 2)."""
    return sigmoid(slope * z)


def membership_low(z: float, slope: float) -> float:
    """mu_1(z) = 1 / (1 + exp(s z)) = mu_2(-z) of the paper's pair; mu_1 + mu_2 = 1."""
    return sigmoid(slope * -z)


def membership_boundaries(universe: float, sets: int) -> tuple:
    """The m - 1 boundaries c_l = -E + 2 E l / m (l = 1..m-1), evenly inside [-E, E].

    m = 2 gives (0.0,): the paper's pair crosses at z = 0.
    """
    return tuple(-universe + 2.0 * universe * l / sets for l in range(1, sets))


def memberships(z: float, slope: float, boundaries) -> tuple:
    """(mu_1(z), ..., mu_m(z)): a partition of unity by differences of sigmoids.

    With sig(a) = 1 / (1 + exp(-a)) and the m - 1 boundaries c_l:
    mu_1 = 1 - sig(s (z - c_1)), mu_l = sig(s (z - c_(l-1))) - sig(s (z - c_l)),
    mu_m = sig(s (z - c_(m-1))).  mu_1 is evaluated as sig(s (c_1 - z)) (the
    same number in exact arithmetic, accurate where sig(s (z - c_1)) is near 1),
    so m = 2 (c_1 = 0) is the paper's pair membership_low, membership_high
    bit for bit.
    """
    first = boundaries[0]
    if len(boundaries) == 1:  # m = 2
        return sigmoid(slope * (first - z)), sigmoid(slope * (z - first))
    result = [sigmoid(slope * (first - z))]
    previous = sigmoid(slope * (z - first))
    for c in boundaries[1:]:
        rising = sigmoid(slope * (z - c))
        result.append(previous - rising)
        previous = rising
    result.append(previous)
    return tuple(result)


def fuzzy_basis(z, slope: float, boundaries) -> tuple:
    """xi_j = mu_l1(z_1) mu_l2(z_2) ... mu_ln(z_n)  [8], j - 1 = sum_i (l_i - 1) m^(n-i).

    ``z`` holds the n normalised inputs, ``boundaries[i]`` the m - 1
    boundaries of input i (:func:`membership_boundaries`).  M = m^n basis
    functions, l1 slowest (n = 2, m = 2: (1,1), (1,2), (2,1), (2,2)); they sum
    to 1.  The product runs left to right: xi = mu(z_1) (x) mu(z_2) (x) ...
    """
    if len(z) == 2:  # two inputs unrolled (the same products as the loop below)
        mu1 = memberships(z[0], slope, boundaries[0])
        mu2 = memberships(z[1], slope, boundaries[1])
        if len(mu1) == 2 == len(mu2):  # m = 2: the paper's four rules
            return mu1[0] * mu2[0], mu1[0] * mu2[1], mu1[1] * mu2[0], mu1[1] * mu2[1]
        return tuple([a * b for a in mu1 for b in mu2])
    xi = memberships(z[0], slope, boundaries[0])
    for i in range(1, len(z)):
        mu = memberships(z[i], slope, boundaries[i])
        xi = [a * b for a in xi for b in mu]
    return tuple(xi)


# ----------------------------------------------- modified error  [36]
def remark3_coefficients(error0, lambda_e: float) -> tuple:
    """(a_0, ..., a_(n-1)) of p(t) = sum_k a_k t^k in Remark 3  [36].

    With E = e - p(t) exp(-lambda_e t), E^(i)(0) = 0 for i < n needs
    p(t) exp(-lambda_e t) to match e(0), de(0), ..., e^(n-1)(0): p is the
    Taylor polynomial of degree n - 1 of exp(lambda_e t) sum_i e^(i)(0) t^i / i!:
    a_k = sum_(j <= k) e^(j)(0) / j! * lambda_e^(k-j) / (k-j)!.
    n = 2: a_0 = e(0), a_1 = de(0) + lambda_e e(0) (the paper's choice).
    """
    n = len(error0)
    result = []
    for k in range(n):
        total = 0.0
        for j in range(k + 1):
            total += error0[j] / math.factorial(j) * (lambda_e ** (k - j) / math.factorial(k - j))
        result.append(total)
    return tuple(result)


def remark3_polynomials(coefficients) -> tuple:
    """The derivatives p, p', ..., p^(n-1) of p(t) = sum_k a_k t^k  [36], for Horner.

    Entry j holds the coefficients of p^(j), highest power first:
    a_k k! / (k - j)! for k = n-1 down to j.  Computed once per latch.
    """
    n = len(coefficients)
    return tuple(tuple(coefficients[k] * (math.factorial(k) // math.factorial(k - j)) for k in range(n - 1, j - 1, -1))
                 for j in range(n))


def remark3_offset(polynomials, elapsed: float, lambda_e: float) -> tuple:
    """(d/dt)^i [p(t) exp(-lambda_e t)] at t = elapsed, i = 0..n-1  [36].

    ``polynomials`` from :func:`remark3_polynomials`.  With r_0 = p and
    r_i = r_(i-1)' - lambda_e r_(i-1), the i-th derivative is
    r_i(t) exp(-lambda_e t); the values r_i^(j)(t) follow from p^(j)(t)
    (Horner) by that recursion.  n = 2: ((a0 + a1 t) e^(-lambda_e t),
    (a1 - lambda_e (a0 + a1 t)) e^(-lambda_e t)).
    """
    t = elapsed
    if len(polynomials) == 2:  # n = 2 unrolled (the same arithmetic as the loops below)
        (a1, a0), (b1,) = polynomials
        value = (0.0 * t + a1) * t + a0
        decay = math.exp(-lambda_e * t)
        return value * decay, ((0.0 * t + b1) - lambda_e * value) * decay
    values = []  # p^(j)(t), j = 0..n-1
    for polynomial in polynomials:
        acc = 0.0
        for coefficient in polynomial:
            acc = acc * t + coefficient
        values.append(acc)
    decay = math.exp(-lambda_e * t)
    offsets = [values[0] * decay]
    while len(values) > 1:
        values = [values[j + 1] - lambda_e * values[j] for j in range(len(values) - 1)]
        offsets.append(values[0] * decay)
    return tuple(offsets)


def modified_error(error, t: float, error0, t0: float, lambda_e: float, polynomials=None) -> tuple:
    """(E, dE, ..., E^(n-1)) of Remark 3  [36]: E = e - p(t - t0) exp(-lambda_e (t - t0)).

    ``error`` = (e, de, ..., e^(n-1)) at time t; ``error0`` the same vector
    latched at the time origin t0, so that E^(i)(t0) = 0 for i < n.  p is a
    polynomial of degree n - 1 (:func:`remark3_coefficients`); a per-step
    caller passes ``polynomials`` = remark3_polynomials(remark3_coefficients(
    error0, lambda_e)), computed once per latch.  lambda_e = 0 means no
    modification (E = e).
    """
    if lambda_e == 0.0:
        return tuple(error)
    if polynomials is None:
        polynomials = remark3_polynomials(remark3_coefficients(error0, lambda_e))
    offsets = remark3_offset(polynomials, t - t0, lambda_e)
    if len(error) == 2:  # unrolled
        return error[0] - offsets[0], error[1] - offsets[1]
    return tuple(map(sub, error, offsets))


# ------------------------------------------------------- adaptation  [31]
def adaptation_signal(error, p_b) -> float:
    """tau = E^T P B with B = [0, ..., 0, 1]^T  [31]: sum_i E^(i) P[i][n-1].

    ``error`` the modified error vector (E, dE, ...), ``p_b`` = P B, the last
    column of P.  n = 2: tau = E p12 + dE p22.
    """
    if len(error) == 2:  # unrolled (0.0 + a = a)
        return error[0] * p_b[0] + error[1] * p_b[1]
    tau = 0.0
    for value, weight in zip(error, p_b):
        tau += value * weight
    return tau


def projected_rate(theta_j: float, tau: float, xi_j: float, gamma: float,
                   m_theta: float, delta: float) -> float:
    """dtheta_j of the adaptive law with smooth projection  [31]."""
    rate = gamma * tau * xi_j
    if theta_j > m_theta and tau > 0.0:
        return (1.0 + (m_theta - theta_j) / delta) * rate
    if theta_j < -m_theta and tau < 0.0:
        return (1.0 + (m_theta + theta_j) / delta) * rate
    return rate


def adapted_weights(theta, tau: float, xi, gamma: float, m_theta: float, delta: float,
                    step_size: float) -> list:
    """theta_j + h dtheta_j for every rule j: the sampled-data (explicit Euler) step of [31].

    dtheta_j = projected_rate(theta_j, tau, xi_j, ...); where |theta_j| <= M_theta the
    projection is inactive and dtheta_j = gamma tau xi_j (the same arithmetic, inline).
    """
    rate = gamma * tau
    return [value + step_size * (rate * basis) if -m_theta <= value <= m_theta
            else value + step_size * projected_rate(value, tau, basis, gamma, m_theta, delta)
            for value, basis in zip(theta, xi)]


def adaptation_rates(theta, tau: float, xi, gamma: float, m_theta: float, delta: float) -> list:
    """dtheta_j for every rule j: the adaptive law with smooth projection [31] in continuous time
    (Model Exchange: the host's solver integrates them).

    The same numbers as the rates :func:`adapted_weights` multiplies by the step: gamma tau xi_j
    where |theta_j| <= M_theta, else :func:`projected_rate`.  Continuous in theta_j and tau (the
    projection factor is 1 at |theta_j| = M_theta, the rate 0 at tau = 0): no event is needed.
    """
    rate = gamma * tau
    return [rate * basis if -m_theta <= value <= m_theta
            else projected_rate(value, tau, basis, gamma, m_theta, delta)
            for value, basis in zip(theta, xi)]


def estimate_rate(tau: float, gamma_w: float) -> float:
    """dw_hat = gamma_w tau: the approximation-error estimate of variant 3 in continuous time."""
    return gamma_w * tau


# ------------------------------------- robust cures  [23a], [31a], [31b], (F1)
# The standard cures of robust adaptive control (docs/model.md section 14 (robust cures)), each off at 0: the
# FMU calls them only when its parameter is not 0, so the defaults are the paper's controller bit for bit.
def floored_contraction_factors(alpha, alpha_min: float) -> tuple:
    """(max(alpha_1, alpha_min), ..., max(alpha_n, alpha_min)): the floor on alpha  [23a].

    Bounds the magnification 1 / alpha of the normalised input (7) by 1 / alpha_min.
    """
    if len(alpha) == 2:  # unrolled
        return (alpha[0] if alpha[0] > alpha_min else alpha_min, alpha[1] if alpha[1] > alpha_min else alpha_min)
    return tuple(a if a > alpha_min else alpha_min for a in alpha)


def dead_zone_signal(tau: float, width: float) -> float:
    """tau of the adaptive law through a continuous dead zone of half-width d0  [31a]:
    0 for |tau| <= d0, tau - d0 above, tau + d0 below.

    No adaptation while the filtered tracking error tau = E^T P B stays inside the band the
    noise alone keeps it in; continuous in tau, so Model Exchange needs no event.
    """
    if tau > width:
        return tau - width
    if tau < -width:
        return tau + width
    return 0.0


def leaky_weights(theta, rates, sigma: float, step_size: float) -> list:
    """theta_j + h (dtheta_j - sigma theta_j) for every rule j: sigma-modification  [31b].

    ``rates`` the law's dtheta_j (:func:`adaptation_rates`); the leakage -sigma theta_j pulls
    every weight towards 0 when the error no longer drives it.
    """
    return [value + step_size * (rate - sigma * value) for value, rate in zip(theta, rates)]


def leaky_rates(theta, rates, sigma: float) -> list:
    """dtheta_j - sigma theta_j for every rule j: [31b] in continuous time (Model Exchange)."""
    return [rate - sigma * value for value, rate in zip(theta, rates)]


def measurement_filter_gain(elapsed: float, time_constant: float) -> float:
    """a = 1 - exp(-dt / T_m) of the first-order measurement filter (F1) over ``elapsed`` = dt."""
    return 1.0 - math.exp(-elapsed / time_constant)


def filtered_measurements(previous, sample, gain: float) -> tuple:
    """f_k = f_(k-1) + a (x_k - f_(k-1)) for each entry: the measurement filter on e, de, ...  (F1).

    The step-invariant discretisation of T_m df/dt = x - f with unit DC gain; gain = 1 gives the
    sample itself (the filter started at rest on it).
    """
    return tuple(f + gain * (x - f) for f, x in zip(previous, sample))


# ------------------------------------------------------- control law  [9]
def fls_inputs(error, reference, modified, fls_input: int) -> tuple:
    """The FLS input vector: E = (E, dE, ...) (fls_input 1) or the state
    x = (ym - e, dym - de, ...) (fls_input 2), n entries."""
    if fls_input == FLS_INPUT_STATE:
        return tuple(map(sub, reference, error))
    return modified


def contraction_factors(x, lambda_ce: float, kappa) -> tuple:
    """(alpha_1(x_1), ..., alpha_n(x_n))  [23]."""
    if len(x) == 2:  # unrolled
        return contraction_factor(x[0], lambda_ce, kappa[0]), contraction_factor(x[1], lambda_ce, kappa[1])
    return tuple(map(contraction_factor, x, repeat(lambda_ce), kappa))


def normalized_inputs(x, alpha, universe) -> tuple:
    """(z_1, ..., z_n) = (x_1 / alpha_1, ...)  [7], each saturated to its universe."""
    if len(x) == 2:  # unrolled
        return normalized_input(x[0], alpha[0], universe[0]), normalized_input(x[1], alpha[1], universe[1])
    return tuple(map(normalized_input, x, alpha, universe))


def controller_parameters(values, error0=None, t0: float = 0.0) -> dict:
    """The mapping ``p`` of :func:`controller_output` from the FMU's parameter values.

    ``values`` maps the FMU's parameter names (order, sets, variant,
    fls_input, k1.., q1.., kappa1.., E1.., lambda_e, lambda_ce, mf_slope,
    gamma, gamma_w, m_theta, delta, theta0; alpha_min, default 0) to values; ``error0`` is the
    latched (e(t0), de(t0), ...) (first n entries used; default zeros).
    Adds the vectors of the first n entries (k, q, kappa, universe), the
    membership boundaries, P B and the Remark 3 coefficients.
    """
    n, m = int(values["order"]), int(values["sets"])
    p = dict(values)
    p["order"], p["sets"] = n, m
    p["k"] = tuple(float(values[f"k{i}"]) for i in range(1, n + 1))
    p["q"] = tuple(float(values[f"q{i}"]) for i in range(1, n + 1))
    p["kappa"] = tuple(float(values[f"kappa{i}"]) for i in range(1, n + 1))
    p["universe"] = tuple(float(values[f"E{i}"]) for i in range(1, n + 1))
    p["boundaries"] = tuple(membership_boundaries(e, m) for e in p["universe"])
    p["rules"] = m ** n
    p["unit_alpha"] = (1.0,) * n
    p["alpha_min"] = float(values.get("alpha_min", 0.0))  # the floor [23a]; 0 = off
    p["p_b"] = tuple(row[n - 1] for row in lyapunov_p(p["k"], p["q"]))
    error0 = tuple(error0[:n]) if error0 is not None else ()
    latch_error(p, error0 + (0.0,) * (n - len(error0)), t0)
    return p


def latch_error(p: dict, error0, t0: float) -> None:
    """Set the latched error vector e(t0), ... and the time origin t0 of Remark 3 in ``p``."""
    p["error0"] = tuple(error0)
    p["t0"] = t0
    p["remark3"] = remark3_polynomials(remark3_coefficients(p["error0"], p["lambda_e"]))


def controller_output(error, reference, t, theta, w_hat, p) -> tuple:
    """u and diagnostics of the controller at time t  [9].

    ``error`` = (e, de, ...), ``reference`` = (ym, dym, ...) (n entries
    each), ``theta`` the M rule weights, ``p`` from
    :func:`controller_parameters`.  Returns (u, E, alpha, xi): u = theta^T xi
    (+ w_hat for variant 3), the modified error vector E, the contraction
    factors alpha (1 for variants 2, 3) and the basis xi.  The FMU, the
    in-process oracle and the tests all run this function.
    """
    modified = modified_error(error, t, p["error0"], p["t0"], p["lambda_e"], p["remark3"])
    x = fls_inputs(error, reference, modified, p["fls_input"])
    variant = p["variant"]
    if variant == VARIANT_VUD:
        alpha = contraction_factors(x, p["lambda_ce"], p["kappa"])
        if p["alpha_min"] > 0.0:  # the floor [23a], off at 0
            alpha = floored_contraction_factors(alpha, p["alpha_min"])
    else:
        alpha = p["unit_alpha"]
    z = normalized_inputs(x, alpha, p["universe"])
    xi = fuzzy_basis(z, p["mf_slope"], p["boundaries"])
    if len(xi) == 4:  # the paper's four rules unrolled (the same sum, left to right)
        u = theta[0] * xi[0] + theta[1] * xi[1] + theta[2] * xi[2] + theta[3] * xi[3]
    else:
        u = 0.0
        for weight, basis in zip(theta, xi):
            u += weight * basis
    if variant == VARIANT_FAE:
        u += w_hat
    return u, modified, alpha, xi

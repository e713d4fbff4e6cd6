"""The controller of Pan, Er, Huang and Wang (IEEE TFS 19(5), 2011) as pure functions.

Equation numbers in brackets are the paper's; SPEC.md sections 1-5 restate
them.  Standard library only: this module travels inside the FMU.
"""
from __future__ import annotations

import math

VARIANT_VUD = 1  # variable universes of discourse: the paper's proposed AFC
VARIANT_FIXED = 2  # alpha = 1: stand-in for the direct AFC of [46]
VARIANT_FAE = 3  # alpha = 1 plus approximation-error estimate w_hat: stand-in for [28]
FLS_INPUT_ERROR = 1  # FLS input [E, dE] (the paper)
FLS_INPUT_STATE = 2  # FLS input x = [ym - e, dym - de] (the ablation of Remark 4)
RULE_COUNT = 4  # M = m^n = 2^2 rules


def lyapunov_p(k1: float, k2: float, q1: float, q2: float) -> tuple[float, float, float]:
    """(p11, p12, p22) of P solving A^T P + P A = -Q  [30].

    A = [[0, 1], [-k2, -k1]] (Hurwitz for k1, k2 > 0), Q = diag(q1, q2).
    Element-wise: -2 k2 p12 = -q1, p11 - k1 p12 - k2 p22 = 0, 2 (p12 - k1 p22) = -q2.
    """
    p12 = q1 / (2.0 * k2)
    p22 = (p12 + 0.5 * q2) / k1
    p11 = k1 * p12 + k2 * p22
    return p11, p12, p22


def contraction_factor(x: float, lambda_ce: float, kappa: float) -> float:
    """alpha(x) = 1 - lambda_ce exp(-kappa x^2)  [23]; alpha(0) = 1 - lambda_ce."""
    return 1.0 - lambda_ce * math.exp(-kappa * x * x)


def normalized_input(x: float, alpha: float, universe: float) -> float:
    """z = x / alpha(x)  [7], saturated to the universe [-E, E] (SPEC choice)."""
    z = x / alpha
    if z > universe:
        return universe
    if z < -universe:
        return -universe
    return z


def membership_high(z: float, slope: float) -> float:
    """mu_2(z) = 1 / (1 + exp(-s z)), evaluated without overflow."""
    a = slope * z
    if a >= 0.0:
        return 1.0 / (1.0 + math.exp(-a))
    ea = math.exp(a)
    return ea / (1.0 + ea)


def membership_low(z: float, slope: float) -> float:
    """mu_1(z) = 1 / (1 + exp(s z)) = mu_2(-z); mu_1 + mu_2 = 1."""
    return membership_high(-z, slope)


def fuzzy_basis(z1: float, z2: float, slope: float) -> tuple[float, float, float, float]:
    """xi_j = mu_l1(z1) mu_l2(z2)  [8], j = 2 (l1 - 1) + l2 (l1 slowest)."""
    low1, high1 = membership_low(z1, slope), membership_high(z1, slope)
    low2, high2 = membership_low(z2, slope), membership_high(z2, slope)
    return low1 * low2, low1 * high2, high1 * low2, high1 * high2


def modified_error(e: float, de: float, t: float, e0: float, de0: float,
                   lambda_e: float) -> tuple[float, float]:
    """(E, dE) of Remark 3: E = e - (a0 + a1 t) exp(-lambda_e t), so E(0) = dE(0) = 0.

    t is the time since the start; a0 = e(0), a1 = de(0) + lambda_e e(0).
    lambda_e = 0 means no modification (E = e).
    """
    if lambda_e == 0.0:
        return e, de
    a0 = e0
    a1 = de0 + lambda_e * e0
    decay = math.exp(-lambda_e * t)
    offset = (a0 + a1 * t) * decay
    # d/dt[(a0 + a1 t) exp(-l t)] = (a1 - l (a0 + a1 t)) exp(-l t)
    offset_rate = (a1 - lambda_e * (a0 + a1 * t)) * decay
    return e - offset, de - offset_rate


def adaptation_signal(error: float, error_rate: float, p12: float, p22: float) -> float:
    """tau = [E, dE] P B with B = [0, 1]^T  [31]."""
    return error * p12 + error_rate * p22


def projected_rate(theta_j: float, tau: float, xi_j: float, gamma: float,
                   m_theta: float, delta: float) -> float:
    """dtheta_j of the adaptive law with smooth projection  [31]."""
    rate = gamma * tau * xi_j
    if theta_j > m_theta and tau > 0.0:
        return (1.0 + (m_theta - theta_j) / delta) * rate
    if theta_j < -m_theta and tau < 0.0:
        return (1.0 + (m_theta + theta_j) / delta) * rate
    return rate


def fls_inputs(e: float, de: float, ym: float, dym: float, error: float, error_rate: float,
               fls_input: int) -> tuple[float, float]:
    """The FLS input vector: [E, dE] (fls_input 1) or the state [ym - e, dym - de] (2)."""
    if fls_input == FLS_INPUT_STATE:
        return ym - e, dym - de
    return error, error_rate


def controller_output(e, de, ym, dym, t, theta, w_hat, p):
    """u and diagnostics of the controller at time t since start  [9].

    ``p`` is a mapping with variant, fls_input, lambda_e, lambda_ce, kappa1,
    kappa2, E1, E2, mf_slope, e0, de0.  Returns
    (u, E, dE, alpha1, alpha2, xi).  Used by the tests and the in-process
    oracle; the FMU runs the same functions.
    """
    error, error_rate = modified_error(e, de, t, p["e0"], p["de0"], p["lambda_e"])
    x1, x2 = fls_inputs(e, de, ym, dym, error, error_rate, p["fls_input"])
    if p["variant"] == VARIANT_VUD:
        alpha1 = contraction_factor(x1, p["lambda_ce"], p["kappa1"])
        alpha2 = contraction_factor(x2, p["lambda_ce"], p["kappa2"])
    else:
        alpha1 = alpha2 = 1.0
    xi = fuzzy_basis(normalized_input(x1, alpha1, p["E1"]),
                     normalized_input(x2, alpha2, p["E2"]), p["mf_slope"])
    u = theta[0] * xi[0] + theta[1] * xi[1] + theta[2] * xi[2] + theta[3] * xi[3]
    if p["variant"] == VARIANT_FAE:
        u += w_hat
    return u, error, error_rate, alpha1, alpha2, xi

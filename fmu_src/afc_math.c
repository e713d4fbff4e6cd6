/* The controller's math: the C twin of afc_math.py (see afc_math.h for the list of twins and
 * the argument convention).  Each function performs its Python twin's floating-point
 * operations in the same order; where the Python unrolls n = 2 (or M = 4), the C either
 * unrolls too or runs a loop whose operations are the same. */
#include <math.h>
#include <stddef.h>

#include "afc_math.h"

/* ------------------------------------------------------------------ P  [30] */
enum { UNKNOWNS = MAX_ORDER * (MAX_ORDER + 1) / 2 };

/* x of the augmented system rows (size x (size + 1)): Gauss with partial pivoting (the first
 * largest pivot, as Python's max); returns -1 if singular (k is not Hurwitz), else 0 */
static int solve(double rows[UNKNOWNS][UNKNOWNS + 1], int size, double x[]) {
    for (int column = 0; column < size; column++) {
        int pivot = column;
        for (int r = column + 1; r < size; r++)
            if (fabs(rows[r][column]) > fabs(rows[pivot][column])) pivot = r;
        if (rows[pivot][column] == 0.0) return -1;
        if (pivot != column)
            for (int c = 0; c <= size; c++) {
                double swap = rows[column][c]; rows[column][c] = rows[pivot][c]; rows[pivot][c] = swap;
            }
        for (int r = column + 1; r < size; r++) {
            double factor = rows[r][column] / rows[column][column];
            if (factor != 0.0)
                for (int c = column; c <= size; c++) rows[r][c] -= factor * rows[column][c];
        }
    }
    for (int r = size - 1; r >= 0; r--) {
        double total = rows[r][size];
        for (int c = r + 1; c < size; c++) total -= rows[r][c] * x[c];
        x[r] = total / rows[r][r];
    }
    return 0;
}

/* The n (n + 1) / 2 unknowns p_ij (i <= j) solve (A^T P + P A)_ij = -q_i [i = j]; element (i, j)
 * of A^T P + P A is p_(i-1)j [i >= 1] + p_i(j-1) [j >= 1] - k_(n-i) p_(n-1)j - k_(n-j) p_i(n-1).
 * (For n = 2 it can differ in the last bit from the element-wise formulas p12 = q1 / (2 k2),
 * p22 = (p12 + q2 / 2) / k1, p11 = k1 p12 + k2 p22; for the default k, q it does not.) */
int lyapunov_p(int n, const double k[], const double q[], double p[MAX_ORDER][MAX_ORDER]) {
    int unknown[MAX_ORDER][MAX_ORDER];
    int size = 0;
    for (int i = 0; i < n; i++)
        for (int j = i; j < n; j++) { unknown[i][j] = unknown[j][i] = size; size++; }
    double rows[UNKNOWNS][UNKNOWNS + 1];
    int r = 0;
    for (int i = 0; i < n; i++)
        for (int j = i; j < n; j++, r++) {
            for (int c = 0; c <= size; c++) rows[r][c] = 0.0;
            if (i >= 1) rows[r][unknown[i - 1][j]] += 1.0;
            if (j >= 1) rows[r][unknown[i][j - 1]] += 1.0;
            rows[r][unknown[n - 1][j]] -= k[n - 1 - i]; /* A[n-1][i] = -k_(n-i) */
            rows[r][unknown[i][n - 1]] -= k[n - 1 - j];
            rows[r][size] = i == j ? -q[i] : 0.0;
        }
    double x[UNKNOWNS];
    if (solve(rows, size, x) != 0) return -1;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) p[i][j] = x[unknown[i][j]];
    return 0;
}

/* Cholesky.  The sum of lower[i][c] lower[j][c] runs from 0.0 as Python 3.11's sum(); Python 3.12
 * sums floats with compensation, which can flip the verdict only for a matrix within rounding
 * of singular (a validation check, not the per-step path). */
int is_positive_definite(int n, const double matrix[MAX_ORDER][MAX_ORDER]) {
    double lower[MAX_ORDER][MAX_ORDER] = {{0}};
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) {
            double sum = 0.0;
            for (int c = 0; c < j; c++) sum += lower[i][c] * lower[j][c];
            double total = matrix[i][j] - sum;
            if (i == j) {
                if (!(total > 0.0)) return 0;
                lower[i][i] = sqrt(total);
            } else {
                lower[i][j] = total / lower[j][j];
            }
        }
    return 1;
}

/* ---------------------------------------------------------- contraction  [23] */
/* [23] */
double contraction_factor(double x, double lambda_ce, double kappa) {
    return 1.0 - lambda_ce * exp(-kappa * x * x);
}

/* [7] */
double normalized_input(double x, double alpha, double universe) {
    double z = x / alpha;
    if (z > universe) return universe;
    if (z < -universe) return -universe;
    return z;
}

/* ------------------------------------------------------------ memberships */
double sigmoid(double a) {
    if (a >= 0.0) return 1.0 / (1.0 + exp(-a));
    double ea = exp(a);
    return ea / (1.0 + ea);
}

double membership_high(double z, double slope) { return sigmoid(slope * z); }

double membership_low(double z, double slope) { return sigmoid(slope * -z); }

void membership_boundaries(double universe, int sets, double boundaries[]) {
    for (int l = 1; l < sets; l++) boundaries[l - 1] = -universe + 2.0 * universe * l / sets;
}

/* mu_1 = sig(s (c_1 - z)), mu_l = sig(s (z - c_(l-1))) - sig(s (z - c_l)), mu_m = sig(s (z - c_(m-1)));
 * m = 2 as Python's pair (sig(s (c_1 - z)), sig(s (z - c_1))) */
void memberships(int sets, double z, double slope, const double boundaries[], double mu[]) {
    double first = boundaries[0];
    if (sets == 2) {
        mu[0] = sigmoid(slope * (first - z));
        mu[1] = sigmoid(slope * (z - first));
        return;
    }
    mu[0] = sigmoid(slope * (first - z));
    double previous = sigmoid(slope * (z - first));
    for (int l = 1; l + 1 < sets; l++) {
        double rising = sigmoid(slope * (z - boundaries[l]));
        mu[l] = previous - rising;
        previous = rising;
    }
    mu[sets - 1] = previous;
}

/* [8]: xi = mu(z_1) (x) mu(z_2) (x) ..., the products left to right; n = 2, m = 2 unrolled as Python's
 * four rules (the same products) */
int fuzzy_basis(int n, int sets, const double z[], double slope, const double boundaries[][MAX_BOUNDARIES],
                double xi[]) {
    if (n == 2 && sets == 2) {
        double mu1[2], mu2[2];
        memberships(2, z[0], slope, boundaries[0], mu1);
        memberships(2, z[1], slope, boundaries[1], mu2);
        xi[0] = mu1[0] * mu2[0], xi[1] = mu1[0] * mu2[1], xi[2] = mu1[1] * mu2[0], xi[3] = mu1[1] * mu2[1];
        return 4;
    }
    memberships(sets, z[0], slope, boundaries[0], xi);
    int count = sets;
    for (int i = 1; i < n; i++) {
        double mu[MAX_SETS];
        memberships(sets, z[i], slope, boundaries[i], mu);
        for (int a = count - 1; a >= 0; a--) { /* in place from the end: xi[a m + b] = xi[a] mu[b] */
            double head = xi[a];
            for (int b = sets - 1; b >= 0; b--) xi[a * sets + b] = head * mu[b];
        }
        count *= sets;
    }
    return count;
}

/* ------------------------------------------------------ modified error  [36] */
static const double FACTORIAL[MAX_ORDER] = {1.0, 1.0, 2.0, 6.0}; /* j! for j < n: Python's int, exact */

/* a_k = sum_(j <= k) e^(j)(0) / j! * lambda_e^(k-j) / (k-j)!  (Python's float ** int is libm pow);
 * n = 2: a_0 = e(0), a_1 = de(0) + lambda_e e(0) */
void remark3_coefficients(int n, const double error0[], double lambda_e, double coefficients[]) {
    for (int k = 0; k < n; k++) {
        double total = 0.0;
        for (int j = 0; j <= k; j++)
            total += error0[j] / FACTORIAL[j] * (pow(lambda_e, (double)(k - j)) / FACTORIAL[k - j]);
        coefficients[k] = total;
    }
}

/* row j: a_k (k! // (k - j)!) for k = n-1 down to j (the integer ratio is exact in a double) */
void remark3_polynomials(int n, const double coefficients[], double polynomials[][MAX_ORDER]) {
    for (int j = 0; j < n; j++)
        for (int k = n - 1; k >= j; k--)
            polynomials[j][n - 1 - k] = coefficients[k] * (FACTORIAL[k] / FACTORIAL[k - j]);
}

/* p^(j)(t) by Horner from 0.0, then r_0 = p, r_i = r_(i-1)' - lambda_e r_(i-1): offset i is
 * r_i(t) exp(-lambda_e t).  Python's unrolled n = 2 path is this arithmetic:
 * ((0 t + a1) t + a0) e^(-lambda_e t), ((0 t + b1) - lambda_e ((0 t + a1) t + a0)) e^(-lambda_e t) */
void remark3_offset(int n, const double polynomials[][MAX_ORDER], double elapsed, double lambda_e, double offsets[]) {
    double t = elapsed;
    if (n == 2) { /* unrolled as Python's n = 2 path (the same arithmetic as the loops below) */
        double a1 = polynomials[0][0], a0 = polynomials[0][1], b1 = polynomials[1][0];
        double value = (0.0 * t + a1) * t + a0;
        double decay = exp(-lambda_e * t);
        offsets[0] = value * decay;
        offsets[1] = ((0.0 * t + b1) - lambda_e * value) * decay;
        return;
    }
    double values[MAX_ORDER]; /* p^(j)(t), j = 0..n-1 */
    for (int j = 0; j < n; j++) {
        double acc = 0.0;
        for (int c = 0; c < n - j; c++) acc = acc * t + polynomials[j][c];
        values[j] = acc;
    }
    double decay = exp(-lambda_e * t);
    offsets[0] = values[0] * decay;
    for (int i = 1; i < n; i++) {
        for (int j = 0; j < n - i; j++) values[j] = values[j + 1] - lambda_e * values[j];
        offsets[i] = values[0] * decay;
    }
}

void modified_error(int n, const double error[], double t, const double error0[], double t0, double lambda_e,
                    const double polynomials[][MAX_ORDER], double modified[]) {
    if (lambda_e == 0.0) {
        for (int i = 0; i < n; i++) modified[i] = error[i];
        return;
    }
    double computed[MAX_ORDER][MAX_ORDER];
    if (!polynomials) {
        double coefficients[MAX_ORDER];
        remark3_coefficients(n, error0, lambda_e, coefficients);
        remark3_polynomials(n, coefficients, computed);
        polynomials = (const double (*)[MAX_ORDER])computed;
    }
    double offsets[MAX_ORDER];
    remark3_offset(n, polynomials, t - t0, lambda_e, offsets);
    if (n == 2) { /* unrolled as Python */
        modified[0] = error[0] - offsets[0], modified[1] = error[1] - offsets[1];
        return;
    }
    for (int i = 0; i < n; i++) modified[i] = error[i] - offsets[i];
}

/* ------------------------------------------------------------ adaptation  [31] */
/* sum_i E^(i) P[i][n-1]; n = 2 unrolled as in Python (E p12 + dE p22), else from 0.0 */
double adaptation_signal(int n, const double error[], const double p_b[]) {
    if (n == 2) return error[0] * p_b[0] + error[1] * p_b[1];
    double tau = 0.0;
    for (int i = 0; i < n; i++) tau += error[i] * p_b[i];
    return tau;
}

double projected_rate(double theta_j, double tau, double xi_j, double gamma, double m_theta, double delta) {
    double rate = gamma * tau * xi_j;
    if (theta_j > m_theta && tau > 0.0) return (1.0 + (m_theta - theta_j) / delta) * rate;
    if (theta_j < -m_theta && tau < 0.0) return (1.0 + (m_theta + theta_j) / delta) * rate;
    return rate;
}

/* where |theta_j| <= M_theta the projection is inactive: dtheta_j = (gamma tau) xi_j inline */
void adapted_weights(int rules, const double theta[], double tau, const double xi[], double gamma, double m_theta,
                     double delta, double step_size, double adapted[]) {
    double rate = gamma * tau;
    for (int j = 0; j < rules; j++) {
        double value = theta[j], basis = xi[j];
        adapted[j] = -m_theta <= value && value <= m_theta
                         ? value + step_size * (rate * basis)
                         : value + step_size * projected_rate(value, tau, basis, gamma, m_theta, delta);
    }
}

void adaptation_rates(int rules, const double theta[], double tau, const double xi[], double gamma, double m_theta,
                      double delta, double rates[]) {
    double rate = gamma * tau;
    for (int j = 0; j < rules; j++) {
        double value = theta[j], basis = xi[j];
        rates[j] = -m_theta <= value && value <= m_theta ? rate * basis
                                                          : projected_rate(value, tau, basis, gamma, m_theta, delta);
    }
}

double estimate_rate(double tau, double gamma_w) { return gamma_w * tau; }

/* ------------------------------------ robust cures  [23a], [31a], [31b], (F1) */
void floored_contraction_factors(int n, const double alpha[], double alpha_min, double floored[]) {
    for (int i = 0; i < n; i++) floored[i] = alpha[i] > alpha_min ? alpha[i] : alpha_min;
}

double dead_zone_signal(double tau, double width) {
    if (tau > width) return tau - width;
    if (tau < -width) return tau + width;
    return 0.0;
}

void leaky_weights(int rules, const double theta[], const double rates[], double sigma, double step_size,
                   double adapted[]) {
    for (int j = 0; j < rules; j++) adapted[j] = theta[j] + step_size * (rates[j] - sigma * theta[j]);
}

void leaky_rates(int rules, const double theta[], const double rates[], double sigma, double out[]) {
    for (int j = 0; j < rules; j++) out[j] = rates[j] - sigma * theta[j];
}

double measurement_filter_gain(double elapsed, double time_constant) { return 1.0 - exp(-elapsed / time_constant); }

void filtered_measurements(int n, const double previous[], const double sample[], double gain, double filtered[]) {
    for (int i = 0; i < n; i++) filtered[i] = previous[i] + gain * (sample[i] - previous[i]);
}

/* ----------------------------------------------------------- control law  [9] */
void fls_inputs(int n, const double error[], const double reference[], const double modified[], int fls_input,
                double x[]) {
    if (fls_input == FLS_INPUT_STATE) {
        for (int i = 0; i < n; i++) x[i] = reference[i] - error[i];
        return;
    }
    if (n == 2) { /* Python returns the modified error itself */
        x[0] = modified[0], x[1] = modified[1];
        return;
    }
    for (int i = 0; i < n; i++) x[i] = modified[i];
}

void contraction_factors(int n, const double x[], double lambda_ce, const double kappa[], double alpha[]) {
    if (n == 2) { /* unrolled as Python */
        alpha[0] = contraction_factor(x[0], lambda_ce, kappa[0]), alpha[1] = contraction_factor(x[1], lambda_ce, kappa[1]);
        return;
    }
    for (int i = 0; i < n; i++) alpha[i] = contraction_factor(x[i], lambda_ce, kappa[i]);
}

void normalized_inputs(int n, const double x[], const double alpha[], const double universe[], double z[]) {
    if (n == 2) { /* unrolled as Python */
        z[0] = normalized_input(x[0], alpha[0], universe[0]), z[1] = normalized_input(x[1], alpha[1], universe[1]);
        return;
    }
    for (int i = 0; i < n; i++) z[i] = normalized_input(x[i], alpha[i], universe[i]);
}

void latch_error(ControllerParameters *p, const double error0[], double t0) {
    double coefficients[MAX_ORDER];
    for (int i = 0; i < p->order; i++) p->error0[i] = error0[i];
    p->t0 = t0;
    remark3_coefficients(p->order, p->error0, p->lambda_e, coefficients);
    remark3_polynomials(p->order, coefficients, p->remark3);
}

/* u = theta^T xi: the paper's four rules summed left to right as Python's unrolled path, any
 * other M from 0.0 as Python's loop */
double controller_output(const double error[], const double reference[], double t, const double theta[],
                         double w_hat, const ControllerParameters *p, double modified[], double alpha[],
                         double xi[]) {
    int n = p->order;
    double x[MAX_ORDER], z[MAX_ORDER];
    modified_error(n, error, t, p->error0, p->t0, p->lambda_e, (const double (*)[MAX_ORDER])p->remark3, modified);
    fls_inputs(n, error, reference, modified, p->fls_input, x);
    if (p->variant == VARIANT_VUD) {
        contraction_factors(n, x, p->lambda_ce, p->kappa, alpha);
        if (p->alpha_min > 0.0) floored_contraction_factors(n, alpha, p->alpha_min, alpha); /* [23a], off at 0 */
    } else {
        for (int i = 0; i < n; i++) alpha[i] = 1.0;
    }
    normalized_inputs(n, x, alpha, p->universe, z);
    int rules = fuzzy_basis(n, p->sets, z, p->mf_slope, (const double (*)[MAX_BOUNDARIES])p->boundaries, xi);
    double u;
    if (rules == 4) {
        u = theta[0] * xi[0] + theta[1] * xi[1] + theta[2] * xi[2] + theta[3] * xi[3];
    } else {
        u = 0.0;
        for (int j = 0; j < rules; j++) u += theta[j] * xi[j];
    }
    if (p->variant == VARIANT_FAE) u += w_hat;
    return u;
}

/* The controller's math: see afc_math.h and afc_math.py. */
#include <math.h>

#include "afc_math.h"

/* [30]: the n (n + 1) / 2 unknowns p_ij (i <= j) solve (A^T P + P A)_ij = -q_i [i = j] by
 * Gaussian elimination with partial pivoting, built and solved in the same order as the
 * general afc_math.py lyapunov_p of issue 17 (for n = 2 it can differ in the last bit from
 * the element-wise formulas p12 = q1 / (2 k2), p22 = (p12 + q2 / 2) / k1, p11 = k1 p12 + k2 p22,
 * for the default k, q it does not).  Element (i, j) of A^T P + P A is
 * p_(i-1)j [i >= 1] + p_i(j-1) [j >= 1] - k_(n-i) p_(n-1)j - k_(n-j) p_i(n-1). */
int lyapunov_p(int n, const double k[], const double q[], double p[MAX_ORDER][MAX_ORDER]) {
    enum { U = MAX_ORDER * (MAX_ORDER + 1) / 2 };
    int unknown[MAX_ORDER][MAX_ORDER];
    int size = 0;
    for (int i = 0; i < n; i++)
        for (int j = i; j < n; j++) { unknown[i][j] = unknown[j][i] = size; size++; }
    double rows[U][U + 1];
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
    for (int column = 0; column < size; column++) { /* forward elimination, first largest pivot */
        int pivot = column;
        for (int s = column + 1; s < size; s++)
            if (fabs(rows[s][column]) > fabs(rows[pivot][column])) pivot = s;
        if (rows[pivot][column] == 0.0) return -1; /* singular: k is not Hurwitz */
        if (pivot != column)
            for (int c = 0; c <= size; c++) {
                double swap = rows[column][c]; rows[column][c] = rows[pivot][c]; rows[pivot][c] = swap;
            }
        for (int s = column + 1; s < size; s++) {
            double factor = rows[s][column] / rows[column][column];
            if (factor != 0.0)
                for (int c = column; c <= size; c++) rows[s][c] -= factor * rows[column][c];
        }
    }
    double x[U];
    for (int s = size - 1; s >= 0; s--) { /* back substitution */
        double total = rows[s][size];
        for (int c = s + 1; c < size; c++) total -= rows[s][c] * x[c];
        x[s] = total / rows[s][s];
    }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) p[i][j] = x[unknown[i][j]];
    return 0;
}

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

double contraction_factor(double x, double lambda_ce, double kappa) {
    return 1.0 - lambda_ce * exp(-kappa * x * x); /* [23] */
}

double normalized_input(double x, double alpha, double universe) {
    double z = x / alpha; /* [7] */
    if (z > universe) return universe;
    if (z < -universe) return -universe;
    return z;
}

double membership_high(double z, double slope) {
    double a = slope * z;
    if (a >= 0.0) return 1.0 / (1.0 + exp(-a));
    double ea = exp(a);
    return ea / (1.0 + ea);
}

double membership_low(double z, double slope) { return membership_high(-z, slope); }

void memberships(double z, double slope, double universe, int sets, double mu[]) {
    double boundary[MAX_SETS];
    for (int l = 1; l < sets; l++) boundary[l] = -universe + 2.0 * universe * l / sets;
    mu[0] = membership_low(z - boundary[1], slope);
    for (int l = 1; l + 1 < sets; l++)
        mu[l] = membership_high(z - boundary[l], slope) - membership_high(z - boundary[l + 1], slope);
    mu[sets - 1] = membership_high(z - boundary[sets - 1], slope);
}

int fuzzy_basis(int n, int sets, const double z[], const double universe[], double slope, double xi[]) {
    double mu[MAX_ORDER][MAX_SETS];
    int rules = 1;
    for (int i = 0; i < n; i++) {
        memberships(z[i], slope, universe[i], sets, mu[i]);
        rules *= sets;
    }
    for (int j = 0; j < rules; j++) { /* [8], l1 slowest */
        int rest = j, stride = rules;
        double product = 1.0;
        for (int i = 0; i < n; i++) {
            stride /= sets;
            product = i == 0 ? mu[0][rest / stride] : product * mu[i][rest / stride];
            rest %= stride;
        }
        xi[j] = product;
    }
    return rules;
}

/* Remark 3 [36]: a_k = sum_(j <= k) e^(j)(0) / j! * lambda_e^(k-j) / (k-j)!  (remark3_coefficients),
 * p^(j)(t) by Horner (remark3_polynomials), and the derivatives of p(t) exp(-lambda_e t) by
 * r_0 = p, r_i = r_(i-1)' - lambda_e r_(i-1) (remark3_offset); n = 2: a0 = e(0),
 * a1 = de(0) + lambda_e e(0), offsets (a0 + a1 t) e^(-lambda_e t), (a1 - lambda_e (a0 + a1 t)) e^(-lambda_e t) */
void modified_error(int n, const double e[], double t, const double e0[], double lambda_e, double error[]) {
    static const double factorial[MAX_ORDER] = {1.0, 1.0, 2.0, 6.0};
    if (lambda_e == 0.0) {
        for (int i = 0; i < n; i++) error[i] = e[i];
        return;
    }
    double a[MAX_ORDER];
    for (int k = 0; k < n; k++) {
        double total = 0.0;
        for (int j = 0; j <= k; j++)
            total += e0[j] / factorial[j] * (pow(lambda_e, (double)(k - j)) / factorial[k - j]);
        a[k] = total;
    }
    double values[MAX_ORDER]; /* p^(j)(t) */
    for (int j = 0; j < n; j++) {
        double acc = 0.0;
        for (int k = n - 1; k >= j; k--) acc = acc * t + a[k] * (factorial[k] / factorial[k - j]);
        values[j] = acc;
    }
    double decay = exp(-lambda_e * t);
    for (int i = 0; i < n; i++) {
        error[i] = e[i] - values[0] * decay;
        for (int j = 0; j + 1 < n - i; j++) values[j] = values[j + 1] - lambda_e * values[j];
    }
}

double adaptation_signal(int n, const double error[], const double p[MAX_ORDER][MAX_ORDER]) {
    double tau = error[0] * p[0][n - 1]; /* [31] */
    for (int i = 1; i < n; i++) tau += error[i] * p[i][n - 1];
    return tau;
}

double projected_rate(double theta_j, double tau, double xi_j, double gamma, double m_theta, double delta) {
    double rate = gamma * tau * xi_j; /* [31] */
    if (theta_j > m_theta && tau > 0.0) return (1.0 + (m_theta - theta_j) / delta) * rate;
    if (theta_j < -m_theta && tau < 0.0) return (1.0 + (m_theta + theta_j) / delta) * rate;
    return rate;
}

void fls_inputs(int n, const double e[], const double ym[], const double error[], int fls_input, double x[]) {
    for (int i = 0; i < n; i++) x[i] = fls_input == FLS_INPUT_STATE ? ym[i] - e[i] : error[i];
}

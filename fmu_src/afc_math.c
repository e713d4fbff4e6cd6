/* The controller's math: see afc_math.h and afc_math.py. */
#include <math.h>

#include "afc_math.h"

/* [30] element-wise for n = 2 (afc_math.py lyapunov_p), a linear solve otherwise */
int lyapunov_p(int n, const double k[], const double q[], double p[MAX_ORDER][MAX_ORDER]) {
    if (n == 2) {
        /* A = [[0, 1], [-k2, -k1]]: -2 k2 p12 = -q1, p11 - k1 p12 - k2 p22 = 0, 2 (p12 - k1 p22) = -q2 */
        double p12 = q[0] / (2.0 * k[1]);
        double p22 = (p12 + 0.5 * q[1]) / k[0];
        double p11 = k[0] * p12 + k[1] * p22;
        p[0][0] = p11; p[0][1] = p12; p[1][0] = p12; p[1][1] = p22;
        return 0;
    }
    /* companion matrix: A[i][i+1] = 1, last row -[kn, ..., k1] */
    double a[MAX_ORDER][MAX_ORDER] = {{0}};
    for (int i = 0; i + 1 < n; i++) a[i][i + 1] = 1.0;
    for (int j = 0; j < n; j++) a[n - 1][j] = -k[n - 1 - j];
    /* unknowns p_ij, i <= j; equations (A^T P + P A)_ij = -Q_ij, i <= j */
    enum { U = MAX_ORDER * (MAX_ORDER + 1) / 2 };
    int index[MAX_ORDER][MAX_ORDER];
    int count = 0;
    for (int i = 0; i < n; i++)
        for (int j = i; j < n; j++) index[i][j] = index[j][i] = count++;
    double system[U][U + 1] = {{0}};
    int row = 0;
    for (int i = 0; i < n; i++)
        for (int j = i; j < n; j++, row++) {
            for (int l = 0; l < n; l++) {
                system[row][index[l][j]] += a[l][i]; /* (A^T P)_ij = sum_l A_li P_lj */
                system[row][index[i][l]] += a[l][j]; /* (P A)_ij = sum_l P_il A_lj */
            }
            system[row][count] = i == j ? -q[i] : 0.0;
        }
    for (int c = 0; c < count; c++) { /* Gaussian elimination with partial pivoting */
        int pivot = c;
        for (int r = c + 1; r < count; r++)
            if (fabs(system[r][c]) > fabs(system[pivot][c])) pivot = r;
        if (system[pivot][c] == 0.0) return -1;
        for (int j = 0; j <= count; j++) {
            double swap = system[c][j]; system[c][j] = system[pivot][j]; system[pivot][j] = swap;
        }
        for (int r = 0; r < count; r++) {
            if (r == c) continue;
            double factor = system[r][c] / system[c][c];
            for (int j = c; j <= count; j++) system[r][j] -= factor * system[c][j];
        }
    }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) p[i][j] = system[index[i][j]][count] / system[index[i][j]][index[i][j]];
    return 0;
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

void modified_error(int n, const double e[], double t, const double e0[], double lambda_e, double error[]) {
    if (lambda_e == 0.0) {
        for (int i = 0; i < n; i++) error[i] = e[i];
        return;
    }
    /* d^i p(0) from E^(i)(0) = 0: d^i p(0) = e^(i)(0) - sum_{k<i} C(i,k) d^k p(0) (-lambda_e)^(i-k)
     * (n = 2: a0 = e(0), a1 = de(0) + lambda_e e(0)) */
    double derivative0[MAX_ORDER], a[MAX_ORDER];
    static const double binomial[MAX_ORDER][MAX_ORDER] = {{1}, {1, 1}, {1, 2, 1}, {1, 3, 3, 1}};
    static const double factorial[MAX_ORDER] = {1, 1, 2, 6};
    for (int i = 0; i < n; i++) {
        double value = e0[i];
        for (int k = i - 1; k >= 0; k--) {
            double power = 1.0;
            for (int r = 0; r < i - k; r++) power *= lambda_e;
            double term = binomial[i][k] * derivative0[k] * power;
            value = (i - k) % 2 ? value + term : value - term;
        }
        derivative0[i] = value;
        a[i] = value / factorial[i]; /* p(t) = a0 + a1 t + ... */
    }
    double decay = exp(-lambda_e * t);
    /* d^k p(t), Horner */
    double pk[MAX_ORDER];
    for (int k = 0; k < n; k++) {
        double value = 0.0;
        for (int j = n - 1; j >= k; j--) {
            double coefficient = a[j] * (factorial[j] / factorial[j - k]);
            value = j == n - 1 ? coefficient : coefficient + value * t;
        }
        pk[k] = value;
    }
    /* E^(i) = e^(i) - d^i[p(t) exp(-l t)] = e^(i) - exp(-l t) sum_k C(i,k) p^(k)(t) (-l)^(i-k) */
    for (int i = 0; i < n; i++) {
        double sum = pk[i];
        for (int k = i - 1; k >= 0; k--) {
            double power = 1.0;
            for (int r = 0; r < i - k; r++) power *= lambda_e;
            double term = binomial[i][k] * power * pk[k];
            sum = (i - k) % 2 ? sum - term : sum + term;
        }
        error[i] = e[i] - sum * decay;
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

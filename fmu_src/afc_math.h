/* The controller of Pan, Er, Huang and Wang (IEEE TFS 19(5), 2011) as pure functions:
 * the C twin of afc_math.py, function for function, in the general form of issue 17
 * (plant order n = 1..4, m = 2..5 fuzzy sets per FLS input, M = m^n rules).  Equation
 * numbers in brackets are the paper's.  For n = 2, m = 2 every function performs the
 * same floating-point operations in the same order as the Python edition. */
#ifndef AFC_MATH_H
#define AFC_MATH_H

#define VARIANT_VUD 1       /* variable universes of discourse: the paper's proposed AFC */
#define VARIANT_FIXED 2     /* alpha = 1: stand-in for the direct AFC of [46] */
#define VARIANT_FAE 3       /* alpha = 1 plus approximation-error estimate w_hat: stand-in for [28] */
#define FLS_INPUT_ERROR 1   /* FLS input [E, dE, ...] (the paper) */
#define FLS_INPUT_STATE 2   /* FLS input x = [ym - e, dym - de, ...] (the ablation of Remark 4) */

#define MAX_ORDER 4         /* n */
#define MIN_SETS 2          /* m */
#define MAX_SETS 5
#define MAX_RULES 625       /* m^n for m = 5, n = 4 */

/* P solving A^T P + P A = -Q [30] for the companion matrix A of s^n + k1 s^(n-1) + ... + kn
 * and Q = diag(q1..qn); returns 0, or -1 if the system is singular (A not Hurwitz). */
int lyapunov_p(int n, const double k[], const double q[], double p[MAX_ORDER][MAX_ORDER]);

/* 1 when the symmetric n x n matrix is positive definite (Cholesky), else 0 */
int is_positive_definite(int n, const double matrix[MAX_ORDER][MAX_ORDER]);

/* alpha(x) = 1 - lambda_ce exp(-kappa x^2)  [23] */
double contraction_factor(double x, double lambda_ce, double kappa);

/* z = x / alpha(x)  [7], saturated to the universe [-E, E] */
double normalized_input(double x, double alpha, double universe);

/* sig(s z) = 1 / (1 + exp(-s z)) without overflow: the paper's mu_2 for m = 2 */
double membership_high(double z, double slope);

/* mu_1(z) = 1 / (1 + exp(s z)) = mu_2(-z) */
double membership_low(double z, double slope);

/* mu_1..mu_m(z): a partition of unity by differences of sigmoids with boundaries
 * c_l = -E + 2 E l / m (issue 17); m = 2 gives (membership_low, membership_high) */
void memberships(double z, double slope, double universe, int sets, double mu[]);

/* xi_j = prod_i mu_{l_i}(z_i)  [8], j over the m^n rules with l1 slowest; returns M */
int fuzzy_basis(int n, int sets, const double z[], const double universe[], double slope, double xi[]);

/* E^(i) of Remark 3 (36): E = e - p(t) exp(-lambda_e t), p of degree n - 1 chosen so that
 * E^(i)(0) = 0 for i < n; t since the start, e0[i] = e^(i)(0); lambda_e = 0: E = e */
void modified_error(int n, const double e[], double t, const double e0[], double lambda_e, double error[]);

/* tau = E^T P B with B = [0, ..., 0, 1]^T  [31] */
double adaptation_signal(int n, const double error[], const double p[MAX_ORDER][MAX_ORDER]);

/* dtheta_j of the adaptive law with smooth projection  [31] */
double projected_rate(double theta_j, double tau, double xi_j, double gamma, double m_theta, double delta);

/* the FLS input vector: E (fls_input 1) or the state ym^(i) - e^(i) (2) */
void fls_inputs(int n, const double e[], const double ym[], const double error[], int fls_input, double x[]);

#endif

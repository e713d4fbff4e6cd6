/* The controller of Pan, Er, Huang and Wang (IEEE TFS 19(5), 2011) as pure functions:
 * the C twin of afc_math.py, function for function, with the same names, in the general form
 * of docs/general_order.md (plant order n = 1..4, m = 2..5 fuzzy sets per FLS input, M = m^n rules).
 * Equation numbers in brackets are the paper's.  Every function performs the same IEEE
 * floating-point operations in the same order as its Python twin (compiled with
 * -ffp-contract=off, no fast-math, calling the same libm), so the editions agree bit for bit.
 *
 * Arguments: the counts first (n, m or M: C arrays carry no length), then the Python
 * function's arguments in its order (arrays for tuples), then the outputs (what the Python
 * returns as a tuple; a single number is the return value).
 *
 * afc_math.py                C twin
 * lyapunov_p                 lyapunov_p            [30]
 * is_positive_definite       is_positive_definite
 * _solve                     solve (static, in afc_math.c)
 * contraction_factor         contraction_factor    [23]
 * normalized_input           normalized_input      [7]
 * sigmoid                    sigmoid
 * membership_high            membership_high
 * membership_low             membership_low
 * membership_boundaries      membership_boundaries
 * memberships                memberships
 * fuzzy_basis                fuzzy_basis           [8]
 * remark3_coefficients       remark3_coefficients  [36]
 * remark3_polynomials        remark3_polynomials   [36]
 * remark3_offset             remark3_offset        [36]
 * modified_error             modified_error        [36]
 * adaptation_signal          adaptation_signal     [31]
 * projected_rate             projected_rate        [31]
 * adapted_weights            adapted_weights       [31]
 * adaptation_rates           adaptation_rates      [31]
 * estimate_rate              estimate_rate
 * fls_inputs                 fls_inputs
 * contraction_factors        contraction_factors   [23]
 * normalized_inputs          normalized_inputs     [7]
 * floored_contraction_factors floored_contraction_factors [23a]
 * dead_zone_signal           dead_zone_signal      [31a]
 * leaky_weights              leaky_weights         [31b]
 * leaky_rates                leaky_rates           [31b]
 * measurement_filter_gain    measurement_filter_gain (F1)
 * filtered_measurements      filtered_measurements (F1)
 * controller_parameters      none: it builds the Python dict p from the FMU's parameter names;
 *                            in C, p is a ControllerParameters struct that the FMU fills
 *                            (configure in adaptive_fuzzy_controller.c, as the Python FMU's
 *                            _configure calls controller_parameters)
 * latch_error                latch_error
 * controller_output          controller_output     [9]
 */
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
#define MAX_BOUNDARIES (MAX_SETS - 1) /* m - 1 membership boundaries per input */
#define MAX_RULES 625       /* m^n for m = 5, n = 4 */

/* The Python dict p of controller_parameters / latch_error: what controller_output needs. */
typedef struct {
    double lambda_e;                              /* decay rate of the modified error (Remark 3) */
    double lambda_ce;                             /* contraction-expansion depth lambda (23) */
    double mf_slope;                              /* slope s of the sigmoid memberships */
    double kappa[MAX_ORDER];                      /* contraction-expansion widths (23) */
    double universe[MAX_ORDER];                   /* E_i of the universes [-E_i, E_i] */
    double boundaries[MAX_ORDER][MAX_BOUNDARIES]; /* membership_boundaries of each input */
    double p_b[MAX_ORDER];                        /* P B: the last column of P (30) */
    double error0[MAX_ORDER];                     /* the latched e(t0), de(t0), ... (Remark 3) */
    double t0;                                    /* its time origin */
    double remark3[MAX_ORDER][MAX_ORDER];         /* remark3_polynomials of error0, per latch */
    int order, sets, rules;                       /* n, m, M = m^n */
    int variant, fls_input;
    double alpha_min;                             /* the floor on alpha [23a]; 0 = off (appended) */
} ControllerParameters;

/* P solving A^T P + P A = -Q [30] for the companion matrix A of s^n + k1 s^(n-1) + ... + kn
 * and Q = diag(q1..qn); returns 0, or -1 if the system is singular (A not Hurwitz). */
int lyapunov_p(int n, const double k[], const double q[], double p[MAX_ORDER][MAX_ORDER]);

/* 1 when the symmetric n x n matrix is positive definite (Cholesky), else 0 */
int is_positive_definite(int n, const double matrix[MAX_ORDER][MAX_ORDER]);

/* alpha(x) = 1 - lambda_ce exp(-kappa x^2)  [23] */
double contraction_factor(double x, double lambda_ce, double kappa);

/* z = x / alpha(x)  [7], saturated to the universe [-E, E] */
double normalized_input(double x, double alpha, double universe);

/* 1 / (1 + exp(-a)), evaluated without overflow */
double sigmoid(double a);

/* mu_2(z) = 1 / (1 + exp(-s z)) of the paper's pair (m = 2) */
double membership_high(double z, double slope);

/* mu_1(z) = 1 / (1 + exp(s z)) = mu_2(-z) of the paper's pair; mu_1 + mu_2 = 1 */
double membership_low(double z, double slope);

/* the m - 1 boundaries c_l = -E + 2 E l / m (l = 1..m-1), evenly inside [-E, E] */
void membership_boundaries(double universe, int sets, double boundaries[]);

/* mu_1..mu_m(z): a partition of unity by differences of sigmoids at the m - 1 boundaries;
 * m = 2 (boundary 0) gives (membership_low, membership_high) bit for bit */
void memberships(int sets, double z, double slope, const double boundaries[], double mu[]);

/* xi_j = mu_l1(z_1) ... mu_ln(z_n)  [8], j over the m^n rules with l1 slowest; returns M */
int fuzzy_basis(int n, int sets, const double z[], double slope, const double boundaries[][MAX_BOUNDARIES],
                double xi[]);

/* (a_0, ..., a_(n-1)) of p(t) = sum_k a_k t^k in Remark 3  [36] */
void remark3_coefficients(int n, const double error0[], double lambda_e, double coefficients[]);

/* the derivatives p, p', ..., p^(n-1) of p(t)  [36]: row j holds a_k k! / (k - j)!, k = n-1 down to j */
void remark3_polynomials(int n, const double coefficients[], double polynomials[][MAX_ORDER]);

/* (d/dt)^i [p(t) exp(-lambda_e t)] at t = elapsed, i = 0..n-1  [36] */
void remark3_offset(int n, const double polynomials[][MAX_ORDER], double elapsed, double lambda_e, double offsets[]);

/* (E, dE, ..., E^(n-1)) of Remark 3  [36]: E = e - p(t - t0) exp(-lambda_e (t - t0)); polynomials
 * from remark3_polynomials (once per latch) or NULL (computed here); lambda_e = 0: E = e */
void modified_error(int n, const double error[], double t, const double error0[], double t0, double lambda_e,
                    const double polynomials[][MAX_ORDER], double modified[]);

/* tau = E^T P B with B = [0, ..., 0, 1]^T  [31]; p_b the last column of P */
double adaptation_signal(int n, const double error[], const double p_b[]);

/* dtheta_j of the adaptive law with smooth projection  [31] */
double projected_rate(double theta_j, double tau, double xi_j, double gamma, double m_theta, double delta);

/* theta_j + h dtheta_j for every rule j: the sampled-data (explicit Euler) step of [31] */
void adapted_weights(int rules, const double theta[], double tau, const double xi[], double gamma, double m_theta,
                     double delta, double step_size, double adapted[]);

/* dtheta_j for every rule j: the adaptive law with smooth projection [31] in continuous time (model
 * exchange): the rates adapted_weights multiplies by the step */
void adaptation_rates(int rules, const double theta[], double tau, const double xi[], double gamma, double m_theta,
                      double delta, double rates[]);

/* dw_hat = gamma_w tau: the approximation-error estimate of variant 3 in continuous time */
double estimate_rate(double tau, double gamma_w);

/* the FLS input vector: the modified error (fls_input 1) or the state ym^(i) - e^(i) (2) */
void fls_inputs(int n, const double error[], const double reference[], const double modified[], int fls_input,
                double x[]);

/* (alpha_1(x_1), ..., alpha_n(x_n))  [23] */
void contraction_factors(int n, const double x[], double lambda_ce, const double kappa[], double alpha[]);

/* (z_1, ..., z_n) = (x_1 / alpha_1, ...)  [7], each saturated to its universe */
void normalized_inputs(int n, const double x[], const double alpha[], const double universe[], double z[]);

/* ---- the robust cures (docs/model.md section 14 (robust cures)), each off at 0 */

/* max(alpha_i, alpha_min) for each input: the floor on alpha [23a]; floored may be alpha */
void floored_contraction_factors(int n, const double alpha[], double alpha_min, double floored[]);

/* tau through the continuous dead zone of half-width d0 [31a]: 0 for |tau| <= d0, tau -+ d0 outside */
double dead_zone_signal(double tau, double width);

/* theta_j + h (dtheta_j - sigma theta_j) for every rule j: sigma-modification [31b] */
void leaky_weights(int rules, const double theta[], const double rates[], double sigma, double step_size,
                   double adapted[]);

/* dtheta_j - sigma theta_j for every rule j: [31b] in continuous time (model exchange); out may be rates */
void leaky_rates(int rules, const double theta[], const double rates[], double sigma, double out[]);

/* a = 1 - exp(-dt / T_m) of the first-order measurement filter (F1) over elapsed = dt */
double measurement_filter_gain(double elapsed, double time_constant);

/* f_k = f_(k-1) + a (x_k - f_(k-1)) for each of the n entries (F1); filtered may be sample */
void filtered_measurements(int n, const double previous[], const double sample[], double gain, double filtered[]);

/* set the latched error vector e(t0), ... (p->order entries), t0 and the Remark 3 polynomials in p */
void latch_error(ControllerParameters *p, const double error0[], double t0);

/* u = theta^T xi (+ w_hat for variant 3)  [9] at time t; also the modified error E, the contraction
 * factors alpha (1 for variants 2, 3) and the basis xi (p->rules entries) */
double controller_output(const double error[], const double reference[], double t, const double theta[],
                         double w_hat, const ControllerParameters *p, double modified[], double alpha[],
                         double xi[]);

#endif

/*
 * The math floor of the pendulum's closed loop: pendulum_case1 / vud (plant (37) without disturbance,
 * reference ym = A sin(omega t), the controller of order n = 2 with m = 2 sets, variant vud) with
 * every equation inlined in one C function and no FMI: what a step costs when nothing but its
 * arithmetic is done.  The benchmark (harness/hosts/bench.py) times it beside our master and the
 * plain C host (plain_c_host.c); tests/test_c_baselines.py holds its record equal, bit for bit, to
 * the master's with the native FMUs.
 *
 * It performs the FMUs' floating-point operations in their order (afc_math.c, plants/inverted_pendulum/
 * model.c, plants/plant_integration.c, plants/tracking_reference/model.c; compiled with the same
 * -ffp-contract=off), specialised to this one loop and written out by hand: no function pointer,
 * no loop over n or m, no FMI call, no check of a status, a bound or a finite value.  The constants
 * are computed once before the loop, as the FMUs compute theirs at initialisation.  The latch of
 * the initial error stays where the master's consistent initial values put it (the FMU's check over
 * the first doSteps confirms it), and the chatter monitor, which only warns, is left out.
 *
 * Row n (t = start + n step) of the record holds the master's 15 columns: y, dy, d; ym, dym, e, de;
 * u, E, dE, theta1..4, w_hat; then the plant, the reference and the controller step from t.
 */
#include <math.h>
#include <stdint.h>
#include <stddef.h>

#if defined(_WIN32)
#define EXPORT __declspec(dllexport)
#else
#define EXPORT __attribute__((visibility("default")))
#endif

#define FOUR_THIRDS (4.0 / 3.0)
#define SPLIT_TOLERANCE 1e-12

/* the parameters of the three FMUs (their declaration's starts with the scenario's values) */
typedef struct {
    double gv, mc, mp, lp, x1_start, x2_start, max_internal_step;     /* InvertedPendulum */
    double amplitude, omega;                                          /* TrackingReference */
    double universe1, universe2, mf_slope, lambda_ce, kappa1, kappa2; /* AdaptiveFuzzyController */
    double gamma, m_theta, delta, lambda_e, theta0;
    double p_b1, p_b2;                                                /* P B of (30), afc_math.lyapunov_p */
    double start, step;
} FloorParameters;

static inline double sigmoid(double a) {
    if (a >= 0.0) return 1.0 / (1.0 + exp(-a));
    double ea = exp(a);
    return ea / (1.0 + ea);
}

/* theta_j + h dtheta_j of [31], the projection where |theta_j| > M_theta */
static inline double adapted(double theta, double rate, double tau, double xi, const FloorParameters *p) {
    if (-p->m_theta <= theta && theta <= p->m_theta) return theta + p->step * (rate * xi);
    double projected = p->gamma * tau * xi;
    if (theta > p->m_theta && tau > 0.0) projected = (1.0 + (p->m_theta - theta) / p->delta) * projected;
    else if (theta < -p->m_theta && tau < 0.0) projected = (1.0 + (p->m_theta + theta) / p->delta) * projected;
    return theta + p->step * projected;
}

/* rows 0 .. steps of the record (steps + 1 rows of 15 columns) */
EXPORT int math_floor_run(const FloorParameters *p, int64_t steps, double *record) {
    /* plant: the constants of (37) and the RK4 split of the step (plant_params, internal_step_count) */
    const double mt = p->mc + p->mp;
    const double gv = p->gv, lp = p->lp, mp_lp_over_mt = p->mp * p->lp / mt, mp_over_mt = p->mp / mt;
    const double inv_mt = 1.0 / mt;
    double internal = ceil(p->step / p->max_internal_step - SPLIT_TOLERANCE);
    const long splits = internal > 1.0 ? (long)internal : 1;
    const double h = p->step / (double)splits, half = 0.5 * h, sixth = h / 6.0;
    /* controller: membership boundaries (m = 2) and the latch of Remark 3 [36] */
    const double c1 = -p->universe1 + 2.0 * p->universe1 * 1 / 2, c2 = -p->universe2 + 2.0 * p->universe2 * 1 / 2;
    const double slope = p->mf_slope, lambda_e = p->lambda_e, lambda_ce = p->lambda_ce;
    const double kappa1 = p->kappa1, kappa2 = p->kappa2, universe1 = p->universe1, universe2 = p->universe2;
    double x1 = p->x1_start, x2 = p->x2_start;
    double theta[4] = {p->theta0, p->theta0, p->theta0, p->theta0};
    const double t0 = p->start;
    /* e(t0), de(t0): the initial values the master propagates (reference at t0, plant at its start) */
    const double e0 = p->amplitude * sin(p->omega * t0) - x1;
    const double de0 = p->amplitude * p->omega * cos(p->omega * t0) - x2;
    const double a0 = 0.0 + e0 / 1.0 * (pow(lambda_e, 0.0) / 1.0);
    const double a1 = 0.0 + e0 / 1.0 * (pow(lambda_e, 1.0) / 1.0) + de0 / 1.0 * (pow(lambda_e, 0.0) / 1.0);
    const double poly00 = a1 * (1.0 / 1.0), poly01 = a0 * (1.0 / 1.0), poly10 = a1 * (1.0 / 1.0);
    double time = p->start; /* the FMUs' own time: where their last doStep ended */
    for (int64_t n = 0;; n++) {
        double t = p->start + (double)n * p->step; /* the communication point */
        double *row = record + (size_t)n * 15;
        /* reference */
        double phase = p->omega * time;
        double s = sin(phase);
        double ym = p->amplitude * s, dym = p->amplitude * p->omega * cos(phase);
        double e = ym - x1, de = dym - x2;
        /* controller [9]: modified error [36], contraction [23], normalisation [7], basis [8] */
        double elapsed = time - t0;
        double value = (0.0 * elapsed + poly00) * elapsed + poly01;
        double decay = exp(-lambda_e * elapsed);
        double E = e - value * decay;
        double dE = de - ((0.0 * elapsed + poly10) - lambda_e * value) * decay;
        double alpha1 = 1.0 - lambda_ce * exp(-kappa1 * E * E), alpha2 = 1.0 - lambda_ce * exp(-kappa2 * dE * dE);
        double z1 = E / alpha1, z2 = dE / alpha2;
        z1 = z1 > universe1 ? universe1 : z1 < -universe1 ? -universe1 : z1;
        z2 = z2 > universe2 ? universe2 : z2 < -universe2 ? -universe2 : z2;
        double mu10 = sigmoid(slope * (c1 - z1)), mu11 = sigmoid(slope * (z1 - c1));
        double mu20 = sigmoid(slope * (c2 - z2)), mu21 = sigmoid(slope * (z2 - c2));
        double xi[4] = {mu10 * mu20, mu10 * mu21, mu11 * mu20, mu11 * mu21};
        double u = theta[0] * xi[0] + theta[1] * xi[1] + theta[2] * xi[2] + theta[3] * xi[3];
        row[0] = x1, row[1] = x2, row[2] = 0.0;
        row[3] = ym, row[4] = dym, row[5] = e, row[6] = de;
        row[7] = u, row[8] = E, row[9] = dE;
        row[10] = theta[0], row[11] = theta[1], row[12] = theta[2], row[13] = theta[3], row[14] = 0.0;
        if (n == steps) break;
        /* plant: RK4 of (37) with u held, `splits` internal steps */
        for (long i = 0; i < splits; i++) {
            double k1[2], k2[2], k3[2], k4[2], stage[2];
#define PENDULUM(x, dx)                                                                          \
    do {                                                                                         \
        double c_ = cos((x)[0]), s_ = sin((x)[0]);                                               \
        double den_ = lp * (FOUR_THIRDS - mp_over_mt * c_ * c_);                                 \
        (dx)[0] = (x)[1];                                                                        \
        (dx)[1] = (gv * s_ - mp_lp_over_mt * (x)[1] * (x)[1] * c_ * s_ + c_ * inv_mt * u) / den_; \
    } while (0)
            double x[2] = {x1, x2};
            PENDULUM(x, k1);
            stage[0] = x1 + half * k1[0], stage[1] = x2 + half * k1[1];
            PENDULUM(stage, k2);
            stage[0] = x1 + half * k2[0], stage[1] = x2 + half * k2[1];
            PENDULUM(stage, k3);
            stage[0] = x1 + h * k3[0], stage[1] = x2 + h * k3[1];
            PENDULUM(stage, k4);
            x1 = x1 + sixth * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]);
            x2 = x2 + sixth * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]);
#undef PENDULUM
        }
        /* controller: the adaptive law [31], one explicit Euler step */
        double tau = E * p->p_b1 + dE * p->p_b2;
        double rate = p->gamma * tau;
        for (int j = 0; j < 4; j++) theta[j] = adapted(theta[j], rate, tau, xi[j], p);
        time = t + p->step;
    }
    return 0;
}

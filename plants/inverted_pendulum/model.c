/* InvertedPendulum: the inverted pendulum on a cart, eq. (37) of Pan, Er, Huang, Wang
 * (IEEE TFS 2011), as a native FMU.  The C twin of this folder's model.py and
 * fmu.py: same equations, same order of operations.
 *
 *   dx1 = x2                                                            (37)
 *   den = lp (4/3 - mp cos^2 x1 / (mc + mp))
 *   dx2 = (gv sin x1 - mp lp x2^2 cos x1 sin x1 / (mc + mp)) / den
 *         + (cos x1 / (mc + mp)) / den * u + d(t)                       (37)
 *   d(t) = dist_gain * (3 cos 2t + 2 sin((0.09 t + 1) t))
 *   (docs/model.md section 10, choice 10 (disturbance): additive in dx2)
 */
#include <math.h>

#include "rk4_plant_slave.h"

#define FOUR_THIRDS (4.0 / 3.0)

/* pendulum_params: (gv, lp, mp lp / mt, mp / mt, 1 / mt, dist_gain) with mt = mc + mp */
void plant_params(ModelInstance *m, double *params) {
    double mt = V(m, mc) + V(m, mp);
    params[0] = V(m, gv);
    params[1] = V(m, lp);
    params[2] = V(m, mp) * V(m, lp) / mt;
    params[3] = V(m, mp) / mt;
    params[4] = 1.0 / mt;
    params[5] = V(m, dist_gain);
}

/* d(t) = dist_gain * (3 cos 2t + 2 sin((0.09 t + 1) t)) in rad/s2
 * (case 2 of docs/model.md section 8 (scenarios)) */
static double pendulum_disturbance(double t, double dist_gain) {
    if (dist_gain == 0.0) return 0.0;
    return dist_gain * (3.0 * cos(2.0 * t) + 2.0 * sin((0.09 * t + 1.0) * t));
}

/* (dx1, dx2) of eq. (37) plus the disturbance d(t) in dx2 */
static void pendulum_derivative(double t, const double x[], double u, const double *params, double dx[]) {
    double x1 = x[0], x2 = x[1];
    double gv = params[0], lp = params[1], mp_lp_over_mt = params[2], mp_over_mt = params[3];
    double inv_mt = params[4], dist_gain = params[5];
    double c = cos(x1);
    double s = sin(x1);
    double den = lp * (FOUR_THIRDS - mp_over_mt * c * c);                              /* (37) */
    double rate = (gv * s - mp_lp_over_mt * x2 * x2 * c * s + c * inv_mt * u) / den;  /* (37) */
    if (dist_gain != 0.0) /* d(t), docs/model.md section 10, choice 10 (disturbance): additive in dx2 */
        rate += dist_gain * (3.0 * cos(2.0 * t) + 2.0 * sin((0.09 * t + 1.0) * t));
    dx[0] = x2;
    dx[1] = rate;
}

const PlantDerivative plant_derivative = pendulum_derivative;

/* co-simulation's step: RK4 with u held, pendulum_derivative inlined into its stages; without a disturbance
 * (dist_gain = 0) its constants are a local copy whose dist_gain the compiler sees, so the stages carry
 * neither the test of d(t) nor the times only d(t) reads (the same operations on x) */
void plant_advance(double t, double x[], double u, const Rk4Split *split, const double *params) {
    if (params[5] == 0.0) {
        const double undisturbed[6] = {params[0], params[1], params[2], params[3], params[4], 0.0};
        rk4_advance(pendulum_derivative, t, x, u, split, undisturbed);
    } else {
        rk4_advance(pendulum_derivative, t, x, u, split, params);
    }
}

int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    (void)m; (void)message; (void)size;
    return MODEL_OK;
}

int model_compute_outputs(ModelInstance *m) {
    V(m, y) = PLANT(m)->x[0];
    V(m, dy) = PLANT(m)->x[1];
    V(m, d) = pendulum_disturbance(m->s->time, V(m, dist_gain));
    m->outputs_stale = 0;
    return MODEL_OK;
}

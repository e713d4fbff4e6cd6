/* DcMotorArm: an arm driven by a DC motor with armature inductance, a third-order plant of
 * our own (docs/general_order.md), as a native FMU: the C twin of
 * model.py and fmu.py of this folder.
 *
 *   dx1 = x2
 *   dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J                       (motion)
 *   dx3 = (u - R x3 - Ke x2) / L                                    (armature)
 */
#include <math.h>

#include "rk4_plant_slave.h"

/* motor_arm_params: (1 / J, b, m gv lc, Kt, 1 / L, R, Ke) */
void plant_params(ModelInstance *m, double *params) {
    params[0] = 1.0 / V(m, J);
    params[1] = V(m, b);
    params[2] = V(m, m) * V(m, gv) * V(m, lc);
    params[3] = V(m, Kt);
    params[4] = 1.0 / V(m, L);
    params[5] = V(m, R);
    params[6] = V(m, Ke);
}

/* d2y = dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J */
static double motor_arm_acceleration(double x1, double x2, double x3, const double *params) {
    return (params[3] * x3 - params[1] * x2 - params[2] * sin(x1)) * params[0];
}

static void motor_arm_derivative(double t, const double x[], double u, const double *params, double dx[]) {
    (void)t;
    double inv_j = params[0], b = params[1], m_gv_lc = params[2], kt = params[3], inv_l = params[4];
    double resistance = params[5], ke = params[6];
    dx[0] = x[1];
    dx[1] = (kt * x[2] - b * x[1] - m_gv_lc * sin(x[0])) * inv_j;
    dx[2] = (u - resistance * x[2] - ke * x[1]) * inv_l;
}

const PlantDerivative plant_derivative = motor_arm_derivative;

/* co-simulation's step: RK4 with u held, motor_arm_derivative inlined into its stages */
void plant_advance(double t, double x[], double u, const Rk4Split *split, const double *params) {
    rk4_advance_states(motor_arm_derivative, t, x, PLANT_STATES, u, split, params);
}

int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    (void)m; (void)message; (void)size;
    return MODEL_OK;
}

int model_compute_outputs(ModelInstance *m) {
    double params[PLANT_MAX_PARAMS];
    const double *x = PLANT(m)->x;
    plant_params(m, params);
    V(m, y) = x[0];
    V(m, dy) = x[1];
    V(m, d2y) = motor_arm_acceleration(x[0], x[1], x[2], params);
    V(m, i) = x[2];
    m->outputs_stale = 0;
    return MODEL_OK;
}

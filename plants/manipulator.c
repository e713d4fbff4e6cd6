/* Manipulator: the single-link manipulator with friction and a varying payload,
 * eqs. (38, 39) of Pan, Er, Huang, Wang (IEEE TFS 2011), as a native FMU.  The C twin
 * of manipulator_model.py and manipulator_fmu.py: same equations, same order.
 *
 *   dx1 = x2                                                        (38)
 *   dx2 = -(dr x2 + mr gv lr cos x1) / J + u / J + d                (38)
 *   J   = 1.33 mr lr^2                                              (39)
 *   d   = -(sgn(x2) cr + vr x2) / J      (friction, sgn(0) = 0)      (39)
 *   mr(t) = mr0 + mr1 sin t              (payload)                  (39)
 */
#include <math.h>
#include <stdio.h>

#include "rk4_plant_slave.h"

#define INERTIA_COEFFICIENT 1.33 /* J = 1.33 mr lr^2  (39) */

/* manipulator_params: (gv lr, 1.33 lr^2, dr + vr, cr, mr0, mr1) */
void plant_params(ModelInstance *m, double *params) {
    params[0] = V(m, gv) * V(m, lr);
    params[1] = INERTIA_COEFFICIENT * V(m, lr) * V(m, lr);
    params[2] = V(m, dr) + V(m, vr);
    params[3] = V(m, cr);
    params[4] = V(m, mr0);
    params[5] = V(m, mr1);
}

/* mr(t) = mr0 + mr1 sin t  (39) */
static double manipulator_payload(double t, double mr0, double mr1) { return mr0 + mr1 * sin(t); }

/* J = 1.33 mr lr^2  (39) */
static double manipulator_inertia(double mr, double lr) { return INERTIA_COEFFICIENT * mr * lr * lr; }

/* sgn with sgn(0) = 0 (and sgn(NaN) = 0) */
static double sgn(double x) { return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0); }

/* d = -(sgn(x2) cr + vr x2) / J  (39) */
static double manipulator_friction(double x2, double inertia, double cr, double vr) {
    return -(sgn(x2) * cr + vr * x2) / inertia;
}

/* (dx1, dx2) of eq. (38) with J, d, mr of (39) */
static void manipulator_derivative(double t, const double x[], double u, const double *params, double dx[]) {
    double x1 = x[0], x2 = x[1];
    double gv_lr = params[0], inertia_factor = params[1], dr_plus_vr = params[2], cr = params[3];
    double mr = params[4] + params[5] * sin(t);                  /* (39) */
    double torque = u - dr_plus_vr * x2 - mr * gv_lr * cos(x1);  /* (38), viscous part of d (39) */
    if (x2 > 0.0) /* Coulomb part of d (39), sgn(0) = 0 */
        torque -= cr;
    else if (x2 < 0.0)
        torque += cr;
    dx[0] = x2;
    dx[1] = torque / (inertia_factor * mr); /* J = 1.33 mr lr^2 (39) */
}

const PlantDerivative plant_derivative = manipulator_derivative;

int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    REPRS;
    if (!(V(m, mr1) < V(m, mr0))) {
        snprintf(message, size, "parameter mr1 = %s is invalid; valid range: 0 <= mr1 < mr0 = %s "
                 "(the payload mr(t) = mr0 + mr1 sin t must stay > 0)", R(V(m, mr1)), R(V(m, mr0)));
        return MODEL_ERROR;
    }
    return MODEL_OK;
}

int model_compute_outputs(ModelInstance *m) {
    double mr = manipulator_payload(m->s->time, V(m, mr0), V(m, mr1));
    V(m, y) = PLANT(m)->x[0];
    V(m, dy) = PLANT(m)->x[1];
    V(m, d) = manipulator_friction(PLANT(m)->x[1], manipulator_inertia(mr, V(m, lr)), V(m, cr), V(m, vr));
    V(m, mr) = mr;
    m->outputs_stale = 0;
    return MODEL_OK;
}

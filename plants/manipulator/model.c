/* Manipulator: the single-link manipulator with friction and a varying payload,
 * eqs. (38, 39) of Pan, Er, Huang, Wang (IEEE TFS 2011), as a native FMU.  The C twin
 * of this folder's model.py and fmu.py: same equations, same order.
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

/* co-simulation's step: RK4 with u held, manipulator_derivative inlined into its stages */
void plant_advance(double t, double x[], double u, const Rk4Split *split, const double *params) {
    rk4_advance(manipulator_derivative, t, x, u, split, params);
}

int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    if (!(V(m, mr1) < V(m, mr0))) {
        snprintf(message, size, "parameter mr1 = %.17g is invalid; valid range: 0 <= mr1 < mr0 = %.17g "
                 "(the payload mr(t) = mr0 + mr1 sin t must stay > 0)", V(m, mr1), V(m, mr0));
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

/* ------------------------------------------- model exchange: friction modes (model.py)
 * docs/model_exchange.md: slipping forwards (+1) or backwards (-1), the Coulomb sign is the
 * mode's; stuck (0), static friction balances the applied torque and the link rests. */
#define SLIP_BACKWARD (-1.0)
#define STICK 0.0
#define SLIP_FORWARD 1.0
#define ZERO_VELOCITY 1e-10   /* rad/s: z_slip = mode x2 + ZERO_VELOCITY */
#define TORQUE_TOLERANCE 1e-9 /* N.m: break-away once |F| >= cr - TORQUE_TOLERANCE */

/* F = u - mr(t) gv lr cos x1: the torque on the link at rest besides friction (38, 39) */
static double manipulator_applied_torque(double t, double x1, double u, const double *params) {
    double gv_lr = params[0], mr0 = params[4], mr1 = params[5];
    double mr = mr0 + mr1 * sin(t); /* (39) */
    return u - mr * gv_lr * cos(x1);
}

/* the mode at rest: stuck while |F| < cr, else slipping in the direction of F */
static double manipulator_rest_mode(double force, double cr) {
    if (fabs(force) < cr - TORQUE_TOLERANCE) return STICK;
    return force >= 0.0 ? SLIP_FORWARD : SLIP_BACKWARD;
}

/* a slipping link has not come to rest: z_slip > ZERO_VELOCITY / 2 */
static int manipulator_still_slipping(double x2, double mode) {
    return mode * x2 + ZERO_VELOCITY > 0.5 * ZERO_VELOCITY;
}

/* the friction mode after an event (or at the initial state, from mode = STICK) */
static double manipulator_friction_mode(double t, double x1, double x2, double u, const double *params, double mode) {
    if (mode != STICK) {
        if (manipulator_still_slipping(x2, mode)) return mode;
    } else if (x2 != 0.0) {
        return x2 > 0.0 ? SLIP_FORWARD : SLIP_BACKWARD;
    }
    return manipulator_rest_mode(manipulator_applied_torque(t, x1, u, params), params[3]);
}

/* (mode, x2) after an event: x2 = 0 where a slipping link came to rest */
static double manipulator_event_update(double t, double x1, double *x2, double u, const double *params, double mode) {
    double new_mode = manipulator_friction_mode(t, x1, *x2, u, params, mode);
    if (mode != STICK && !manipulator_still_slipping(*x2, mode)) *x2 = 0.0;
    return new_mode;
}

/* (dx1, dx2) of (38, 39) in a friction mode; stuck: (x2, 0) with x2 = 0 */
static void manipulator_mode_derivative(double t, double x1, double x2, double u, const double *params, double mode,
                                        double dx[]) {
    dx[0] = x2;
    if (mode == STICK) {
        dx[1] = 0.0;
        return;
    }
    double gv_lr = params[0], inertia_factor = params[1], dr_plus_vr = params[2], cr = params[3];
    double mr = params[4] + params[5] * sin(t);                  /* (39) */
    double torque = u - dr_plus_vr * x2 - mr * gv_lr * cos(x1);  /* (38), viscous part of d (39) */
    if (mode > 0.0) /* Coulomb part of d (39) with the mode's sign */
        torque -= cr;
    else
        torque += cr;
    dx[1] = torque / (inertia_factor * mr); /* J = 1.33 mr lr^2 (39) */
}

/* (z_slip, z_stick), both > 0 between events */
static void manipulator_event_indicators(double t, double x1, double x2, double u, const double *params, double mode,
                                         double z[]) {
    double cr = params[3];
    if (mode == STICK) {
        z[0] = ZERO_VELOCITY;
        z[1] = cr - fabs(manipulator_applied_torque(t, x1, u, params));
    } else {
        z[0] = mode * x2 + ZERO_VELOCITY;
        z[1] = cr;
    }
}

double plant_mode_update(ModelInstance *m, const double *params, double mode, double x[], int *states_changed) {
    double x2 = x[1];
    double next = manipulator_event_update(m->s->time, x[0], &x2, V(m, u), params, mode);
    if (x2 != x[1]) {
        x[1] = x2;
        *states_changed = 1;
    }
    return next;
}

void plant_mode_derivative(ModelInstance *m, const double *params, double mode, double dx[]) {
    const double *x = PLANT(m)->x;
    manipulator_mode_derivative(m->s->time, x[0], x[1], V(m, u), params, mode, dx);
}

void plant_mode_event_indicators(ModelInstance *m, const double *params, double mode, double z[]) {
    const double *x = PLANT(m)->x;
    manipulator_event_indicators(m->s->time, x[0], x[1], V(m, u), params, mode, z);
}

/* friction_mode: -1, 0, +1 */
void plant_mode_locals(ModelInstance *m, double mode, double values[]) {
    (void)m;
    values[0] = mode;
}

/* co-simulation integrates (39) with sgn(x2), sgn(0) = 0: the mode of its state */
double plant_cosimulation_mode(ModelInstance *m) { return sgn(PLANT(m)->x[1]); }

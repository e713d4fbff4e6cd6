/* TrackingReference: ym(t) = A sin(omega t), its derivatives and the tracking errors
 * e = ym - y, de = dym - dy as a native FMU (the C twin of this folder's fmu.py).
 * ym, dym, ddym depend on time only; e, de directly on the inputs y, dy. */
#include <math.h>

#include "fmi_layer.h"

const size_t MODEL_INTERNAL_BYTES = 0;

void model_construct(ModelInstance *m) { (void)m; }

int model_initialize(ModelInstance *m, double start_time) {
    (void)m; (void)start_time;
    return MODEL_OK;
}

int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    (void)m; (void)message; (void)size;
    return MODEL_OK;
}

int model_compute_outputs(ModelInstance *m) {
    double amplitude = V(m, amplitude), omega = V(m, omega);
    double phase = omega * m->s->time;
    double s = sin(phase);
    double ym = amplitude * s;
    double dym = amplitude * omega * cos(phase);
    V(m, ym) = ym;
    V(m, dym) = dym;
    V(m, ddym) = -amplitude * omega * omega * s;
    V(m, e) = ym - V(m, y);
    V(m, de) = dym - V(m, dy);
#ifdef VR_d2y /* third-order plants: d2e = ddym - d2y */
    V(m, d2e) = V(m, ddym) - V(m, d2y);
#endif
    m->outputs_stale = 0;
    return MODEL_OK;
}

int model_step(ModelInstance *m, double current_time, double step_size) {
    (void)m; (void)current_time; (void)step_size;
    return MODEL_OK;
}

/* model exchange: no continuous states, no events (ym, dym, ddym are functions of time, e, de
 * of the inputs: the outputs are all there is) */
int model_get_continuous_states(ModelInstance *m, double x[]) {
    (void)m; (void)x;
    return MODEL_OK;
}

int model_set_continuous_states(ModelInstance *m, const double x[]) {
    (void)m; (void)x;
    return MODEL_OK;
}

int model_get_derivatives(ModelInstance *m, double dx[]) {
    (void)m; (void)dx;
    return MODEL_OK;
}

int model_get_event_indicators(ModelInstance *m, double z[]) {
    (void)m; (void)z;
    return MODEL_OK;
}

int model_get_locals(ModelInstance *m, double values[]) {
    (void)m; (void)values;
    return MODEL_OK;
}

int model_update_discrete_states(ModelInstance *m, int *states_changed) {
    (void)m;
    *states_changed = 0;
    return MODEL_OK;
}

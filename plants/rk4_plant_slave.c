/* The FMI hooks common to the RK4 plants: see rk4_plant_slave.py (RK4PlantSlave). */
#include <stdio.h>

#include "rk4_plant_slave.h"

const size_t MODEL_INTERNAL_BYTES = sizeof(PlantState);

int model_initialize(ModelInstance *m, double start_time) {
    (void)start_time;
    for (int s = 0; s < PLANT_STATES; s++) PLANT(m)->x[s] = m->s->values[VRS_x_start[s]];
    return MODEL_OK;
}

void model_construct(ModelInstance *m) { model_initialize(m, m->s->start_time); }

int model_step(ModelInstance *m, double current_time, double step_size) {
    REPRS;
    double params[PLANT_MAX_PARAMS];
    PlantState *state = PLANT(m);
    double x[PLANT_STATES];
    int finite = 1;
    for (int s = 0; s < PLANT_STATES; s++) x[s] = state->x[s];
    plant_params(m, params);
    rk4_advance_states(plant_derivative, current_time, x, PLANT_STATES, V(m, u), step_size,
                       V(m, max_internal_step), params);
    for (int s = 0; s < PLANT_STATES; s++) finite = finite && x[s] - x[s] == 0.0; /* not NaN or inf */
    if (!finite) {
        char start[512];
        size_t used = 0;
        for (int s = 0; s < PLANT_STATES && used < sizeof start; s++)
            used += (size_t)snprintf(start + used, sizeof start - used, "%sx%d=%s", s ? ", " : "", s + 1,
                                     R(state->x[s]));
        return fmu_fail(m, "state diverged in doStep(t=%s, h=%s) from %s with u=%s; "
                        "the closed loop is unstable at this step size",
                        R(current_time), R(step_size), start, R(V(m, u)));
    }
    for (int s = 0; s < PLANT_STATES; s++) state->x[s] = x[s];
    return MODEL_OK;
}

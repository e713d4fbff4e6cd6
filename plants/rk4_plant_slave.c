/* The FMI hooks common to the RK4 plants: see rk4_plant_slave.py (RK4PlantSlave). */
#include "rk4_plant_slave.h"

const size_t MODEL_INTERNAL_BYTES = sizeof(PlantState);

int model_initialize(ModelInstance *m, double start_time) {
    (void)start_time;
    PLANT(m)->x1 = V(m, x1_start);
    PLANT(m)->x2 = V(m, x2_start);
    return MODEL_OK;
}

void model_construct(ModelInstance *m) { model_initialize(m, m->s->start_time); }

int model_step(ModelInstance *m, double current_time, double step_size) {
    REPRS;
    double params[PLANT_MAX_PARAMS];
    PlantState *state = PLANT(m);
    double x1 = state->x1, x2 = state->x2;
    plant_params(m, params);
    rk4_advance(plant_derivative, current_time, &x1, &x2, V(m, u), step_size, V(m, max_internal_step), params);
    if (x1 - x1 != 0.0 || x2 - x2 != 0.0) /* NaN or inf */
        return fmu_fail(m, "state diverged in doStep(t=%s, h=%s) from x1=%s, x2=%s with u=%s; "
                        "the closed loop is unstable at this step size",
                        R(current_time), R(step_size), R(state->x1), R(state->x2), R(V(m, u)));
    state->x1 = x1;
    state->x2 = x2;
    return MODEL_OK;
}

/* The FMI hooks common to the RK4 plants: see rk4_plant_slave.py (RK4PlantSlave). */
#include <stdio.h>

#include "rk4_plant_slave.h"

const size_t MODEL_INTERNAL_BYTES = sizeof(PlantState);

#if N_STATES != PLANT_STATES
#error "the declaration's model exchange states must be the plant's x1 .. xn"
#endif
#define PLANT_HAS_EVENTS (N_EVENT_INDICATORS > 0)

int model_initialize(ModelInstance *m, double start_time) {
    (void)start_time;
    PlantState *state = PLANT(m);
    for (int s = 0; s < PLANT_STATES; s++) state->x[s] = m->s->values[VRS_x_start[s]];
    state->mode = 0.0;
    plant_params(m, state->params);
    state->split = rk4_split(0.0, V(m, max_internal_step));
#if PLANT_HAS_EVENTS /* the mode of the initial state (model exchange; co-simulation has none) */
    int changed = 0;
    state->mode = plant_mode_update(m, state->params, 0.0, state->x, &changed);
#endif
    return MODEL_OK;
}

void model_construct(ModelInstance *m) { model_initialize(m, m->s->start_time); }

int model_step(ModelInstance *m, double current_time, double step_size) {
    PlantState *state = PLANT(m);
    double x[PLANT_STATES];
    for (int s = 0; s < PLANT_STATES; s++) x[s] = state->x[s];
    /* max_internal_step is a parameter, fixed from initialisation on (a restored FMU state brings its split) */
    if (state->split.step_size != step_size) state->split = rk4_split(step_size, V(m, max_internal_step));
    plant_advance(current_time, x, V(m, u), &state->split, state->params);
    double spread = 0.0; /* x - x is 0 for a finite x, NaN for NaN or inf: their sum 0 for finite states alone */
    for (int s = 0; s < PLANT_STATES; s++) spread += x[s] - x[s];
    if (!(spread == 0.0)) {
        char start[512];
        size_t used = 0;
        for (int s = 0; s < PLANT_STATES && used < sizeof start; s++)
            used += (size_t)snprintf(start + used, sizeof start - used, "%sx%d=%.17g", s ? ", " : "", s + 1,
                                     state->x[s]);
        return fmu_fail(m, "state diverged in doStep(t=%.17g, h=%.17g) from %s with u=%.17g; "
                        "the closed loop is unstable at this step size",
                        current_time, step_size, start, V(m, u));
    }
    for (int s = 0; s < PLANT_STATES; s++) state->x[s] = x[s];
    return MODEL_OK;
}

/* ---------------------------------------------------------------- model exchange */

int model_get_continuous_states(ModelInstance *m, double x[]) {
    for (int s = 0; s < PLANT_STATES; s++) x[s] = PLANT(m)->x[s];
    return MODEL_OK;
}

int model_set_continuous_states(ModelInstance *m, const double x[]) {
    for (int s = 0; s < PLANT_STATES; s++) PLANT(m)->x[s] = x[s];
    return MODEL_OK;
}

/* dx = plant_derivative(t, x, u) (model exchange; co-simulation integrates the same function);
 * a plant with events: the derivative of its current mode */
int model_get_derivatives(ModelInstance *m, double dx[]) {
    double params[PLANT_MAX_PARAMS];
    plant_params(m, params);
#if PLANT_HAS_EVENTS
    if (m->model_exchange) {
        plant_mode_derivative(m, params, PLANT(m)->mode, dx);
        return MODEL_OK;
    }
#endif
    plant_derivative(m->s->time, PLANT(m)->x, V(m, u), params, dx);
    return MODEL_OK;
}

/* the mode the event indicators and locals describe: the discrete state in model exchange; in
 * co-simulation, the mode its state is in (it integrates without events) */
#if PLANT_HAS_EVENTS
static double current_mode(ModelInstance *m) {
    return m->model_exchange ? PLANT(m)->mode : plant_cosimulation_mode(m);
}
#endif

int model_get_event_indicators(ModelInstance *m, double z[]) {
#if PLANT_HAS_EVENTS
    double params[PLANT_MAX_PARAMS];
    plant_params(m, params);
    plant_mode_event_indicators(m, params, current_mode(m), z);
#else
    (void)m; (void)z;
#endif
    return MODEL_OK;
}

int model_get_locals(ModelInstance *m, double values[]) {
#if PLANT_HAS_EVENTS
    plant_mode_locals(m, current_mode(m), values);
#else
    (void)m; (void)values;
#endif
    return MODEL_OK;
}

int model_update_discrete_states(ModelInstance *m, int *states_changed) {
    *states_changed = 0;
#if PLANT_HAS_EVENTS
    double params[PLANT_MAX_PARAMS];
    plant_params(m, params);
    PLANT(m)->mode = plant_mode_update(m, params, PLANT(m)->mode, PLANT(m)->x, states_changed);
#else
    (void)m;
#endif
    return MODEL_OK;
}

/* Shared part of the plant FMUs (rk4_plant_slave.py): a model integrated by fixed-step RK4
 * inside doStep (co-simulation), or by the host's solver (model exchange: the states x, their
 * derivatives plant_derivative).  A plant file defines the hooks below plus
 * model_compute_outputs and model_cross_parameter_errors; a plant whose equations switch
 * (N_EVENT_INDICATORS > 0 in its declaration) defines the plant_mode_* hooks too. */
#ifndef AFC_RK4_PLANT_SLAVE_H
#define AFC_RK4_PLANT_SLAVE_H

#include "fmi_layer.h"
#include "plant_integration.h"

#define PLANT_MAX_PARAMS 8

/* the number of states: one x<k>_start parameter per state (x1, x2 for the paper's plants) */
#define PLANT_STATES N_x_start

/* the internal state (STATE_ATTRIBUTES = x1, x2, ...), for a plant with events its discrete mode in
 * model exchange (docs/model_exchange.md; 0 for the smooth plants), and the constants of
 * plant_derivative computed when initialisation ends (rk4_plant_slave.py's _params: a restored FMU
 * state brings the constants of its own parameters) */
typedef struct {
    double x[PLANT_STATES];
    double mode;
    double params[PLANT_MAX_PARAMS];
    Rk4Split split; /* the RK4 split of the last doStep's step size */
} PlantState;

#define PLANT(m) ((PlantState *)(m)->internal)

/* provided by each plant */
extern const PlantDerivative plant_derivative;
/* the constants of plant_derivative from the current parameters (model_params) */
void plant_params(ModelInstance *m, double *params);
/* x over the split's communication step with u held (RK4PlantSlave.step): rk4_advance (2 states) or
 * rk4_advance_states of plant_integration.h called with the plant's own derivative, which the compiler
 * inlines there */
void plant_advance(double t, double x[], double u, const Rk4Split *split, const double *params);

/* a plant with events (model exchange): the mode that follows the state at time t (from
 * mode = 0 at the initial state), whether it resets states (*states_changed), the
 * derivative in a mode, the event indicators and locals in a mode */
double plant_mode_update(ModelInstance *m, const double *params, double mode, double x[], int *states_changed);
void plant_mode_derivative(ModelInstance *m, const double *params, double mode, double dx[]);
void plant_mode_event_indicators(ModelInstance *m, const double *params, double mode, double z[]);
void plant_mode_locals(ModelInstance *m, double mode, double values[]);
/* the mode a co-simulation instance (no events, sgn(x2)) is in at its state */
double plant_cosimulation_mode(ModelInstance *m);

#endif

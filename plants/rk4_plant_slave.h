/* Shared part of the plant FMUs (rk4_plant_slave.py): a 2-state model integrated by
 * fixed-step RK4 inside doStep.  A plant file defines the three hooks below plus
 * model_compute_outputs and model_cross_parameter_errors. */
#ifndef AFC_RK4_PLANT_SLAVE_H
#define AFC_RK4_PLANT_SLAVE_H

#include "fmi_layer.h"
#include "plant_integration.h"

#define PLANT_MAX_PARAMS 8

/* the number of states: one x<k>_start parameter per state (x1, x2 for the paper's plants) */
#define PLANT_STATES N_x_start

/* the internal state (STATE_ATTRIBUTES = x1, x2, ...) */
typedef struct {
    double x[PLANT_STATES];
} PlantState;

#define PLANT(m) ((PlantState *)(m)->internal)

/* provided by each plant */
extern const PlantDerivative plant_derivative;
/* the constants of plant_derivative from the current parameters (model_params) */
void plant_params(ModelInstance *m, double *params);

#endif

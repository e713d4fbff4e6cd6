/* Fixed-step classical Runge-Kutta (RK4) integration of a 2-state plant: the C twin of
 * plant_integration.py, with the same arithmetic in the same order, so that the native
 * plants reproduce the Python ones to the last bit where the libm agrees. */
#ifndef AFC_PLANT_INTEGRATION_H
#define AFC_PLANT_INTEGRATION_H

/* relative slack when splitting a communication step into internal steps (SPLIT_TOLERANCE) */
#define SPLIT_TOLERANCE 1e-12

#define PLANT_MAX_STATES 8

/* dx of the model at (t, x) with input u; params: the model's constants */
typedef void (*PlantDerivative)(double t, const double x[], double u, const double *params, double dx[]);

/* n = ceil(step_size / max_internal_step - 1e-12), at least 1 (0 for step_size 0) */
long internal_step_count(double step_size, double max_internal_step);

/* advance the states x[0..states-1] from t to t + step_size with u held, in n equal RK4 steps
 * (rk4_advance_states; with two states the same numbers as rk4_advance, bit for bit) */
void rk4_advance_states(PlantDerivative derivative, double t, double x[], int states, double u,
                        double step_size, double max_internal_step, const double *params);

#endif

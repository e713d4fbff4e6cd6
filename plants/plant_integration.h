/* Fixed-step classical Runge-Kutta (RK4) integration of a plant: the C twin of plant_integration.py,
 * with the same arithmetic in the same order, so that the native plants reproduce the Python ones to
 * the last bit where the libm agrees.
 *
 * plant_integration.py      C twin
 * internal_step_count       internal_step_count  (plant_integration.c)
 * rk4_advance               rk4_split + rk4_advance          (here: the lean 2-state path)
 * rk4_advance_states        rk4_split + rk4_advance_states   (here: any number of states)
 *
 * The two advances are static inline: a plant file that calls one with its own derivative (its
 * plant_advance, rk4_plant_slave.h) gets the derivative inlined into the RK4 stages, with no call
 * through a pointer on the per-step path. */
#ifndef AFC_PLANT_INTEGRATION_H
#define AFC_PLANT_INTEGRATION_H

/* relative slack when splitting a communication step into internal steps (SPLIT_TOLERANCE) */
#define SPLIT_TOLERANCE 1e-12

#define PLANT_MAX_STATES 8

/* inlined at every call, also where a plant calls it twice (its plant_advance, once per set of constants) */
#if defined(__GNUC__)
#define PLANT_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define PLANT_ALWAYS_INLINE inline
#endif

/* dx of the model at (t, x) with input u; params: the model's constants */
typedef void (*PlantDerivative)(double t, const double x[], double u, const double *params, double dx[]);

/* n = ceil(step_size / max_internal_step - 1e-12), at least 1 (0 for step_size 0) */
long internal_step_count(double step_size, double max_internal_step);

/* The split of a communication step into n equal RK4 steps: n = internal_step_count(step_size,
 * max_internal_step), h = step_size / n, h / 2, h / 6 (the first lines of plant_integration.py's
 * rk4_advance and rk4_advance_states, the same arithmetic).  A plant keeps the split of its step size:
 * a master's communication step is the same at every doStep, and the divisions stay off the per-step path. */
typedef struct {
    double step_size; /* what the split was made for (max_internal_step is a parameter: fixed for a run) */
    long n;
    double h, half, sixth;
} Rk4Split;

static inline Rk4Split rk4_split(double step_size, double max_internal_step) {
    Rk4Split split = {step_size, internal_step_count(step_size, max_internal_step), 0.0, 0.0, 0.0};
    if (split.n == 0) return split;
    split.h = step_size / (double)split.n;
    split.half = 0.5 * split.h;
    split.sixth = split.h / 6.0;
    return split;
}

/* advance (x[0], x[1]) from t to t + step_size with u held, in the split's n equal RK4 steps h that start
 * at t + i h (not at an accumulated sum) */
static PLANT_ALWAYS_INLINE void rk4_advance(PlantDerivative derivative, double t, double x[2], double u, const Rk4Split *split,
                               const double *params) {
    long n = split->n;
    double h = split->h, half = split->half, sixth = split->sixth;
    double x1 = x[0], x2 = x[1];
    for (long i = 0; i < n; i++) {
        double ti = t + (double)i * h;
        double tm = ti + half;
        double stage[2] = {x1, x2}, a[2], b[2], c[2], d[2];
        derivative(ti, stage, u, params, a);
        stage[0] = x1 + half * a[0], stage[1] = x2 + half * a[1];
        derivative(tm, stage, u, params, b);
        stage[0] = x1 + half * b[0], stage[1] = x2 + half * b[1];
        derivative(tm, stage, u, params, c);
        stage[0] = x1 + h * c[0], stage[1] = x2 + h * c[1];
        derivative(ti + h, stage, u, params, d);
        x1 = x1 + sixth * (a[0] + 2.0 * (b[0] + c[0]) + d[0]);
        x2 = x2 + sixth * (a[1] + 2.0 * (b[1] + c[1]) + d[1]);
    }
    x[0] = x1, x[1] = x2;
}

/* advance the states x[0..states-1] like rk4_advance (with two states the same numbers, bit for bit) */
static inline void rk4_advance_states(PlantDerivative derivative, double t, double x[], int states, double u,
                                      const Rk4Split *split, const double *params) {
    long n = split->n;
    double h = split->h, half = split->half, sixth = split->sixth;
    double k1[PLANT_MAX_STATES], k2[PLANT_MAX_STATES], k3[PLANT_MAX_STATES], k4[PLANT_MAX_STATES];
    double stage[PLANT_MAX_STATES];
    for (long i = 0; i < n; i++) {
        double ti = t + (double)i * h; /* the grid point, not an accumulated sum */
        double tm = ti + half;
        derivative(ti, x, u, params, k1);
        for (int s = 0; s < states; s++) stage[s] = x[s] + half * k1[s];
        derivative(tm, stage, u, params, k2);
        for (int s = 0; s < states; s++) stage[s] = x[s] + half * k2[s];
        derivative(tm, stage, u, params, k3);
        for (int s = 0; s < states; s++) stage[s] = x[s] + h * k3[s];
        derivative(ti + h, stage, u, params, k4);
        for (int s = 0; s < states; s++) x[s] = x[s] + sixth * (k1[s] + 2.0 * (k2[s] + k3[s]) + k4[s]);
    }
}

#endif

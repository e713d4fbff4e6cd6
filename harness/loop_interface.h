/*
 * The interface of the masters' compiled loops (harness/master_loop.c, harness/me_loop.c) with
 * the Python masters, written once: the structs Python fills and reads (their ctypes mirrors are
 * harness/loop_interface.py; tests/test_loop_interface.py holds the two layouts equal), the codes
 * of what stopped a loop, and the steps both loops take the same way (one pass of the plan, the
 * record of a row, the divergence check of a block of rows).
 *
 * Every function here is static inline: each loop gets its own copy, and the per-step path makes
 * no call that the loop did not make before the helpers were shared.
 */
#ifndef AFC_LOOP_INTERFACE_H
#define AFC_LOOP_INTERFACE_H

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#if defined(_WIN32)
#define EXPORT __declspec(dllexport)
#else
#define EXPORT __attribute__((visibility("default")))
#endif

#define STATUS_WARNING 1 /* fmi2Warning = fmi3Warning: a status above it stops the loop */

/* getReal / setReal (FMI 2.0) and GetFloat64 / SetFloat64 (FMI 3.0); a setter takes const values,
 * the same pointer type serves both directions */
typedef int (*Fmi2ArrayCall)(void *instance, const unsigned *references, size_t count, double *values);
typedef int (*Fmi3ArrayCall)(void *instance, const unsigned *references, size_t count, double *values,
                             size_t value_count);

enum { ACTION_READ = 0, ACTION_WRITE = 1 };

/* One read or write of the master's plan (harness/master.py's _Read and _Write), pointing into the
 * Python plan's own value-reference and value arrays. */
typedef struct {
    int32_t kind;              /* ACTION_READ or ACTION_WRITE */
    int32_t fmi_version;       /* 2 or 3 */
    void *instance;
    void *call;                /* fmi2GetReal / fmi3GetFloat64, or fmi2SetReal / fmi3SetFloat64 */
    const unsigned *references;
    size_t count;
    double *values;            /* the Python plan's own value array */
    /* read: the recorded outputs come first in values */
    size_t first_column;
    size_t recorded;
    /* write: values[k] = sources[k][source_index[k]] for k < count, checked against bounds[k] */
    double *const *sources;
    const size_t *source_index;
    const double *bounds;
} Action;

/* co-simulation (master_loop.c): one FMU's doStep */
typedef struct {
    int32_t fmi_version;
    void *instance;
    void *do_step;             /* fmi2DoStep / fmi3DoStep */
} Stepper;

/* Model Exchange (me_loop.c): one FMU's SetTime */
typedef struct {
    void *instance;
    void *set_time;
} Timer;

/* Model Exchange: one FMU's states and event indicators, bound to slices of the shared x, dx, z */
typedef struct {
    void *instance;
    void *set_states;
    void *get_derivatives;
    void *get_indicators;
    size_t offset;             /* of its states in x, dx */
    size_t states;
    size_t indicator_offset;   /* of its indicators in z */
    size_t indicators;
} Block;

/* What stopped a loop, or what failed inside a Model Exchange evaluation (the Outcome's `outcome`).
 * `index` is the plan's action for the plan's codes, the stepper, timer or block for the others. */
enum {
    LOOP_DONE = 0,               /* the rows of the block were run (recorded) */
    LOOP_READ_FAILED = 1,        /* getReal of action `index` returned `status` */
    LOOP_WRITE_DIVERGED = 2,     /* copy `copy` of action `index` was beyond its bound (`value`) */
    LOOP_WRITE_FAILED = 3,       /* setReal of action `index` returned `status` */
    LOOP_RECORD_DIVERGED = 4,    /* a recorded value of the block ending at row `row` is beyond its bound */
    LOOP_STEP_FAILED = 5,        /* doStep of stepper `index` returned `status` */
    LOOP_SET_TIME_FAILED = 6,    /* SetTime of timer `index` returned `status` */
    LOOP_SET_STATES_FAILED = 7,  /* SetContinuousStates of block `index` */
    LOOP_DERIVATIVES_FAILED = 8, /* GetDerivatives of block `index` */
    LOOP_INDICATORS_FAILED = 9,  /* GetEventIndicators of block `index` */
    LOOP_SOLVER_FAILED = 10,     /* CVode (or CVodeGetDky) returned `status` < 0 */
    LOOP_EVENT = 11,             /* a step ended at `time` with an event for the master (`status`: CVode's flag) */
    LOOP_OUT_OF_MEMORY = 12,     /* the loop could not allocate its working memory (nothing was run) */
};

typedef struct {
    int32_t outcome;           /* a LOOP_ code */
    int32_t status;
    int64_t row;
    int64_t index;
    int64_t copy;
    double value;
    double time;               /* Model Exchange: the time of the failure or of the step's end */
} Outcome;

/* The Model Exchange loop's state: what me_loop.py prepares, CVODE's memory and functions. */
typedef void *N_Vector;
typedef struct {
    const Action *plan;
    size_t actions;
    const Timer *timers;
    size_t timer_count;
    const Block *blocks;
    size_t block_count;
    double *x;
    double *dx;
    double *z;
    size_t states;             /* length of x and dx (at least 1) */
    size_t indicators;         /* length of z */
    void *cvode_memory;
    N_Vector y;
    N_Vector interpolated;
    void *cvode;
    void *get_dky;
    void *get_array_pointer;
    void *get_last_order;
    void *get_current_time;
    double *taylor;            /* (cvode.MAX_ORDER + 1) x states: the last step's interpolant, y^(k)(tn) / k! */
    double *record;
    size_t columns;
    const double *column_bounds;
    int64_t check_every;
    int64_t rows;
    double start;
    double step;
    Outcome failure;           /* the last evaluation's failure (cleared before each step) */
    int64_t evaluations;
} MeLoop;

/* the action's getReal or setReal on its own arrays */
static inline int action_call(const Action *a) {
    if (a->fmi_version == 3)
        return ((Fmi3ArrayCall)a->call)(a->instance, a->references, a->count, a->values, a->count);
    return ((Fmi2ArrayCall)a->call)(a->instance, a->references, a->count, a->values);
}

/* `what` at `index` with `status` in the outcome; returns `what` */
static inline int loop_stop(Outcome *outcome, int32_t what, int64_t index, int32_t status) {
    outcome->outcome = what;
    outcome->index = index;
    outcome->status = status;
    return what;
}

/* One pass of the plan (Master._propagate): each read, and each write after every value it copies is
 * checked against its bound, !(-bound < value < bound) also for NaN (tested as !(|value| < bound), the
 * same for every bound), so no FMU is handed a runaway input.  LOOP_DONE, or what stopped it (outcome,
 * index, status; copy and value for a divergence). */
static inline int run_plan(const Action *plan, size_t actions, Outcome *outcome) {
    for (size_t i = 0; i < actions; i++) {
        const Action *a = &plan[i];
        if (a->kind == ACTION_READ) {
            int status = action_call(a);
            if (status > STATUS_WARNING) return loop_stop(outcome, LOOP_READ_FAILED, (int64_t)i, status);
            continue;
        }
        for (size_t k = 0; k < a->count; k++) {
            double value = a->sources[k][a->source_index[k]];
            if (!(fabs(value) < a->bounds[k])) {
                outcome->copy = (int64_t)k;
                outcome->value = value;
                return loop_stop(outcome, LOOP_WRITE_DIVERGED, (int64_t)i, 0);
            }
            a->values[k] = value;
        }
        int status = action_call(a);
        if (status > STATUS_WARNING) return loop_stop(outcome, LOOP_WRITE_FAILED, (int64_t)i, status);
    }
    return LOOP_DONE;
}

/* the plan's recorded reads into one row of the record */
static inline void record_reads(const Action *plan, size_t actions, double *row) {
    for (size_t i = 0; i < actions; i++) {
        const Action *a = &plan[i];
        if (a->kind == ACTION_READ && a->recorded)
            memcpy(row + a->first_column, a->values, a->recorded * sizeof(double));
    }
}

/* Master._check_bound's test on rows [first, last): is every recorded value below its bound
 * (!(|v| < bound) also for NaN)? */
static inline int record_within_bounds(const double *record, size_t columns, const double *bounds, int64_t first,
                                       int64_t last) {
    for (int64_t row = first; row < last; row++) {
        const double *values = record + (size_t)row * columns;
        for (size_t c = 0; c < columns; c++)
            if (!(fabs(values[c]) < bounds[c])) return 0;
    }
    return 1;
}

#endif /* AFC_LOOP_INTERFACE_H */

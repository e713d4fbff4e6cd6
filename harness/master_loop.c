/*
 * The master's fixed-step loop in C: the same FMI calls, in the same order, with the same
 * checks as the per-step path of harness/master.py (Master._propagate and the loop of
 * Master.run), for a block of communication points, with no Python between the calls.
 *
 * harness/master_loop.py prepares the plan once (the very value-reference and value arrays
 * of the Python plan) and calls master_loop_run for blocks of rows; whenever something
 * stops the loop (an FMI status >= error, a value beyond its divergence bound) it returns
 * what happened and where, and the Python master raises the same exception as its own
 * loop would, from the same state.  It is a speed-up, not a second master: no decision is
 * taken here that the Python loop does not take, and tests/test_master_loop.py holds the
 * two bit-identical, including their failures.
 *
 * Row n (n = first_row .. last_row - 1) of the Python loop:
 *   t = start + n * step
 *   for each action of the plan, in order:
 *       read:  status = getReal(instance, references, count, values)       stop if status > warning
 *       write: for each copy k: value = source[j];
 *                  stop if !(-bound < value < bound)  (also for NaN)
 *                  values[k] = value
 *              status = setReal(instance, references, count, values)       stop if status > warning
 *   record[n, first .. first + recorded) = the read values
 *   if (n + 1) % check_every == 0: stop if a recorded value of the last check_every rows
 *       is not below its bound in magnitude (!(|v| < bound), NaN too)
 *   for each FMU: status = doStep(instance, t, step, noSetFMUStatePriorToCurrentPoint = true)
 *       stop if status > warning
 *
 * Built for the machine that runs the harness (c_toolchain.host_library), with the
 * native edition's flags (-ffp-contract=off: t is computed exactly as Python computes it).
 */
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

#define STATUS_WARNING 1

/* the FMI calls the loop makes: FMI 2.0 and FMI 3.0 signatures */
typedef int (*Fmi2ArrayCall)(void *instance, const unsigned *references, size_t count, double *values);
typedef int (*Fmi3ArrayCall)(void *instance, const unsigned *references, size_t count, double *values,
                             size_t value_count);
typedef int (*Fmi2DoStep)(void *instance, double time, double step, int no_prior_state);
typedef int (*Fmi3DoStep)(void *instance, double time, double step, bool no_prior_state, bool *event_needed,
                          bool *terminate, bool *early_return, double *last_successful_time);

enum { ACTION_READ = 0, ACTION_WRITE = 1 };

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

typedef struct {
    int32_t fmi_version;
    void *instance;
    void *do_step;
} Stepper;

/* what stopped the loop */
enum {
    LOOP_DONE = 0,            /* every row of the block was run */
    LOOP_READ_FAILED = 1,     /* getReal of `action` returned `status` at row `row` */
    LOOP_WRITE_DIVERGED = 2,  /* copy `copy` of `action` was beyond its bound (`value`) at row `row` */
    LOOP_WRITE_FAILED = 3,    /* setReal of `action` returned `status` */
    LOOP_RECORD_DIVERGED = 4, /* a recorded value of the block ending at row `row` is beyond its bound */
    LOOP_STEP_FAILED = 5,     /* doStep of stepper `action` returned `status` */
};

typedef struct {
    int32_t outcome;
    int32_t status;
    int64_t row;
    int64_t action;
    int64_t copy;
    double value;
} Outcome;

static int read_values(const Action *a) {
    if (a->fmi_version == 3)
        return ((Fmi3ArrayCall)a->call)(a->instance, a->references, a->count, a->values, a->count);
    return ((Fmi2ArrayCall)a->call)(a->instance, a->references, a->count, a->values);
}

/* setReal takes const values; the same function pointer type serves both directions */
static int write_values(const Action *a) { return read_values(a); }

static int do_step(const Stepper *s, double time, double step) {
    if (s->fmi_version == 3) {
        bool event_needed = false, terminate = false, early_return = false;
        double last_successful_time = 0.0;
        return ((Fmi3DoStep)s->do_step)(s->instance, time, step, true, &event_needed, &terminate, &early_return,
                                        &last_successful_time);
    }
    return ((Fmi2DoStep)s->do_step)(s->instance, time, step, 1);
}

static int stop(Outcome *outcome, int32_t what, int64_t row, int64_t action, int32_t status) {
    outcome->outcome = what;
    outcome->row = row;
    outcome->action = action;
    outcome->status = status;
    return what;
}

/* Master._check_bound's test on rows [first, last): is every recorded value below its bound? */
static int record_within_bounds(const double *record, size_t columns, const double *bounds, int64_t first,
                                int64_t last) {
    for (int64_t row = first; row < last; row++) {
        const double *values = record + (size_t)row * columns;
        for (size_t c = 0; c < columns; c++)
            if (!(fabs(values[c]) < bounds[c])) return 0;
    }
    return 1;
}

EXPORT int master_loop_run(const Action *plan, size_t actions, const Stepper *steppers, size_t stepper_count,
                           double start, double step, int64_t first_row, int64_t last_row, double *record,
                           size_t columns, const double *column_bounds, int64_t check_every, Outcome *outcome) {
    memset(outcome, 0, sizeof *outcome);
    for (int64_t n = first_row; n < last_row; n++) {
        double t = start + (double)n * step;
        double *row = record + (size_t)n * columns;
        for (size_t i = 0; i < actions; i++) {
            const Action *a = &plan[i];
            if (a->kind == ACTION_READ) {
                int status = read_values(a);
                if (status > STATUS_WARNING) return stop(outcome, LOOP_READ_FAILED, n, (int64_t)i, status);
                continue;
            }
            for (size_t k = 0; k < a->count; k++) {
                double value = a->sources[k][a->source_index[k]];
                double bound = a->bounds[k];
                if (!(-bound < value && value < bound)) {
                    outcome->copy = (int64_t)k;
                    outcome->value = value;
                    return stop(outcome, LOOP_WRITE_DIVERGED, n, (int64_t)i, 0);
                }
                a->values[k] = value;
            }
            int status = write_values(a);
            if (status > STATUS_WARNING) return stop(outcome, LOOP_WRITE_FAILED, n, (int64_t)i, status);
        }
        for (size_t i = 0; i < actions; i++) {
            const Action *a = &plan[i];
            if (a->kind == ACTION_READ && a->recorded)
                memcpy(row + a->first_column, a->values, a->recorded * sizeof(double));
        }
        if ((n + 1) % check_every == 0 &&
            !record_within_bounds(record, columns, column_bounds, n + 1 - check_every, n + 1))
            return stop(outcome, LOOP_RECORD_DIVERGED, n, -1, 0);
        for (size_t s = 0; s < stepper_count; s++) {
            int status = do_step(&steppers[s], t, step);
            if (status > STATUS_WARNING) return stop(outcome, LOOP_STEP_FAILED, n, (int64_t)s, status);
        }
    }
    return LOOP_DONE;
}

/*
 * The Model Exchange master's integration loop in C: the same FMI calls, in the same order, with
 * the same checks as the Python loop of harness/me_master.py (ModelExchangeMaster._python_evaluate,
 * _record_row, _integrate_python), with no Python between CVODE's steps.
 *
 * harness/me_loop.py prepares the loop once: the master's plan (the very value-reference and
 * value arrays of the Python plan: the Action layout of harness/master_loop.c), SetTime of every
 * FMU, the state blocks (SetContinuousStates / GetDerivatives / GetEventIndicators bound to
 * slices of the shared arrays x, dx, z), CVODE's memory and three of its functions.  CVODE calls
 * me_rhs and me_roots (their addresses go to CVodeInit and CVodeRootInit, this struct as user
 * data); me_loop_run takes CVODE's steps and records the output grid until a block of rows is
 * done, an event needs the master (a root, a time event, a step end an FMU asked to see) or
 * something failed; the Python master handles events and raises what its Python loop raises.
 *
 * One derivative evaluation at (t, y):
 *   x = y;  SetTime(t) on every FMU;  SetContinuousStates on every block with states;
 *   the plan: read outputs / write inputs (a write beyond its bound: recoverable, return 1);
 *   GetDerivatives of every block into dx;  ydot = dx;  return 1 if a derivative is not finite.
 * The root function does the same with GetEventIndicators into z, gout = z.
 * An FMU status > warning: remembered, return -1 (CVODE stops; the master raises the FmiError).
 *
 * Built for the machine that runs the harness (c_toolchain.host_library), -ffp-contract=off.
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
#define CV_ONE_STEP 2
#define CV_ROOT_RETURN 2

typedef int (*Fmi2ArrayCall)(void *instance, const unsigned *references, size_t count, double *values);
typedef int (*Fmi3ArrayCall)(void *instance, const unsigned *references, size_t count, double *values,
                             size_t value_count);
typedef int (*SetTimeCall)(void *instance, double time);
typedef int (*VectorCall)(void *instance, double *values, size_t count); /* states, derivatives, indicators */

typedef void *N_Vector;
typedef int (*CVodeCall)(void *memory, double tout, N_Vector yout, double *tret, int itask);
typedef int (*CVodeGetDkyCall)(void *memory, double t, int k, N_Vector dky);
typedef double *(*GetArrayPointerCall)(N_Vector vector);
typedef int (*CVodeGetLastOrderCall)(void *memory, int *order);
typedef int (*CVodeGetCurrentTimeCall)(void *memory, double *time);

#define MAX_ORDER 5 /* BDF's highest order */

enum { ACTION_READ = 0, ACTION_WRITE = 1 };

/* harness/master_loop.c's Action, field for field (harness/master_loop.py's ctypes Action) */
typedef struct {
    int32_t kind;
    int32_t fmi_version;
    void *instance;
    void *call;
    const unsigned *references;
    size_t count;
    double *values;
    size_t first_column;
    size_t recorded;
    double *const *sources;
    const size_t *source_index;
    const double *bounds;
} Action;

typedef struct {
    void *instance;
    void *set_time;
} Timer;

typedef struct {
    void *instance;
    void *set_states;
    void *get_derivatives;
    void *get_indicators;
    size_t offset;           /* of its states in x, dx */
    size_t states;
    size_t indicator_offset; /* of its indicators in z */
    size_t indicators;
} Block;

/* what stopped me_loop_run, or what failed inside an evaluation */
enum {
    LOOP_DONE = 0,             /* the rows of the block were recorded */
    LOOP_READ_FAILED = 1,      /* getReal of action `index` returned `status` */
    LOOP_WRITE_DIVERGED = 2,   /* copy `copy` of action `index` was beyond its bound (`value`) */
    LOOP_WRITE_FAILED = 3,     /* setReal of action `index` returned `status` */
    LOOP_RECORD_DIVERGED = 4,  /* a recorded value of the rows ending at `row` is beyond its bound */
    LOOP_SET_TIME_FAILED = 5,  /* SetTime of timer `index` returned `status` */
    LOOP_SET_STATES_FAILED = 6,/* SetContinuousStates of block `index` */
    LOOP_DERIVATIVES_FAILED = 7,  /* GetDerivatives of block `index` */
    LOOP_INDICATORS_FAILED = 8,   /* GetEventIndicators of block `index` */
    LOOP_SOLVER_FAILED = 9,    /* CVode (or CVodeGetDky) returned `status` < 0 */
    LOOP_EVENT = 10,           /* a step ended at `time` with an event for the master (`status`: CVode's flag) */
};

typedef struct {
    int32_t outcome;
    int32_t status;
    int64_t row;
    int64_t index;
    int64_t copy;
    double value;
    double time;
} Outcome;

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
    size_t states;      /* length of x and dx (at least 1) */
    size_t indicators;  /* length of z */
    void *cvode_memory;
    N_Vector y;
    N_Vector interpolated;
    void *cvode;
    void *get_dky;
    void *get_array_pointer;
    void *get_last_order;
    void *get_current_time;
    double *taylor;     /* (MAX_ORDER + 1) x states: the last step's interpolant, y^(k)(tn) / k! */
    double *record;
    size_t columns;
    const double *column_bounds;
    int64_t check_every;
    int64_t rows;
    double start;
    double step;
    Outcome failure;    /* the last evaluation's failure (cleared before each step) */
    int64_t evaluations;
} MeLoop;

static int array_call(const Action *a) {
    if (a->fmi_version == 3)
        return ((Fmi3ArrayCall)a->call)(a->instance, a->references, a->count, a->values, a->count);
    return ((Fmi2ArrayCall)a->call)(a->instance, a->references, a->count, a->values);
}

static int fail(Outcome *o, int32_t what, int64_t index, int32_t status, double time) {
    o->outcome = what;
    o->index = index;
    o->status = status;
    o->time = time;
    return what;
}

/* SetTime, SetContinuousStates from x, the plan: Master._propagate after ModelExchangeMaster._set_point */
static int set_point(MeLoop *m, double t, Outcome *o) {
    for (size_t i = 0; i < m->timer_count; i++) {
        int status = ((SetTimeCall)m->timers[i].set_time)(m->timers[i].instance, t);
        if (status > STATUS_WARNING) return fail(o, LOOP_SET_TIME_FAILED, (int64_t)i, status, t);
    }
    for (size_t b = 0; b < m->block_count; b++) {
        const Block *block = &m->blocks[b];
        if (!block->states) continue;
        int status = ((VectorCall)block->set_states)(block->instance, m->x + block->offset, block->states);
        if (status > STATUS_WARNING) return fail(o, LOOP_SET_STATES_FAILED, (int64_t)b, status, t);
    }
    for (size_t i = 0; i < m->actions; i++) {
        const Action *a = &m->plan[i];
        if (a->kind == ACTION_READ) {
            int status = array_call(a);
            if (status > STATUS_WARNING) return fail(o, LOOP_READ_FAILED, (int64_t)i, status, t);
            continue;
        }
        for (size_t k = 0; k < a->count; k++) {
            double value = a->sources[k][a->source_index[k]];
            double bound = a->bounds[k];
            if (!(-bound < value && value < bound)) {
                o->copy = (int64_t)k;
                o->value = value;
                return fail(o, LOOP_WRITE_DIVERGED, (int64_t)i, 0, t);
            }
            a->values[k] = value;
        }
        int status = array_call(a);
        if (status > STATUS_WARNING) return fail(o, LOOP_WRITE_FAILED, (int64_t)i, status, t);
    }
    return LOOP_DONE;
}

/* an evaluation's verdict for CVODE: 0, 1 (recoverable: a value beyond its bound), -1 (an FMU failed) */
static int verdict(MeLoop *m, int what) {
    if (what == LOOP_DONE) return 0;
    return what == LOOP_WRITE_DIVERGED ? 1 : -1;
}

EXPORT int me_rhs(double t, N_Vector y, N_Vector ydot, void *user_data) {
    MeLoop *m = (MeLoop *)user_data;
    GetArrayPointerCall data = (GetArrayPointerCall)m->get_array_pointer;
    m->evaluations++;
    memcpy(m->x, data(y), m->states * sizeof(double));
    int what = set_point(m, t, &m->failure);
    if (what != LOOP_DONE) return verdict(m, what);
    for (size_t b = 0; b < m->block_count; b++) {
        const Block *block = &m->blocks[b];
        if (!block->states) continue;
        int status = ((VectorCall)block->get_derivatives)(block->instance, m->dx + block->offset, block->states);
        if (status > STATUS_WARNING) return verdict(m, fail(&m->failure, LOOP_DERIVATIVES_FAILED, (int64_t)b, status, t));
    }
    memcpy(data(ydot), m->dx, m->states * sizeof(double));
    for (size_t i = 0; i < m->states; i++)
        if (!isfinite(m->dx[i])) return 1;  /* recoverable: CVODE retries a smaller step */
    return 0;
}

EXPORT int me_roots(double t, N_Vector y, double *gout, void *user_data) {
    MeLoop *m = (MeLoop *)user_data;
    GetArrayPointerCall data = (GetArrayPointerCall)m->get_array_pointer;
    memcpy(m->x, data(y), m->states * sizeof(double));
    int what = set_point(m, t, &m->failure);
    if (what != LOOP_DONE) return verdict(m, what);
    for (size_t b = 0; b < m->block_count; b++) {
        const Block *block = &m->blocks[b];
        if (!block->indicators) continue;
        int status = ((VectorCall)block->get_indicators)(block->instance, m->z + block->indicator_offset,
                                                         block->indicators);
        if (status > STATUS_WARNING) return verdict(m, fail(&m->failure, LOOP_INDICATORS_FAILED, (int64_t)b, status, t));
    }
    memcpy(gout, m->z, m->indicators * sizeof(double));
    return 0;
}

static int record_within_bounds(const double *record, size_t columns, const double *bounds, int64_t first,
                                int64_t last) {
    for (int64_t row = first; row < last; row++) {
        const double *values = record + (size_t)row * columns;
        for (size_t c = 0; c < columns; c++)
            if (!(fabs(values[c]) < bounds[c])) return 0;
    }
    return 1;
}

/*
 * Steps from the current state towards `target` until row `last_row` is recorded (a block: the
 * progress interval), an event needs the master, or something fails.  `row` is the next row to
 * record.  After each step every grid row t_row = start + row * step <= t reached is recorded
 * from the step's interpolant (its Taylor polynomial about tn); then the step is an event when CVode returned a root, when t reached
 * `next_event` (a time event), or after every step when `every_step` (an FMU needs
 * CompletedIntegratorStep).
 */
EXPORT int me_loop_run(MeLoop *m, double target, double next_event, int32_t every_step, int64_t row,
                       int64_t last_row, Outcome *outcome) {
    CVodeCall cvode = (CVodeCall)m->cvode;
    CVodeGetDkyCall get_dky = (CVodeGetDkyCall)m->get_dky;
    GetArrayPointerCall data = (GetArrayPointerCall)m->get_array_pointer;
    memset(outcome, 0, sizeof *outcome);
    while (row < m->rows) {
        double reached = 0.0;
        memset(&m->failure, 0, sizeof m->failure);
        int flag = cvode(m->cvode_memory, target, m->y, &reached, CV_ONE_STEP);
        outcome->time = reached;
        if (flag < 0) {
            outcome->row = row;
            outcome->status = flag;
            outcome->outcome = LOOP_SOLVER_FAILED;
            return LOOP_SOLVER_FAILED;
        }
        double tn = 0.0;
        int order = 0;
        if (row < m->rows && m->start + (double)row * m->step <= reached) {
            /* the interpolant as a Taylor polynomial about tn (Cvode.taylor in harness/cvode.py) */
            ((CVodeGetLastOrderCall)m->get_last_order)(m->cvode_memory, &order);
            ((CVodeGetCurrentTimeCall)m->get_current_time)(m->cvode_memory, &tn);
            double factorial = 1.0;
            for (int k = 0; k <= order; k++) {
                int status = get_dky(m->cvode_memory, tn, k, m->interpolated);
                if (status < 0) {
                    outcome->row = row;
                    outcome->status = status;
                    outcome->outcome = LOOP_SOLVER_FAILED;
                    return LOOP_SOLVER_FAILED;
                }
                if (k) factorial *= (double)k;
                const double *derivative = data(m->interpolated);
                double *coefficient = m->taylor + (size_t)k * m->states;
                for (size_t i = 0; i < m->states; i++) coefficient[i] = derivative[i] / factorial;
            }
        }
        while (row < m->rows) {
            double t = m->start + (double)row * m->step;
            if (!(t <= reached)) break;
            double dt = t - tn;  /* Horner: x = ((c_q dt + c_q-1) dt + ...) dt + c_0 */
            memcpy(m->x, m->taylor + (size_t)order * m->states, m->states * sizeof(double));
            for (int k = order - 1; k >= 0; k--) {
                const double *coefficient = m->taylor + (size_t)k * m->states;
                for (size_t i = 0; i < m->states; i++) m->x[i] = m->x[i] * dt + coefficient[i];
            }
            int what = set_point(m, t, outcome);
            if (what != LOOP_DONE) {
                outcome->row = row;
                return what;
            }
            double *values = m->record + (size_t)row * m->columns;
            for (size_t i = 0; i < m->actions; i++) {
                const Action *a = &m->plan[i];
                if (a->kind == ACTION_READ && a->recorded)
                    memcpy(values + a->first_column, a->values, a->recorded * sizeof(double));
            }
            row++;
            if (row % m->check_every == 0 &&
                !record_within_bounds(m->record, m->columns, m->column_bounds, row - m->check_every, row)) {
                outcome->row = row;
                outcome->outcome = LOOP_RECORD_DIVERGED;
                return LOOP_RECORD_DIVERGED;
            }
        }
        outcome->time = reached;
        if (flag == CV_ROOT_RETURN || reached >= next_event || every_step) {
            outcome->row = row;
            outcome->status = flag;
            outcome->outcome = LOOP_EVENT;
            return LOOP_EVENT;
        }
        if (row >= last_row) break;
    }
    outcome->row = row;
    outcome->outcome = LOOP_DONE;
    return LOOP_DONE;
}

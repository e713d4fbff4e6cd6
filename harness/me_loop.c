/*
 * The Model Exchange master's integration loop in C: the same FMI calls, in the same order, with
 * the same checks as the Python loop of harness/me_master.py (ModelExchangeMaster._python_evaluate,
 * _record_row, _steps_python), with no Python between CVODE's steps.
 *
 * harness/me_loop.py prepares the loop once: the master's plan (the very value-reference and
 * value arrays of the Python plan: the Actions of harness/loop_interface.h), SetTime of every
 * FMU, the state blocks (SetContinuousStates / GetDerivatives / GetEventIndicators bound to
 * slices of the shared arrays x, dx, z), CVODE's memory and the CVODE functions it calls.  CVODE calls
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
 * The structs (MeLoop among them), the LOOP_ codes and the plan's pass are harness/loop_interface.h,
 * shared with harness/master_loop.c.  Built for the machine that runs the harness
 * (c_toolchain.host_library), -ffp-contract=off.
 */
#include "loop_interface.h"

#define CV_ONE_STEP 2
#define CV_ROOT_RETURN 2

typedef int (*SetTimeCall)(void *instance, double time);
typedef int (*VectorCall)(void *instance, double *values, size_t count); /* states, derivatives, indicators */

typedef int (*CVodeCall)(void *memory, double tout, N_Vector yout, double *tret, int itask);
typedef int (*CVodeGetDkyCall)(void *memory, double t, int k, N_Vector dky);
typedef double *(*GetArrayPointerCall)(N_Vector vector);
typedef int (*CVodeGetLastOrderCall)(void *memory, int *order);
typedef int (*CVodeGetCurrentTimeCall)(void *memory, double *time);

static int fail(Outcome *o, int32_t what, int64_t index, int32_t status, double time) {
    o->time = time;
    return loop_stop(o, what, index, status);
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
    int what = run_plan(m->plan, m->actions, o);
    if (what != LOOP_DONE) o->time = t;
    return what;
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
            record_reads(m->plan, m->actions, m->record + (size_t)row * m->columns);
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

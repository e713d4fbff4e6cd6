/*
 * The master's fixed-step loop in C: the same FMI calls, in the same order, with the same
 * checks as the per-step path of harness/master.py (Master._propagate and Master._loop_python),
 * for a block of communication points, with no Python between the calls.
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
 *       is not below its bound in magnitude (!(|v| < bound), NaN too; each value is tested as its
 *       row is recorded, the run stops at the block's end)
 *   for each FMU: status = doStep(instance, t, step, noSetFMUStatePriorToCurrentPoint = true)
 *       stop if status > warning
 *
 * The last communication point (row `steps`, master_loop_finish; Master._loop's end and Master.run's
 * last check): the plan's pass at t = start + steps * step, its record, no doStep; then the rows no
 * block check has seen, [steps + 1 - check_every, steps + 1), below their bounds.
 *
 * master_loop_run makes the rows' plan once per call (RowPlan below): the same calls with the same
 * values and the same checks, with fewer copies; master_loop_finish runs the plan's pass as it is.
 *
 * The structs, the LOOP_ codes and the plan's pass are harness/loop_interface.h, shared with
 * harness/me_loop.c.  Built for the machine that runs the harness (c_toolchain.host_library), with
 * the native edition's flags (-ffp-contract=off: t is computed exactly as Python computes it).
 */
#include <stdlib.h>

#include "loop_interface.h"

#if defined(__GNUC__)
#define ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define ALWAYS_INLINE inline
#endif

/* the doStep of FMI 2.0 and FMI 3.0 */
typedef int (*Fmi2DoStep)(void *instance, double time, double step, int no_prior_state);
typedef int (*Fmi3DoStep)(void *instance, double time, double step, bool no_prior_state, bool *event_needed,
                          bool *terminate, bool *early_return, double *last_successful_time);

static ALWAYS_INLINE int do_step(const Stepper *s, double time, double step, const int lean) {
    if (!lean && s->fmi_version == 3) {
        bool event_needed = false, terminate = false, early_return = false;
        double last_successful_time = 0.0;
        return ((Fmi3DoStep)s->do_step)(s->instance, time, step, true, &event_needed, &terminate, &early_return,
                                        &last_successful_time);
    }
    return ((Fmi2DoStep)s->do_step)(s->instance, time, step, 1);
}

/* The rows' plan, made once per call of master_loop_run from the plan (the same calls, checks and values;
 * less copying):
 * - a read whose every value is recorded (recorded == count) has its getReal fill the record's row
 *   itself, and the writes take those values from the row;
 * - the test of the recorded values against their bounds leaves out a value that a write later in the
 *   pass tests against a bound no larger than its column's: a value beyond its column's bound has already
 *   stopped the row on its way to an input;
 * - lean, the usual shape (every FMU of FMI 2.0, every read filling the row, every copy from it): the rows run
 *   without the tests of the other shapes. */
typedef struct {
    size_t column;
    double bound;
} Check;

typedef struct {
    unsigned char *direct;   /* per action: a read that fills its record columns itself */
    const double **from;     /* per copy of the writes, in plan order: where its value is, outside the row */
    int64_t *column;         /* ... or its column in the row (-1: `from`) */
    Check *checks;           /* the columns the block check tests, with their bounds */
    size_t check_count;
    int copies_after;        /* some read's recorded values are copied into the row after the pass */
    int lean;                /* the usual shape: FMI 2.0 throughout, every read fills the row, every copy is from it */
    void *memory;
} RowPlan;

static int make_row_plan(const Action *plan, size_t actions, size_t columns, const double *column_bounds,
                         RowPlan *rows) {
    size_t copies = 0;
    for (size_t i = 0; i < actions; i++)
        if (plan[i].kind == ACTION_WRITE) copies += plan[i].count;
    size_t bytes = columns * sizeof(Check) + copies * (sizeof(double *) + sizeof(int64_t)) + columns + actions + 64;
    char *memory = (char *)calloc(1, bytes);
    if (!memory) return 0;
    rows->memory = memory;
    rows->checks = (Check *)memory;
    rows->from = (const double **)(memory + columns * sizeof(Check));
    rows->column = (int64_t *)(rows->from + copies);
    rows->direct = (unsigned char *)(rows->column + copies);
    unsigned char *covered = rows->direct + actions; /* per column: tested on its way to an input */
    rows->copies_after = 0;
    for (size_t i = 0; i < actions; i++) {
        rows->direct[i] = plan[i].kind == ACTION_READ && plan[i].recorded == plan[i].count && plan[i].count > 0;
        rows->copies_after |= plan[i].kind == ACTION_READ && plan[i].recorded && !rows->direct[i];
    }
    size_t copy = 0;
    for (size_t i = 0; i < actions; i++) {
        const Action *a = &plan[i];
        if (a->kind != ACTION_WRITE) continue;
        for (size_t k = 0; k < a->count; k++, copy++) {
            size_t j = a->source_index[k];
            rows->from[copy] = a->sources[k] + j;
            rows->column[copy] = -1;
            for (size_t r = 0; r < i; r++) { /* the read earlier in the pass that fills the source */
                const Action *read = &plan[r];
                if (read->kind != ACTION_READ || read->values != a->sources[k]) continue;
                if (rows->direct[r]) rows->column[copy] = (int64_t)(read->first_column + j);
                if (j < read->recorded && a->bounds[k] <= column_bounds[read->first_column + j])
                    covered[read->first_column + j] = 1;
            }
        }
    }
    rows->check_count = 0;
    for (size_t i = 0; i < actions; i++) {
        const Action *a = &plan[i];
        if (a->kind != ACTION_READ) continue;
        for (size_t c = a->first_column; c < a->first_column + a->recorded; c++)
            if (!covered[c]) {
                rows->checks[rows->check_count].column = c;
                rows->checks[rows->check_count++].bound = column_bounds[c];
            }
    }
    rows->lean = 1;
    for (size_t i = 0; i < actions; i++)
        rows->lean &= plan[i].fmi_version == 2 && (plan[i].kind != ACTION_READ || rows->direct[i]);
    for (size_t k = 0; k < copies; k++) rows->lean &= rows->column[k] >= 0;
    return 1;
}

/* the getReal or setReal of an action into (or from) `values` (lean: FMI 2.0) */
static ALWAYS_INLINE int action_call_with(const Action *a, double *values, const int lean) {
    if (!lean && a->fmi_version == 3)
        return ((Fmi3ArrayCall)a->call)(a->instance, a->references, a->count, values, a->count);
    return ((Fmi2ArrayCall)a->call)(a->instance, a->references, a->count, values);
}

/* run_plan for one row of the record, with the rows' plan; the values not read into the row itself are
 * copied there afterwards (record_reads); returns LOOP_DONE or what stopped it, as run_plan.  `lean` (a
 * constant where it is inlined): the rows' plan is lean, the tests it makes true are left out */
static ALWAYS_INLINE int run_row(const Action *plan, size_t actions, const RowPlan *rows, double *row,
                                 Outcome *outcome, const int lean) {
    size_t copy = 0;
    for (size_t i = 0; i < actions; i++) {
        const Action *a = &plan[i];
        if (a->kind == ACTION_READ) {
            int status = action_call_with(a, lean || rows->direct[i] ? row + a->first_column : a->values, lean);
            if (status > STATUS_WARNING) return loop_stop(outcome, LOOP_READ_FAILED, (int64_t)i, status);
            continue;
        }
        for (size_t k = 0; k < a->count; k++, copy++) {
            int64_t column = rows->column[copy];
            double value = lean || column >= 0 ? row[column] : *rows->from[copy];
            if (!(fabs(value) < a->bounds[k])) {
                outcome->copy = (int64_t)k;
                outcome->value = value;
                return loop_stop(outcome, LOOP_WRITE_DIVERGED, (int64_t)i, 0);
            }
            a->values[k] = value;
        }
        int status = action_call_with(a, a->values, lean);
        if (status > STATUS_WARNING) return loop_stop(outcome, LOOP_WRITE_FAILED, (int64_t)i, status);
    }
    if (lean || !rows->copies_after) return LOOP_DONE;
    for (size_t i = 0; i < actions; i++) {
        const Action *a = &plan[i];
        if (a->kind == ACTION_READ && a->recorded && !rows->direct[i])
            memcpy(row + a->first_column, a->values, a->recorded * sizeof(double));
    }
    return LOOP_DONE;
}

/* the block check's test of one recorded row (record_within_bounds on the columns the rows' plan keeps):
 * whether a value is not below its bound (!(|v| < bound), NaN too) */
static inline int row_beyond(const RowPlan *rows, const double *row) {
    const Check *check = rows->checks;
    for (size_t c = 0, count = rows->check_count; c < count; c++)
        if (!(fabs(row[check[c].column]) < check[c].bound)) return 1;
    return 0;
}

/* rows first_row .. last_row - 1; `lean` (a constant where it is inlined): the rows' plan is lean and every
 * stepper of FMI 2.0 */
static ALWAYS_INLINE int run_rows(const Action *plan, size_t actions, const RowPlan *rows, const Stepper *steppers,
                                  size_t stepper_count, double start, double step, int64_t first_row,
                                  int64_t last_row, double *record, size_t columns, const double *column_bounds,
                                  int64_t check_every, Outcome *outcome, const int lean) {
    int64_t to_check = check_every - (first_row + 1) % check_every; /* rows left until (n + 1) % check_every == 0 */
    if (to_check == check_every) to_check = 0;
    int beyond = 0;                                         /* a recorded value of this block is beyond its bound */
    int whole_block = (first_row + 1 + to_check) - check_every >= first_row; /* the first block began in this call */
    for (int64_t n = first_row; n < last_row; n++) {
        double t = start + (double)n * step;
        double *row = record + (size_t)n * columns;
        int what = run_row(plan, actions, rows, row, outcome, lean);
        if (what != LOOP_DONE) {
            outcome->row = n;
            return what;
        }
        beyond |= row_beyond(rows, row);
        if (to_check-- == 0) {
            to_check = check_every - 1;
            if (!whole_block) /* the block's first rows were recorded by an earlier call: test them all */
                beyond |= !record_within_bounds(record, columns, column_bounds, n + 1 - check_every, n + 1);
            whole_block = 1;
            if (beyond) {
                outcome->row = n;
                return loop_stop(outcome, LOOP_RECORD_DIVERGED, -1, 0);
            }
        }
        for (size_t s = 0; s < stepper_count; s++) {
            int status = do_step(&steppers[s], t, step, lean);
            if (status > STATUS_WARNING) {
                outcome->row = n;
                return loop_stop(outcome, LOOP_STEP_FAILED, (int64_t)s, status);
            }
        }
    }
    return LOOP_DONE;
}

EXPORT int master_loop_finish(const Action *plan, size_t actions, int64_t steps, double *record, size_t columns,
                              const double *column_bounds, int64_t check_every, Outcome *outcome);

/* rows first_row .. last_row - 1; when last_row is `steps`, then the last communication point too
 * (master_loop_finish: one call for a whole run; steps < 0: never) */
EXPORT int master_loop_run(const Action *plan, size_t actions, const Stepper *steppers, size_t stepper_count,
                           double start, double step, int64_t first_row, int64_t last_row, int64_t steps,
                           double *record, size_t columns, const double *column_bounds, int64_t check_every,
                           Outcome *outcome) {
    memset(outcome, 0, sizeof *outcome);
    RowPlan rows;
    if (!make_row_plan(plan, actions, columns, column_bounds, &rows)) {
        outcome->row = first_row;
        return loop_stop(outcome, LOOP_OUT_OF_MEMORY, -1, 0);
    }
    int lean = rows.lean;
    for (size_t s = 0; s < stepper_count; s++) lean &= steppers[s].fmi_version == 2;
    int what = lean ? run_rows(plan, actions, &rows, steppers, stepper_count, start, step, first_row, last_row,
                               record, columns, column_bounds, check_every, outcome, 1)
                    : run_rows(plan, actions, &rows, steppers, stepper_count, start, step, first_row, last_row,
                               record, columns, column_bounds, check_every, outcome, 0);
    free(rows.memory);
    if (what == LOOP_DONE && last_row == steps)
        what = master_loop_finish(plan, actions, steps, record, columns, column_bounds, check_every, outcome);
    return what;
}

EXPORT int master_loop_finish(const Action *plan, size_t actions, int64_t steps, double *record, size_t columns,
                              const double *column_bounds, int64_t check_every, Outcome *outcome) {
    memset(outcome, 0, sizeof *outcome);
    outcome->row = steps;
    int what = run_plan(plan, actions, outcome);
    if (what != LOOP_DONE) return what;
    record_reads(plan, actions, record + (size_t)steps * columns);
    int64_t first = steps + 1 - check_every > 0 ? steps + 1 - check_every : 0;
    if (!record_within_bounds(record, columns, column_bounds, first, steps + 1))
        return loop_stop(outcome, LOOP_RECORD_DIVERGED, -1, 0);
    return LOOP_DONE;
}

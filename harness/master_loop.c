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
 *       is not below its bound in magnitude (!(|v| < bound), NaN too)
 *   for each FMU: status = doStep(instance, t, step, noSetFMUStatePriorToCurrentPoint = true)
 *       stop if status > warning
 *
 * The last communication point (row `steps`, master_loop_finish; Master._loop's end and Master.run's
 * last check): the plan's pass at t = start + steps * step, its record, no doStep; then the rows no
 * block check has seen, [steps + 1 - check_every, steps + 1), below their bounds.
 *
 * The structs, the LOOP_ codes and the plan's pass are harness/loop_interface.h, shared with
 * harness/me_loop.c.  Built for the machine that runs the harness (c_toolchain.host_library), with
 * the native edition's flags (-ffp-contract=off: t is computed exactly as Python computes it).
 */
#include "loop_interface.h"

/* the doStep of FMI 2.0 and FMI 3.0 */
typedef int (*Fmi2DoStep)(void *instance, double time, double step, int no_prior_state);
typedef int (*Fmi3DoStep)(void *instance, double time, double step, bool no_prior_state, bool *event_needed,
                          bool *terminate, bool *early_return, double *last_successful_time);

static int do_step(const Stepper *s, double time, double step) {
    if (s->fmi_version == 3) {
        bool event_needed = false, terminate = false, early_return = false;
        double last_successful_time = 0.0;
        return ((Fmi3DoStep)s->do_step)(s->instance, time, step, true, &event_needed, &terminate, &early_return,
                                        &last_successful_time);
    }
    return ((Fmi2DoStep)s->do_step)(s->instance, time, step, 1);
}

EXPORT int master_loop_run(const Action *plan, size_t actions, const Stepper *steppers, size_t stepper_count,
                           double start, double step, int64_t first_row, int64_t last_row, double *record,
                           size_t columns, const double *column_bounds, int64_t check_every, Outcome *outcome) {
    memset(outcome, 0, sizeof *outcome);
    int64_t to_check = check_every - (first_row + 1) % check_every; /* rows left until (n + 1) % check_every == 0 */
    if (to_check == check_every) to_check = 0;
    for (int64_t n = first_row; n < last_row; n++) {
        double t = start + (double)n * step;
        int what = run_plan(plan, actions, outcome);
        if (what != LOOP_DONE) {
            outcome->row = n;
            return what;
        }
        record_reads(plan, actions, record + (size_t)n * columns);
        if (to_check-- == 0) {
            to_check = check_every - 1;
            if (!record_within_bounds(record, columns, column_bounds, n + 1 - check_every, n + 1)) {
                outcome->row = n;
                return loop_stop(outcome, LOOP_RECORD_DIVERGED, -1, 0);
            }
        }
        for (size_t s = 0; s < stepper_count; s++) {
            int status = do_step(&steppers[s], t, step);
            if (status > STATUS_WARNING) {
                outcome->row = n;
                return loop_stop(outcome, LOOP_STEP_FAILED, (int64_t)s, status);
            }
        }
    }
    return LOOP_DONE;
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

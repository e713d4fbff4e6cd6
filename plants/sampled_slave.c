/* The FMI hooks common to the sampled FMUs: see sampled_slave.py (SampledSlave) and sampled_slave.h. */
#include <math.h>

#include "sampled_slave.h"

#if N_EVENT_INDICATORS != 0
#error "a sampled FMU's events are its sample instants: time events, no event indicators"
#endif

static double sample_period(ModelInstance *m) { return V(m, sample_period); }
static long delay_samples(ModelInstance *m) { return (long)V(m, delay_samples); }

static void raw_inputs(ModelInstance *m, double raw[]) {
    for (int c = 0; c < SAMPLED_CHANNELS; c++) raw[c] = m->s->values[SAMPLED_INPUTS[c]];
}

/* sample k of every channel from raw, each after the committed sample k - 1 (_processed) */
static void processed(ModelInstance *m, long k, const double raw[], double out[]) {
    const double *state = SAMPLED(m)->chain;
    for (int c = 0; c < SAMPLED_CHANNELS; c++) {
        double previous = k > 0 ? state[chain_slot(SAMPLED_CHANNELS, k - 1, c)] : 0.0;
        out[c] = sampled_process(m, k, c, raw[c], previous);
    }
}

/* the values of sample j as held at sample k (pending: sample k's values if not committed) (_value_of) */
static void value_of(ModelInstance *m, long j, long k, const double *pending, double out[]) {
    if (pending && j == k) {
        for (int c = 0; c < SAMPLED_CHANNELS; c++) out[c] = pending[c];
        return;
    }
    int base = chain_slot(SAMPLED_CHANNELS, j, 0);
    for (int c = 0; c < SAMPLED_CHANNELS; c++) out[c] = SAMPLED(m)->chain[base + c];
}

/* model exchange after initialisation: the samples a host passed without an event, taken now */
static void take_missed_samples(ModelInstance *m, const double raw[]) {
    SampledState *s = SAMPLED(m);
    double start = m->s->start_time, period = sample_period(m);
    long missed = samples_before(s->chain, m->s->time, start, period);
    if (missed <= 0) return;
    if (s->warned_missed_event == 0.0) {
        s->warned_missed_event = 1.0;
        fmu_warn(m, "the host passed the sample instant t = %.17g without an event (the next event time this "
                 "FMU announced) and reached t = %.17g: the samples due in between were taken from the inputs "
                 "at t = %.17g. Stop at each announced event time (fmi2NewDiscreteStates / "
                 "fmi3UpdateDiscreteStates: nextEventTime)",
                 sample_time(start, period, chain_committed(s->chain)), m->s->time, m->s->time);
    }
    double values[CHAIN_MAX_CHANNELS];
    for (long i = 0; i < missed; i++) {
        processed(m, chain_committed(s->chain), raw, values);
        chain_commit(s->chain, SAMPLED_CHANNELS, values);
    }
}

/* the chain's values at the FMU's time, the pending sample taken from raw (held) */
static void held(ModelInstance *m, const double raw[], double out[]) {
    SampledState *s = SAMPLED(m);
    if (sample_period(m) == 0.0) {
        for (int c = 0; c < SAMPLED_CHANNELS; c++) out[c] = sampled_process(m, 0, c, raw[c], 0.0);
        return;
    }
    if (m->model_exchange && m->s->initialized != 0.0 && chain_committed(s->chain) > 0) {
        /* the committed samples (left-continuous); before the first event update, sample 0 as pending */
        take_missed_samples(m, raw);
        long k = chain_committed(s->chain) - 1;
        value_of(m, delayed_index(k, delay_samples(m)), k, NULL, out);
        return;
    }
    int is_pending = 0;
    long k = held_index(s->chain, m->s->time, m->s->start_time, sample_period(m), &is_pending);
    double pending[CHAIN_MAX_CHANNELS];
    if (is_pending) processed(m, k, raw, pending);
    value_of(m, delayed_index(k, delay_samples(m)), k, is_pending ? pending : NULL, out);
}

int model_initialize(ModelInstance *m, double start_time) {
    (void)start_time;
    SampledState *s = SAMPLED(m);
    chain_new_state(s->chain, CHAIN_MAX_CHANNELS);
    s->read_time = NAN;
    for (int c = 0; c < CHAIN_MAX_CHANNELS; c++) s->read_inputs[c] = 0.0;
    s->warned_read_before_set = 0.0;
    s->committed_at = NAN;
    s->warned_missed_event = 0.0;
    sampled_initialize(m);
    return MODEL_OK;
}

void model_construct(ModelInstance *m) { model_initialize(m, m->s->start_time); }

int model_compute_outputs(ModelInstance *m) {
    SampledState *s = SAMPLED(m);
    double raw[CHAIN_MAX_CHANNELS], values[CHAIN_MAX_CHANNELS];
    raw_inputs(m, raw);
    if (m->s->initialized != 0.0 && m->s->time != s->read_time) { /* what the host reads first at this point */
        s->read_time = m->s->time;
        for (int c = 0; c < SAMPLED_CHANNELS; c++) s->read_inputs[c] = raw[c];
    }
    held(m, raw, values);
    sampled_set_outputs(m, values);
    m->outputs_stale = 0;
    return MODEL_OK;
}

static int depends_on_input_now(ModelInstance *m, double t) {
    if (!sampled_feeds_through(m)) return 0;
    if (sample_period(m) == 0.0) return 1;
    return delay_samples(m) == 0 &&
           at_instant(t, m->s->start_time, sample_period(m), chain_committed(SAMPLED(m)->chain));
}

static void check_read_before_set(ModelInstance *m, double t, const double raw[]) {
    SampledState *s = SAMPLED(m);
    int differ = 0;
    for (int c = 0; c < SAMPLED_CHANNELS; c++) differ = differ || s->read_inputs[c] != raw[c];
    if (s->warned_read_before_set == 0.0 && s->read_time == t && differ && depends_on_input_now(m, t)) {
        s->warned_read_before_set = 1.0;
        fmu_warn(m, "the host read %s at t = %.17g before it set %s there (a host that delays every link one "
                 "communication step, Jacobi, or one that reads this FMU before it sets it): it got values from the "
                 "inputs of its previous communication point, while this FMU takes its sample from the inputs set "
                 "for doStep, so every FMU that passes its input straight through adds one step of delay to the "
                 "loop in such a host. Set this FMU's inputs before reading its outputs (a master that respects "
                 "direct feedthrough)", SAMPLED_OUTPUT_NAMES, t, SAMPLED_INPUT_NAMES);
    }
}

int model_step(ModelInstance *m, double current_time, double step_size) {
    SampledState *s = SAMPLED(m);
    double raw[CHAIN_MAX_CHANNELS], values[CHAIN_MAX_CHANNELS], sample[CHAIN_MAX_CHANNELS];
    raw_inputs(m, raw);
    check_read_before_set(m, current_time, raw);
    double end = current_time + step_size;
    if (sample_period(m) == 0.0) {
        held(m, raw, values);
        sampled_advance(m, current_time, end, values);
        return MODEL_OK;
    }
    double start = m->s->start_time, period = sample_period(m);
    held(m, raw, values);
    double begin = current_time;
    long count = samples_before(s->chain, end, start, period);
    for (long i = 0; i < count; i++) {
        long k = chain_committed(s->chain);
        double instant = sample_time(start, period, k);
        if (instant > begin) {
            sampled_advance(m, begin, instant, values);
            begin = instant;
        }
        processed(m, k, raw, sample);
        chain_commit(s->chain, SAMPLED_CHANNELS, sample);
        value_of(m, delayed_index(k, delay_samples(m)), k + 1, NULL, values);
    }
    sampled_advance(m, begin, end, values);
    return MODEL_OK;
}

/* ---------------------------------------------------------------- model exchange */

/* the event at a sample instant takes that sample from the inputs of this pass; a later pass of the
 * same event takes it again (its inputs may have changed: another FMU's event changed them) */
int model_update_discrete_states(ModelInstance *m, int *states_changed) {
    SampledState *s = SAMPLED(m);
    *states_changed = 0;
    if (sample_period(m) == 0.0) return MODEL_OK;
    double raw[CHAIN_MAX_CHANNELS], values[CHAIN_MAX_CHANNELS];
    raw_inputs(m, raw);
    double t = m->s->time, start = m->s->start_time, period = sample_period(m);
    long k = chain_committed(s->chain);
    if (k > 0 && s->committed_at == t) {
        s->chain[CHAIN_NEXT] = (double)(k - 1); /* take the sample of this event again */
        k -= 1;
    } else if (!at_instant(t, start, period, k)) {
        return MODEL_OK; /* no sample at this event (another FMU's) */
    }
    processed(m, k, raw, values);
    chain_commit(s->chain, SAMPLED_CHANNELS, values);
    s->committed_at = t;
    return MODEL_OK;
}

int model_next_event_time(ModelInstance *m, double *time) {
    if (sample_period(m) == 0.0) return 0;
    *time = sample_time(m->s->start_time, sample_period(m), chain_committed(SAMPLED(m)->chain));
    return 1;
}

int model_get_event_indicators(ModelInstance *m, double z[]) {
    (void)m; (void)z;
    return MODEL_OK;
}

int model_get_locals(ModelInstance *m, double values[]) {
    (void)m; (void)values;
    return MODEL_OK;
}

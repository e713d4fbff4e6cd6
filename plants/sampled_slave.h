/* Shared part of the sampled FMUs (sampled_slave.py, SampledSlave): the chain of sampled_chain.h as
 * the hooks of fmi_layer.h.  A model file defines the hooks below, model_cross_parameter_errors and
 * the continuous-state hooks (model_get_continuous_states, model_set_continuous_states,
 * model_get_derivatives); its internal state begins with a SampledState.  The variable table has
 * the parameters sample_period and delay_samples (docs/model.md section 13).
 *
 * Model Exchange (docs/model_exchange.md): the samples are time events.  After initialisation the
 * outputs hold the committed samples (left-continuous: the value before an event's update at its
 * time); the event update at t_k takes sample k from the inputs of that pass (a later pass of the
 * same event takes it again, from that pass's inputs), and the next event time is t_(k+1).  A host
 * that passes a sample instant without an event gets the sample from the inputs it then sets, and
 * one warning. */
#ifndef AFC_SAMPLED_SLAVE_H
#define AFC_SAMPLED_SLAVE_H

#include "fmi_layer.h"
#include "sampled_chain.h"

typedef struct {
    double chain[CHAIN_SIZE(CHAIN_MAX_CHANNELS)];
    double read_time;                        /* the first output computation of the current communication point */
    double read_inputs[CHAIN_MAX_CHANNELS];  /* the inputs it used */
    double warned_read_before_set;
    double committed_at;                     /* model exchange: the time of the last event's sample (NaN: none) */
    double warned_missed_event;
} SampledState;

#define SAMPLED(m) ((SampledState *)(m)->internal)

/* provided by each sampled model */
extern const int SAMPLED_CHANNELS;
extern const int SAMPLED_INPUTS[];  /* the value references of the channels' inputs */
extern const char *const SAMPLED_INPUT_NAMES;   /* "y, dy, d2y, d3y": for the messages */
extern const char *const SAMPLED_OUTPUT_NAMES;
/* sample k of a channel from its input value (previous: the processed sample k - 1) */
double sampled_process(ModelInstance *m, long k, int channel, double value, double previous);
/* the outputs from the chain's values that hold now */
void sampled_set_outputs(ModelInstance *m, const double held[]);
/* advance the model's own state over [begin, end] with the chain's values held (co-simulation) */
void sampled_advance(ModelInstance *m, double begin, double end, const double held[]);
/* does an output depend on the current input (at a sample instant)? */
int sampled_feeds_through(ModelInstance *m);
/* the model's own state at the end of initialisation (after the chain's) */
void sampled_initialize(ModelInstance *m);

#endif

/* A sampled chain: sample-and-hold on a clock of its own, a delay of d samples: the C twin of
 * sampled_chain.py (the same functions, the same arithmetic in the same order; docs/model.md
 * section 13, (C1), (C2)).  The state is one array of doubles, [NEXT, ring...]. */
#ifndef AFC_SAMPLED_CHAIN_H
#define AFC_SAMPLED_CHAIN_H

#define MAX_DELAY_SAMPLES 16
#define RING (MAX_DELAY_SAMPLES + 2)
#define CHAIN_NEXT 0
#define RING_BASE 1
#define INSTANT_TOLERANCE 1e-9
#define CHAIN_MAX_CHANNELS 4
#define CHAIN_SIZE(channels) (RING_BASE + RING * (channels))

/* the state before the first sample: nothing committed (new_state) */
void chain_new_state(double state[], int channels);
/* t_k of (C1) */
double sample_time(double start, double period, long k);
double instant_tolerance(double t, double period);
/* is t the sample instant t_k (within rounding)? */
int at_instant(double t, double start, double period, long k);
/* the index in the state of sample k's value of a channel */
int chain_slot(int channels, long k, int channel);
/* the number of samples committed (the index of the next one) */
long chain_committed(const double state[]);
/* the sample whose value holds at t; *pending = 1 when t is its instant and it is not committed yet */
long held_index(const double state[], double t, double start, double period, int *pending);
/* the sample (C2) outputs at sample k: k - d, the first sample before that */
long delayed_index(long k, long delay);
/* append the processed values of the next sample (one per channel) to the delay line */
void chain_commit(double state[], int channels, const double values[]);
/* how many samples are due strictly before end (beyond rounding) and not committed yet */
long samples_before(const double state[], double end, double start, double period);

#endif

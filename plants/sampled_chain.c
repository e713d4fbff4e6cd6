/* A sampled chain: see sampled_chain.py (new_state, sample_time, tolerance, at_instant, slot, committed,
 * held_index, delayed_index, commit, samples_before). */
#include <math.h>

#include "sampled_chain.h"

void chain_new_state(double state[], int channels) {
    for (int i = 0; i < CHAIN_SIZE(channels); i++) state[i] = 0.0;
}

double sample_time(double start, double period, long k) { return start + (double)k * period; }

double instant_tolerance(double t, double period) { return INSTANT_TOLERANCE * (fabs(t) + period); }

int at_instant(double t, double start, double period, long k) {
    return fabs(t - sample_time(start, period, k)) <= instant_tolerance(t, period);
}

int chain_slot(int channels, long k, int channel) { return RING_BASE + (int)(k % RING) * channels + channel; }

long chain_committed(const double state[]) { return (long)state[CHAIN_NEXT]; }

long held_index(const double state[], double t, double start, double period, int *pending) {
    long k = chain_committed(state);
    *pending = at_instant(t, start, period, k);
    return *pending ? k : k - 1;
}

long delayed_index(long k, long delay) { return k > delay ? k - delay : 0; }

void chain_commit(double state[], int channels, const double values[]) {
    long k = chain_committed(state);
    int base = chain_slot(channels, k, 0);
    for (int c = 0; c < channels; c++) state[base + c] = values[c];
    state[CHAIN_NEXT] = (double)(k + 1);
}

long samples_before(const double state[], double end, double start, double period) {
    long k = chain_committed(state);
    double limit = end - instant_tolerance(end, period);
    long count = 0;
    while (sample_time(start, period, k + count) < limit) count++;
    return count;
}

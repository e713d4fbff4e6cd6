/* Sensor: the measurement between a plant and the controller as a native FMU: the C twin of this
 * folder's model.py (mix64, splitmix64, stream_key, gaussian, quantise, filter_coefficient, measure:
 * the same operations in the same order) and fmu.py.  docs/model.md section 13:
 *
 *   v_k = x_k + sigma_c n(seed, local_seed, c, k)        (S1)  SplitMix64 + Box-Muller
 *   q_k = quantum_c floor(v_k / quantum_c + 1/2)          (S2)
 *   f_k = f_(k-1) + a (q_k - f_(k-1)), f_0 = q_0,  a = 1 - exp(-Ts / T)   (S3)
 *
 * sampled on the sensor's clock and delayed by the chain (sampled_chain.c, (C1), (C2)). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "sampled_slave.h"

#define GAMMA 0x9E3779B97F4A7C15ULL
#define UNIT (1.0 / 9007199254740992.0) /* 2^-53 */
#define TWO_PI (2.0 * 3.141592653589793)
#define SENSOR_CHANNELS 4

/* the chain's state, then the constants of measure that the parameters fix, computed when initialisation ends
 * (fmu.py's Sensor.configure: _keys, _coefficient, _filtered; a restored FMU state brings those of its own
 * parameters) */
typedef struct {
    SampledState sampled;
    uint64_t keys[SENSOR_CHANNELS]; /* stream_key of each channel */
    double coefficient;             /* a of (S3) */
    double filtered;                /* the filter runs (filter_time_constant != 0) */
} SensorState;

#define SENSOR(m) ((SensorState *)(m)->internal)

const size_t MODEL_INTERNAL_BYTES = sizeof(SensorState);
const int SAMPLED_CHANNELS = SENSOR_CHANNELS;
const int SAMPLED_INPUTS[] = {VR_y, VR_dy, VR_d2y, VR_d3y};
const char *const SAMPLED_INPUT_NAMES = "y, dy, d2y, d3y";
const char *const SAMPLED_OUTPUT_NAMES = "y_measured, dy_measured, d2y_measured, d3y_measured";
static const int NOISE[] = {VR_noise_y, VR_noise_dy, VR_noise_d2y, VR_noise_d3y};
static const int QUANTUM[] = {VR_quantum_y, VR_quantum_dy, VR_quantum_d2y, VR_quantum_d3y};
static const char *const CHANNEL_NAMES[] = {"y", "dy", "d2y", "d3y"};

/* SplitMix64's output function (mix64) */
static uint64_t mix64(uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

/* the index-th output of SplitMix64 started from state (splitmix64) */
static uint64_t splitmix64(uint64_t state, uint64_t index) { return mix64(state + index * GAMMA); }

/* the key of one channel's noise stream (stream_key) */
static uint64_t stream_key(uint64_t seed, uint64_t local_seed, int channel) {
    return splitmix64(((seed & 0xFFFFFFFFULL) << 32) | (local_seed & 0xFFFFFFFFULL), (uint64_t)channel + 1);
}

/* n ~ N(0, 1) of (S1): Box-Muller on outputs 2k + 1, 2k + 2 of the stream (gaussian) */
static double gaussian(uint64_t key, long k) {
    double u1 = (double)((splitmix64(key, 2 * (uint64_t)k + 1) >> 11) + 1) * UNIT;
    double u2 = (double)(splitmix64(key, 2 * (uint64_t)k + 2) >> 11) * UNIT;
    return sqrt(-2.0 * log(u1)) * cos(TWO_PI * u2);
}

/* (S2) (quantise) */
static double quantise(double value, double quantum) {
    if (quantum == 0.0) return value;
    return floor(value / quantum + 0.5) * quantum;
}

/* a of (S3) (filter_coefficient) */
static double filter_coefficient(double sample_period, double time_constant) {
    if (time_constant == 0.0) return 1.0;
    return -expm1(-sample_period / time_constant);
}

/* f_k of (S1)-(S3) for one channel (measure) */
static double measure(uint64_t key, long k, double true_value, double previous, double sigma, double quantum,
                      double coefficient, int filtered) {
    double value = true_value;
    if (sigma != 0.0) value = value + sigma * gaussian(key, k); /* (S1) */
    value = quantise(value, quantum);                          /* (S2) */
    if (filtered && k > 0) value = previous + coefficient * (value - previous); /* (S3) */
    return value;
}

double sampled_process(ModelInstance *m, long k, int channel, double value, double previous) {
    const SensorState *sensor = SENSOR(m);
    return measure(sensor->keys[channel], k, value, previous, m->s->values[NOISE[channel]],
                   m->s->values[QUANTUM[channel]], sensor->coefficient, sensor->filtered != 0.0);
}

void sampled_set_outputs(ModelInstance *m, const double held[]) {
    V(m, y_measured) = held[0];
    V(m, dy_measured) = held[1];
    V(m, d2y_measured) = held[2];
    V(m, d3y_measured) = held[3];
}

void sampled_advance(ModelInstance *m, double begin, double end, const double held[]) {
    (void)m; (void)begin; (void)end; (void)held;
}

int sampled_feeds_through(ModelInstance *m) { (void)m; return 1; }

/* Sensor.configure: the constants of measure from the parameters */
void sampled_initialize(ModelInstance *m) {
    SensorState *sensor = SENSOR(m);
    for (int c = 0; c < SENSOR_CHANNELS; c++)
        sensor->keys[c] = stream_key((uint64_t)V(m, seed), (uint64_t)V(m, local_seed), c);
    sensor->coefficient = filter_coefficient(V(m, sample_period), V(m, filter_time_constant));
    sensor->filtered = V(m, filter_time_constant) != 0.0 ? 1.0 : 0.0;
}

/* the stages that need the sensor's clock, refused without one (Sensor.cross_parameter_errors); in Model
 * Exchange a quantiser without a clock too: its steps would be state events this FMU does not declare */
int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size) {
    if (V(m, sample_period) != 0.0) return MODEL_OK;
    const char *needs = "needs a sample period of its own: give sample_period > 0";
    size_t used = 0;
    int count = 0;
    message[0] = 0;
#define APPEND(...)                                                                               \
    do {                                                                                          \
        int written = snprintf(message + used, size - used, "%s", count ? "; " : "");             \
        if (written > 0 && (size_t)written < size - used) used += (size_t)written;                \
        written = snprintf(message + used, size - used, __VA_ARGS__);                             \
        if (written > 0 && (size_t)written < size - used) used += (size_t)written;                \
        count++;                                                                                  \
    } while (0)
    for (int c = 0; c < SENSOR_CHANNELS; c++)
        if (m->s->values[NOISE[c]] != 0.0)
            APPEND("parameter noise_%s = %.17g is invalid with sample_period = 0; valid range: 0 (the noise is "
                   "drawn once per sample of the sensor's clock, so it %s)", CHANNEL_NAMES[c],
                   m->s->values[NOISE[c]], needs);
    if (V(m, delay_samples) != 0.0)
        APPEND("parameter delay_samples = %.17g is invalid with sample_period = 0; valid range: 0 (a delay in "
               "samples %s)", V(m, delay_samples), needs);
    if (V(m, filter_time_constant) != 0.0)
        APPEND("parameter filter_time_constant = %.17g is invalid with sample_period = 0; valid range: 0 (the "
               "filter runs at each sample, so it %s)", V(m, filter_time_constant), needs);
    if (m->model_exchange)
        for (int c = 0; c < SENSOR_CHANNELS; c++)
            if (m->s->values[QUANTUM[c]] != 0.0)
                APPEND("parameter quantum_%s = %.17g is invalid with sample_period = 0 in Model Exchange; valid "
                       "range: 0 (a quantiser without a clock has steps that would be state events this FMU does "
                       "not declare: give sample_period > 0, a sampled converter, or use co-simulation)",
                       CHANNEL_NAMES[c], m->s->values[QUANTUM[c]]);
#undef APPEND
    return count ? MODEL_ERROR : MODEL_OK;
}

/* model exchange: no continuous states (the samples are time events: sampled_slave.c) */
int model_get_continuous_states(ModelInstance *m, double x[]) {
    (void)m; (void)x;
    return MODEL_OK;
}

int model_set_continuous_states(ModelInstance *m, const double x[]) {
    (void)m; (void)x;
    return MODEL_OK;
}

int model_get_derivatives(ModelInstance *m, double dx[]) {
    (void)m; (void)dx;
    return MODEL_OK;
}

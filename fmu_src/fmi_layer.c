/* The FMI layer of the native FMUs: FMI 2.0 (FMI_VERSION 2) or FMI 3.0 (FMI_VERSION 3),
 * co-simulation and model exchange, written once for the models (see fmi_layer.h).
 *
 * Life cycle (a state machine in the manner of the Modelica Reference-FMUs):
 *
 *   instantiated --enterInitializationMode--> initialization --exitInitializationMode-->
 *   co-simulation:  step --terminate--> terminated;
 *   model exchange: event <--enterEventMode / enterContinuousTimeMode--> continuous time
 *                   --terminate--> terminated;
 *   reset from any state -> instantiated.
 *
 * Each call checks it is allowed in the current state and otherwise returns Error with
 * a message naming the call and the state.  Model errors (invalid parameters, NaN
 * inputs, divergence) are returned as Error, never Fatal, and leave the instance usable:
 * the host may correct a parameter and exit initialisation again, or free the instance.
 * Every function of the API is exported; those this FMU does not support (directional
 * derivatives, clocks, scheduled execution, types it has no variables of, the other
 * interface's calls) return Error with a log message.  Model exchange: docs/model_exchange.md.
 */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi_layer.h"

#if FMI_VERSION == 2
#include "fmi2Functions.h"
typedef fmi2Status Status;
#define STATUS_OK fmi2OK
#define STATUS_WARNING fmi2Warning
#define STATUS_DISCARD fmi2Discard
#define STATUS_ERROR fmi2Error
#define STATUS_FATAL fmi2Fatal
#define TERMINATE_CALL "fmi2Terminate"
#define EXIT_INIT_CALL "fmi2ExitInitializationMode"
#define SET_STATE_CALL "fmi2SetFMUstate"
#elif FMI_VERSION == 3
#include "fmi3Functions.h"
typedef fmi3Status Status;
#define STATUS_OK fmi3OK
#define STATUS_WARNING fmi3Warning
#define STATUS_DISCARD fmi3Discard
#define STATUS_ERROR fmi3Error
#define STATUS_FATAL fmi3Fatal
#define TERMINATE_CALL "fmi3Terminate"
#define EXIT_INIT_CALL "fmi3ExitInitializationMode"
#define SET_STATE_CALL "fmi3SetFMUState"
#else
#error "compile with -DFMI_VERSION=2 or -DFMI_VERSION=3"
#endif

enum {
    MODE_INSTANTIATED = 1,
    MODE_INITIALIZATION = 2,
    MODE_STEP = 4,
    MODE_TERMINATED = 8,
    MODE_EVENT = 16,      /* model exchange */
    MODE_CONTINUOUS = 32, /* model exchange */
};
#define ANY_MODE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_TERMINATED | MODE_EVENT | MODE_CONTINUOUS)
#define INITIALIZED_MODES (MODE_STEP | MODE_EVENT | MODE_CONTINUOUS) /* between exitInitializationMode and terminate */

static const char *mode_name(int mode) {
    switch (mode) {
    case MODE_INSTANTIATED: return "Instantiated";
    case MODE_INITIALIZATION: return "Initialization Mode";
    case MODE_STEP: return "Step Mode";
    case MODE_TERMINATED: return "Terminated";
    case MODE_EVENT: return "Event Mode";
    case MODE_CONTINUOUS: return "Continuous-Time Mode";
    default: return "unknown";
    }
}

/* the host's callbacks */
typedef struct {
#if FMI_VERSION == 2
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment environment;
#else
    fmi3LogMessageCallback logger;
    fmi3InstanceEnvironment environment;
#endif
} Host;

static size_t snapshot_bytes(void) { return sizeof(Snapshot) + MODEL_INTERNAL_BYTES; }

/* ------------------------------------------------------------------ logging */

static void log_message(ModelInstance *m, Status status, const char *category, const char *message) {
    Host *host = (Host *)m->host;
    if (!host->logger) return;
#if FMI_VERSION == 2
    host->logger(host->environment, m->instance_name, status, category, message);
#else
    host->logger(host->environment, status, category, message);
#endif
}

static void log_formatted(ModelInstance *m, Status status, const char *category, const char *format, va_list args) {
    char message[2048];
    int prefix = snprintf(message, sizeof message, "%s: ", m->instance_name);
    if (prefix < 0) prefix = 0;
    vsnprintf(message + prefix, sizeof message - (size_t)prefix, format, args);
    log_message(m, status, category, message);
}

int fmu_fail(ModelInstance *m, const char *format, ...) {
    va_list args;
    va_start(args, format);
    log_formatted(m, STATUS_ERROR, "logStatusError", format, args);
    va_end(args);
    return MODEL_ERROR;
}

void fmu_warn(ModelInstance *m, const char *format, ...) {
    va_list args;
    va_start(args, format);
    log_formatted(m, STATUS_WARNING, "logStatusWarning", format, args);
    va_end(args);
}

const char *numbers_text(char *buffer, size_t size, const double x[], int n, const char *brackets) {
    size_t used = (size_t)snprintf(buffer, size, "%c", brackets[0]);
    for (int i = 0; i < n && used < size; i++)
        used += (size_t)snprintf(buffer + used, size - used, "%s%.17g", i ? ", " : "", x[i]);
    if (used < size) /* a tuple of one: "(a,)" */
        snprintf(buffer + used, size - used, "%s%c", n == 1 && brackets[0] == '(' ? "," : "", brackets[1]);
    return buffer;
}

/* --------------------------------------------------------------- validation */

/* Variable.check: NULL-equivalent (0) if valid, else writes the message */
static int check_variable(int vr, double value, char *message, size_t size) {
    const VariableInfo *v = &MODEL_VARIABLES[vr];
    int bad = !isfinite(value);
    if (!bad && v->is_integer && value != floor(value)) bad = 1;
    if (!bad && v->has_minimum) bad = v->exclusive_minimum ? value <= v->minimum : value < v->minimum;
    if (!bad && v->has_maximum) bad = v->exclusive_maximum ? value >= v->maximum : value > v->maximum;
    if (bad)
        snprintf(message, size, "parameter %s = %.17g is invalid; valid range: %s", v->name, value, v->valid_range);
    return bad;
}

/* TableSlave._parameter_errors: the messages joined by "; " (0 if none) */
static int parameter_errors(ModelInstance *m, char *message, size_t size) {
    size_t used = 0;
    int count = 0;
    message[0] = 0;
    for (int vr = 0; vr < N_VARIABLES; vr++) {
        char one[512];
        if (MODEL_VARIABLES[vr].causality != CAUSALITY_PARAMETER) continue;
        if (!check_variable(vr, m->s->values[vr], one, sizeof one)) continue;
        int written = snprintf(message + used, size - used, "%s%s", count ? "; " : "", one);
        if (written > 0 && (size_t)written < size - used) used += (size_t)written;
        count++;
    }
    if (count) return 1;
    return model_cross_parameter_errors(m, message, size) != MODEL_OK;
}

/* -------------------------------------------------------------- life cycle */

static void reset_snapshot(ModelInstance *m) {
    memset(m->s, 0, snapshot_bytes());
    for (int vr = 0; vr < N_VARIABLES; vr++) m->s->values[vr] = MODEL_VARIABLES[vr].start;
    m->s->time = 0.0;
    m->s->start_time = 0.0;
    m->s->initialized = 0.0;
    m->outputs_stale = 1;
    m->stale_on_set = 1;
    m->mode = MODE_INSTANTIATED;
    model_construct(m);
}

static ModelInstance *create_instance(const char *name, Host host, int logging_on, int model_exchange) {
    ModelInstance *m = (ModelInstance *)calloc(1, sizeof(ModelInstance));
    if (!m) return NULL;
    m->s = (Snapshot *)calloc(1, snapshot_bytes());
    m->host = malloc(sizeof(Host));
    m->instance_name = (char *)malloc(strlen(name ? name : "") + 1);
    if (!m->s || !m->host || !m->instance_name) {
        free(m->s); free(m->host); free(m->instance_name); free(m);
        return NULL;
    }
    strcpy(m->instance_name, name ? name : "");
    *(Host *)m->host = host;
    m->internal = (char *)m->s + sizeof(Snapshot);
    m->logging_on = logging_on;
    m->model_exchange = model_exchange;
    m->feedthrough = MODEL_FEEDTHROUGH;
    reset_snapshot(m);
    return m;
}

static void free_instance(ModelInstance *m) {
    if (!m) return;
    free(m->s);
    free(m->host);
    free(m->instance_name);
    free(m);
}

/* the call is allowed in the current state, else log and return 0 */
static int allowed(ModelInstance *m, const char *call, int modes) {
    if (!m) return 0;
    if (m->mode & modes) return 1;
    fmu_fail(m, "%s is not allowed in state %s", call, mode_name(m->mode));
    return 0;
}

#define CHECK(call, modes) \
    do { if (!allowed(m, call, modes)) return STATUS_ERROR; } while (0)

static Status unsupported(ModelInstance *m, const char *call) {
    if (m) fmu_fail(m, "%s is not supported by this FMU", call);
    return STATUS_ERROR;
}

static void begin_experiment(ModelInstance *m, double start_time) {
    m->s->start_time = start_time;
    m->s->time = start_time;
}

static Status exit_initialization(ModelInstance *m) {
    char message[4096];
    if (parameter_errors(m, message, sizeof message)) {
        fmu_fail(m, "%s", message);
        return STATUS_ERROR;
    }
    m->s->time = m->s->start_time;
    if (model_initialize(m, m->s->start_time) != MODEL_OK) return STATUS_ERROR;
    m->s->initialized = 1.0;
    m->stale_on_set = m->feedthrough;
    m->outputs_stale = 1;
    m->mode = m->model_exchange ? MODE_EVENT : MODE_STEP; /* model exchange: the initial event iteration */
    return STATUS_OK;
}

/* TableSlave._initial_outputs / get_real's refresh */
static int refresh_outputs(ModelInstance *m) {
    if (!m->outputs_stale) return MODEL_OK;
    if (m->s->initialized != 0.0) return model_compute_outputs(m);
    char message[4096];
    if (parameter_errors(m, message, sizeof message)) return MODEL_OK; /* keep start values */
    if (model_initialize(m, m->s->start_time) != MODEL_OK) return MODEL_ERROR;
    return model_compute_outputs(m);
}

/* doStep only between exitInitializationMode and terminate, with the communication point at the
 * FMU's own time (where the last step ended, or the time of a restored state; 1e-9 relative) and
 * a step >= 0; a refused doStep changes nothing and returns Discard (the wording and rules of
 * afc_slave_base.TableSlave._refuse_step) */
static int step_allowed(const ModelInstance *m, double current_time, double step_size) {
    double time = m->s->time;
    return m->mode == MODE_STEP && step_size >= 0.0 && fabs(current_time - time) <= 1e-9 * (fabs(time) + step_size);
}

/* the message of a doStep step_allowed refuses */
MESSAGE_PATH static Status refuse_step(ModelInstance *m, double current_time, double step_size, const char *call) {
    const char *rule;
    char expected[256];
    if (m->mode == MODE_TERMINATED)
        rule = "the FMU was terminated (" TERMINATE_CALL "); doStep is allowed only between "
               EXIT_INIT_CALL " and " TERMINATE_CALL;
    else if (m->mode != MODE_STEP)
        rule = "the FMU is not initialised: call " EXIT_INIT_CALL " first; doStep is allowed only "
               "between " EXIT_INIT_CALL " and " TERMINATE_CALL;
    else if (!(step_size >= 0.0))
        rule = "the communication step must be >= 0";
    else {
        snprintf(expected, sizeof expected, "expected currentCommunicationPoint = %.17g, the FMU's time "
                 "(where the last step ended, or the time of the state restored by " SET_STATE_CALL "); a step "
                 "must start there", m->s->time);
        rule = expected;
    }
    fmu_fail(m, "%s(currentCommunicationPoint = %.17g, communicationStepSize = %.17g) refused: %s; state and "
             "time unchanged", call, current_time, step_size, rule);
    return STATUS_DISCARD;
}

static Status do_step(ModelInstance *m, double current_time, double step_size, const char *call) {
    if (!step_allowed(m, current_time, step_size)) { /* a model exchange instance is never in step mode */
        if (m->model_exchange) {
            fmu_fail(m, "%s is a co-simulation function; this instance was instantiated for model exchange", call);
            return STATUS_ERROR;
        }
        return refuse_step(m, current_time, step_size, call);
    }
    if (m->outputs_stale && model_compute_outputs(m) != MODEL_OK) return STATUS_ERROR;
    if (model_step(m, current_time, step_size) != MODEL_OK) return STATUS_ERROR;
    m->s->time = current_time + step_size;
    m->outputs_stale = 1;
    return STATUS_OK;
}

/* ----------------------------------------------------------- value access */

/* FMI 3.0: the independent variable time has the value reference after the table's */
#define VR_TIME ((unsigned)N_VARIABLES)

/* the variables the description adds after the table for model exchange (der(x), event
 * indicators, the model's locals): Real, calculated by the FMU */
#define IS_EXTRA(vr) ((vr) >= (unsigned)VR_FIRST_DERIVATIVE && (vr) < (unsigned)VR_END)

static int valid_reference(ModelInstance *m, unsigned vr, int integer, const char *call) {
    if (FMI_VERSION == 3 && vr == VR_TIME && !integer) return 1;
    if (IS_EXTRA(vr) && !integer) return 1;
    if (vr >= (unsigned)N_VARIABLES) {
        if (IS_EXTRA(vr))
            fmu_fail(m, "%s: variable %s (value reference %u) is of type Real", call,
                     EXTRA_NAMES[vr - VR_FIRST_DERIVATIVE], vr);
        else
            fmu_fail(m, "%s: unknown value reference %u (this FMU has 0 .. %d)", call, vr, VR_END - 1);
        return 0;
    }
    if (MODEL_VARIABLES[vr].is_integer != integer) {
        fmu_fail(m, "%s: variable %s (value reference %u) is of type %s", call, MODEL_VARIABLES[vr].name,
                 vr, MODEL_VARIABLES[vr].is_integer ? "Integer" : "Real");
        return 0;
    }
    return 1;
}

/* the values of the variables after the table (derivatives, event indicators, locals), computed
 * once per call that reads any of them */
static int extra_values(ModelInstance *m, double extra[]) {
    if (model_get_derivatives(m, extra) != MODEL_OK) return MODEL_ERROR;
    if (model_get_event_indicators(m, extra + N_STATES) != MODEL_OK) return MODEL_ERROR;
    return model_get_locals(m, extra + N_STATES + N_EVENT_INDICATORS);
}

static Status get_values(ModelInstance *m, const unsigned *vr, size_t n, double *real, int *integer,
                         const char *call) {
    CHECK(call, MODE_INITIALIZATION | INITIALIZED_MODES | MODE_TERMINATED);
    if (n == 0) return STATUS_OK;
    if (refresh_outputs(m) != MODEL_OK) return STATUS_ERROR;
    const double *values = m->s->values;
    double extra[VR_END - VR_FIRST_DERIVATIVE + 1];
    int extra_ready = 0;
    for (size_t i = 0; i < n; i++) {
        if (!valid_reference(m, vr[i], integer != NULL, call)) return STATUS_ERROR;
        if (integer) integer[i] = (int)values[vr[i]];
        else if (vr[i] == VR_TIME) real[i] = m->s->time;
        else if (IS_EXTRA(vr[i])) {
            if (!extra_ready && extra_values(m, extra) != MODEL_OK) return STATUS_ERROR;
            extra_ready = 1;
            real[i] = extra[vr[i] - VR_FIRST_DERIVATIVE];
        } else real[i] = values[vr[i]];
    }
    return STATUS_OK;
}

/* fmi2GetReal / fmi3GetFloat64.  The per-step path: an initialised instance (a mode between
 * exitInitializationMode and terminate: set_state leaves those modes for a state not initialised) reads
 * Reals of the table after its outputs are brought up to date; anything else (another state, time, a
 * derivative, an Integer, a value reference out of range) goes to get_values, which checks each and says
 * what is wrong. */
static Status get_reals(ModelInstance *m, const unsigned *vr, size_t n, double *real, const char *call) {
    if (m && (m->mode & INITIALIZED_MODES)) {
        if (m->outputs_stale && model_compute_outputs(m) != MODEL_OK) return STATUS_ERROR;
        const double *values = m->s->values;
        size_t i = 0;
        while (i < n && vr[i] < (unsigned)N_VARIABLES && IS_REAL[vr[i]]) {
            real[i] = values[vr[i]];
            i++;
        }
        if (i == n) return STATUS_OK;
    }
    return get_values(m, vr, n, real, NULL, call);
}

/* TableSlave._reject plus the fixed-parameter rule */
/* TableSlave._reject: outputs are never set; after terminate nothing; parameters (variability
 * fixed) only before exitInitializationMode; NaN and inf never */
static int settable(ModelInstance *m, unsigned vr, double value, const char *call) {
    const VariableInfo *v = &MODEL_VARIABLES[vr];
    if (v->causality == CAUSALITY_OUTPUT) {
        fmu_fail(m, "%s is an output and cannot be set", v->name);
        return 0;
    }
    if (m->mode == MODE_TERMINATED) {
        fmu_fail(m, "%s: %s = %.17g refused: the FMU was terminated (" TERMINATE_CALL "); no variable can be "
                 "set after " TERMINATE_CALL, call, v->name, value);
        return 0;
    }
    if (v->causality == CAUSALITY_PARAMETER) {
        if (m->mode & INITIALIZED_MODES) {
            fmu_fail(m, "%s: %s = %.17g refused at t = %.17g: %s is a parameter of variability fixed, which can be "
                     "set only before " EXIT_INIT_CALL " (it keeps %.17g); in %s only inputs can be set", call,
                     v->name, value, m->s->time, v->name, m->s->values[vr],
                     m->mode == MODE_STEP ? "step mode" : "event and continuous-time mode");
            return 0;
        }
        if (!isfinite(value)) {
            char message[512];
            check_variable((int)vr, value, message, sizeof message);
            fmu_fail(m, "%s", message);
            return 0;
        }
        return 1;
    }
    if (!isfinite(value)) {
        fmu_fail(m, "input %s = %.17g is not finite", v->name, value);
        return 0;
    }
    return 1;
}

static Status set_values(ModelInstance *m, const unsigned *vr, size_t n, const double *real, const int *integer,
                         const char *call) {
    CHECK(call, ANY_MODE); /* the rules per variable and state: settable() */
    Status status = STATUS_OK;
    for (size_t i = 0; i < n; i++) {
        if (!valid_reference(m, vr[i], integer != NULL, call)) { status = STATUS_ERROR; break; }
        if (vr[i] == VR_TIME) {
            fmu_fail(m, "%s: time is the independent variable and cannot be set", call);
            status = STATUS_ERROR;
            break;
        }
        if (IS_EXTRA(vr[i])) {
            fmu_fail(m, "%s: %s is calculated by the FMU and cannot be set", call, EXTRA_NAMES[vr[i] - VR_FIRST_DERIVATIVE]);
            status = STATUS_ERROR;
            break;
        }
        double value = integer ? (double)integer[i] : real[i];
        if (!settable(m, vr[i], value, call)) { status = STATUS_ERROR; break; }
        m->s->values[vr[i]] = value;
    }
    if (m->stale_on_set || integer) m->outputs_stale = 1;
    return status;
}

/* fmi2SetReal / fmi3SetFloat64.  The per-step path: finite values of Real inputs, before terminate (what
 * settable() allows them); anything else goes to set_values, which checks each and refuses what it must. */
static Status set_reals(ModelInstance *m, const unsigned *vr, size_t n, const double *real, const char *call) {
    if (m && m->mode != MODE_TERMINATED) {
        double *values = m->s->values;
        size_t i = 0;
        while (i < n && vr[i] < (unsigned)N_VARIABLES && IS_REAL_INPUT[vr[i]] && isfinite(real[i])) {
            values[vr[i]] = real[i];
            i++;
        }
        if (i == n) {
            m->outputs_stale |= m->stale_on_set;
            return STATUS_OK;
        }
    }
    return set_values(m, vr, n, real, NULL, call);
}

static Status no_variables_of_type(ModelInstance *m, size_t n, const char *call) {
    if (!m) return STATUS_ERROR;
    if (n == 0) return STATUS_OK;
    fmu_fail(m, "%s: this FMU has no variables of that type", call);
    return STATUS_ERROR;
}

/* --------------------------------------------------------------- FMU state */

#define STATE_MAGIC 0x53434641u /* "AFCS" */
typedef struct {
    uint32_t magic;
    uint32_t variables;
    uint64_t bytes;
} SerializedHeader;

static Status get_state(ModelInstance *m, void **state) {
    if (!m) return STATUS_ERROR;
    if (!*state) {
        *state = malloc(snapshot_bytes());
        if (!*state) { fmu_fail(m, "getFMUState: out of memory"); return STATUS_ERROR; }
    }
    memcpy(*state, m->s, snapshot_bytes());
    return STATUS_OK;
}

static Status set_state(ModelInstance *m, const void *state) {
    if (!m) return STATUS_ERROR;
    if (!state) { fmu_fail(m, "setFMUState: the state is NULL"); return STATUS_ERROR; }
    memcpy(m->s, state, snapshot_bytes());
    m->stale_on_set = m->feedthrough || m->s->initialized == 0.0;
    m->outputs_stale = 1;
    /* the restored state decides the mode: an initialised state steps from its time, also in
     * a fresh instance (the FMU is as it was when the state was taken); terminate stays final.
     * Model exchange: an initialised state keeps the event or continuous-time mode the instance
     * is in, and brings a fresh instance to event mode at its time */
    if (m->mode == MODE_TERMINATED) return STATUS_OK;
    if (m->s->initialized == 0.0)
        m->mode = (m->mode & INITIALIZED_MODES) ? MODE_INITIALIZATION : m->mode;
    else if (!m->model_exchange)
        m->mode = MODE_STEP;
    else if (!(m->mode & (MODE_EVENT | MODE_CONTINUOUS)))
        m->mode = MODE_EVENT;
    return STATUS_OK;
}

static Status free_state(ModelInstance *m, void **state) {
    if (!m) return STATUS_ERROR;
    if (state && *state) { free(*state); *state = NULL; }
    return STATUS_OK;
}

static size_t serialized_size(void) { return sizeof(SerializedHeader) + snapshot_bytes(); }

static Status serialize_state(ModelInstance *m, const void *state, unsigned char *out, size_t size) {
    if (!m) return STATUS_ERROR;
    if (!state) { fmu_fail(m, "serializeFMUState: the state is NULL"); return STATUS_ERROR; }
    if (size < serialized_size()) {
        fmu_fail(m, "serializeFMUState: buffer of %zu bytes, %zu needed", size, serialized_size());
        return STATUS_ERROR;
    }
    SerializedHeader header = {STATE_MAGIC, (uint32_t)N_VARIABLES, (uint64_t)snapshot_bytes()};
    memcpy(out, &header, sizeof header);
    memcpy(out + sizeof header, state, snapshot_bytes());
    return STATUS_OK;
}

static Status deserialize_state(ModelInstance *m, const unsigned char *in, size_t size, void **state) {
    if (!m) return STATUS_ERROR;
    SerializedHeader header;
    if (size != serialized_size()) {
        fmu_fail(m, "deSerializeFMUState: %zu bytes, a state of this FMU has %zu", size, serialized_size());
        return STATUS_ERROR;
    }
    memcpy(&header, in, sizeof header);
    if (header.magic != STATE_MAGIC || header.variables != (uint32_t)N_VARIABLES ||
        header.bytes != (uint64_t)snapshot_bytes()) {
        fmu_fail(m, "deSerializeFMUState: the bytes are not a state of this FMU");
        return STATUS_ERROR;
    }
    if (!*state) {
        *state = malloc(snapshot_bytes());
        if (!*state) { fmu_fail(m, "deSerializeFMUState: out of memory"); return STATUS_ERROR; }
    }
    memcpy(*state, in + sizeof header, snapshot_bytes());
    return STATUS_OK;
}

/* ---------------------------------------------------------- model exchange */

/* the call is a model exchange function allowed in the current state, else log and return 0 */
static int me_allowed(ModelInstance *m, const char *call, int modes) {
    if (!m) return 0;
    if (!m->model_exchange) {
        fmu_fail(m, "%s is a model exchange function; this instance was instantiated for co-simulation", call);
        return 0;
    }
    return allowed(m, call, modes);
}

#define ME_CHECK(call, modes) \
    do { if (!me_allowed(m, call, modes)) return STATUS_ERROR; } while (0)
/* where the states, derivatives and indicators can be read */
#define ME_READ_MODES (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED)

static int me_count(ModelInstance *m, size_t given, size_t expected, const char *what, const char *call) {
    if (given == expected) return 1;
    fmu_fail(m, "%s: %zu %s requested; this FMU has %zu", call, given, what, expected);
    return 0;
}

static Status me_get_states(ModelInstance *m, double x[], size_t nx, const char *call) {
    ME_CHECK(call, ME_READ_MODES);
    if (!me_count(m, nx, N_STATES, "continuous states", call)) return STATUS_ERROR;
    if (refresh_outputs(m) != MODEL_OK) return STATUS_ERROR; /* in initialization mode: the initial state */
    return model_get_continuous_states(m, x) == MODEL_OK ? STATUS_OK : STATUS_ERROR;
}

static Status me_set_states(ModelInstance *m, const double x[], size_t nx, const char *call) {
    ME_CHECK(call, MODE_CONTINUOUS);
    if (!me_count(m, nx, N_STATES, "continuous states", call)) return STATUS_ERROR;
    if (model_set_continuous_states(m, x) != MODEL_OK) return STATUS_ERROR;
    m->outputs_stale = 1;
    return STATUS_OK;
}

static Status me_get_derivatives(ModelInstance *m, double dx[], size_t nx, const char *call) {
    ME_CHECK(call, ME_READ_MODES);
    if (!me_count(m, nx, N_STATES, "derivatives", call)) return STATUS_ERROR;
    if (refresh_outputs(m) != MODEL_OK || model_get_derivatives(m, dx) != MODEL_OK) return STATUS_ERROR;
    for (size_t i = 0; i < nx; i++)
        if (!isfinite(dx[i])) {
            fmu_fail(m, "%s: %s = %.17g at t = %.17g: the state or the inputs are out of range (the host's solver "
                     "may have stepped too far, or the closed loop diverged)", call, EXTRA_NAMES[i], dx[i],
                     m->s->time);
            return STATUS_ERROR;
        }
    return STATUS_OK;
}

static Status me_get_event_indicators(ModelInstance *m, double z[], size_t nz, const char *call) {
    ME_CHECK(call, ME_READ_MODES);
    if (!me_count(m, nz, N_EVENT_INDICATORS, "event indicators", call)) return STATUS_ERROR;
    if (nz == 0) return STATUS_OK;
    if (refresh_outputs(m) != MODEL_OK) return STATUS_ERROR;
    return model_get_event_indicators(m, z) == MODEL_OK ? STATUS_OK : STATUS_ERROR;
}

static Status me_get_nominals(ModelInstance *m, double nominals[], size_t nx, const char *call) {
    ME_CHECK(call, MODE_INSTANTIATED | ME_READ_MODES);
    if (!me_count(m, nx, N_STATES, "nominals", call)) return STATUS_ERROR;
    for (size_t i = 0; i < nx; i++) nominals[i] = 1.0; /* the states are O(1) in their units */
    return STATUS_OK;
}

/* the event update (newDiscreteStates / updateDiscreteStates): one pass settles the model's
 * discrete states (docs/model_exchange.md), so no further iteration is needed */
static Status me_update_discrete_states(ModelInstance *m, int *states_changed, const char *call) {
    ME_CHECK(call, MODE_EVENT);
    *states_changed = 0;
    if (refresh_outputs(m) != MODEL_OK) return STATUS_ERROR;
    if (model_update_discrete_states(m, states_changed) != MODEL_OK) return STATUS_ERROR;
    m->outputs_stale = 1;
    return STATUS_OK;
}

/* the next time event the model announces after an event update (a sampled model's next sample
 * instant: ModelExchange.time_events, model_next_event_time); 0 when it announces none */
static int next_event_time(ModelInstance *m, double *time) {
    *time = 0.0;
#if MODEL_TIME_EVENTS
    return model_next_event_time(m, time);
#else
    (void)m;
    return 0;
#endif
}

static Status me_enter_event_mode(ModelInstance *m, const char *call) {
    ME_CHECK(call, MODE_EVENT | MODE_CONTINUOUS);
    m->mode = MODE_EVENT;
    return STATUS_OK;
}

static Status me_enter_continuous_time_mode(ModelInstance *m, const char *call) {
    ME_CHECK(call, MODE_EVENT);
    m->mode = MODE_CONTINUOUS;
    return STATUS_OK;
}

static Status me_completed_integrator_step(ModelInstance *m, const char *call) {
    ME_CHECK(call, MODE_CONTINUOUS);
    return STATUS_OK; /* nothing to do at an accepted step: no step events, no monitor (chatter: CS only) */
}

static Status me_set_time(ModelInstance *m, double time, const char *call) {
    ME_CHECK(call, MODE_EVENT | MODE_CONTINUOUS);
    if (!isfinite(time)) {
        fmu_fail(m, "%s(%.17g) refused: the time must be finite", call, time);
        return STATUS_ERROR;
    }
    m->s->time = time;
    m->outputs_stale = 1;
    return STATUS_OK;
}

#if FMI_VERSION == 2
/* =================================================================== FMI 2.0 */
#define M ((ModelInstance *)c)
#define UNSUPPORTED2(call) return unsupported(M, call)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    (void)nCategories; (void)categories;
    if (!c) return fmi2Error;
    M->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuResourceLocation; (void)visible;
    Host host = {functions ? functions->logger : NULL, functions ? functions->componentEnvironment : NULL};
    const char *name = instanceName ? instanceName : "";
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        if (host.logger) host.logger(host.environment, name, fmi2Error, "logStatusError",
                                     "unknown fmuType: this FMU supports co-simulation and model exchange");
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MODEL_GUID) != 0) {
        if (host.logger) host.logger(host.environment, name, fmi2Error, "logStatusError",
                                     "wrong GUID: this binary belongs to GUID " MODEL_GUID);
        return NULL;
    }
    return create_instance(name, host, loggingOn, fmuType == fmi2ModelExchange);
}

void fmi2FreeInstance(fmi2Component c) { free_instance(M); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ModelInstance *m = M;
    CHECK("fmi2SetupExperiment", MODE_INSTANTIATED);
    begin_experiment(m, startTime);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ModelInstance *m = M;
    CHECK("fmi2EnterInitializationMode", MODE_INSTANTIATED);
    m->mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    ModelInstance *m = M;
    CHECK("fmi2ExitInitializationMode", MODE_INITIALIZATION);
    return exit_initialization(m);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ModelInstance *m = M;
    CHECK("fmi2Terminate", INITIALIZED_MODES);
    m->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    ModelInstance *m = M;
    CHECK("fmi2Reset", ANY_MODE);
    reset_snapshot(m);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    return get_reals(M, vr, nvr, value, "fmi2GetReal");
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    return get_values(M, vr, nvr, NULL, value, "fmi2GetInteger");
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)vr; (void)value;
    return no_variables_of_type(M, nvr, "fmi2GetBoolean");
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)vr; (void)value;
    return no_variables_of_type(M, nvr, "fmi2GetString");
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    return set_reals(M, vr, nvr, value, "fmi2SetReal");
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    return set_values(M, vr, nvr, NULL, value, "fmi2SetInteger");
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)vr; (void)value;
    return no_variables_of_type(M, nvr, "fmi2SetBoolean");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)vr; (void)value;
    return no_variables_of_type(M, nvr, "fmi2SetString");
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) { return get_state(M, FMUstate); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) { return set_state(M, FMUstate); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) { return free_state(M, FMUstate); }

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    if (!c) return fmi2Error;
    *size = serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    return serialize_state(M, FMUstate, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    return deserialize_state(M, (const unsigned char *)serializedState, size, FMUstate);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    UNSUPPORTED2("fmi2GetDirectionalDerivative");
}

/* model exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) {
    if (!c) return fmi2Error;
    return me_enter_event_mode(M, "fmi2EnterEventMode");
}
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    if (!c || !eventInfo) return fmi2Error;
    int changed = 0;
    fmi2Status status = me_update_discrete_states(M, &changed, "fmi2NewDiscreteStates");
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
    double next = 0.0;
    eventInfo->nextEventTimeDefined = status == fmi2OK && next_event_time(M, &next) ? fmi2True : fmi2False;
    eventInfo->nextEventTime = next;
    return status;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    if (!c) return fmi2Error;
    return me_enter_continuous_time_mode(M, "fmi2EnterContinuousTimeMode");
}
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    if (enterEventMode) *enterEventMode = fmi2False;
    if (terminateSimulation) *terminateSimulation = fmi2False;
    return me_completed_integrator_step(M, "fmi2CompletedIntegratorStep");
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    if (!c) return fmi2Error;
    return me_set_time(M, time, "fmi2SetTime");
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    if (!c) return fmi2Error;
    return me_set_states(M, x, nx, "fmi2SetContinuousStates");
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    if (!c) return fmi2Error;
    return me_get_derivatives(M, derivatives, nx, "fmi2GetDerivatives");
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    if (!c) return fmi2Error;
    return me_get_event_indicators(M, eventIndicators, ni, "fmi2GetEventIndicators");
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    if (!c) return fmi2Error;
    return me_get_states(M, x, nx, "fmi2GetContinuousStates");
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    if (!c) return fmi2Error;
    return me_get_nominals(M, x_nominal, nx, "fmi2GetNominalsOfContinuousStates");
}

/* co-simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    UNSUPPORTED2("fmi2SetRealInputDerivatives");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    UNSUPPORTED2("fmi2GetRealOutputDerivatives");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    return do_step(M, currentCommunicationPoint, communicationStepSize, "fmi2DoStep");
}

fmi2Status fmi2CancelStep(fmi2Component c) { UNSUPPORTED2("fmi2CancelStep (doStep never returns fmi2Pending)"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    UNSUPPORTED2("fmi2GetStatus (doStep is synchronous)");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    (void)s; (void)value;
    UNSUPPORTED2("fmi2GetRealStatus (doStep is synchronous)");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    UNSUPPORTED2("fmi2GetIntegerStatus (doStep is synchronous)");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)s; (void)value;
    UNSUPPORTED2("fmi2GetBooleanStatus (doStep is synchronous)");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    UNSUPPORTED2("fmi2GetStringStatus (doStep is synchronous)");
}

#else
/* =================================================================== FMI 3.0 */
#define M ((ModelInstance *)instance)
#define UNSUPPORTED3(call) return unsupported(M, call)

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    (void)nCategories; (void)categories;
    if (!instance) return fmi3Error;
    M->logging_on = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath; (void)visible;
    Host host = {logMessage, instanceEnvironment};
    if (!instantiationToken || strcmp(instantiationToken, MODEL_GUID) != 0) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                                   "wrong instantiationToken: this binary belongs to " MODEL_GUID);
        return NULL;
    }
    return create_instance(instanceName, host, loggingOn, 1);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    Host host = {logMessage, instanceEnvironment};
    if (eventModeUsed) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                                   "this FMU has no event mode (eventModeUsed must be false)");
        return NULL;
    }
    if (!instantiationToken || strcmp(instantiationToken, MODEL_GUID) != 0) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                                   "wrong instantiationToken: this binary belongs to " MODEL_GUID);
        return NULL;
    }
    return create_instance(instanceName, host, loggingOn, 0);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "this FMU supports co-simulation and model exchange, not scheduled execution");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { free_instance(M); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ModelInstance *m = M;
    CHECK("fmi3EnterInitializationMode", MODE_INSTANTIATED);
    begin_experiment(m, startTime);
    m->mode = MODE_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    ModelInstance *m = M;
    CHECK("fmi3ExitInitializationMode", MODE_INITIALIZATION);
    return exit_initialization(m);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    if (instance && !M->model_exchange)
        UNSUPPORTED3("fmi3EnterEventMode in co-simulation (hasEventMode is false)");
    return me_enter_event_mode(M, "fmi3EnterEventMode");
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    ModelInstance *m = M;
    CHECK("fmi3Terminate", INITIALIZED_MODES);
    m->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    ModelInstance *m = M;
    CHECK("fmi3Reset", ANY_MODE);
    reset_snapshot(m);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
    if (instance && nValues != nValueReferences) {
        fmu_fail(M, "fmi3GetFloat64: %zu values for %zu value references", nValues, nValueReferences);
        return fmi3Error;
    }
    return get_reals(M, valueReferences, nValueReferences, values, "fmi3GetFloat64");
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues) {
    if (instance && nValues != nValueReferences) {
        fmu_fail(M, "fmi3GetInt32: %zu values for %zu value references", nValues, nValueReferences);
        return fmi3Error;
    }
    return get_values(M, valueReferences, nValueReferences, NULL, (int *)values, "fmi3GetInt32");
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues) {
    if (instance && nValues != nValueReferences) {
        fmu_fail(M, "fmi3SetFloat64: %zu values for %zu value references", nValues, nValueReferences);
        return fmi3Error;
    }
    return set_reals(M, valueReferences, nValueReferences, values, "fmi3SetFloat64");
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues) {
    if (instance && nValues != nValueReferences) {
        fmu_fail(M, "fmi3SetInt32: %zu values for %zu value references", nValues, nValueReferences);
        return fmi3Error;
    }
    return set_values(M, valueReferences, nValueReferences, NULL, (const int *)values, "fmi3SetInt32");
}

/* types this FMU has no variables of */
#define NO_GETTER(name, type)                                                                                  \
    fmi3Status name(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                    type values[], size_t nValues) {                                                           \
        (void)valueReferences; (void)values; (void)nValues;                                                    \
        return no_variables_of_type(M, nValueReferences, #name);                                               \
    }
#define NO_SETTER(name, type)                                                                                  \
    fmi3Status name(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences, \
                    const type values[], size_t nValues) {                                                     \
        (void)valueReferences; (void)values; (void)nValues;                                                    \
        return no_variables_of_type(M, nValueReferences, #name);                                               \
    }
NO_GETTER(fmi3GetFloat32, fmi3Float32)
NO_GETTER(fmi3GetInt8, fmi3Int8)
NO_GETTER(fmi3GetUInt8, fmi3UInt8)
NO_GETTER(fmi3GetInt16, fmi3Int16)
NO_GETTER(fmi3GetUInt16, fmi3UInt16)
NO_GETTER(fmi3GetUInt32, fmi3UInt32)
NO_GETTER(fmi3GetInt64, fmi3Int64)
NO_GETTER(fmi3GetUInt64, fmi3UInt64)
NO_GETTER(fmi3GetBoolean, fmi3Boolean)
NO_GETTER(fmi3GetString, fmi3String)
NO_SETTER(fmi3SetFloat32, fmi3Float32)
NO_SETTER(fmi3SetInt8, fmi3Int8)
NO_SETTER(fmi3SetUInt8, fmi3UInt8)
NO_SETTER(fmi3SetInt16, fmi3Int16)
NO_SETTER(fmi3SetUInt16, fmi3UInt16)
NO_SETTER(fmi3SetUInt32, fmi3UInt32)
NO_SETTER(fmi3SetInt64, fmi3Int64)
NO_SETTER(fmi3SetUInt64, fmi3UInt64)
NO_SETTER(fmi3SetBoolean, fmi3Boolean)
NO_SETTER(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return no_variables_of_type(M, nValueReferences, "fmi3GetBinary");
}
fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return no_variables_of_type(M, nValueReferences, "fmi3SetBinary");
}
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[]) {
    (void)valueReferences; (void)values;
    return no_variables_of_type(M, nValueReferences, "fmi3GetClock");
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[]) {
    (void)valueReferences; (void)values;
    return no_variables_of_type(M, nValueReferences, "fmi3SetClock");
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    UNSUPPORTED3("fmi3GetNumberOfVariableDependencies (the dependencies are in modelDescription.xml)");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    UNSUPPORTED3("fmi3GetVariableDependencies (the dependencies are in modelDescription.xml)");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) { return get_state(M, FMUState); }
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) { return set_state(M, FMUState); }
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) { return free_state(M, FMUState); }

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState;
    if (!instance) return fmi3Error;
    *size = serialized_size();
    return fmi3OK;
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    return serialize_state(M, FMUState, serializedState, size);
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    return deserialize_state(M, serializedState, size, FMUState);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    UNSUPPORTED3("fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    UNSUPPORTED3("fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    UNSUPPORTED3("fmi3EnterConfigurationMode (no structural parameters)");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    UNSUPPORTED3("fmi3ExitConfigurationMode (no structural parameters)");
}

/* clocks: none */
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences; (void)intervals; (void)qualifiers;
    return no_variables_of_type(M, nValueReferences, "fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences; (void)counters; (void)resolutions; (void)qualifiers;
    return no_variables_of_type(M, nValueReferences, "fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    (void)valueReferences; (void)shifts;
    return no_variables_of_type(M, nValueReferences, "fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)counters; (void)resolutions;
    return no_variables_of_type(M, nValueReferences, "fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    (void)valueReferences; (void)intervals;
    return no_variables_of_type(M, nValueReferences, "fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)counters; (void)resolutions;
    return no_variables_of_type(M, nValueReferences, "fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)valueReferences; (void)shifts;
    return no_variables_of_type(M, nValueReferences, "fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)counters; (void)resolutions;
    return no_variables_of_type(M, nValueReferences, "fmi3SetShiftFraction");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { UNSUPPORTED3("fmi3EvaluateDiscreteStates"); }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    if (instance && !M->model_exchange)
        UNSUPPORTED3("fmi3UpdateDiscreteStates in co-simulation (hasEventMode is false)");
    int changed = 0;
    fmi3Status status = me_update_discrete_states(M, &changed, "fmi3UpdateDiscreteStates");
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = changed ? fmi3True : fmi3False;
    double next = 0.0;
    int defined = status == fmi3OK && next_event_time(M, &next);
    if (nextEventTimeDefined) *nextEventTimeDefined = defined ? fmi3True : fmi3False;
    if (nextEventTime) *nextEventTime = next;
    return status;
}

/* model exchange */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    if (!instance) return fmi3Error;
    return me_enter_continuous_time_mode(M, "fmi3EnterContinuousTimeMode");
}
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!instance) return fmi3Error;
    if (enterEventMode) *enterEventMode = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    return me_completed_integrator_step(M, "fmi3CompletedIntegratorStep");
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    if (!instance) return fmi3Error;
    return me_set_time(M, time, "fmi3SetTime");
}
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    if (!instance) return fmi3Error;
    return me_set_states(M, continuousStates, nContinuousStates, "fmi3SetContinuousStates");
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    if (!instance) return fmi3Error;
    return me_get_derivatives(M, derivatives, nContinuousStates, "fmi3GetContinuousStateDerivatives");
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    if (!instance) return fmi3Error;
    return me_get_event_indicators(M, eventIndicators, nEventIndicators, "fmi3GetEventIndicators");
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    if (!instance) return fmi3Error;
    return me_get_states(M, continuousStates, nContinuousStates, "fmi3GetContinuousStates");
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates) {
    if (!instance) return fmi3Error;
    return me_get_nominals(M, nominals, nContinuousStates, "fmi3GetNominalsOfContinuousStates");
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    if (!instance || !nEventIndicators) return fmi3Error;
    *nEventIndicators = N_EVENT_INDICATORS;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    if (!instance || !nContinuousStates) return fmi3Error;
    *nContinuousStates = N_STATES;
    return fmi3OK;
}

/* co-simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance instance) { UNSUPPORTED3("fmi3EnterStepMode (no event mode)"); }
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    UNSUPPORTED3("fmi3GetOutputDerivatives");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    (void)noSetFMUStatePriorToCurrentPoint;
    ModelInstance *m = M;
    if (!m) return fmi3Error;
    fmi3Status status = do_step(m, currentCommunicationPoint, communicationStepSize, "fmi3DoStep");
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = m->s->time;
    return status;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    UNSUPPORTED3("fmi3ActivateModelPartition (no scheduled execution)");
}
#endif

/* The FMI layer shared by the native FMUs: the interface between it and a model.
 *
 * The native edition of each FMU is one small model file (in plants/ or fmu_src/) plus
 * fmi_layer.c, compiled once for FMI 2.0 (-DFMI_VERSION=2) and once for FMI 3.0
 * (-DFMI_VERSION=3); each binary serves co-simulation and model exchange (one
 * modelDescription declares both, as the Modelica Reference-FMUs do; the same model
 * functions serve both: docs/model_exchange.md).  The build generates model_variables.h from the
 * Python declaration table (the VARIABLES of each pythonfmu FMU class, see
 * harness/fmu_build/native.py): value references VR_<name>, N_VARIABLES and the table of names,
 * causalities, starts and valid ranges that the layer validates with.
 *
 * The layer mirrors fmu_src/afc_slave_base.py (TableSlave): values in table order,
 * outputs recomputed lazily once their inputs or the state changed, parameters
 * validated when initialisation ends, NaN/inf inputs rejected, the FMU state the
 * whole snapshot (values, internal state, time) and messages worded the same.
 *
 * Messages write every number with %.17g, which reads back to the same double (the Python
 * edition writes the shortest text that does): the two editions' messages have the same words
 * and the same numbers, not the same bytes.  A message is built only when it is logged: no
 * function on the per-step path prepares message buffers.
 */
#ifndef AFC_FMI_LAYER_H
#define AFC_FMI_LAYER_H

#include <stddef.h>

enum { CAUSALITY_PARAMETER = 0, CAUSALITY_INPUT = 1, CAUSALITY_OUTPUT = 2 };

/* One row of the declaration table (generated into model_variables.h). */
typedef struct {
    const char *name;
    int causality;        /* CAUSALITY_* */
    int is_integer;       /* kind "Integer" */
    double start;
    int has_minimum, exclusive_minimum;
    double minimum;
    int has_maximum, exclusive_maximum;
    double maximum;
    const char *valid_range; /* Variable.valid_range() of the Python table */
} VariableInfo;

/* generated: MODEL_IDENTIFIER, MODEL_GUID, N_VARIABLES, VR_<name>, MODEL_FEEDTHROUGH,
 * MODEL_VARIABLES[] (the table); for model exchange N_STATES, N_EVENT_INDICATORS, N_LOCALS and
 * the value references of the variables the description adds after the table (FMI 3.0's time
 * is N_VARIABLES), MODEL_TIME_EVENTS (the model announces time events): der(<state>) from VR_FIRST_DERIVATIVE, the event indicators from
 * VR_FIRST_EVENT_INDICATOR, the model's other locals from VR_FIRST_LOCAL, names in EXTRA_NAMES[] */
#include "model_variables.h"

/* Everything the FMU state holds (afc_slave_base TableSlave._state_names):
 * the variables, time, start time, initialized; the model's internal state
 * (STATE_ATTRIBUTES) follows it in the same allocation. */
typedef struct {
    double time;
    double start_time;
    double initialized;
    double values[N_VARIABLES];
} Snapshot;

typedef struct ModelInstance ModelInstance;

/* The model's view of an instance. */
struct ModelInstance {
    Snapshot *s;           /* values, time: the model reads and writes these */
    void *internal;        /* the model's internal state, MODEL_INTERNAL_BYTES */
    int outputs_stale;     /* outputs must be recomputed before they are read */
    int stale_on_set;      /* setting an input makes the outputs stale */
    int feedthrough;       /* some output depends directly on an input */
    int mode;              /* life-cycle state of the FMI layer */
    int model_exchange;    /* instantiated for model exchange (else co-simulation) */
    int logging_on;
    char *instance_name;
    void *host;            /* the layer's logger and environment */
};

/* Variable access by name: V(m, k1) is the value of variable k1. */
#define V(m, name) ((m)->s->values[VR_##name])

/* Return codes of the model hooks. */
enum { MODEL_OK = 0, MODEL_ERROR = 1 };

/* ---- provided by the model file ---- */
extern const size_t MODEL_INTERNAL_BYTES;
/* constructor: internal state of a fresh instance (TableSlave.__init__ and subclass) */
void model_construct(ModelInstance *m);
/* the state at the end of initialisation (TableSlave.initialize) */
int model_initialize(ModelInstance *m, double start_time);
/* outputs from state and inputs, no side effect on the state (compute_outputs) */
int model_compute_outputs(ModelInstance *m);
/* advance the state from current_time by step_size (step) */
int model_step(ModelInstance *m, double current_time, double step_size);
/* invalid combinations of individually valid parameters (cross_parameter_errors):
 * writes one message into message and returns MODEL_ERROR, else MODEL_OK */
int model_cross_parameter_errors(ModelInstance *m, char *message, size_t size);

/* model exchange (docs/model_exchange.md): the continuous states x (N_STATES values, in the
 * order of the description's derivatives), their derivatives at the instance's time, state and
 * inputs, the event indicators z (N_EVENT_INDICATORS values, > 0 between events), the model's
 * other locals (N_LOCALS values, e.g. a discrete mode), and the event update: the discrete
 * states that follow the state, time and inputs at an event; *states_changed = 1 when it also
 * set continuous states.  A co-simulation instance may be asked for derivatives, indicators
 * and locals too (the variables are in its description): they describe what it integrates. */
int model_get_continuous_states(ModelInstance *m, double x[]);
int model_set_continuous_states(ModelInstance *m, const double x[]);
int model_get_derivatives(ModelInstance *m, double dx[]);
int model_get_event_indicators(ModelInstance *m, double z[]);
int model_get_locals(ModelInstance *m, double values[]);
int model_update_discrete_states(ModelInstance *m, int *states_changed);
#if MODEL_TIME_EVENTS
/* a model that declares time events (ModelExchange.time_events, MODEL_TIME_EVENTS of the generated header):
 * after its event update, 1 and *time = its next event time (model exchange), or 0 for none */
int model_next_event_time(ModelInstance *m, double *time);
#endif

/* A function that only builds and logs a message (a failure, a warning): compiled apart from its caller,
 * so that the caller's per-step path carries none of its buffers. */
#if defined(__GNUC__)
#define MESSAGE_PATH __attribute__((noinline, cold))
#else
#define MESSAGE_PATH
#endif

/* ---- provided by the layer ---- */
/* log message with status Error ("<instance>: message"), return MODEL_ERROR (TableSlave.fail) */
int fmu_fail(ModelInstance *m, const char *format, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
/* log a warning ("<instance>: message") */
void fmu_warn(ModelInstance *m, const char *format, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
/* x[0], ..., x[n-1] as Python writes a tuple, "(a, b)" or "(a,)", or with brackets "[]" a list,
 * each number with %.17g; returns buffer */
const char *numbers_text(char *buffer, size_t size, const double x[], int n, const char *brackets);

#endif

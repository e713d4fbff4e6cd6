/*
 * A plain C host of the pendulum's closed loop (plant -> reference -> controller -> plant), written
 * apart from the master: it loads the three native FMI 2.0 binaries itself (dlopen / LoadLibrary),
 * calls them through their FMI functions and checks every status, with no Python, no plan and no
 * divergence bound.  The benchmark (harness/hosts/bench.py) times it beside our master's compiled
 * loop (harness/master_loop.c) on the same FMUs: what a host of its own would pay for the same calls.
 *
 * The calls are the master's (harness/master.py, feedthrough), in its order:
 *   fmi2Instantiate plant, reference, controller (loggingOn, not visible);
 *   for each: fmi2SetupExperiment(start, stop), fmi2EnterInitializationMode, one fmi2SetReal or
 *   fmi2SetInteger per parameter in the scenario's order;
 *   the initial values along the connections (the row below without recording and without doStep);
 *   fmi2ExitInitializationMode plant, reference, controller;
 *   row n = 0 .. steps - 1 at t = start + n step:
 *       getReal plant (y, dy, d); setReal reference (y, dy); getReal reference (ym, dym, e, de);
 *       setReal controller (e, de, ym, dym); getReal controller (u, E, dE, theta1..4, w_hat);
 *       setReal plant (u); the 15 values read are row n of the record;
 *       fmi2DoStep plant, reference, controller (t, step, noSetFMUStatePriorToCurrentPoint = true);
 *   row steps: the same reads and writes at the stop time, recorded;
 *   fmi2Terminate and fmi2FreeInstance plant, reference, controller.
 * The reads fill the record's row directly: its columns are the master's (plant.y, plant.dy, plant.d,
 * reference.ym, reference.dym, reference.e, reference.de, controller.u, controller.E, controller.dE,
 * controller.theta1..4, controller.w_hat), so tests/test_c_baselines.py compares the two records bit
 * for bit.
 *
 * A status above fmi2Warning stops the host: plain_host_open and plain_host_run return it, and
 * plain_host_message says which call of which FMU failed (at which row) with the FMU's last message.
 */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(_WIN32)
#include <windows.h>
#define EXPORT __declspec(dllexport)
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *library_symbol(Library library, const char *name) { return (void *)GetProcAddress(library, name); }
static void close_library(Library library) { FreeLibrary(library); }
#else
#include <dlfcn.h>
#define EXPORT __attribute__((visibility("default")))
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *library_symbol(Library library, const char *name) { return dlsym(library, name); }
static void close_library(Library library) { dlclose(library); }
#endif

/* the FMI 2.0 types and functions this host calls (fmi2TypesPlatform.h, fmi2FunctionTypes.h) */
typedef void *fmi2Component;
typedef unsigned int fmi2ValueReference;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
enum { fmi2CoSimulation = 1 };
typedef void (*fmi2CallbackLogger)(void *, const char *, int, const char *, const char *, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void *, int);
    void *componentEnvironment;
} fmi2CallbackFunctions;
typedef fmi2Component (*Instantiate)(const char *, int, const char *, const char *, const fmi2CallbackFunctions *,
                                     int, int);
typedef int (*SetupExperiment)(fmi2Component, int, double, double, int, double);
typedef int (*ComponentCall)(fmi2Component);
typedef void (*FreeInstance)(fmi2Component);
typedef int (*GetReal)(fmi2Component, const fmi2ValueReference *, size_t, double *);
typedef int (*SetReal)(fmi2Component, const fmi2ValueReference *, size_t, const double *);
typedef int (*SetInteger)(fmi2Component, const fmi2ValueReference *, size_t, const int *);
typedef int (*DoStep)(fmi2Component, double, double, int);

/* One FMU as the host is told of it (harness/hosts/c_baselines.py reads it from the scenario and the
 * modelDescription): its binary, identity and parameters in the scenario's order. */
typedef struct {
    const char *library;                   /* binaries/<platform>/<modelIdentifier>.so */
    const char *guid;
    const char *resources;                 /* file URI of the extracted FMU's resources folder */
    const char *name;                      /* instance name */
    size_t parameters;
    const char *parameter_kinds;           /* 'r' (fmi2SetReal) or 'i' (fmi2SetInteger), one per parameter */
    const fmi2ValueReference *parameter_references;
    const double *parameter_values;
} HostFmu;

/* The closed loop: the three FMUs and the value references of its connections and records. */
typedef struct {
    HostFmu plant, reference, controller;
    fmi2ValueReference plant_outputs[3];      /* y, dy, d */
    fmi2ValueReference plant_input[1];        /* u */
    fmi2ValueReference reference_inputs[2];   /* y, dy */
    fmi2ValueReference reference_outputs[4];  /* ym, dym, e, de */
    fmi2ValueReference controller_inputs[4];  /* e, de, ym, dym */
    fmi2ValueReference controller_outputs[8]; /* u, E, dE, theta1, theta2, theta3, theta4, w_hat */
    double start, stop, step;
} HostSystem;

enum { COLUMNS = 15, PLANT_COLUMN = 0, REFERENCE_COLUMN = 3, CONTROLLER_COLUMN = 7 };

typedef struct {
    Library library;
    fmi2Component instance;
    const char *name;
    SetupExperiment setup_experiment;
    ComponentCall enter_initialization, exit_initialization, terminate;
    FreeInstance free_instance;
    GetReal get_real;
    SetReal set_real;
    SetInteger set_integer;
    DoStep do_step;
} Fmu;

typedef struct {
    HostSystem system;
    Fmu plant, reference, controller;
    fmi2CallbackFunctions callbacks;
    char message[1024];      /* what stopped the host */
    char last_log[1024];     /* the FMUs' last message */
} Host;

enum { HOST_OK = 0, HOST_LOAD_FAILED = -1 };

/* the FMUs' messages: the last one is kept for the report of a failed call (the FMI layer begins it with the
 * instance's name) */
static void logger(void *environment, const char *instance, int status, const char *category, const char *format, ...) {
    Host *host = (Host *)environment;
    va_list args;
    (void)instance; (void)status; (void)category;
    va_start(args, format);
    vsnprintf(host->last_log, sizeof host->last_log, format, args);
    va_end(args);
}

/* the status of `call` of `fmu`, said in host->message when it is above fmi2Warning */
static int checked(Host *host, const Fmu *fmu, const char *call, int status, int64_t row) {
    if (status <= fmi2Warning) return HOST_OK;
    if (row >= 0)
        snprintf(host->message, sizeof host->message, "%s of %s returned %d at row %lld: %s", call, fmu->name, status,
                 (long long)row, host->last_log);
    else
        snprintf(host->message, sizeof host->message, "%s of %s returned %d: %s", call, fmu->name, status,
                 host->last_log);
    return status;
}

#define CHECK(fmu, call, expression, row)                                               \
    do {                                                                                \
        int status_ = checked(host, fmu, call, (expression), row);                      \
        if (status_ != HOST_OK) return status_;                                         \
    } while (0)

static void *symbol(Host *host, Fmu *fmu, const char *name, int *missing) {
    void *found = library_symbol(fmu->library, name);
    if (!found && !*missing) {
        snprintf(host->message, sizeof host->message, "%s: the binary has no %s", fmu->name, name);
        *missing = 1;
    }
    return found;
}

static int load(Host *host, Fmu *fmu, const HostFmu *given) {
    fmu->name = given->name;
    fmu->library = open_library(given->library);
    if (!fmu->library) {
        snprintf(host->message, sizeof host->message, "%s: cannot load %s", given->name, given->library);
        return HOST_LOAD_FAILED;
    }
    int missing = 0;
    Instantiate instantiate = (Instantiate)symbol(host, fmu, "fmi2Instantiate", &missing);
    fmu->setup_experiment = (SetupExperiment)symbol(host, fmu, "fmi2SetupExperiment", &missing);
    fmu->enter_initialization = (ComponentCall)symbol(host, fmu, "fmi2EnterInitializationMode", &missing);
    fmu->exit_initialization = (ComponentCall)symbol(host, fmu, "fmi2ExitInitializationMode", &missing);
    fmu->terminate = (ComponentCall)symbol(host, fmu, "fmi2Terminate", &missing);
    fmu->free_instance = (FreeInstance)symbol(host, fmu, "fmi2FreeInstance", &missing);
    fmu->get_real = (GetReal)symbol(host, fmu, "fmi2GetReal", &missing);
    fmu->set_real = (SetReal)symbol(host, fmu, "fmi2SetReal", &missing);
    fmu->set_integer = (SetInteger)symbol(host, fmu, "fmi2SetInteger", &missing);
    fmu->do_step = (DoStep)symbol(host, fmu, "fmi2DoStep", &missing);
    if (missing) return HOST_LOAD_FAILED;
    fmu->instance = instantiate(given->name, fmi2CoSimulation, given->guid, given->resources, &host->callbacks, 0, 1);
    if (!fmu->instance) {
        snprintf(host->message, sizeof host->message, "fmi2Instantiate of %s failed: %s", given->name, host->last_log);
        return HOST_LOAD_FAILED;
    }
    return HOST_OK;
}

static int set_parameters(Host *host, const Fmu *fmu, const HostFmu *given) {
    for (size_t k = 0; k < given->parameters; k++) {
        const fmi2ValueReference *reference = &given->parameter_references[k];
        if (given->parameter_kinds[k] == 'i') {
            int value = (int)given->parameter_values[k];
            CHECK(fmu, "fmi2SetInteger", fmu->set_integer(fmu->instance, reference, 1, &value), -1);
        } else {
            CHECK(fmu, "fmi2SetReal", fmu->set_real(fmu->instance, reference, 1, &given->parameter_values[k]), -1);
        }
    }
    return HOST_OK;
}

/* the reads and writes of one communication point; the values read go to row[] (15 columns) */
static inline int communication_point(Host *host, double *row, int64_t n) {
    const HostSystem *s = &host->system;
    Fmu *plant = &host->plant, *reference = &host->reference, *controller = &host->controller;
    CHECK(plant, "fmi2GetReal", plant->get_real(plant->instance, s->plant_outputs, 3, row + PLANT_COLUMN), n);
    CHECK(reference, "fmi2SetReal", reference->set_real(reference->instance, s->reference_inputs, 2,
                                                        row + PLANT_COLUMN), n); /* y, dy */
    CHECK(reference, "fmi2GetReal", reference->get_real(reference->instance, s->reference_outputs, 4,
                                                        row + REFERENCE_COLUMN), n);
    const double *ref = row + REFERENCE_COLUMN;
    double errors_and_reference[4] = {ref[2], ref[3], ref[0], ref[1]}; /* e, de, ym, dym */
    CHECK(controller, "fmi2SetReal", controller->set_real(controller->instance, s->controller_inputs, 4,
                                                          errors_and_reference), n);
    CHECK(controller, "fmi2GetReal", controller->get_real(controller->instance, s->controller_outputs, 8,
                                                          row + CONTROLLER_COLUMN), n);
    CHECK(plant, "fmi2SetReal", plant->set_real(plant->instance, s->plant_input, 1, row + CONTROLLER_COLUMN), n); /* u */
    return HOST_OK;
}

EXPORT const char *plain_host_message(const Host *host) { return host ? host->message : "out of memory"; }

/* load, instantiate and initialise the three FMUs; *opened is the host (free it with plain_host_close,
 * also after a failure) */
EXPORT int plain_host_open(const HostSystem *system, Host **opened) {
    Host *host = (Host *)calloc(1, sizeof(Host));
    *opened = host;
    if (!host) return HOST_LOAD_FAILED;
    host->system = *system;
    host->callbacks.logger = logger;
    host->callbacks.allocateMemory = calloc;
    host->callbacks.freeMemory = free;
    host->callbacks.componentEnvironment = host;
    int status;
    if ((status = load(host, &host->plant, &system->plant)) != HOST_OK) return status;
    if ((status = load(host, &host->reference, &system->reference)) != HOST_OK) return status;
    if ((status = load(host, &host->controller, &system->controller)) != HOST_OK) return status;
    Fmu *fmus[3] = {&host->plant, &host->reference, &host->controller};
    const HostFmu *given[3] = {&system->plant, &system->reference, &system->controller};
    for (int i = 0; i < 3; i++) {
        Fmu *fmu = fmus[i];
        CHECK(fmu, "fmi2SetupExperiment", fmu->setup_experiment(fmu->instance, 0, 0.0, system->start, 1, system->stop),
              -1);
        CHECK(fmu, "fmi2EnterInitializationMode", fmu->enter_initialization(fmu->instance), -1);
        if ((status = set_parameters(host, fmu, given[i])) != HOST_OK) return status;
    }
    double initial[COLUMNS];
    if ((status = communication_point(host, initial, -1)) != HOST_OK) return status;
    for (int i = 0; i < 3; i++)
        CHECK(fmus[i], "fmi2ExitInitializationMode", fmus[i]->exit_initialization(fmus[i]->instance), -1);
    return HOST_OK;
}

/* rows 0 .. steps of the record (steps + 1 rows of 15 columns): the fixed-step loop */
EXPORT int plain_host_run(Host *host, int64_t steps, double *record) {
    const double start = host->system.start, step = host->system.step;
    Fmu *plant = &host->plant, *reference = &host->reference, *controller = &host->controller;
    int status;
    for (int64_t n = 0; n < steps; n++) {
        double t = start + (double)n * step;
        if ((status = communication_point(host, record + (size_t)n * COLUMNS, n)) != HOST_OK) return status;
        CHECK(plant, "fmi2DoStep", plant->do_step(plant->instance, t, step, 1), n);
        CHECK(reference, "fmi2DoStep", reference->do_step(reference->instance, t, step, 1), n);
        CHECK(controller, "fmi2DoStep", controller->do_step(controller->instance, t, step, 1), n);
    }
    return communication_point(host, record + (size_t)steps * COLUMNS, steps);
}

/* fmi2Terminate and fmi2FreeInstance of every FMU instantiated, then the libraries; returns the first
 * failed fmi2Terminate's status (said in the message), else HOST_OK */
EXPORT int plain_host_close(Host *host) {
    if (!host) return HOST_OK;
    int result = HOST_OK;
    Fmu *fmus[3] = {&host->plant, &host->reference, &host->controller};
    for (int i = 0; i < 3; i++) {
        Fmu *fmu = fmus[i];
        if (fmu->instance) {
            int status = checked(host, fmu, "fmi2Terminate", fmu->terminate(fmu->instance), -1);
            if (result == HOST_OK) result = status;
            fmu->free_instance(fmu->instance);
        }
        if (fmu->library) close_library(fmu->library);
    }
    free(host);
    return result;
}

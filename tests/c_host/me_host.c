/*
 * A minimal FMI Model Exchange host in C (FMI 2.0, or FMI 3.0 for a library that exports
 * fmi3InstantiateModelExchange and not fmi2Instantiate): it integrates one FMU alone with
 * fixed-step classical RK4 through SetTime / SetContinuousStates / GetDerivatives, and handles
 * events at the step ends (an event indicator that went from > 0 to <= 0, or an input that
 * changed).  tests/test_native_windows.py builds it for Linux and for Windows and compares
 * the win64 DLLs' Model Exchange under wine with the linux64 binaries.
 *
 *   me_host LIBRARY RESOURCE GUID STEP NX NZ INPUT_VRS OUTPUT_VRS [r:VR=VALUE | i:VR=VALUE]... < INPUTS
 *
 *   LIBRARY, RESOURCE, GUID   as tests/c_host/host.c (RESOURCE: a URI for FMI 2.0, a path for 3.0)
 *   STEP          the RK4 step in s
 *   NX, NZ        numberOfContinuousStates, numberOfEventIndicators of the description
 *   INPUT_VRS     comma-separated value references of the Real inputs ("-" for none)
 *   OUTPUT_VRS    comma-separated value references of the Real variables to print
 *   INPUTS        on stdin, one line per step: one number per input (the inputs over that step)
 *
 * Per line: set the inputs (an event if any changed), print the outputs and then the states
 * (%.17g, one line), one RK4 step, completedIntegratorStep, the event indicators.
 * Exit status: 0 all calls returned OK; 1 usage; 2 loading the library or a symbol failed;
 * 3 a call returned Error or worse (reported on stderr).
 */
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <fcntl.h>
#include <io.h>
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *library_symbol(Library library, const char *name) { return (void *)GetProcAddress(library, name); }
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *library_symbol(Library library, const char *name) { return dlsym(library, name); }
#endif

#define MAX 256

typedef struct {
    void (*logger)(void *, const char *, int, const char *, const char *, ...);
    void *(*allocate)(size_t, size_t);
    void (*release)(void *);
    void *step_finished;
    void *environment;
} Callbacks2;

typedef struct {
    int new_discrete_states_needed, terminate, nominals_changed, values_changed, next_time_defined;
    double next_time;
} EventInfo2;

static Library library;
static bool fmi3;
static void *instance;

static void *symbol(const char *name)
{
    void *found = library_symbol(library, name);
    if (!found) {
        fprintf(stderr, "me_host: missing symbol %s\n", name);
        exit(2);
    }
    return found;
}

static void check(int status, const char *call)
{
    if (status < 3) return;
    fprintf(stderr, "me_host: %s returned %d\n", call, status);
    exit(3);
}

static void logger2(void *env, const char *name, int status, const char *category, const char *message, ...)
{
    (void)env; (void)category;
    fprintf(stderr, "[%d] %s: %s\n", status, name, message);
}

static void logger3(void *env, int status, const char *category, const char *message)
{
    (void)env; (void)category;
    fprintf(stderr, "[%d] %s\n", status, message);
}

/* the calls, one signature for both versions */
static void set_reals(const unsigned *vr, size_t n, const double *values)
{
    if (n == 0) return;
    if (fmi3)
        check(((int (*)(void *, const unsigned *, size_t, const double *, size_t))symbol("fmi3SetFloat64"))(
                  instance, vr, n, values, n), "SetFloat64");
    else
        check(((int (*)(void *, const unsigned *, size_t, const double *))symbol("fmi2SetReal"))(instance, vr, n, values),
              "SetReal");
}

static void get_reals(const unsigned *vr, size_t n, double *values)
{
    if (fmi3)
        check(((int (*)(void *, const unsigned *, size_t, double *, size_t))symbol("fmi3GetFloat64"))(
                  instance, vr, n, values, n), "GetFloat64");
    else
        check(((int (*)(void *, const unsigned *, size_t, double *))symbol("fmi2GetReal"))(instance, vr, n, values),
              "GetReal");
}

static void set_integer(unsigned vr, int value)
{
    if (fmi3)
        check(((int (*)(void *, const unsigned *, size_t, const int *, size_t))symbol("fmi3SetInt32"))(
                  instance, &vr, 1, &value, 1), "SetInt32");
    else
        check(((int (*)(void *, const unsigned *, size_t, const int *))symbol("fmi2SetInteger"))(instance, &vr, 1, &value),
              "SetInteger");
}

static void call(const char *name2, const char *name3)
{
    check(((int (*)(void *))symbol(fmi3 ? name3 : name2))(instance), fmi3 ? name3 : name2);
}

static void set_time(double t)
{
    check(((int (*)(void *, double))symbol(fmi3 ? "fmi3SetTime" : "fmi2SetTime"))(instance, t), "SetTime");
}

static void states_call(const char *name2, const char *name3, double *x, size_t n)
{
    check(((int (*)(void *, double *, size_t))symbol(fmi3 ? name3 : name2))(instance, x, n), fmi3 ? name3 : name2);
}

static void set_states(const double *x, size_t n)
{
    check(((int (*)(void *, const double *, size_t))symbol(fmi3 ? "fmi3SetContinuousStates" : "fmi2SetContinuousStates"))(
              instance, x, n), "SetContinuousStates");
}

/* the event iteration; then continuous-time mode */
static void event_iteration(bool enter_event_mode)
{
    if (enter_event_mode) call("fmi2EnterEventMode", "fmi3EnterEventMode");
    for (int again = 1; again;) {
        if (fmi3) {
            bool need, terminate, nominals, values, defined;
            double next;
            check(((int (*)(void *, bool *, bool *, bool *, bool *, bool *, double *))symbol("fmi3UpdateDiscreteStates"))(
                      instance, &need, &terminate, &nominals, &values, &defined, &next), "UpdateDiscreteStates");
            again = need;
        } else {
            EventInfo2 info;
            check(((int (*)(void *, EventInfo2 *))symbol("fmi2NewDiscreteStates"))(instance, &info), "NewDiscreteStates");
            again = info.new_discrete_states_needed;
        }
    }
    call("fmi2EnterContinuousTimeMode", "fmi3EnterContinuousTimeMode");
}

static size_t parse_list(char *text, unsigned *out)
{
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    for (char *token = strtok(text, ","); token && n < MAX; token = strtok(NULL, ",")) out[n++] = (unsigned)strtoul(token, NULL, 10);
    return n;
}

static int read_row(double *row, size_t n)
{
    for (size_t k = 0; k < n; k++)
        if (scanf("%lf", &row[k]) != 1) return 0;
    return 1;
}

int main(int argc, char **argv)
{
    if (argc < 9) {
        fprintf(stderr, "usage: %s LIBRARY RESOURCE GUID STEP NX NZ INPUT_VRS OUTPUT_VRS [r:VR=V | i:VR=V]... < INPUTS\n",
                argv[0]);
        return 1;
    }
#ifdef _WIN32
    _setmode(_fileno(stdout), _O_BINARY);
#endif
    double h = strtod(argv[4], NULL);
    size_t nx = strtoul(argv[5], NULL, 10), nz = strtoul(argv[6], NULL, 10);
    unsigned inputs[MAX], outputs[MAX];
    size_t ni = parse_list(argv[7], inputs), no = parse_list(argv[8], outputs);
    library = open_library(argv[1]);
    if (!library) {
        fprintf(stderr, "me_host: loading %s failed\n", argv[1]);
        return 2;
    }
    fmi3 = !library_symbol(library, "fmi2Instantiate") && library_symbol(library, "fmi3InstantiateModelExchange");
    if (fmi3) {
        instance = ((void *(*)(const char *, const char *, const char *, bool, bool, void *,
                               void (*)(void *, int, const char *, const char *)))symbol("fmi3InstantiateModelExchange"))(
            "me_host", argv[3], argv[2], false, true, NULL, logger3);
    } else {
        static Callbacks2 callbacks = {logger2, calloc, free, NULL, NULL};
        instance = ((void *(*)(const char *, int, const char *, const char *, const Callbacks2 *, int, int))symbol(
            "fmi2Instantiate"))("me_host", 0 /* fmi2ModelExchange */, argv[3], argv[2], &callbacks, 0, 1);
    }
    if (!instance) {
        fprintf(stderr, "me_host: instantiation failed\n");
        return 3;
    }
    if (fmi3) {
        check(((int (*)(void *, bool, double, double, bool, double))symbol("fmi3EnterInitializationMode"))(
                  instance, false, 0.0, 0.0, false, 0.0), "EnterInitializationMode");
    } else {
        check(((int (*)(void *, int, double, double, int, double))symbol("fmi2SetupExperiment"))(instance, 0, 0.0, 0.0, 0,
                                                                                                  0.0), "SetupExperiment");
        call("fmi2EnterInitializationMode", "-");
    }
    for (int k = 9; k < argc; k++) {
        char kind, value[64];
        unsigned vr;
        if (sscanf(argv[k], "%c:%u=%63s", &kind, &vr, value) != 3) return 1;
        if (kind == 'r') {
            double real = strtod(value, NULL);
            set_reals(&vr, 1, &real);
        } else {
            set_integer(vr, (int)strtol(value, NULL, 10));
        }
    }
    double row[MAX], previous[MAX], x[MAX], x0[MAX], k[4][MAX], z[MAX], z_next[MAX], values[MAX];
    int have = read_row(row, ni);
    if (have) set_reals(inputs, ni, row);
    call("fmi2ExitInitializationMode", "fmi3ExitInitializationMode");
    event_iteration(false);
    memcpy(previous, row, sizeof(double) * ni);
    if (nz) states_call("fmi2GetEventIndicators", "fmi3GetEventIndicators", z, nz);
    for (long n = 0; have; n++) {
        double t = (double)n * h;
        set_reals(inputs, ni, row);
        if (n > 0 && memcmp(row, previous, sizeof(double) * ni) != 0) { /* an input event */
            event_iteration(true);
            if (nz) states_call("fmi2GetEventIndicators", "fmi3GetEventIndicators", z, nz);
        }
        memcpy(previous, row, sizeof(double) * ni);
        get_reals(outputs, no, values);
        if (nx) states_call("fmi2GetContinuousStates", "fmi3GetContinuousStates", x0, nx);
        for (size_t i = 0; i < no; i++) printf("%.17g ", values[i]);
        for (size_t i = 0; i < nx; i++) printf("%.17g ", x0[i]);
        printf("\n");
        /* classical RK4 from t to t + h with the inputs held */
        static const double c[4] = {0.0, 0.5, 0.5, 1.0};
        for (int s = 0; s < 4; s++) {
            for (size_t i = 0; i < nx; i++) x[i] = s == 0 ? x0[i] : x0[i] + c[s] * h * k[s - 1][i];
            set_time(t + c[s] * h);
            if (nx) set_states(x, nx);
            if (nx) states_call("fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives", k[s], nx);
        }
        for (size_t i = 0; i < nx; i++) x[i] = x0[i] + h / 6.0 * (k[0][i] + 2.0 * (k[1][i] + k[2][i]) + k[3][i]);
        set_time(t + h);
        if (nx) set_states(x, nx);
        if (fmi3) {
            bool enter, terminate;
            check(((int (*)(void *, bool, bool *, bool *))symbol("fmi3CompletedIntegratorStep"))(instance, true, &enter,
                                                                                                 &terminate),
                  "CompletedIntegratorStep");
        } else {
            int enter, terminate;
            check(((int (*)(void *, int, int *, int *))symbol("fmi2CompletedIntegratorStep"))(instance, 1, &enter,
                                                                                              &terminate),
                  "CompletedIntegratorStep");
        }
        if (nz) {
            states_call("fmi2GetEventIndicators", "fmi3GetEventIndicators", z_next, nz);
            int crossed = 0;
            for (size_t i = 0; i < nz; i++) crossed = crossed || (z[i] > 0.0 && z_next[i] <= 0.0);
            if (crossed) {
                event_iteration(true);
                states_call("fmi2GetEventIndicators", "fmi3GetEventIndicators", z_next, nz);
            }
            memcpy(z, z_next, sizeof(double) * nz);
        }
        have = read_row(row, ni);
    }
    call("fmi2Terminate", "fmi3Terminate");
    ((void (*)(void *))symbol(fmi3 ? "fmi3FreeInstance" : "fmi2FreeInstance"))(instance);
    fflush(stdout);
    return 0;
}

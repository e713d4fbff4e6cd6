/*
 * A minimal FMI 2.0 co-simulation host in C: it runs one FMU's shared library
 * without any Python on the host side (the pythonfmu binary embeds CPython).
 * It runs an FMI 3.0 co-simulation library too (one that exports fmi3InstantiateCoSimulation
 * and not fmi2Instantiate), with the FMI 3.0 counterparts of the same calls.
 *
 *   host LIBRARY RESOURCE_URI GUID STEP INPUT_VRS OUTPUT_VRS [r:VR=VALUE | i:VR=VALUE]... < INPUTS
 *
 *   LIBRARY       binaries/linux64/<modelIdentifier>.so of the extracted FMU (on Windows,
 *                 binaries\win64\<modelIdentifier>.dll)
 *   RESOURCE_URI  file:///.../resources of the extracted FMU (FMI 3.0: the resources folder's path)
 *   GUID          the guid attribute of modelDescription.xml (FMI 3.0: instantiationToken)
 *   STEP          communication step in s
 *   INPUT_VRS     comma-separated value references of the Real inputs, e.g. 18,19,20,21
 *   OUTPUT_VRS    value reference of the Real output to print, e.g. 22, or comma-separated
 *                 references of several (printed on one line, separated by a space)
 *   r:VR=VALUE    set a Real parameter; i:VR=VALUE an Integer parameter
 *   INPUTS        on stdin, one line per communication point: one number per input
 *
 * Sequence: fmi2Instantiate, fmi2SetupExperiment(start 0), fmi2EnterInitializationMode,
 * the parameters, the first input line, fmi2ExitInitializationMode; then for each line
 * n: set the inputs, get the outputs and print them (%.17g, one line per step), fmi2DoStep(n*STEP,
 * STEP); finally fmi2Terminate and fmi2FreeInstance.  The FMU's log goes to stderr.
 *
 * Exit status: 0 all calls returned fmi2OK; 1 usage; 2 loading the library or a symbol failed;
 * 3 an FMI call returned a status >= fmi2Error (reported on stderr; the instance is
 * then freed and the host exits normally, which shows that it survived the error).
 *
 * Build and run (tests/test_c_host.py does this):
 *   cc -O2 -o host tests/c_host/host.c -ldl
 *   LD_PRELOAD=$LIBPYTHON PYTHONHOME=$PREFIX ./host ...
 * The pythonfmu binary does not link libpython, so libpython must be loaded first.
 *
 * The same file builds a Windows host (LoadLibrary/GetProcAddress instead of dlopen/dlsym),
 * which runs the native edition's win64 DLLs, e.g. under wine (tests/test_build_native_windows.py):
 *   python -m ziglang cc -target x86_64-windows-gnu -O2 -o host.exe tests/c_host/host.c
 *   wine64 host.exe binaries\win64\InvertedPendulum.dll ...
 * Its standard output is in binary mode, so its lines are the Linux host's, byte for byte.
 */
#include <stdarg.h>
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
static const char *library_error(void)
{
    static char text[64];
    snprintf(text, sizeof text, "Windows error %lu", (unsigned long)GetLastError());
    return text;
}
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *library_symbol(Library library, const char *name) { return dlsym(library, name); }
static const char *library_error(void) { return dlerror(); }
#endif

/* the few FMI 2.0 types this host needs (fmi2TypesPlatform.h, fmi2FunctionTypes.h) */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String,
                                   fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);

typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*InstantiateT)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                      const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef fmi2Status (*SetupExperimentT)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean,
                                       fmi2Real);
typedef fmi2Status (*ComponentT)(fmi2Component);
typedef void (*FreeInstanceT)(fmi2Component);
typedef fmi2Status (*SetRealT)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Real *);
typedef fmi2Status (*GetRealT)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
typedef fmi2Status (*SetIntegerT)(fmi2Component, const fmi2ValueReference *, size_t,
                                  const fmi2Integer *);
typedef fmi2Status (*DoStepT)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);

/* the FMI 3.0 functions this host needs (fmi3FunctionTypes.h); fmi3Status has fmi2Status's codes */
typedef void (*fmi3LogMessageCallback)(void *, int, const char *, const char *);
typedef void *(*Instantiate3T)(const char *, const char *, const char *, bool, bool, bool, bool,
                               const unsigned *, size_t, void *, fmi3LogMessageCallback, void *);
typedef int (*EnterInitialization3T)(void *, bool, double, double, bool, double);
typedef int (*SetFloat64T)(void *, const unsigned *, size_t, const double *, size_t);
typedef int (*GetFloat64T)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*SetInt32T)(void *, const unsigned *, size_t, const int *, size_t);
typedef int (*DoStep3T)(void *, double, double, bool, bool *, bool *, bool *, double *);

static EnterInitialization3T enter_init3;
static SetFloat64T set_float64;
static GetFloat64T get_float64;
static SetInt32T set_int32;
static DoStep3T do_step3;

/* the FMI 3.0 calls behind the FMI 2.0 signatures of the host's sequence */
static fmi2Status setup3(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real start, fmi2Boolean d, fmi2Real e)
{
    (void)c; (void)a; (void)b; (void)start; (void)d; (void)e;
    return fmi2OK; /* the start time (0) goes with fmi3EnterInitializationMode */
}
static fmi2Status enter3(fmi2Component c) { return (fmi2Status)enter_init3(c, false, 0.0, 0.0, false, 0.0); }
static fmi2Status set_real3(fmi2Component c, const fmi2ValueReference *vr, size_t n, const fmi2Real *v)
{
    return (fmi2Status)set_float64(c, vr, n, v, n);
}
static fmi2Status get_real3(fmi2Component c, const fmi2ValueReference *vr, size_t n, fmi2Real *v)
{
    return (fmi2Status)get_float64(c, vr, n, v, n);
}
static fmi2Status set_integer3(fmi2Component c, const fmi2ValueReference *vr, size_t n, const fmi2Integer *v)
{
    return (fmi2Status)set_int32(c, vr, n, v, n);
}
static fmi2Status do_step_3(fmi2Component c, fmi2Real time, fmi2Real step, fmi2Boolean no_set_prior)
{
    bool event_needed, terminate, early_return;
    double last_time;
    return (fmi2Status)do_step3(c, time, step, no_set_prior != 0, &event_needed, &terminate, &early_return,
                                &last_time);
}

#define MAX_INPUTS 16
#define MAX_OUTPUTS 16

static const char *STATUS[] = {"OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"};

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    char text[4096];
    va_list args;
    (void)env;
    (void)category;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    fprintf(stderr, "[%s] %s: %s\n", (unsigned)status < 6 ? STATUS[status] : "?",
            instance ? instance : "", text);
}

static void logger3(void *env, int status, const char *category, const char *message)
{
    (void)env;
    (void)category;
    fprintf(stderr, "[%s] c_host: %s\n", (unsigned)status < 6 ? STATUS[status] : "?", message);
}

static void *symbol(Library library, const char *name)
{
    void *found = library_symbol(library, name);
    if (!found) {
        fprintf(stderr, "host: missing symbol %s: %s\n", name, library_error());
        exit(2);
    }
    return found;
}

static FreeInstanceT free_instance;
static fmi2Component instance;

/* report a failed call, free the instance (the host must survive it) and stop */
static void check(fmi2Status status, const char *function)
{
    if (status < fmi2Error)
        return;
    fprintf(stderr, "host: %s returned %s\n", function,
            (unsigned)status < 6 ? STATUS[status] : "?");
    free_instance(instance);
    fprintf(stderr, "host: instance freed after the error; exiting normally\n");
    exit(3);
}

static int read_inputs(double *values, int count)
{
    for (int k = 0; k < count; k++)
        if (scanf("%lf", &values[k]) != 1)
            return 0;
    return 1;
}

int main(int argc, char **argv)
{
    if (argc < 7) {
        fprintf(stderr, "usage: %s LIBRARY RESOURCE_URI GUID STEP INPUT_VRS OUTPUT_VRS "
                        "[r:VR=VALUE | i:VR=VALUE]... < INPUTS\n", argv[0]);
        return 1;
    }
    const char *library_path = argv[1], *resources = argv[2], *guid = argv[3];
    double step = strtod(argv[4], NULL);
    fmi2ValueReference inputs[MAX_INPUTS], outputs[MAX_OUTPUTS];
    int input_count = 0, output_count = 0;
    for (char *token = strtok(argv[5], ","); token && input_count < MAX_INPUTS; token = strtok(NULL, ","))
        inputs[input_count++] = (fmi2ValueReference)strtoul(token, NULL, 10);
    for (char *token = strtok(argv[6], ","); token && output_count < MAX_OUTPUTS; token = strtok(NULL, ","))
        outputs[output_count++] = (fmi2ValueReference)strtoul(token, NULL, 10);
#ifdef _WIN32
    _setmode(_fileno(stdout), _O_BINARY); /* "\n", not "\r\n": the Linux host's bytes */
#endif

    Library library = open_library(library_path);
    if (!library) {
        fprintf(stderr, "host: loading %s failed: %s\n", library_path, library_error());
        return 2;
    }
    const bool fmi3 = !library_symbol(library, "fmi2Instantiate")
                      && library_symbol(library, "fmi3InstantiateCoSimulation");
#define NAME(fmi2_name, fmi3_name) (fmi3 ? fmi3_name : fmi2_name)
    SetupExperimentT setup;
    ComponentT enter_init, exit_init, terminate;
    SetRealT set_real;
    GetRealT get_real;
    SetIntegerT set_integer;
    DoStepT do_step;
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    if (fmi3) {
        Instantiate3T instantiate = (Instantiate3T)symbol(library, "fmi3InstantiateCoSimulation");
        enter_init3 = (EnterInitialization3T)symbol(library, "fmi3EnterInitializationMode");
        set_float64 = (SetFloat64T)symbol(library, "fmi3SetFloat64");
        get_float64 = (GetFloat64T)symbol(library, "fmi3GetFloat64");
        set_int32 = (SetInt32T)symbol(library, "fmi3SetInt32");
        do_step3 = (DoStep3T)symbol(library, "fmi3DoStep");
        exit_init = (ComponentT)symbol(library, "fmi3ExitInitializationMode");
        terminate = (ComponentT)symbol(library, "fmi3Terminate");
        free_instance = (FreeInstanceT)symbol(library, "fmi3FreeInstance");
        setup = setup3, enter_init = enter3, set_real = set_real3, get_real = get_real3;
        set_integer = set_integer3, do_step = do_step_3;
        instance = instantiate("c_host", guid, resources, false, true, false, false, NULL, 0, NULL, logger3, NULL);
    } else {
        InstantiateT instantiate = (InstantiateT)symbol(library, "fmi2Instantiate");
        setup = (SetupExperimentT)symbol(library, "fmi2SetupExperiment");
        enter_init = (ComponentT)symbol(library, "fmi2EnterInitializationMode");
        exit_init = (ComponentT)symbol(library, "fmi2ExitInitializationMode");
        terminate = (ComponentT)symbol(library, "fmi2Terminate");
        set_real = (SetRealT)symbol(library, "fmi2SetReal");
        get_real = (GetRealT)symbol(library, "fmi2GetReal");
        set_integer = (SetIntegerT)symbol(library, "fmi2SetInteger");
        do_step = (DoStepT)symbol(library, "fmi2DoStep");
        free_instance = (FreeInstanceT)symbol(library, "fmi2FreeInstance");
        instance = instantiate("c_host", fmi2CoSimulation, guid, resources, &callbacks, 0, 1);
    }
    if (!instance) {
        fprintf(stderr, "host: %s failed\n", NAME("fmi2Instantiate", "fmi3InstantiateCoSimulation"));
        return 3;
    }
    check(setup(instance, 0, 0.0, 0.0, 0, 0.0), NAME("fmi2SetupExperiment", "-"));
    check(enter_init(instance), NAME("fmi2EnterInitializationMode", "fmi3EnterInitializationMode"));
    for (int k = 7; k < argc; k++) {
        char kind;
        unsigned vr;
        char value[64];
        if (sscanf(argv[k], "%c:%u=%63s", &kind, &vr, value) != 3 || (kind != 'r' && kind != 'i')) {
            fprintf(stderr, "host: bad parameter argument %s (want r:VR=VALUE or i:VR=VALUE)\n", argv[k]);
            free_instance(instance);
            return 1;
        }
        fmi2ValueReference reference = vr;
        if (kind == 'r') {
            fmi2Real real = strtod(value, NULL);
            check(set_real(instance, &reference, 1, &real), NAME("fmi2SetReal (parameter)", "fmi3SetFloat64 (parameter)"));
        } else {
            fmi2Integer integer = (fmi2Integer)strtol(value, NULL, 10);
            check(set_integer(instance, &reference, 1, &integer), NAME("fmi2SetInteger (parameter)", "fmi3SetInt32 (parameter)"));
        }
    }
    double row[MAX_INPUTS];
    int have_row = read_inputs(row, input_count);
    if (have_row)
        check(set_real(instance, inputs, (size_t)input_count, row), NAME("fmi2SetReal (start inputs)", "fmi3SetFloat64 (start inputs)"));
    check(exit_init(instance), NAME("fmi2ExitInitializationMode", "fmi3ExitInitializationMode"));
    for (long n = 0; have_row; n++) {
        double time = (double)n * step, values[MAX_OUTPUTS];
        check(set_real(instance, inputs, (size_t)input_count, row), NAME("fmi2SetReal", "fmi3SetFloat64"));
        check(get_real(instance, outputs, (size_t)output_count, values), NAME("fmi2GetReal", "fmi3GetFloat64"));
        for (int k = 0; k < output_count; k++)
            printf(k + 1 < output_count ? "%.17g " : "%.17g\n", values[k]);
        check(do_step(instance, time, step, 1), NAME("fmi2DoStep", "fmi3DoStep"));
        have_row = read_inputs(row, input_count);
    }
    check(terminate(instance), NAME("fmi2Terminate", "fmi3Terminate"));
    free_instance(instance);
    fflush(stdout);
    return 0;
}

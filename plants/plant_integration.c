/* Fixed-step classical RK4: see plant_integration.py.  internal_step_count is here; rk4_advance and
 * rk4_advance_states are static inline in plant_integration.h (each plant inlines its derivative). */
#include <math.h>

#include "plant_integration.h"

long internal_step_count(double step_size, double max_internal_step) {
    if (step_size <= 0.0) return 0;
    double n = ceil(step_size / max_internal_step - SPLIT_TOLERANCE);
    return n > 1.0 ? (long)n : 1;
}

/* piezo_status.c - parameter diagnostics. See piezo_status.h. */
#include <math.h>
#include <stddef.h>
#include "piezo_status.h"

piezo_status piezo_refuse(piezo_diag *diag, const char *parameter, const char *valid_range, double value)
{
    if (diag != NULL) {
        diag->parameter = parameter;
        diag->valid_range = valid_range;
        diag->value = value;
    }
    return PIEZO_ERR_PARAM;
}

int piezo_in_range(double v, double lo, double hi, int lo_open, int hi_open)
{
    return isfinite(v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
}

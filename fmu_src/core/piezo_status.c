/* piezo_status.c - parameter diagnostics. See piezo_status.h. */
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

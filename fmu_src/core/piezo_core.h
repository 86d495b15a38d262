/* piezo_core.h - umbrella header of the pure C core (no FMI types, no globals,
 * no allocation, no I/O). */
#ifndef PIEZO_CORE_H
#define PIEZO_CORE_H
#include "piezo_status.h"
#include "piezo_hysteresis.h"
#include "piezo_tf.h"
#include "piezo_creep.h"
#include "piezo_plant.h"
#include "piezo_supervisor.h"
#include "piezo_controller.h"
#include "piezo_reference.h"
#endif

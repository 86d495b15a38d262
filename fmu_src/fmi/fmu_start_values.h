/*
 * fmu_start_values.h - parameter start values shipped in the FMU's resources.
 *
 * An FMU must itself start from the start values its modelDescription.xml
 * declares (importers need not set them). A parameterised FMU (written by
 * `python -m harness export`) declares other start values than the compiled
 * defaults, so it also carries them as resources/start_values, which the
 * glue reads once at instantiation and applies over the compiled defaults,
 * again after every reset (both FMI versions).
 *
 * File format (ASCII text), one assignment per line:
 *
 *     # comment
 *     pi.w0 = 0.43172362
 *     pi.m = 9
 *     creep.exact = false
 *
 * name: a parameter of the FMU (its modelDescription name); value: a Real
 * (C decimal syntax, finite), an Integer (decimal, int range) or a Boolean
 * (true, false, 1, 0). Blank lines and lines starting with '#' are skipped;
 * lines hold at most FMU_START_VALUES_LINE_MAX characters; a name may appear
 * once. Ranges are checked as for values set through the setters: by the
 * model at the end of initialization mode.
 *
 * No resources location, or no file: nothing is applied (the FMU behaves as
 * one without resources). A malformed file, or one that exists but cannot
 * be read, makes the instantiation fail with an error naming the line.
 */
#ifndef FMU_START_VALUES_H
#define FMU_START_VALUES_H

#include "fmu_model.h"

struct glue_host;   /* fmu_glue_core.h: where messages go and memory comes from */

#define FMU_START_VALUES_FILE "start_values"
#define FMU_START_VALUES_LINE_MAX 255

typedef struct fmu_start_values fmu_start_values;

/* Read <resource_location>/start_values into *sv and apply it to data. The
 * location is the resources folder: a file: URI when is_uri (FMI 2.0's
 * fmuResourceLocation), else a path (FMI 3.0's resourcePath). Messages begin
 * with "<fname>: start values" and call the location location_arg. Returns 1
 * on success (*sv = NULL when there is nothing to apply), 0 after logging why
 * through host (the file is malformed or unreadable, or out of memory). */
int fmu_start_values_init(fmu_start_values **sv, const char *resource_location, int is_uri,
                          const char *fname, const char *location_arg, const struct glue_host *host,
                          const char *instance_name, ModelData *data);

/* Apply the values read by fmu_start_values_init (nothing when sv is NULL). */
void fmu_start_values_apply(const fmu_start_values *sv, ModelData *data);

/* Release *sv (allocated through host) and set it to NULL. */
void fmu_start_values_free(fmu_start_values **sv, const struct glue_host *host);

#endif

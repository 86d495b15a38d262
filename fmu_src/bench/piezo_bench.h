/*
 * piezo_bench.h - timing loops of the core, for `python -m harness bench`
 * (the figures are printed, never asserted).
 *
 * Every loop times blocks of `block` samples with the thread's CPU clock:
 * block_ns[i] is the CPU time of samples [i block, (i+1) block), so the cost
 * at any point of a long run can be read (n / block values; block_ns may be
 * NULL). Each returns the number of samples it ran: n, or fewer when the
 * core refused a sample (its status in *status, PIEZO_OK otherwise).
 *
 * Header rules as in piezo_status.h (the harness's cffi binding reads it).
 */
#ifndef PIEZO_BENCH_H
#define PIEZO_BENCH_H

#include <stddef.h>
#include "piezo_plant.h"
#include "piezo_controller.h"

/*
 * The closed loop of the FMUs' default timing on the core: at sample k the
 * controller steps with y_ref[k] and y_meas(k); the plant applies the voltage
 * the controller published at the end of the previous step (with
 * mv.feedthrough, the one just computed). Records y_meas(k) and the applied
 * v(k) when the arrays are not NULL, so that the plant and the controller can
 * be timed alone on the same trajectory. SOE creep only (PIEZO_ERR_PARAM else).
 */
size_t piezo_bench_closed_loop(const piezo_plant_params *plant_params,
                               const piezo_controller_params *controller_params,
                               const double *y_ref, size_t n, double *y_meas, double *v,
                               size_t block, double *block_ns, int *status);

/* The plant alone, driven by v[0..n-1] (SOE creep only). */
size_t piezo_bench_plant(const piezo_plant_params *params, const double *v, size_t n,
                         size_t block, double *block_ns, int *status);

/* The controller alone, fed y_ref[k] and y_meas[k] (SOE creep only). */
size_t piezo_bench_controller(const piezo_controller_params *params, const double *y_ref,
                              const double *y_meas, size_t n, size_t block, double *block_ns,
                              int *status);

/*
 * The plant with exact creep (O(k) per sample), n samples starting at sample
 * k0: the creep history of the first k0 samples is filled in directly (x(j)
 * a sine, w_j by eq 14, the layout of piezo_creep.h) and the creep's sample
 * counter set to k0, so the cost at k0 is measured without running k0
 * samples first. Allocates the 16 (k0 + n + 1) bytes of history itself.
 */
size_t piezo_bench_exact_plant(const piezo_plant_params *params, size_t k0, size_t n,
                               size_t block, double *block_ns, int *status);

#endif

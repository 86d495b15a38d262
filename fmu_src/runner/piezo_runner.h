/*
 * piezo_runner.h - a native co-simulation master for the closed loop of the
 * PiezoStage and AdaptiveCompoundController FMUs.
 *
 * It loads the two FMU binaries through the FMI 2.0 API (dlopen/dlsym), keeps
 * one instance of each, and runs the closed loop with the schedule of the
 * harness's fmpy master (harness/cosim.py), exchanging values at
 * communication points only, per sample k at t_k = k h:
 *
 *   Gauss-Seidel (ModelStructure order):
 *     plant.get(y, y_meas, t_meas) -> ctrl.set(y_ref(k), y_meas, y_preview(k),
 *     t_preview(k), t_meas) -> ctrl.get(outputs)
 *     -> plant.set(v) -> doStep of both (plant first, or controller first)
 *   Jacobi (textbook): every output first (plant, then controller), then
 *     every input (plant.v, then the controller's), then both doSteps.
 *
 * y_ref(k) and the stamped preview y_preview(k), t_preview(k) are given by
 * the caller (the harness computes them, as ReferenceSignal would publish).
 * Each row of the result holds, at t_k: y, y_meas, v, q, est.a1, est.a2,
 * est.b1, est.b2, pred_error, saturated (0 or 1) - the values the fmpy master
 * records, bit for bit.
 *
 * Errors never end the process: every FMI status above fmi2Warning stops the
 * run and is returned with the sample, the FMU and the call that failed; the
 * FMUs' log messages are kept (piezo_runner_log_*). fmi2Warning (e.g. the
 * controller's first clipped voltage) is a completed call.
 *
 * Header rules (read by the harness's cffi binding): only size_t, int,
 * double, const char * and char * types, integer-literal #defines.
 */
#ifndef PIEZO_RUNNER_H
#define PIEZO_RUNNER_H

#include <stddef.h>

#define PIEZO_RUNNER_PLANT 0
#define PIEZO_RUNNER_CONTROLLER 1

#define PIEZO_RUNNER_GAUSS_SEIDEL 0
#define PIEZO_RUNNER_JACOBI 1

#define PIEZO_RUNNER_PLANT_FIRST 0
#define PIEZO_RUNNER_CONTROLLER_FIRST 1

/* the FMI call that failed */
#define PIEZO_RUNNER_CALL_NONE 0
#define PIEZO_RUNNER_CALL_GET_REAL 1
#define PIEZO_RUNNER_CALL_SET_REAL 2
#define PIEZO_RUNNER_CALL_GET_BOOLEAN 3
#define PIEZO_RUNNER_CALL_DO_STEP 4
#define PIEZO_RUNNER_CALL_SET_INTEGER 5
#define PIEZO_RUNNER_CALL_SET_BOOLEAN 6
#define PIEZO_RUNNER_CALL_SETUP_EXPERIMENT 7
#define PIEZO_RUNNER_CALL_ENTER_INITIALIZATION 8
#define PIEZO_RUNNER_CALL_EXIT_INITIALIZATION 9
#define PIEZO_RUNNER_CALL_TERMINATE 10
#define PIEZO_RUNNER_CALL_RESET 11

/* doubles per row of a recorded run */
#define PIEZO_RUNNER_ROW 10
/* controller outputs read as Reals: v, q, est.a1, est.a2, est.b1, est.b2, pred_error */
#define PIEZO_RUNNER_CTRL_REALS 7

/* One FMU: its binary and identity. */
typedef struct {
    const char *library;        /* path of binaries/<platform>/<modelIdentifier>.so */
    const char *guid;           /* the model description's guid */
    const char *resource_uri;   /* file URI of the extracted resources folder, or NULL */
    const char *instance_name;
} piezo_runner_fmu;

/* Value references of the exchanged variables (from the model descriptions). */
typedef struct {
    int plant_y;
    int plant_y_meas;
    int plant_v;
    int plant_t_meas;
    int ctrl_y_ref;
    int ctrl_y_meas;
    int ctrl_y_preview;
    int ctrl_t_preview;
    int ctrl_t_meas;
    int ctrl_reals[PIEZO_RUNNER_CTRL_REALS];
    int ctrl_saturated;
} piezo_runner_refs;

/* What a run did. */
typedef struct {
    int status;                 /* worst FMI status seen (0 OK, 1 Warning, 2 Discard, 3 Error, 4 Fatal) */
    size_t samples;             /* samples completed (rows filled) */
    int failed_role;            /* PIEZO_RUNNER_PLANT / _CONTROLLER, or -1 */
    int failed_call;            /* PIEZO_RUNNER_CALL_*, 0 when nothing failed */
} piezo_runner_result;

typedef struct piezo_runner piezo_runner;

/* Load both binaries and instantiate one instance of each (logging of
 * warnings and errors on, events off). NULL on failure, the reason in
 * error[0..error_size-1] (including the FMUs' messages). */
piezo_runner *piezo_runner_new(const piezo_runner_fmu *plant, const piezo_runner_fmu *controller,
                               const piezo_runner_refs *refs, char *error, size_t error_size);
/* Free both instances (no fmi2Terminate) and unload. NULL is ignored. */
void piezo_runner_free(piezo_runner *runner);

/* fmi2Set* on one instance (role); returns the FMI status (3 for a bad role). */
int piezo_runner_set_real(piezo_runner *runner, int role, const int *refs, const double *values, size_t n);
int piezo_runner_set_integer(piezo_runner *runner, int role, const int *refs, const int *values, size_t n);
int piezo_runner_set_boolean(piezo_runner *runner, int role, const int *refs, const int *values, size_t n);

/* fmi2SetupExperiment(start, stop), fmi2EnterInitializationMode and
 * fmi2ExitInitializationMode on the plant, then on the controller. */
int piezo_runner_initialize(piezo_runner *runner, double start_time, double stop_time,
                            piezo_runner_result *result);

/*
 * Run n samples of h from the current time (start_time + k h, k counted
 * since initialization) with the given master and doStep order.
 * y_preview, t_preview: the stamped preview per sample, or NULL (the
 * controller's y_preview and t_preview inputs are then set to 0: no stamped
 * preview). rows: n * row_stride doubles, PIEZO_RUNNER_ROW written per row at
 * rows[k * row_stride]; NULL runs the loop with the minimal exchange
 * (y_ref, y_meas and v only, nothing recorded: the cost of the FMI loop itself).
 * block_ns: when not NULL and timing_block > 0, the thread CPU time [ns] of
 * every complete block of timing_block samples (n / timing_block values).
 * Returns result->status.
 */
int piezo_runner_run(piezo_runner *runner, size_t n, double h, int master, int step_order,
                     const double *y_ref, const double *y_preview, const double *t_preview,
                     double *rows, size_t row_stride,
                     size_t timing_block, double *block_ns, piezo_runner_result *result);

/*
 * A batch: the same experiment run once per set of parameters, each run as
 * the harness runs one (harness/masters/native.py): fmi2Reset of both
 * (except before the first run of fresh instances), the parameters set (the
 * plant's, then the controller's; Reals, then Integers, then Booleans),
 * initialization over [0, n h], piezo_runner_run (in blocks of
 * PIEZO_RUNNER_BATCH_BLOCK samples, whose rows stay in the cache: the same
 * calls as one piezo_runner_run), then fmi2Terminate when the run
 * completed. Any status above fmi2Warning, whichever it is, stops that run
 * and is recorded with the call; the next run starts with fmi2Reset.
 * Nothing returns to the caller between runs; every run is summarised by
 * what the harness's checks and metrics read (harness/loop/checks.py,
 * harness/loop/metrics.py), so the caller decides on them, and runs again on its
 * own path any run that fails them or whose FMI calls failed, to report it
 * with its messages (the FMUs' log holds only the last run's).
 */

/* samples a batch runs at a time (a block's rows are 80 KB) */
#define PIEZO_RUNNER_BATCH_BLOCK 1024

/* The parameters set on one FMU in each run of a batch: row r of each table
 * for run r, or row 0 for every run when per_run is 0. */
typedef struct {
    size_t n_real;
    const int *real_refs;
    const double *reals;        /* n_real per row */
    size_t n_int;
    const int *int_refs;
    const int *ints;            /* n_int per row */
    size_t n_bool;
    const int *bool_refs;
    const int *bools;           /* n_bool per row, 0 or 1 */
    int per_run;
} piezo_runner_params;

/* The experiment of every run of a batch. */
typedef struct {
    size_t n;                   /* samples per run */
    double h;
    int master;                 /* PIEZO_RUNNER_GAUSS_SEIDEL or _JACOBI */
    int step_order;             /* PIEZO_RUNNER_PLANT_FIRST or _CONTROLLER_FIRST */
    const double *y_ref;        /* n, as piezo_runner_run */
    const double *y_preview;    /* n or NULL, as piezo_runner_run */
    const double *t_preview;
    const double *y_d;          /* n: the desired displacement the error is taken from */
    size_t window_start;        /* the metric window: samples [window_start, window_stop) */
    size_t window_stop;
} piezo_runner_experiment;

/* What each run of a batch gave: arrays of one value per run. */
typedef struct {
    int *status;                /* worst FMI status; above fmi2Warning the run stopped at failed_call */
    int *failed_call;           /* PIEZO_RUNNER_CALL_*, 0 when nothing failed */
    size_t *samples;            /* samples completed */
    int *finite;                /* 1 when y, y_meas and v are finite in every sample */
    double *sum_error2;         /* sum of (y_d - y)^2 over the window, summed as NumPy sums (below) */
    double *sum_y2;             /* sum of y^2 over the window, likewise */
    size_t *saturated;          /* samples of the window with saturated set */
    double *seconds;            /* wall-clock seconds of the run, reset to terminate */
} piezo_runner_outcomes;

/* Run `runs` runs (fresh: the instances are fresh, the first run resets
 * nothing). The sums are NumPy's pairwise summation of float64 (0.0 plus:
 * fewer than 8 terms in order; up to 128 in 8 interleaved partial sums
 * combined as ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7)), then the
 * rest in order; more: the first n/2 rounded down to a multiple of 8 and the
 * rest, each summed so, then added), so they are the bits np.sum gives.
 * Returns the number of runs done (all of them unless an argument is bad or
 * memory for a block's rows and a run's y cannot be had). */
size_t piezo_runner_batch(piezo_runner *runner, const piezo_runner_experiment *experiment,
                          const piezo_runner_params *plant, const piezo_runner_params *controller,
                          size_t runs, int fresh, piezo_runner_outcomes *outcomes);
/* NumPy's pairwise sum of x[0..n-1] (as in piezo_runner_batch). */
double piezo_runner_pairwise_sum(const double *x, size_t n);

/* fmi2Terminate on both (the controller's summary comes as a warning). */
int piezo_runner_terminate(piezo_runner *runner);
/* fmi2Reset on both: back to the start values, ready for new parameters. */
int piezo_runner_reset(piezo_runner *runner);

/* The FMUs' log messages since creation or the last clear (at most 256 kept;
 * piezo_runner_log_dropped counts the rest). */
size_t piezo_runner_log_count(const piezo_runner *runner);
size_t piezo_runner_log_dropped(const piezo_runner *runner);
const char *piezo_runner_log_text(const piezo_runner *runner, size_t i);
int piezo_runner_log_status(const piezo_runner *runner, size_t i);
int piezo_runner_log_role(const piezo_runner *runner, size_t i);
void piezo_runner_clear_log(piezo_runner *runner);

/* Bytes the FMUs of this process hold through the runners' allocator
 * (fmi2CallbackFunctions.allocateMemory), all runners together. */
size_t piezo_runner_live_bytes(void);
/* Bytes one instance (role) allocated in its fmi2Instantiate. */
size_t piezo_runner_instance_bytes(const piezo_runner *runner, int role);

#endif

/*
 * fmu_xproc.c - an FMU state serialized in one process continues in another:
 * the continuation is bitwise the uninterrupted run. Built once per FMI
 * version: fmu_xproc (FMI 2.0 editions), fmu3_xproc (FMI 3.0 editions, and
 * across editions).
 *
 * For each FMU and configuration (host_apply_config 0 and 1: SOE and exact
 * creep where the FMU has creep), a first process runs N samples and, at N/2,
 * serializes the state into a file; a second process loads the FMU binary
 * itself, deserializes the file into a fresh instance that was never
 * initialized or given a parameter, and runs samples N/2..N with the same
 * inputs. Both are this program again (fork + execv: other address spaces,
 * other heap layouts) and write their outputs into files, which must agree bit
 * for bit. The pairs of editions (first -> second):
 *
 *   fmu_xproc    FMI 2.0 -> FMI 2.0
 *   fmu3_xproc   FMI 3.0 -> FMI 3.0, FMI 2.0 -> FMI 3.0, FMI 3.0 -> FMI 2.0
 *
 * fmu3_xproc runs the FMI 2.0 side with fmu_xproc, which must stand beside it.
 * Both editions compile the same model and glue core, whose serialized-state
 * format has no version field beyond its own: the modes, the GUID, which is the
 * instantiation token, and the model data are the same.
 *
 * usage: fmu_xproc MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]
 *        fmu3_xproc FMI3.xml FMI3.so FMI2.xml FMI2.so [...]   (each FMU's two editions)
 *        fmu_xproc|fmu3_xproc --first|--resume MODEL.xml MODEL.so CONFIG K0 N STATE_FILE OUT_FILE
 *            (the processes: --first runs samples 0..N, saving the state at K0;
 *            --resume restores it and runs K0..N; both write their outputs)
 */
#if FMI_VERSION == 3
#include "host_fmi2.h"      /* the FMI 2.0 edition's GUID */
#endif
#include "host.h"

#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#define N_SAMPLES 3000

/* Samples [k0, n) of configuration `config` on a prepared instance. */
static int run_samples(const host_fmu *f, void *c, int config, int k0, int n, double *outputs)
{
    int k;
    for (k = k0; k < n; k++)
        if (!host_set_inputs(f, c, config, k) || host_step(f, c, k * f->h, f->h) > HOST_WARNING
            || host_real_outputs(f, c, outputs + (size_t)(k - k0) * HOST_MAX_OUTPUTS, HOST_MAX_OUTPUTS) < 0)
            return 0;
    return 1;
}

/* A process of the pair: exit code 0 when its files were written. */
static int child(const char *mode, char **argv)
{
    host_fmu f;
    host_inst in;
    int config = atoi(argv[2]), k0 = atoi(argv[3]), n = atoi(argv[4]), first = strcmp(mode, "--first") == 0;
    int ok, from = first ? 0 : k0;
    size_t size = 0;
    unsigned char *blob = first ? NULL : (unsigned char *)host_read_file(argv[5], &size);
    double *outputs = calloc((size_t)(n - from) * HOST_MAX_OUTPUTS, sizeof *outputs);
    if ((!first && blob == NULL) || outputs == NULL || !host_load(&f, argv[0], argv[1]))
        return 3;
    if (first) {
        ok = host_instantiate(&in, &f, "first") != NULL && host_enter_init(&f, in.c, 0.0, 0, 0.0) == HOST_OK
             && host_apply_config(&f, in.c, config) && f.api.ExitInitializationMode(in.c) == HOST_OK
             && run_samples(&f, in.c, config, 0, k0, outputs) && (blob = host_snapshot(&f, in.c, &size)) != NULL
             && host_write_file(argv[5], blob, size)
             && run_samples(&f, in.c, config, k0, n, outputs + (size_t)k0 * HOST_MAX_OUTPUTS);
    } else {
        host_state s = NULL;
        ok = host_instantiate(&in, &f, "resumed") != NULL && host_deserialize(&f, in.c, blob, size, &s) == HOST_OK
             && host_set_state(&f, in.c, s) == HOST_OK && host_free_state(&f, in.c, &s) == HOST_OK
             && run_samples(&f, in.c, config, k0, n, outputs);
    }
    ok = ok && host_write_file(argv[6], outputs, (size_t)(n - from) * HOST_MAX_OUTPUTS * sizeof *outputs);
    if (!ok)
        printf("%s failed: %s\n", first ? "first run" : "resume", in.log.last_error);
    host_free_instance(&in);
    host_unload(&f);
    free(blob);
    free(outputs);
    return ok ? 0 : 4;
}

/* Runs `binary mode xml so config K0 N state out` in a new process: its exit status, or -1. */
static int run_child(const char *binary, const char *mode, const char *xml, const char *so, int config,
                     const char *state_file, const char *out_file)
{
    char config_text[16], k0_text[16], n_text[16];
    int status = -1;
    pid_t pid;
    snprintf(config_text, sizeof config_text, "%d", config);
    snprintf(k0_text, sizeof k0_text, "%d", N_SAMPLES / 2);
    snprintf(n_text, sizeof n_text, "%d", N_SAMPLES);
    fflush(stdout);
    pid = fork();
    if (pid == 0) {
        char *args[] = {(char *)binary, (char *)mode, (char *)xml, (char *)so, config_text, k0_text, n_text,
                        (char *)state_file, (char *)out_file, NULL};
        execv(binary, args);
        _exit(127);
    }
    if (pid > 0)
        waitpid(pid, &status, 0);
    return pid > 0 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/* The binary of each edition and its FMU's files (xml, so). */
typedef struct {
    const char *binary;
    const char *xml, *so;
} edition;

/* One pair: the state of edition `from` continued by edition `to`. */
static void one(const char *id, const edition *from, const edition *to, int config, int from_version,
                int to_version)
{
    const int half = N_SAMPLES / 2;
    double *reference = NULL, *theirs = NULL;
    size_t size = 0, ref_size = 0, their_size = 0;
    char state_file[] = "/tmp/fmu_xproc_state_XXXXXX", ref_file[] = "/tmp/fmu_xproc_ref_XXXXXX";
    char out_file[] = "/tmp/fmu_xproc_out_XXXXXX", ran[64], pair[48] = "";
    int fd1 = mkstemp(state_file), fd2 = mkstemp(ref_file), fd3 = mkstemp(out_file), status = -1, ok;
    unsigned char *blob = NULL;

#if FMI_VERSION == 2
    snprintf(ran, sizeof ran, "%d samples in the first process", N_SAMPLES);
    (void)from_version;
    (void)to_version;
#else
    snprintf(ran, sizeof ran, "FMI %d.0 ran %d samples", from_version, N_SAMPLES);
    snprintf(pair, sizeof pair, "FMI %d.0 -> FMI %d.0: ", from_version, to_version);
#endif
    ok = fd1 >= 0 && fd2 >= 0 && fd3 >= 0
         && run_child(from->binary, "--first", from->xml, from->so, config, state_file, ref_file) == 0
         && (blob = (unsigned char *)host_read_file(state_file, &size)) != NULL && size > 0
         && (reference = (double *)(void *)host_read_file(ref_file, &ref_size)) != NULL
         && ref_size == (size_t)N_SAMPLES * HOST_MAX_OUTPUTS * sizeof(double);
    if (!check(ok, "%s configuration %d: %s, state saved at %d (%llu bytes)", id, config, ran, half,
               (unsigned long long)size))
        goto done;
    status = run_child(to->binary, "--resume", to->xml, to->so, config, state_file, out_file);
    theirs = (double *)(void *)host_read_file(out_file, &their_size);
    check(status == 0 && theirs != NULL && their_size == (size_t)(N_SAMPLES - half) * HOST_MAX_OUTPUTS * sizeof(double)
              && memcmp(theirs, reference + (size_t)half * HOST_MAX_OUTPUTS, their_size) == 0,
          "%s configuration %d: %sanother process continued samples %d..%d from the file, bitwise equal "
          "(exit status %d)", id, config, pair, half, N_SAMPLES, status);
done:
    if (fd1 >= 0) {
        close(fd1);
        unlink(state_file);
    }
    if (fd2 >= 0) {
        close(fd2);
        unlink(ref_file);
    }
    if (fd3 >= 0) {
        close(fd3);
        unlink(out_file);
    }
    free(blob);
    free(reference);
    free(theirs);
}

int main(int argc, char **argv)
{
    /* the pairs (first, second edition) this build runs; per FMU, argv holds its
     * own edition's files and, for FMI 3.0, the FMI 2.0 edition's after them */
#if FMI_VERSION == 2
    static const int pairs[][2] = {{2, 2}};
    const int per_fmu = 2;
#else
    static const int pairs[][2] = {{3, 3}, {2, 3}, {3, 2}};
    const int per_fmu = 4;
    char sibling[4096];
    const char *slash = strrchr(argv[0], '/');
    /* the FMI 2.0 side: fmu_xproc in this program's folder */
    snprintf(sibling, sizeof sibling, "%.*sfmu_xproc", slash != NULL ? (int)(slash - argv[0] + 1) : 0, argv[0]);
#endif
    int i, config, p;
    if (argc == 9 && (strcmp(argv[1], "--first") == 0 || strcmp(argv[1], "--resume") == 0))
        return child(argv[1], argv + 2);
    if (argc < 1 + per_fmu || (argc - 1) % per_fmu != 0) {
        fprintf(stderr, "usage: %s %s [...]\n", argv[0],
                BY_VERSION("MODEL.xml MODEL.so", "FMI3.xml FMI3.so FMI2.xml FMI2.so"));
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
#if FMI_VERSION == 3
    if (access(sibling, X_OK) != 0) {
        host_fail("%s runs the FMI 2.0 side with %s, which is missing (build both: target c_test_hosts)",
               argv[0], sibling);
        return 2;
    }
#endif
    for (i = 1; i + per_fmu - 1 < argc; i += per_fmu) {
        host_fmu f;
        edition editions[4];        /* by FMI version */
        if (!host_load(&f, argv[i], argv[i + 1]))
            return 2;
        editions[FMI_VERSION].binary = argv[0];
        editions[FMI_VERSION].xml = argv[i];
        editions[FMI_VERSION].so = argv[i + 1];
#if FMI_VERSION == 3
        {
            host2_fmu f2;
            int same;
            if (!host2_load(&f2, argv[i + 2], argv[i + 3]))
                return 2;
            same = check(strcmp(f.token, f2.token) == 0 && strcmp(f.id, f2.id) == 0,
                         "%s: the FMI 3.0 instantiationToken is the FMI 2.0 GUID %s", f.id, f2.token);
            host2_unload(&f2);
            if (!same) {
                host_unload(&f);
                continue;
            }
            editions[2].binary = sibling;
            editions[2].xml = argv[i + 2];
            editions[2].so = argv[i + 3];
        }
#endif
        for (config = 0; config < 2; config++)
            for (p = 0; p < (int)(sizeof pairs / sizeof pairs[0]); p++)
                one(f.id, &editions[pairs[p][0]], &editions[pairs[p][1]], config, pairs[p][0], pairs[p][1]);
        host_unload(&f);
    }
    return host_summary();
}

/*
 * fmu3_xproc.c - an FMU state serialized in one process continues in another,
 * for the FMI 3.0 editions, and across editions: the continuation is bitwise
 * the uninterrupted run.
 *
 * For each FMU and configuration (0 and 1: SOE and exact creep where the FMU
 * has creep), this process runs N samples and, at N/2, serializes the state
 * into a file. A second process (this program again, fork + execv: another
 * address space and heap layout) loads a binary, deserializes the file into a
 * fresh instance that was never initialized or given a parameter, and runs
 * samples N/2..N with the same inputs; its outputs must equal this process's
 * bit for bit. Three pairs per FMU and configuration:
 *
 *   FMI 3.0 -> FMI 3.0   the FMI 3.0 edition alone
 *   FMI 2.0 -> FMI 3.0   a state of the FMI 2.0 edition continued by the FMI 3.0 one
 *   FMI 3.0 -> FMI 2.0   and the other way round
 *
 * (both editions compile the same model and glue core, whose serialized-state
 * format has no version field beyond its own: the modes, the GUID, which is the
 * instantiation token, and the model data are the same).
 *
 * usage: fmu3_xproc FMI3.xml FMI3.so FMI2.xml FMI2.so [...]   (each FMU's two editions)
 *        fmu3_xproc --resume2|--resume3 MODEL.xml MODEL.so CONFIG K0 N STATE_FILE OUT_FILE
 */
#include "fmu3_host.h"

#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#define N_SAMPLES 3000
#define MAX_OUT 16

static int run3(const host3_fmu *f, fmi3Instance c, int config, int k0, int n, double *outputs)
{
    int k;
    for (k = k0; k < n; k++)
        if (!host3_set_inputs(f, c, config, k) || host3_step(f, c, k * f->h, f->h) > fmi3Warning
            || host3_real_outputs(f, c, outputs + (size_t)(k - k0) * MAX_OUT) < 0)
            return 0;
    return 1;
}

static int run2(const host_fmu *f, fmi2Component c, int config, int k0, int n, double *outputs)
{
    int k;
    for (k = k0; k < n; k++)
        if (!host_set_inputs(f, c, config, k) || f->api.DoStep(c, k * f->h, f->h, fmi2True) > fmi2Warning
            || host_real_outputs(f, c, outputs + (size_t)(k - k0) * MAX_OUT) < 0)
            return 0;
    return 1;
}

static int write_file(const char *path, const void *data, size_t size)
{
    FILE *f = fopen(path, "wb");
    int ok = f != NULL && fwrite(data, 1, size, f) == size;
    if (f != NULL && fclose(f) != 0)
        ok = 0;
    return ok;
}

static unsigned char *read_all(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    unsigned char *data;
    long n;
    if (f == NULL)
        return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    data = malloc(n > 0 ? (size_t)n : 1);
    if (data != NULL && fread(data, 1, (size_t)n, f) != (size_t)n) {
        free(data);
        data = NULL;
    }
    fclose(f);
    *size = (size_t)n;
    return data;
}

/* The second process: exit code 0 when the outputs were written. */
static int resume(int edition, char **argv)
{
    host_log log;
    int config = atoi(argv[2]), k0 = atoi(argv[3]), n = atoi(argv[4]), ok;
    size_t size = 0;
    unsigned char *blob = read_all(argv[5], &size);
    double *outputs = calloc((size_t)(n - k0) * MAX_OUT, sizeof *outputs);
    host_log_clear(&log);
    if (blob == NULL || outputs == NULL)
        return 3;
    if (edition == 3) {
        host3_fmu f;
        fmi3Instance c;
        fmi3FMUState s = NULL;
        if (!host3_load(&f, argv[0], argv[1]))
            return 3;
        c = host3_instantiate(&f, "resumed", &log);
        ok = c != NULL && f.api.DeserializeFMUState(c, blob, size, &s) == fmi3OK && f.api.SetFMUState(c, s) == fmi3OK
             && f.api.FreeFMUState(c, &s) == fmi3OK && run3(&f, c, config, k0, n, outputs);
        if (c != NULL)
            f.api.FreeInstance(c);
        host3_unload(&f);
    } else {
        host_fmu f;
        fmi2CallbackFunctions cb = host_callbacks(&log);
        fmi2Component c;
        fmi2FMUstate s = NULL;
        if (!host_load(&f, argv[0], argv[1]))
            return 3;
        c = f.api.Instantiate("resumed", fmi2CoSimulation, f.guid, "", &cb, fmi2False, fmi2False);
        ok = c != NULL && f.api.DeSerializeFMUstate(c, (const fmi2Byte *)blob, size, &s) == fmi2OK
             && f.api.SetFMUstate(c, s) == fmi2OK && f.api.FreeFMUstate(c, &s) == fmi2OK
             && run2(&f, c, config, k0, n, outputs);
        if (c != NULL)
            f.api.FreeInstance(c);
        host_unload(&f);
    }
    ok = ok && write_file(argv[6], outputs, (size_t)(n - k0) * MAX_OUT * sizeof *outputs);
    if (!ok)
        fprintf(stderr, "resume failed: %s\n", log.last_error);
    free(blob);
    free(outputs);
    return ok ? 0 : 4;
}

/* This process's run on edition `from` (N samples, the state saved at N/2 into
 * *blob); 1 on success. */
static int first_run(int from, const host3_fmu *f3, const host_fmu *f2, int config, double *reference,
                     unsigned char **blob, size_t *size)
{
    const int half = N_SAMPLES / 2;
    host_log log;
    int ok;
    host_log_clear(&log);
    if (from == 3) {
        fmi3Instance c = host3_instantiate(f3, "first", &log);
        ok = c != NULL && f3->api.EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) == fmi3OK
             && host3_apply_config(f3, c, config) && f3->api.ExitInitializationMode(c) == fmi3OK
             && run3(f3, c, config, 0, half, reference) && (*blob = host3_snapshot(f3, c, size)) != NULL
             && run3(f3, c, config, half, N_SAMPLES, reference + (size_t)half * MAX_OUT);
        if (c != NULL)
            f3->api.FreeInstance(c);
    } else {
        fmi2CallbackFunctions cb = host_callbacks(&log);
        fmi2Component c = f2->api.Instantiate("first", fmi2CoSimulation, f2->guid, "", &cb, fmi2False, fmi2False);
        ok = c != NULL && f2->api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK
             && f2->api.EnterInitializationMode(c) == fmi2OK && host_apply_config(f2, c, config)
             && f2->api.ExitInitializationMode(c) == fmi2OK && run2(f2, c, config, 0, half, reference)
             && (*blob = host_snapshot(f2, c, size)) != NULL
             && run2(f2, c, config, half, N_SAMPLES, reference + (size_t)half * MAX_OUT);
        if (c != NULL)
            f2->api.FreeInstance(c);
    }
    if (!ok)
        printf("first run failed: %s\n", log.last_error);
    return ok;
}

static void one(const char *self, char **files, const host3_fmu *f3, const host_fmu *f2, int config, int from,
                int to)
{
    const int half = N_SAMPLES / 2;
    double *reference = calloc((size_t)N_SAMPLES * MAX_OUT, sizeof(double));
    unsigned char *blob = NULL, *theirs = NULL;
    size_t size = 0, their_size = 0;
    char state_file[] = "/tmp/fmu3_xproc_state_XXXXXX", out_file[] = "/tmp/fmu3_xproc_out_XXXXXX";
    char config_text[16], k0_text[16], n_text[16];
    int fd1 = mkstemp(state_file), fd2 = mkstemp(out_file), status = -1, ok;
    pid_t pid;

    ok = fd1 >= 0 && fd2 >= 0 && first_run(from, f3, f2, config, reference, &blob, &size)
         && write_file(state_file, blob, size);
    if (!check(ok, "%s configuration %d: FMI %d.0 ran %d samples, state saved at %d (%llu bytes)", f3->id, config,
               from, N_SAMPLES, half, (unsigned long long)size))
        goto done;
    snprintf(config_text, sizeof config_text, "%d", config);
    snprintf(k0_text, sizeof k0_text, "%d", half);
    snprintf(n_text, sizeof n_text, "%d", N_SAMPLES);
    fflush(stdout);
    pid = fork();
    if (pid == 0) {
        char *args[] = {(char *)self, to == 3 ? "--resume3" : "--resume2", files[to == 3 ? 0 : 2],
                        files[to == 3 ? 1 : 3], config_text, k0_text, n_text, state_file, out_file, NULL};
        execv(self, args);
        _exit(127);
    }
    if (pid > 0)
        waitpid(pid, &status, 0);
    theirs = read_all(out_file, &their_size);
    check(pid > 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0 && theirs != NULL
              && their_size == (size_t)(N_SAMPLES - half) * MAX_OUT * sizeof(double)
              && memcmp(theirs, reference + (size_t)half * MAX_OUT, their_size) == 0,
          "%s configuration %d: FMI %d.0 -> FMI %d.0: another process continued samples %d..%d from the file, "
          "bitwise equal (exit status %d)", f3->id, config, from, to, half, N_SAMPLES,
          WIFEXITED(status) ? WEXITSTATUS(status) : -1);
done:
    if (fd1 >= 0) {
        close(fd1);
        unlink(state_file);
    }
    if (fd2 >= 0) {
        close(fd2);
        unlink(out_file);
    }
    free(blob);
    free(theirs);
    free(reference);
}

int main(int argc, char **argv)
{
    int i, config;
    static const int pairs[3][2] = {{3, 3}, {2, 3}, {3, 2}};
    if (argc == 9 && (strcmp(argv[1], "--resume3") == 0 || strcmp(argv[1], "--resume2") == 0))
        return resume(argv[1][8] - '0', argv + 2);
    if (argc < 5 || (argc - 1) % 4 != 0) {
        fprintf(stderr, "usage: %s FMI3.xml FMI3.so FMI2.xml FMI2.so [...]\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    for (i = 1; i + 3 < argc; i += 4) {
        host3_fmu f3;
        host_fmu f2;
        int p;
        if (!host3_load(&f3, argv[i], argv[i + 1]) || !host_load(&f2, argv[i + 2], argv[i + 3]))
            return 2;
        if (!check(strcmp(f3.token, f2.guid) == 0 && strcmp(f3.id, f2.id) == 0,
                   "%s: the FMI 3.0 instantiationToken is the FMI 2.0 GUID %s", f3.id, f2.guid))
            continue;
        for (config = 0; config < 2; config++)
            for (p = 0; p < 3; p++)
                one(argv[0], argv + i, &f3, &f2, config, pairs[p][0], pairs[p][1]);
        host3_unload(&f3);
        host_unload(&f2);
    }
    return host_summary();
}

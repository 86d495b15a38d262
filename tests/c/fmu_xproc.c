/*
 * fmu_xproc.c - an FMU state serialized in one process continues in another:
 * the continuation is bitwise the uninterrupted run.
 *
 * For each FMU and configuration (host_apply_config 0 and 1: SOE and exact
 * creep where the FMU has creep), this process runs N samples and, at N/2,
 * serializes the state into a file. A second process (this program, started
 * with fork + execv, so another address space and another heap layout) loads
 * the FMU binary itself, deserializes the file into a fresh instance that was
 * never initialized or given a parameter, and runs samples N/2..N with the
 * same inputs; it writes the outputs into a file, which must equal this
 * process's outputs bit for bit.
 *
 * usage: fmu_xproc MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]
 *        fmu_xproc --resume MODEL.xml MODEL.so CONFIG K0 N STATE_FILE OUT_FILE   (the second process)
 */
#include "fmu_host.h"

#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#define N_SAMPLES 3000
#define MAX_OUT 16

/* Samples [k0, n) of configuration `config` on a prepared instance. */
static int run_samples(const host_fmu *f, fmi2Component c, int config, int k0, int n, double *outputs)
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
static int resume(char **argv)
{
    host_fmu f;
    host_log log;
    fmi2CallbackFunctions cb;
    fmi2Component c;
    fmi2FMUstate s = NULL;
    int config = atoi(argv[2]), k0 = atoi(argv[3]), n = atoi(argv[4]), ok;
    size_t size = 0;
    unsigned char *blob = read_all(argv[5], &size);
    double *outputs = calloc((size_t)(n - k0) * MAX_OUT, sizeof *outputs);
    if (blob == NULL || outputs == NULL || !host_load(&f, argv[0], argv[1]))
        return 3;
    host_log_clear(&log);
    cb = host_callbacks(&log);
    c = f.api.Instantiate("resumed", fmi2CoSimulation, f.guid, "", &cb, fmi2False, fmi2False);
    ok = c != NULL && f.api.DeSerializeFMUstate(c, (const fmi2Byte *)blob, size, &s) == fmi2OK
         && f.api.SetFMUstate(c, s) == fmi2OK && f.api.FreeFMUstate(c, &s) == fmi2OK
         && run_samples(&f, c, config, k0, n, outputs)
         && write_file(argv[6], outputs, (size_t)(n - k0) * MAX_OUT * sizeof *outputs);
    if (!ok)
        fprintf(stderr, "resume failed: %s\n", log.last_error);
    if (c != NULL)
        f.api.FreeInstance(c);
    host_unload(&f);
    free(blob);
    free(outputs);
    return ok ? 0 : 4;
}

static void one(const char *self, const char *xml, const char *so, const host_fmu *f, int config)
{
    host_log log;
    fmi2CallbackFunctions cb;
    fmi2Component c;
    const int half = N_SAMPLES / 2;
    double *reference = calloc((size_t)N_SAMPLES * MAX_OUT, sizeof(double));
    unsigned char *blob = NULL, *theirs = NULL;
    size_t size = 0, their_size = 0;
    char state_file[] = "/tmp/fmu_xproc_state_XXXXXX", out_file[] = "/tmp/fmu_xproc_out_XXXXXX";
    char config_text[16], k0_text[16], n_text[16];
    int fd1 = mkstemp(state_file), fd2 = mkstemp(out_file), status = -1, ok;
    pid_t pid;

    host_log_clear(&log);
    cb = host_callbacks(&log);
    c = f->api.Instantiate("first", fmi2CoSimulation, f->guid, "", &cb, fmi2False, fmi2False);
    ok = c != NULL && fd1 >= 0 && fd2 >= 0 && f->api.SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK
         && f->api.EnterInitializationMode(c) == fmi2OK && host_apply_config(f, c, config)
         && f->api.ExitInitializationMode(c) == fmi2OK && run_samples(f, c, config, 0, half, reference)
         && (blob = host_snapshot(f, c, &size)) != NULL && write_file(state_file, blob, size)
         && run_samples(f, c, config, half, N_SAMPLES, reference + (size_t)half * MAX_OUT);
    if (!check(ok, "%s configuration %d: %d samples in the first process, state saved at %d (%llu bytes)", f->id,
               config, N_SAMPLES, half, (unsigned long long)size))
        goto done;
    snprintf(config_text, sizeof config_text, "%d", config);
    snprintf(k0_text, sizeof k0_text, "%d", half);
    snprintf(n_text, sizeof n_text, "%d", N_SAMPLES);
    fflush(stdout);
    pid = fork();
    if (pid == 0) {
        char *args[] = {(char *)self, "--resume", (char *)xml, (char *)so, config_text, k0_text, n_text,
                        state_file, out_file, NULL};
        execv(self, args);
        _exit(127);
    }
    if (pid > 0)
        waitpid(pid, &status, 0);
    theirs = read_all(out_file, &their_size);
    check(pid > 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0 && theirs != NULL
              && their_size == (size_t)(N_SAMPLES - half) * MAX_OUT * sizeof(double)
              && memcmp(theirs, reference + (size_t)half * MAX_OUT, their_size) == 0,
          "%s configuration %d: another process continued samples %d..%d from the file, bitwise equal "
          "(exit status %d)", f->id, config, half, N_SAMPLES, WIFEXITED(status) ? WEXITSTATUS(status) : -1);
done:
    if (c != NULL)
        f->api.FreeInstance(c);
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
    if (argc == 9 && strcmp(argv[1], "--resume") == 0)
        return resume(argv + 2);
    if (argc < 3 || argc % 2 == 0) {
        fprintf(stderr, "usage: %s MODEL.xml MODEL.so [MODEL.xml MODEL.so ...]\n", argv[0]);
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    for (i = 1; i + 1 < argc; i += 2) {
        host_fmu f;
        if (!host_load(&f, argv[i], argv[i + 1]))
            return 2;
        for (config = 0; config < 2; config++)
            one(argv[0], argv[i], argv[i + 1], &f, config);
        host_unload(&f);
    }
    return host_summary();
}

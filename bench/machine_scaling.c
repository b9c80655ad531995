/* What two threads give on this machine, with nothing of Snell's in the way: the same work on
 * one thread alone, then on each of two threads at once (scaling = 2 t1 / t2), alternated
 * round by round as `snell bench --threads 1,2` alternates its thread counts, the median of
 * the rounds reported with their range. The speed issue asks 1.9x of Snell; this says what the
 * machine itself delivers in the same hour (bench/scaling.sh runs it first).
 *
 * Workloads: "alu", eight independent chains of multiply-adds in registers; "fma-units",
 * sixteen independent chains of 256-bit fused multiply-adds, enough to keep a core's FMA units
 * busy every cycle (run only on x86-64 CPUs with AVX2 and FMA): two vCPUs that were two hardware
 * threads of one core would share those units and give it about 1x, where "alu", waiting on
 * its chains' latency, could still give 2x; "chase-l2" and "chase-memory", a dependent walk
 * through a random cycle of pointers in a buffer of 1 MiB (within a core's L2) and 256 MiB
 * (main memory) per thread, each thread its own buffer.
 *
 *   cc -O2 -pthread -o machine_scaling bench/machine_scaling.c && ./machine_scaling [ROUNDS]
 */
#define _GNU_SOURCE
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#if defined(__x86_64__)
#include <immintrin.h>
#endif

enum kind { ALU, FMA_UNITS, CHASE };

struct job {
    enum kind kind;
    size_t steps;
    uint32_t *next;
    double out;
};

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

#if defined(__x86_64__)
/* Whether this CPU runs fma_units. */
static int has_fma_units(void) {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}

__attribute__((target("avx2,fma"))) static double fma_units(size_t steps) {
    __m256 a[16];
    for (int k = 0; k < 16; k++) a[k] = _mm256_set1_ps(1.0f + 1e-3f * k);
    const __m256 m = _mm256_set1_ps(0.9999999f), c = _mm256_set1_ps(1e-7f);
    for (size_t i = 0; i < steps; i++) {
        /* Unrolled, so that the sixteen chains live in registers rather than in memory. */
#pragma GCC unroll 16
        for (int k = 0; k < 16; k++) a[k] = _mm256_fmadd_ps(a[k], m, c);
    }
    __m256 s = a[0];
    for (int k = 1; k < 16; k++) s = _mm256_add_ps(s, a[k]);
    float f[8];
    _mm256_storeu_ps(f, s);
    return f[0];
}
#else
static int has_fma_units(void) { return 0; }
static double fma_units(size_t steps) { return (double)steps; }
#endif

static void *run(void *arg) {
    struct job *j = arg;
    if (j->kind == FMA_UNITS) {
        j->out = fma_units(j->steps);
    } else if (j->kind == CHASE) {
        uint32_t x = 0;
        for (size_t i = 0; i < j->steps; i++) x = j->next[x];
        j->out = x;
    } else {
        double a[8] = {1, 1, 1, 1, 1, 1, 1, 1};
        for (size_t i = 0; i < j->steps; i++)
            for (int k = 0; k < 8; k++) a[k] = a[k] * (0.999999 - 1e-7 * k) + 1e-9;
        j->out = a[0] + a[1] + a[2] + a[3] + a[4] + a[5] + a[6] + a[7];
    }
    return NULL;
}

/* A single random cycle through all `len` slots (Sattolo's shuffle), from a fixed seed. */
static uint32_t *cycle(size_t len, uint64_t seed) {
    uint32_t *next = malloc(len * sizeof *next), *order = malloc(len * sizeof *order);
    if (!next || !order) {
        fprintf(stderr, "machine_scaling: out of memory\n");
        exit(1);
    }
    for (size_t i = 0; i < len; i++) order[i] = (uint32_t)i;
    for (size_t i = len - 1; i > 0; i--) {
        seed = seed * 6364136223846793005ull + 1442695040888963407ull;
        size_t k = (size_t)((seed >> 33) % i);
        uint32_t t = order[i];
        order[i] = order[k];
        order[k] = t;
    }
    for (size_t i = 0; i < len; i++) next[order[i]] = order[(i + 1) % len];
    free(order);
    return next;
}

static double timed(struct job *jobs, int threads) {
    pthread_t th[2];
    double t0 = now();
    for (int i = 0; i < threads; i++) pthread_create(&th[i], NULL, run, &jobs[i]);
    for (int i = 0; i < threads; i++) pthread_join(th[i], NULL);
    return now() - t0;
}

static int by_value(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv) {
    int rounds = argc > 1 ? atoi(argv[1]) : 9;
    if (rounds < 1 || rounds > 99) {
        fprintf(stderr, "usage: machine_scaling [ROUNDS (1-99)]\n");
        return 2;
    }
    const struct {
        const char *name;
        enum kind kind;
        size_t bytes, steps;
    } loads[] = {{"alu", ALU, 0, 150000000},
                 {"fma-units", FMA_UNITS, 0, 150000000},
                 {"chase-l2", CHASE, 1 << 20, 60000000},
                 {"chase-memory", CHASE, 256 << 20, 8000000}};
    for (size_t w = 0; w < sizeof loads / sizeof loads[0]; w++) {
        if (loads[w].kind == FMA_UNITS && !has_fma_units()) {
            printf("   %-16s (not run: needs an x86-64 CPU with AVX2 and FMA)\n", loads[w].name);
            continue;
        }
        struct job jobs[2];
        for (int i = 0; i < 2; i++) {
            jobs[i].kind = loads[w].kind;
            jobs[i].steps = loads[w].steps;
            jobs[i].next = loads[w].kind == CHASE ? cycle(loads[w].bytes / sizeof(uint32_t), 7 + i) : NULL;
        }
        timed(jobs, 2); /* warm-up: pages touched, clocks up */
        double ratio[99], one[99];
        for (int r = 0; r < rounds; r++) {
            double t1, t2;
            if (r & 1) {
                t2 = timed(jobs, 2);
                t1 = timed(jobs, 1);
            } else {
                t1 = timed(jobs, 1);
                t2 = timed(jobs, 2);
            }
            one[r] = t1;
            ratio[r] = 2 * t1 / t2;
        }
        qsort(ratio, rounds, sizeof ratio[0], by_value);
        qsort(one, rounds, sizeof one[0], by_value);
        printf("   %-16s one thread %.3f s; 2 threads: %.2fx (rounds %.2f-%.2f)\n", loads[w].name, one[rounds / 2],
               ratio[rounds / 2], ratio[0], ratio[rounds - 1]);
        for (int i = 0; i < 2; i++) free(jobs[i].next);
    }
    return 0;
}

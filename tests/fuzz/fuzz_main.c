/* A standalone driver for libFuzzer-style targets, so that every build (gcc included) can
 * run them under its sanitizers as an ordinary test.
 *
 *   fuzz_TARGET [-runs=N] [-seed=S] [-max_len=B] SEED_FILE_OR_DIR...
 *
 * It first feeds every seed as it is, then N inputs made from the seeds by a few random
 * mutations each: bit flips, byte overwrites with boundary values, insertions, deletions,
 * repeated chunks, truncation, a chunk of another seed spliced in, a run of decimal digits
 * replaced by a boundary number (the fields of text headers), and a little-endian length at
 * the start of the input rewritten to a nearby or extreme value (the fields of binary
 * headers). The random generator has a fixed default seed, so a run is reproducible: the
 * same seeds, runs and seed give the same inputs in the same order.
 *
 * The environment overrides the defaults: FG_FUZZ_RUNS, FG_FUZZ_SEED. Each input is passed
 * in a buffer of exactly its size, so a sanitizer catches a read one byte past it. When the
 * target crashes (a sanitizer aborts, a segfault), the input is written to
 * fuzz-crash-<run> (fuzz-crash-seed-<i> for a seed) in the current folder (or to $FG_FUZZ_ARTIFACT) before the process dies;
 * feed that file back as the only argument with -runs=0 to reproduce it.
 *
 * With clang the same target builds as a real libFuzzer binary instead of with this file:
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined -Ilib tests/fuzz/fuzz_TARGET.c \
 *     <the library sources it needs> -ljansson -o fuzz_TARGET */
#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

/* The target, defined by the fuzz_*.c file linked with this driver. */
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

typedef struct seed {
  uint8_t *data;
  size_t len;
} seed;

static seed *seeds;
static size_t nseeds, seeds_cap;

/* ---- crash artifacts ---------------------------------------------------------------- */

/* The input being run, for the crash handler. */
static const uint8_t *volatile cur_data;
static volatile size_t cur_len;
static char artifact_path[512];

/* Writes the current input to artifact_path; async-signal-safe calls only. */
static void on_crash(int sig) {
  if (cur_data) {
    int fd = open(artifact_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      size_t off = 0;
      while (off < cur_len) {
        ssize_t w = write(fd, (const uint8_t *)cur_data + off, cur_len - off);
        if (w <= 0) break;
        off += (size_t)w;
      }
      close(fd);
      static const char msg[] = "fuzz: crashing input written to ";
      ssize_t ignored = write(2, msg, sizeof msg - 1);
      ignored = write(2, artifact_path, strlen(artifact_path));
      ignored = write(2, "\n", 1);
      (void)ignored;
    }
  }
  signal(sig, SIG_DFL);
  raise(sig);
}

/* Runs the target on a copy of exactly len bytes (a sanitizer sees any overread); label
 * names the crash artifact. */
static void run_one(const uint8_t *data, size_t len, const char *label) {
  uint8_t *copy = malloc(len ? len : 1);
  if (!copy) {
    fprintf(stderr, "fuzz: out of memory for a %zu-byte input\n", len);
    exit(2);
  }
  if (len) memcpy(copy, data, len);
  cur_len = len;
  if (!getenv("FG_FUZZ_ARTIFACT"))
    snprintf(artifact_path, sizeof artifact_path, "fuzz-crash-%s", label);
  cur_data = copy;
  LLVMFuzzerTestOneInput(copy, len);
  cur_data = NULL;
  free(copy);
}

/* ---- seeds -------------------------------------------------------------------------- */

static void add_seed(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    fprintf(stderr, "fuzz: cannot open %s\n", path);
    exit(2);
  }
  uint8_t *buf = NULL;
  size_t len = 0, cap = 0;
  for (;;) {
    if (len == cap) {
      cap = cap ? 2 * cap : 4096;
      buf = realloc(buf, cap);
      if (!buf) exit(2);
    }
    size_t n = fread(buf + len, 1, cap - len, f);
    len += n;
    if (n == 0) break;
  }
  fclose(f);
  if (nseeds == seeds_cap) {
    seeds_cap = seeds_cap ? 2 * seeds_cap : 16;
    seeds = realloc(seeds, seeds_cap * sizeof *seeds);
    if (!seeds) exit(2);
  }
  seeds[nseeds].data = buf;
  seeds[nseeds].len = len;
  nseeds++;
}

static int cmp_str(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Adds a file, or every regular file of a folder in name order (for reproducibility). */
static void add_path(const char *path) {
  struct stat sb;
  if (stat(path, &sb) != 0) {
    fprintf(stderr, "fuzz: no such seed file or folder: %s\n", path);
    exit(2);
  }
  if (!S_ISDIR(sb.st_mode)) {
    add_seed(path);
    return;
  }
  DIR *d = opendir(path);
  if (!d) {
    fprintf(stderr, "fuzz: cannot list %s\n", path);
    exit(2);
  }
  char **names = NULL;
  size_t n = 0, cap = 0;
  struct dirent *de;
  while ((de = readdir(d)) != NULL) {
    if (de->d_name[0] == '.') continue;
    if (n == cap) {
      cap = cap ? 2 * cap : 32;
      names = realloc(names, cap * sizeof *names);
      if (!names) exit(2);
    }
    size_t l = strlen(path) + strlen(de->d_name) + 2;
    names[n] = malloc(l);
    if (!names[n]) exit(2);
    snprintf(names[n], l, "%s/%s", path, de->d_name);
    n++;
  }
  closedir(d);
  qsort(names, n, sizeof *names, cmp_str);
  for (size_t i = 0; i < n; i++) {
    if (stat(names[i], &sb) == 0 && S_ISREG(sb.st_mode)) add_seed(names[i]);
    free(names[i]);
  }
  free(names);
}

/* ---- mutations ---------------------------------------------------------------------- */

static uint64_t rng_state;

/* splitmix64: small, fast, and the same sequence everywhere. */
static uint64_t rng(void) {
  uint64_t z = (rng_state += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

/* Uniform in [0, n); n > 0. */
static size_t rnd(size_t n) { return (size_t)(rng() % n); }

typedef struct buf {
  uint8_t *p;
  size_t len, cap;
} buf;

/* Makes room for len + extra bytes, or returns 0 when that is over the size limit. */
static int reserve(buf *b, size_t extra, size_t max_len) {
  if (b->len + extra > max_len) return 0;
  if (b->len + extra > b->cap) {
    b->cap = (b->len + extra) * 2;
    b->p = realloc(b->p, b->cap);
    if (!b->p) exit(2);
  }
  return 1;
}

/* Inputs that start with an 8-byte little-endian length of the header that follows it (as
 * safetensors files do) go stale when bytes are inserted or deleted inside that header, and
 * then the target only ever sees the length check fail. Half the time an edit of delta bytes
 * at offset at therefore moves the length with it, so that the header's contents get
 * exercised; the other half leaves it, so that stale lengths are tried too. */
static void adjust_prefix(buf *b, size_t at, long delta) {
  if (b->len < 8 || rnd(2)) return;
  uint64_t v = 0;
  for (int i = 7; i >= 0; i--) v = v << 8 | b->p[i];
  size_t old_len = (size_t)((long)b->len - delta);
  if (at < 8 || v > old_len - 8 || at > 8 + v) return; /* not a header length, or not inside */
  v = (uint64_t)((int64_t)v + delta);
  for (int i = 0; i < 8; i++) b->p[i] = (uint8_t)(v >> (8 * i));
}

static const uint8_t interesting_bytes[] = {0x00, 0x01, 0x7f, 0x80, 0xff, '{', '}', '[', ']',
                                            '"',  ',',  ':',  '-',  '0',  ' ', '\\', 0xc3, 0xed};

static const char *const interesting_numbers[] = {
    "0", "1", "2", "-1", "7", "8", "255", "256", "65535", "65536", "2147483647", "2147483648",
    "4294967295", "4294967296", "104857600", "104857601", "9223372036854775807",
    "9223372036854775808", "18446744073709551615", "1e3", "0.5", "00", "-0",
};

/* Replaces the run of decimal digits at or after a random position by a boundary number. */
static void splice_digits(buf *b, size_t max_len) {
  if (b->len == 0) return;
  size_t start = rnd(b->len), i = start;
  while (i < b->len && (b->p[i] < '0' || b->p[i] > '9')) i++;
  if (i == b->len) return;
  size_t end = i;
  while (end < b->len && b->p[end] >= '0' && b->p[end] <= '9') end++;
  char num[32];
  if (rnd(3) == 0)
    snprintf(num, sizeof num, "%zu", rnd(4096));
  else
    snprintf(num, sizeof num, "%s",
             interesting_numbers[rnd(sizeof interesting_numbers / sizeof *interesting_numbers)]);
  size_t nl = strlen(num), old = end - i;
  if (nl > old && !reserve(b, nl - old, max_len)) return;
  memmove(b->p + i + nl, b->p + end, b->len - end);
  memcpy(b->p + i, num, nl);
  b->len = b->len - old + nl;
  adjust_prefix(b, i, (long)nl - (long)old);
}

/* Rewrites the little-endian 8- or 4-byte length at the start of the input. */
static void change_length(buf *b) {
  size_t w = rnd(2) ? 8 : 4;
  if (b->len < w) return;
  uint64_t v = 0;
  for (size_t i = w; i-- > 0;) v = v << 8 | b->p[i];
  switch (rnd(6)) {
  case 0: v += 1 + rnd(16); break;
  case 1: v -= 1 + rnd(16); break;
  case 2: v = b->len - w - rnd(4); break;
  case 3: v = 0; break;
  case 4: v = (uint64_t)1 << rnd(64); break;
  default: v = rng(); break;
  }
  for (size_t i = 0; i < w; i++) b->p[i] = (uint8_t)(v >> (8 * i));
}

/* Applies one random mutation to b. */
static void mutate(buf *b, size_t max_len) {
  switch (rnd(10)) {
  case 0: /* bit flip */
    if (b->len) b->p[rnd(b->len)] ^= (uint8_t)(1u << rnd(8));
    break;
  case 1: /* overwrite a byte with a boundary value */
    if (b->len)
      b->p[rnd(b->len)] = interesting_bytes[rnd(sizeof interesting_bytes)];
    break;
  case 2: { /* insert a byte */
    if (!reserve(b, 1, max_len)) break;
    size_t at = rnd(b->len + 1);
    memmove(b->p + at + 1, b->p + at, b->len - at);
    b->p[at] = rnd(2) ? interesting_bytes[rnd(sizeof interesting_bytes)] : (uint8_t)rng();
    b->len++;
    adjust_prefix(b, at, 1);
    break;
  }
  case 3: { /* delete 1..8 bytes */
    if (!b->len) break;
    size_t at = rnd(b->len), n = 1 + rnd(8);
    if (n > b->len - at) n = b->len - at;
    memmove(b->p + at, b->p + at + n, b->len - at - n);
    b->len -= n;
    adjust_prefix(b, at, -(long)n);
    break;
  }
  case 4: { /* repeat a chunk (duplicated keys, overlapping entries) */
    if (!b->len) break;
    size_t at = rnd(b->len), n = 1 + rnd(64);
    if (n > b->len - at) n = b->len - at;
    if (!reserve(b, n, max_len)) break;
    uint8_t chunk[64];
    memcpy(chunk, b->p + at, n);
    size_t to = rnd(b->len + 1);
    memmove(b->p + to + n, b->p + to, b->len - to);
    memcpy(b->p + to, chunk, n);
    b->len += n;
    adjust_prefix(b, to, (long)n);
    break;
  }
  case 5: /* truncate: mostly a few bytes off the end (data sections), sometimes anywhere */
    if (b->len) b->len = rnd(4) ? b->len - 1 - rnd(b->len < 16 ? b->len : 16) : rnd(b->len);
    break;
  case 6: { /* splice in a chunk of another seed */
    const seed *o = &seeds[rnd(nseeds)];
    if (!o->len) break;
    size_t at = rnd(o->len), n = 1 + rnd(128);
    if (n > o->len - at) n = o->len - at;
    size_t to = rnd(b->len + 1);
    if (to + n > b->len && !reserve(b, to + n - b->len, max_len)) break;
    memcpy(b->p + to, o->data + at, n);
    if (to + n > b->len) b->len = to + n;
    break;
  }
  case 7:
  case 8: splice_digits(b, max_len); break;
  default: change_length(b); break;
  }
}

/* ---- main --------------------------------------------------------------------------- */

/* Parses "-name=VALUE" into *v; 1 if arg is that option. */
static int opt_u64(const char *arg, const char *name, uint64_t *v) {
  size_t n = strlen(name);
  if (strncmp(arg, name, n) != 0 || arg[n] != '=') return 0;
  *v = strtoull(arg + n + 1, NULL, 0);
  return 1;
}

int main(int argc, char **argv) {
  uint64_t runs = 2000, seed_value = 0x5eed5afe, max_len = 1 << 16;
  const char *e;
  if ((e = getenv("FG_FUZZ_RUNS")) && *e) runs = strtoull(e, NULL, 0);
  if ((e = getenv("FG_FUZZ_SEED")) && *e) seed_value = strtoull(e, NULL, 0);
  if ((e = getenv("FG_FUZZ_ARTIFACT")) && *e)
    snprintf(artifact_path, sizeof artifact_path, "%s", e);
  for (int i = 1; i < argc; i++) {
    if (argv[i][0] == '-') {
      if (!opt_u64(argv[i], "-runs", &runs) && !opt_u64(argv[i], "-seed", &seed_value) &&
          !opt_u64(argv[i], "-max_len", &max_len))
        fprintf(stderr, "fuzz: ignoring option %s\n", argv[i]);
      continue;
    }
    add_path(argv[i]);
  }
  signal(SIGSEGV, on_crash);
  signal(SIGBUS, on_crash);
  signal(SIGABRT, on_crash);
  signal(SIGFPE, on_crash);
  signal(SIGILL, on_crash);

  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  char label[32];
  for (size_t i = 0; i < nseeds; i++) {
    snprintf(label, sizeof label, "seed-%zu", i);
    run_one(seeds[i].data, seeds[i].len, label);
  }
  run_one(NULL, 0, "empty"); /* the empty input, always */

  rng_state = seed_value;
  buf b = {0};
  for (uint64_t r = 0; r < runs && nseeds; r++) {
    const seed *s = &seeds[rnd(nseeds)];
    b.len = 0;
    if (!reserve(&b, s->len < max_len ? s->len : max_len, SIZE_MAX)) exit(2);
    b.len = s->len < max_len ? s->len : max_len;
    if (b.len) memcpy(b.p, s->data, b.len);
    for (size_t m = 1 + rnd(4); m > 0; m--) mutate(&b, max_len);
    snprintf(label, sizeof label, "%llu", (unsigned long long)r);
    run_one(b.p, b.len, label);
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  double secs = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
  uint64_t total = (nseeds ? runs : 0) + nseeds + 1;
  printf("fuzz: %zu seeds, %llu mutated runs (seed 0x%llx) in %.2f s: %.0f inputs/s\n", nseeds,
         (unsigned long long)(nseeds ? runs : 0), (unsigned long long)seed_value, secs,
         secs > 0 ? (double)total / secs : 0.0);
  free(b.p);
  for (size_t i = 0; i < nseeds; i++) free(seeds[i].data);
  free(seeds);
  return 0;
}

/* Server processes for the Modbus tests: fork/exec, the port file, kill and stop, the atexit
 * hook, the request log. See simproc.h for the contract of each helper. */
#include "simproc.h"

#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "test.h"

#define MAX_PROCS 64  /* running at once; a reaped one frees its slot */
#define MAX_ARGS 48   /* argv entries, the NULL included */
#define PORT_WAIT_MS 10000

static char g_sim[PATH_MAX];      /* absolute path of fieldgrip-sim; empty before init */
static char g_dir[PATH_MAX - 64]; /* room for "/simN.port" in a PATH_MAX name */
static int g_own_dir;             /* 1: made by simproc_init, removed at exit */
static pid_t g_pids[MAX_PROCS];   /* children not yet reaped; 0 or -1: a free slot */

/* ---------------------------------------------------------------- process table */

/* nftw callback of the exit hook: removes each entry, children first. */
static int rm_cb(const char *path, const struct stat *sb, int flag, struct FTW *ftw) {
  (void)sb;
  (void)flag;
  (void)ftw;
  remove(path);
  return 0;
}

/* The atexit hook: SIGKILLs and reaps every child still running, then removes the directory
 * when simproc_init made it. */
static void kill_all(void) {
  for (int i = 0; i < MAX_PROCS; i++) {
    if (g_pids[i] > 0) {
      kill(g_pids[i], SIGKILL);
      waitpid(g_pids[i], NULL, 0);
      g_pids[i] = -1;
    }
  }
  if (g_own_dir && g_dir[0]) nftw(g_dir, rm_cb, 16, FTW_DEPTH | FTW_PHYS);
}

/* Records pid for the exit hook; fails the test when MAX_PROCS are running already. */
static void track(pid_t pid) {
  for (int i = 0; i < MAX_PROCS; i++) {
    if (g_pids[i] <= 0) {
      g_pids[i] = pid;
      return;
    }
  }
  FG_TEST_FAIL("more than %d server processes at once", MAX_PROCS);
}

/* Drops pid from the table once it has been reaped. */
static void forget(pid_t pid) {
  for (int i = 0; i < MAX_PROCS; i++)
    if (g_pids[i] == pid) g_pids[i] = -1;
}

/* ---------------------------------------------------------------- files and argv */

/* Names p's port, log and stderr files in the directory after a counter, so that every start
 * gets files of its own, and marks p as not running. */
static void new_files(simproc *p) {
  static int counter;
  if (!g_sim[0]) FG_TEST_FAIL("simproc_init was not called");
  memset(p, 0, sizeof *p);
  p->pid = -1;
  const int k = counter++;
  snprintf(p->port_file, sizeof p->port_file, "%s/sim%d.port", g_dir, k);
  snprintf(p->log, sizeof p->log, "%s/sim%d.log", g_dir, k);
  snprintf(p->err, sizeof p->err, "%s/sim%d.err", g_dir, k);
  snprintf(p->events, sizeof p->events, "%s/sim%d.events", g_dir, k);
}

/* Fills argv with "sim --listen listen --port-file F --log F extra... NULL"; argv has
 * MAX_ARGS entries and borrows every string. */
static void sim_argv(const char **argv, const simproc *p, const char *listen,
                     const char *const *extra) {
  int n = 0;
  argv[n++] = g_sim;
  argv[n++] = "--listen";
  argv[n++] = listen;
  argv[n++] = "--port-file";
  argv[n++] = p->port_file;
  argv[n++] = "--log";
  argv[n++] = p->log;
  argv[n++] = "--events";
  argv[n++] = p->events;
  /* motions 50 times faster than real time; a test that times one passes its own scale */
  argv[n++] = "--time-scale";
  argv[n++] = "0.02";
  for (int i = 0; extra && extra[i]; i++) {
    ASSERT(n < MAX_ARGS - 1);
    argv[n++] = extra[i];
  }
  argv[n] = NULL;
}

/* ---------------------------------------------------------------- start and wait */

/* Removes a stale port file, then forks and execs argv with stdout and stderr appended to
 * p->err; the child dies with the test process (PR_SET_PDEATHSIG). Sets p->pid. */
static void spawn(simproc *p, const char *const *argv) {
  unlink(p->port_file);
  int efd = open(p->err, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (efd < 0) FG_TEST_FAIL("open %s: %s", p->err, strerror(errno));
  const pid_t parent = getpid();
  pid_t pid = fork();
  ASSERT(pid >= 0);
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    dup2(efd, 1);
    dup2(efd, 2);
    execv(argv[0], (char *const *)argv);
    _exit(127);
  }
  close(efd);
  track(pid);
  p->pid = pid;
}

/* Waits up to 10 s for p's port file and sets p->port from it. The programs write it through a
 * temp file and a rename, so once it exists it must hold the port and a newline. Fails the test
 * with the program's stderr if it exits first. */
static void wait_port(simproc *p, const char *prog) {
  const double deadline = simproc_now_ms() + PORT_WAIT_MS;
  for (;;) {
    char *s = simproc_read(p->port_file);
    if (s) {
      p->port = atoi(s);
      const size_t len = strlen(s);
      ASSERT(len > 0 && s[len - 1] == '\n');
      free(s);
      ASSERT(p->port > 0 && p->port < 65536);
      return;
    }
    int status;
    if (waitpid(p->pid, &status, WNOHANG) == p->pid) {
      forget(p->pid);
      p->pid = -1;
      char *err = simproc_read(p->err);
      FG_TEST_FAIL("%s exited (status 0x%x) before listening: %s", prog, status,
                   err ? err : "");
    }
    if (simproc_now_ms() > deadline)
      FG_TEST_FAIL("%s wrote no port file %s within 10 s", prog, p->port_file);
    simproc_sleep_ms(2);
  }
}

/* Starts the simulator on 127.0.0.1:port with p's files as they are and waits for it. */
static void sim_run(simproc *p, int port, const char *const *extra) {
  char listen[64];
  snprintf(listen, sizeof listen, "127.0.0.1:%d", port);
  const char *argv[MAX_ARGS];
  sim_argv(argv, p, listen, extra);
  spawn(p, argv);
  wait_port(p, g_sim);
}

/* ---------------------------------------------------------------- public */

void simproc_init(const char *sim, const char *dir) {
  ASSERT(!g_sim[0]);
  ASSERT(sim != NULL);
  if (!realpath(sim, g_sim)) FG_TEST_FAIL("%s: %s", sim, strerror(errno));
  if (dir) {
    if (snprintf(g_dir, sizeof g_dir, "%s", dir) >= (int)sizeof g_dir)
      FG_TEST_FAIL("directory name too long: %s", dir);
  } else {
    snprintf(g_dir, sizeof g_dir, "/tmp/fg-simproc-XXXXXX");
    if (!mkdtemp(g_dir)) FG_TEST_FAIL("mkdtemp: %s", strerror(errno));
    g_own_dir = 1;
  }
  atexit(kill_all);
}

void simproc_start(simproc *p, int port, const char *const *extra) {
  new_files(p);
  sim_run(p, port, extra);
}

void simproc_restart(simproc *p, const char *const *extra) {
  ASSERT(p->pid <= 0);
  ASSERT(p->port > 0 && p->log[0]);
  sim_run(p, p->port, extra);
}

void simproc_start_argv(simproc *p, const char *const *argv_in) {
  new_files(p);
  const char *argv[MAX_ARGS];
  int n = 0;
  for (; argv_in[n]; n++) {
    ASSERT(n < MAX_ARGS - 5);
    argv[n] = argv_in[n];
  }
  ASSERT(n > 0);
  argv[n++] = "--port-file";
  argv[n++] = p->port_file;
  argv[n++] = "--log";
  argv[n++] = p->log;
  argv[n] = NULL;
  spawn(p, argv);
  wait_port(p, argv[0]);
}

int simproc_exit_status(const char *const *extra) {
  simproc p;
  new_files(&p);
  const char *argv[MAX_ARGS];
  sim_argv(argv, &p, "127.0.0.1:0", extra);
  spawn(&p, argv);
  int status;
  ASSERT_EQ(waitpid(p.pid, &status, 0), p.pid);
  forget(p.pid);
  ASSERT(WIFEXITED(status));
  return WEXITSTATUS(status);
}

void simproc_kill(simproc *p) {
  ASSERT(p->pid > 0);
  ASSERT_EQ(kill(p->pid, SIGKILL), 0);
  ASSERT_EQ(waitpid(p->pid, NULL, 0), p->pid);
  forget(p->pid);
  p->pid = -1;
}

void simproc_stop(simproc *p) {
  const pid_t pid = p->pid;
  ASSERT(pid > 0);
  kill(pid, SIGCONT);
  ASSERT_EQ(kill(pid, SIGTERM), 0);
  int status;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  forget(pid);
  p->pid = -1;
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    char *err = simproc_read(p->err);
    FG_TEST_FAIL("process %d did not exit 0 on SIGTERM (status 0x%x): %s", (int)pid, status,
                 err ? err : "");
  }
}

int simproc_writes(const simproc *p, int unit, simproc_write *out, int max) {
  char *text = simproc_read(p->log);
  if (!text) return 0;
  int count = 0;
  char *save = NULL;
  for (char *line = strtok_r(text, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
    simproc_write w = {0};
    int used = 0;
    if (sscanf(line, "write unit=%d fn=%d addr=%d n=%d words=%n", &w.unit, &w.fn, &w.addr, &w.n,
               &used) != 4 || used == 0)
      FG_TEST_FAIL("unexpected log line in %s: %s", p->log, line);
    if (unit >= 0 && w.unit != unit) continue;
    char *s = line + used;
    for (int i = 0; i < w.n && i < 64; i++) {
      w.words[i] = (uint16_t)strtoul(s, &s, 10);
      if (*s == ',') s++;
    }
    if (count < max) out[count] = w;
    count++;
  }
  free(text);
  return count;
}

char *simproc_read(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  size_t cap = 4096, len = 0;
  char *buf = malloc(cap);
  ASSERT(buf != NULL);
  size_t got;
  while ((got = fread(buf + len, 1, cap - len - 1, f)) > 0) {
    len += got;
    if (cap - len < 2) {
      cap *= 2;
      buf = realloc(buf, cap);
      ASSERT(buf != NULL);
    }
  }
  fclose(f);
  buf[len] = '\0';
  return buf;
}

double simproc_now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

void simproc_sleep_ms(int ms) {
  struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
  while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
  }
}

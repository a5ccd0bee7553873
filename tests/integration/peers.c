#include "peers.h"

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "harness.h"

#define MAX_PEERS 32
#define MAX_ARGS 48

static pid_t g_pids[MAX_PEERS];
static int g_n, g_registered;

static void kill_all(void) {
  for (int i = 0; i < g_n; i++) {
    if (g_pids[i] > 0) {
      kill(g_pids[i], SIGKILL);
      waitpid(g_pids[i], NULL, 0);
      g_pids[i] = -1;
    }
  }
}

static void forget(pid_t pid) {
  for (int i = 0; i < g_n; i++)
    if (g_pids[i] == pid) g_pids[i] = -1;
}

static char *slurp(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *buf = malloc((size_t)n + 1);
  ASSERT(buf);
  size_t got = fread(buf, 1, (size_t)n, f);
  buf[got] = '\0';
  fclose(f);
  return buf;
}

/* Forks and execs argv with stderr to p->err, then waits up to 10 s for the port file. */
static void spawn_and_wait(it_peer *p, const char *const *argv) {
  if (!g_registered) {
    atexit(kill_all);
    g_registered = 1;
  }
  unlink(p->port_file);
  int efd = open(p->err, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  ASSERT(efd >= 0);
  ASSERT(g_n < MAX_PEERS);
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
  g_pids[g_n++] = pid;
  p->pid = pid;
  for (int i = 0; i < 5000; i++) {
    char *s = slurp(p->port_file);
    if (s && strchr(s, '\n')) {
      p->port = atoi(s);
      free(s);
      ASSERT(p->port > 0 && p->port < 65536);
      return;
    }
    free(s);
    int status;
    if (waitpid(pid, &status, WNOHANG) == pid) {
      forget(pid);
      char *err = slurp(p->err);
      FG_TEST_FAIL("%s exited (status 0x%x) before listening: %s", argv[0], status,
                   err ? err : "");
    }
    const struct timespec ts = {0, 2000000};
    nanosleep(&ts, NULL);
  }
  FG_TEST_FAIL("%s wrote no port file within 10 s", argv[0]);
}

/* Names p's files after a counter unless it ran before (a restart keeps them). */
static void name_files(it_peer *p) {
  static int counter;
  if (p->log[0]) return;
  const int k = counter++;
  snprintf(p->port_file, sizeof p->port_file, "%s/peer%d.port", h_tmpdir(), k);
  snprintf(p->log, sizeof p->log, "%s/peer%d.log", h_tmpdir(), k);
  snprintf(p->err, sizeof p->err, "%s/peer%d.err", h_tmpdir(), k);
}

void it_sim_start(it_peer *p, const char *sim, int port, const char *const *extra) {
  name_files(p);
  char listen[64];
  snprintf(listen, sizeof listen, "127.0.0.1:%d", port);
  const char *argv[MAX_ARGS] = {sim, "--listen", listen, "--port-file", p->port_file, "--log",
                                p->log};
  int n = 7;
  for (int i = 0; extra && extra[i]; i++) {
    ASSERT(n < MAX_ARGS - 1);
    argv[n++] = extra[i];
  }
  argv[n] = NULL;
  spawn_and_wait(p, argv);
}

void it_proc_start(it_peer *p, const char *const *argv_in) {
  name_files(p);
  const char *argv[MAX_ARGS];
  int n = 0;
  for (; argv_in[n]; n++) {
    ASSERT(n < MAX_ARGS - 5);
    argv[n] = argv_in[n];
  }
  argv[n++] = "--port-file";
  argv[n++] = p->port_file;
  argv[n++] = "--log";
  argv[n++] = p->log;
  argv[n] = NULL;
  spawn_and_wait(p, argv);
}

void it_peer_kill(it_peer *p) {
  ASSERT(p->pid > 0);
  kill(p->pid, SIGKILL);
  waitpid(p->pid, NULL, 0);
  forget(p->pid);
  p->pid = -1;
}

void it_peer_stop(it_peer *p) {
  ASSERT(p->pid > 0);
  ASSERT_EQ(kill(p->pid, SIGTERM), 0);
  int status;
  ASSERT_EQ(waitpid(p->pid, &status, 0), p->pid);
  forget(p->pid);
  p->pid = -1;
  ASSERT(WIFEXITED(status) && WEXITSTATUS(status) == 0);
}

int it_peer_writes(const it_peer *p, int unit, it_write *out, int max) {
  char *text = slurp(p->log);
  if (!text) return 0;
  int count = 0;
  for (char *line = strtok(text, "\n"); line; line = strtok(NULL, "\n")) {
    it_write w = {0};
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

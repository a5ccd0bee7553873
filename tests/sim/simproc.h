/* Modbus server processes for the tests: fieldgrip-sim (sim/) or another server program
 * run as a child process on a loopback port with --port-file and --log, killed at exit (also
 * after a failed ASSERT, which calls exit), and the writes it logged, one line per write
 * request: "write unit=U fn=F addr=A n=N words=W1,W2,...".
 *
 * Every helper either succeeds or fails the test through tests/test.h, so none returns an
 * error code. One test process, one thread: nothing here is thread-safe. */
#ifndef FG_TEST_SIMPROC_H
#define FG_TEST_SIMPROC_H

#include <limits.h>
#include <stdint.h>
#include <sys/types.h>

/* A started server. The caller owns the struct (usually on the stack); the process is the
 * library's to kill at exit until simproc_kill or simproc_stop reaps it. */
typedef struct simproc {
  pid_t pid; /* -1 once reaped */
  int port;  /* the TCP port it listens on, read from its port file */
  char port_file[PATH_MAX]; /* the port and a newline, written once it listens */
  char log[PATH_MAX];       /* its request log (--log) */
  char events[PATH_MAX];    /* its robot's motions and stops (--events; fieldgrip-sim only) */
  char err[PATH_MAX];       /* its stdout and stderr, appended */
} simproc;

/* One logged write: Modbus unit id, function code (6 or 16), first register address, register
 * count and the first 64 of its words. */
typedef struct simproc_write {
  int unit, fn, addr, n;
  uint16_t words[64];
} simproc_write;

/* Call once, before any start. sim: the path of fieldgrip-sim, resolved to an absolute path
 * (fails the test when it does not exist; the string is copied). dir: where the port, log and
 * stderr files of later starts go; the caller owns it and removes it; NULL makes a new
 * /tmp/fg-simproc-XXXXXX that is removed at exit. Registers the atexit hook that SIGKILLs and
 * reaps every process still running. */
void simproc_init(const char *sim, const char *dir);

/* Starts the simulator as "sim --listen 127.0.0.1:PORT --port-file F --log F --events F
 * --time-scale 0.02 extra..." (motions 50 times faster than real time unless extra sets
 * another scale), port 0
 * meaning a free one, extra NULL-terminated (NULL: none), with new files, and waits up to 10 s
 * for its port file. Fails the test with the simulator's stderr when it exits first. Fills *p;
 * its previous content is ignored. */
void simproc_start(simproc *p, int port, const char *const *extra);

/* Starts the simulator again on p->port after simproc_kill or simproc_stop, with the same files:
 * its log and stderr are appended to, so the writes of both runs read back as one log. */
void simproc_restart(simproc *p, const char *const *extra);

/* Starts argv (NULL-terminated, argv[0] a path; borrowed for the call) with "--port-file F
 * --log F" appended and new files, and waits for the port as simproc_start does. */
void simproc_start_argv(simproc *p, const char *const *argv);

/* Runs "sim --listen 127.0.0.1:0 --port-file F --log F extra..." to its end and returns its exit
 * status; fails the test when it dies of a signal. For arguments the simulator must refuse. */
int simproc_exit_status(const char *const *extra);

/* SIGKILL and reap, as a crashed or powered-off peer; p->pid becomes -1. */
void simproc_kill(simproc *p);

/* SIGCONT (in case the test stopped it), SIGTERM and reap; fails the test, with the program's
 * stderr, unless it exits with status 0. p->pid becomes -1. */
void simproc_stop(simproc *p);

/* The writes in p's log so far for unit (-1: any), oldest first, into out[0 .. max-1]; returns
 * how many there are (may exceed max). Fails the test on a line of another format. */
int simproc_writes(const simproc *p, int unit, simproc_write *out, int max);

/* The whole file at path, NUL-terminated; malloc'd, the caller frees it. NULL when it cannot be
 * opened. */
char *simproc_read(const char *path);

/* Milliseconds on the monotonic clock, and a sleep of ms milliseconds that resumes after a
 * signal: the timelines the tests measure against the simulator's delays. */
double simproc_now_ms(void);
void simproc_sleep_ms(int ms);

#endif

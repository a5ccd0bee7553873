/* Modbus peers for the daemon's tests: the simulator (fieldgrip-sim) or another server
 * program run as a child process on a free loopback port, killed at exit, and the writes it
 * logged (one line per write request: "write unit=U fn=F addr=A n=N words=W1,W2,..."). */
#ifndef FG_IT_PEERS_H
#define FG_IT_PEERS_H

#include <limits.h>
#include <stdint.h>
#include <sys/types.h>

typedef struct it_peer {
  pid_t pid; /* -1 when not running */
  int port;
  char port_file[PATH_MAX], log[PATH_MAX], err[PATH_MAX];
} it_peer;

/* Starts fieldgrip-sim (path sim) on 127.0.0.1:port (0: a free one) with --port-file, --log
 * and the NULL-terminated extra arguments, and waits for its port file. A restart on the
 * port of a killed one keeps its log file (appends). */
void it_sim_start(it_peer *p, const char *sim, int port, const char *const *extra);

/* Starts argv (NULL-terminated) with --port-file F --log F appended, waits for the port. */
void it_proc_start(it_peer *p, const char *const *argv);

/* SIGKILL and reap; SIGTERM and reap (asserting exit status 0). */
void it_peer_kill(it_peer *p);
void it_peer_stop(it_peer *p);

typedef struct it_write {
  int unit, fn, addr, n;
  uint16_t words[64];
} it_write;

/* The writes logged so far for unit (-1: any), oldest first, into out[0 .. max-1]; returns
 * how many there are (may exceed max). */
int it_peer_writes(const it_peer *p, int unit, it_write *out, int max);

#endif

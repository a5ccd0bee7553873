/* The claim on the Modbus peers (claim.h): one flock()ed file per peer. */
#include "claim.h"

#include "core/error.h"
#include "core/fsutil.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#define DEFAULT_LOCK_DIR "/run/lock"

struct fg_peer_claim {
  int fd[2]; /* [robot], [gripper.modbus]; -1 when not configured or the same peer */
};

char *fg_peer_claim_dir(const fg_conf *conf) {
  if (conf->lock_dir) return strdup(conf->lock_dir);
  struct stat st;
  if (stat(DEFAULT_LOCK_DIR, &st) == 0 && S_ISDIR(st.st_mode) &&
      access(DEFAULT_LOCK_DIR, W_OK | X_OK) == 0)
    return strdup(DEFAULT_LOCK_DIR);
  return strdup(conf->state_dir);
}

/* The peer's address for messages ("tcp 10.0.0.5:502 unit 1") and its file name part
 * ("tcp-10.0.0.5-502-u1"), only [A-Za-z0-9._-] kept. The serial device is taken through
 * its links, so /dev/serial/by-id/... and /dev/ttyUSB0 claim one line. */
static void peer_name(const fg_conf_modbus *m, char *what, size_t what_size, char *file,
                      size_t file_size) {
  char raw[PATH_MAX + 64];
  if (m->transport == FG_TRANSPORT_TCP) {
    const int v6 = strchr(m->host, ':') != NULL;
    snprintf(what, what_size, "tcp %s%s%s:%d unit %d", v6 ? "[" : "", m->host, v6 ? "]" : "",
             m->port, m->unit_id);
    snprintf(raw, sizeof raw, "tcp-%s-%d-u%d", m->host, m->port, m->unit_id);
    for (char *c = raw; *c; c++) *c = (char)(*c >= 'A' && *c <= 'Z' ? *c - 'A' + 'a' : *c);
  } else {
    char real[PATH_MAX];
    const char *dev = realpath(m->device, real) ? real : m->device;
    snprintf(what, what_size, "rtu %s", dev);
    snprintf(raw, sizeof raw, "rtu%s", dev);
  }
  size_t n = 0;
  for (const char *c = raw; *c && n + 1 < file_size; c++) {
    const int ok = (*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') ||
                   (*c >= '0' && *c <= '9') || *c == '.' || *c == '-';
    file[n++] = ok ? *c : (*c == '/' ? '-' : '_');
  }
  file[n] = '\0';
}

/* Claims one peer: the locked descriptor, or -1 with a detail. */
static int claim_one(const char *dir, const char *section, const fg_conf_modbus *m,
                     const fg_conf *conf, const char *listen, int *fd_out) {
  char what[PATH_MAX + 64], file[200], path[PATH_MAX];
  peer_name(m, what, sizeof what, file, sizeof file);
  snprintf(path, sizeof path, "%s/fieldgrip-modbus-%s.lock", dir, file);
  int fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0)
    return fg_fail(FG_EIO, "cannot open the lock file %s that claims the %s peer (%s): %s; "
                   "set [robot] lock_dir to a folder this user may write", path, section, what,
                   strerror(errno));
  if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int e = errno;
    char owner[512] = "";
    const ssize_t n = pread(fd, owner, sizeof owner - 1, 0);
    owner[n > 0 ? n : 0] = '\0';
    close(fd);
    if (e != EWOULDBLOCK)
      return fg_fail(FG_EIO, "cannot lock %s: %s", path, strerror(e));
    long pid = 0;
    char state[400] = "?", addr[100] = "?";
    sscanf(owner, "pid %ld state_dir %399s listen %99s", &pid, state, addr);
    char who[600];
    if (pid > 0)
      snprintf(who, sizeof who, "fieldgripd pid %ld (state dir %s, listening on %s)", pid, state,
               addr);
    else
      snprintf(who, sizeof who, "another process");
    return fg_fail(FG_EBUSY, "the %s peer %s is already driven by %s, which holds %s; two "
                   "daemons would interleave their commands to one robot: stop the other one, "
                   "or point [%s] at another peer", section, what, who, path, section);
  }
  char line[600];
  const int len = snprintf(line, sizeof line, "pid %ld state_dir %s listen %s\n", (long)getpid(),
                           conf->state_dir, listen && listen[0] ? listen : "?");
  /* who holds it, for the message above; the lock does not depend on it */
  if (ftruncate(fd, 0) != 0 || pwrite(fd, line, (size_t)len, 0) != len) {
    /* a lock without its note still does its job */
  }
  *fd_out = fd;
  return 0;
}

int fg_peer_claim_take(fg_peer_claim **out, const fg_conf *conf, const char *listen) {
  *out = NULL;
  fg_peer_claim *c = malloc(sizeof *c);
  char *dir = fg_peer_claim_dir(conf);
  if (!c || !dir) {
    free(c);
    free(dir);
    return fg_fail(FG_ENOMEM, "out of memory claiming the Modbus peers");
  }
  c->fd[0] = c->fd[1] = -1;
  int rc = fg_mkdir_p(dir);
  const fg_conf_modbus *peers[2] = {&conf->robot, &conf->gripper_modbus};
  static const char *const sections[2] = {"robot", "gripper.modbus"};
  char name0[200] = "", scratch[PATH_MAX + 64];
  for (int i = 0; i < 2 && rc == 0; i++) {
    if (peers[i]->transport == FG_TRANSPORT_NONE) continue;
    char name[200];
    peer_name(peers[i], scratch, sizeof scratch, name, sizeof name);
    /* flock conflicts between two descriptors of one process too: a gripper on the robot's
     * own address and unit is claimed once */
    if (i == 1 && strcmp(name, name0) == 0) continue;
    if (i == 0) snprintf(name0, sizeof name0, "%s", name);
    rc = claim_one(dir, sections[i], peers[i], conf, listen, &c->fd[i]);
  }
  free(dir);
  if (rc < 0) {
    fg_peer_claim_release(c);
    return rc;
  }
  *out = c;
  return 0;
}

void fg_peer_claim_release(fg_peer_claim *c) {
  if (!c) return;
  for (int i = 0; i < 2; i++)
    if (c->fd[i] >= 0) close(c->fd[i]);
  free(c);
}

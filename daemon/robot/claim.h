/* One daemon per robot: a claim on each configured Modbus peer ([robot], [gripper.modbus]),
 * held for the life of the process, so that a second fieldgripd configured for the same
 * robot or gripper refuses to start instead of interleaving its commands (and sequence
 * numbers) with the first one's.
 *
 * A claim is an flock() on <lock_dir>/fieldgrip-modbus-<peer>.lock, <peer> being the
 * transport address: tcp-HOST-PORT-uUNIT (two unit ids behind one gateway are two devices),
 * or rtu-DEVICE (one serial line carries one master, whatever the units). The kernel drops
 * the lock when the process ends in any way, kill -9 included, so a stale file never blocks
 * a start; the file holds the owner's pid, state dir and listen address for the message of
 * the daemon that is refused. Files are left in place (a lock file removed while another
 * process opens it would let two hold "the" lock); /run/lock is emptied at boot.
 *
 * Hosts are compared as written: "localhost" and "127.0.0.1" are two names to the claim. */
#ifndef FG_DAEMON_CLAIM_H
#define FG_DAEMON_CLAIM_H

#include "conf/conf.h"

typedef struct fg_peer_claim fg_peer_claim;

/* The folder the claims go in: conf's [robot] lock_dir when set, else /run/lock when this
 * process may write there, else the state dir. Not the state dir first: two daemons with
 * two state dirs and one robot are the case to catch, and only a folder that every
 * fieldgripd of the machine looks in sees both. Returns a malloc'd path, NULL on
 * allocation failure. */
char *fg_peer_claim_dir(const fg_conf *conf);

/* Claims conf's configured peers (none configured: an empty claim). listen is written into
 * the lock files for the refused daemon's message (may be NULL). 0 and *out (owned by the
 * caller: fg_peer_claim_release); FG_EBUSY with a detail naming the peer, the other
 * daemon's pid and what to do, or FG_EIO / FG_ENOMEM with a detail; *out NULL then. */
int fg_peer_claim_take(fg_peer_claim **out, const fg_conf *conf, const char *listen);

/* Drops the claims and frees. NULL is fine. */
void fg_peer_claim_release(fg_peer_claim *c);

#endif

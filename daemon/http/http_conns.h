/* The HTTP layer's connection table: every open client connection, what it is doing, and
 * the limits that keep floods and slow clients from holding the server.
 *
 * Lifecycle of an entry, as the HTTP layer reports it:
 *   open ─► WAITING (no request yet: its headers must be in within header_timeout_s)
 *        ─► RECEIVING (headers in, body arriving: at least min_body_bytes_per_s on average
 *           once a grace of header_timeout_s has passed)
 *        ─► BUSY (whole request in: the handler runs, the answer goes out; no deadline here)
 *        ─► WAITING again after the answer (kept alive: the next request must begin within
 *           idle_timeout_s) ... ─► close.
 * Past max_open connections, each new one sheds the oldest WAITING one: connections that
 * hold no request give way to new clients (a robot's health check still gets in when
 * thousands of idle sockets are open).
 *
 * The table never closes a socket: it shuts it down (shutdown(2), both ways), so that the
 * server's own event loop sees the end, closes the connection and reports the close here.
 * A file descriptor stays valid while its entry is in the table (the server closes the
 * socket only after fg_conns_close), so a shutdown under the table's lock never reaches a
 * reused descriptor.
 *
 * Nothing here knows libmicrohttpd; times are CLOCK_MONOTONIC seconds given by the caller.
 * Every function is thread-safe. */
#ifndef FG_DAEMON_HTTP_CONNS_H
#define FG_DAEMON_HTTP_CONNS_H

#include <stddef.h>

typedef struct fg_conns fg_conns;
typedef struct fg_conn fg_conn;

/* Why the table shut a connection down. */
typedef enum {
  FG_CONN_SHED = 0,           /* over max_open, oldest of those holding no request */
  FG_CONN_HEADER_TIMEOUT,     /* no complete request headers within header_timeout_s */
  FG_CONN_IDLE_TIMEOUT,       /* kept alive without a next request for idle_timeout_s */
  FG_CONN_BODY_TOO_SLOW,      /* the body arrived slower than min_body_bytes_per_s */
  FG_CONN_REASONS
} fg_conn_reason;

/* The limits a sweep applies; the HTTP layer reads them from the configuration in force. */
typedef struct fg_conns_limits {
  double header_timeout_s;     /* > 0; also the body's grace before its rate counts */
  double idle_timeout_s;       /* > 0 */
  double min_body_bytes_per_s; /* 0: no floor */
} fg_conns_limits;

/* Makes an empty table that keeps at most max_open (>= 1) connections before shedding.
 * On success *out is owned by the caller (fg_conns_free). FG_ENOMEM otherwise. */
int fg_conns_new(fg_conns **out, size_t max_open);

/* Frees the table and any entry still in it (sockets are left alone). NULL is fine. */
void fg_conns_free(fg_conns *t);

/* Adds connection fd, accepted at now_s, as WAITING. When more than max_open connections
 * are then live, shuts down the oldest WAITING one other than the new one, and counts it
 * in *shed (0 or 1; shed may be NULL). Returns the entry (owned by the table until
 * fg_conns_close), or NULL when out of memory (the connection then goes untracked). */
fg_conn *fg_conns_open(fg_conns *t, int fd, double now_s, int *shed);

/* Removes and frees c (NULL is fine). Call before the socket is closed. */
void fg_conns_close(fg_conns *t, fg_conn *c);

/* c's request headers are complete: RECEIVING from now_s. */
void fg_conns_request_begin(fg_conns *t, fg_conn *c, double now_s);

/* bytes more of c's body arrived. */
void fg_conns_body(fg_conns *t, fg_conn *c, size_t bytes);

/* c's whole request is in: BUSY. */
void fg_conns_request_ready(fg_conns *t, fg_conn *c);

/* c's answer went out and the connection stays open: WAITING from now_s for the next
 * request. */
void fg_conns_request_end(fg_conns *t, fg_conn *c, double now_s);

/* Shuts down every connection past its deadline at now_s under lim, adding how many to
 * closed[reason] (an array of FG_CONN_REASONS counts the caller zeroed). Returns the total. */
size_t fg_conns_sweep(fg_conns *t, const fg_conns_limits *lim, double now_s,
                      size_t closed[FG_CONN_REASONS]);

/* Connections in the table now (those shut down but not yet closed included). */
size_t fg_conns_count(fg_conns *t);

#endif

/* A Modbus client connection to one peer (TCP through modbus_new_tcp_pi, or RTU), with the
 * reconnection policy libmodbus 3.1.6 lacks: a broken pipe, a reset, a refused connection or
 * two timeouts in a row close the connection, and the next request reconnects once a
 * backoff (100 ms doubling to 5 s) has passed. A reply that comes after its request timed
 * out is dropped, before the next request or when it reaches that request first, so one
 * slow reply costs one request and not the connection. A write is never repeated here:
 * whether a failed write reached the peer is the caller's question (fg_mb_link_maybe_sent).
 *
 * A link belongs to one thread (libmodbus contexts are not thread-safe); only
 * fg_mb_link_state may be called from others. */
#ifndef FG_MODBUS_LINK_H
#define FG_MODBUS_LINK_H

#include <stdint.h>

typedef enum { FG_MB_TCP = 1, FG_MB_RTU = 2 } fg_mb_transport;

typedef struct fg_mb_link_config {
  const char *name;    /* "robot", "gripper": for messages */
  fg_mb_transport transport;
  const char *host;    /* tcp: a name, an IPv4 or an IPv6 address */
  int port;            /* tcp */
  const char *device;  /* rtu: serial device */
  int baud;            /* rtu */
  char parity;         /* rtu: 'N', 'E', 'O'; 8 data bits, 1 stop bit */
  int unit_id;         /* 0..247 */
  int timeout_ms;      /* response timeout (also the TCP connect timeout) */
} fg_mb_link_config;

/* What other threads may read about a link. */
typedef struct fg_mb_link_state {
  int connected;
  char last_error[256]; /* "" when none yet */
  double last_error_s;  /* CLOCK_REALTIME seconds of it, 0 when none */
  uint64_t requests, errors, timeouts, exceptions, reconnects, connect_failures;
  unsigned generation;  /* as fg_mb_link_generation: the number of the last connection */
} fg_mb_link_state;

typedef struct fg_mb_link fg_mb_link;

/* Creates a disconnected link (copies cfg's strings). FG_EINVAL for a bad config,
 * FG_ENOMEM. On failure *out is NULL. */
int fg_mb_link_new(fg_mb_link **out, const fg_mb_link_config *cfg);

/* Closes and frees; NULL is fine. */
void fg_mb_link_free(fg_mb_link *l);

/* Connects unless connected. 0 when connected; FG_EUNAVAIL with a detail ("robot
 * 127.0.0.1:502: Connection refused; next attempt in 400 ms") while the peer is unreachable
 * or its backoff has not passed. */
int fg_mb_link_ensure(fg_mb_link *l);

/* Closes the connection (the next request reconnects at once). */
void fg_mb_link_close(fg_mb_link *l);

/* Increases with every successful connection: a caller that keeps per-connection knowledge
 * (the robot's ack) compares it. */
unsigned fg_mb_link_generation(const fg_mb_link *l);

/* Requests. Each returns 0, or: FG_EUNAVAIL (not connected, or the connection broke),
 * FG_ETIMEDOUT (no reply within the response timeout), FG_EPEER (a Modbus exception:
 * fg_mb_link_exception() has its code), FG_EIO (a garbled reply). The detail names the peer,
 * the request and the cause. */
int fg_mb_read_registers(fg_mb_link *l, int addr, int n, uint16_t *out);       /* function 3 */
int fg_mb_read_input_registers(fg_mb_link *l, int addr, int n, uint16_t *out); /* function 4 */
int fg_mb_write_registers(fg_mb_link *l, int addr, int n, const uint16_t *w);  /* function 16 */

/* Whether the last failed request may have reached the peer (it was being sent on a live
 * connection), so that a failed write cannot be called "not applied". */
int fg_mb_link_maybe_sent(const fg_mb_link *l);

/* The exception code of the last FG_EPEER (1..11), else 0. */
int fg_mb_link_exception(const fg_mb_link *l);

/* A Modbus exception's name ("illegal data address"); static. */
const char *fg_mb_exception_name(int code);

/* Copies the link's state; callable from any thread. */
void fg_mb_link_state_get(fg_mb_link *l, fg_mb_link_state *st);

/* "127.0.0.1:502", "[::1]:502" or "/dev/ttyUSB0" for messages; owned by the link. */
const char *fg_mb_link_address(const fg_mb_link *l);

#endif

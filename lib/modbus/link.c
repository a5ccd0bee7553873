#include "modbus/link.h"

#include <errno.h>
#include <stdarg.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <modbus/modbus.h>

#include "core/error.h"
#include "core/clock.h"
#include "core/log.h"

#define BACKOFF_FIRST_MS 100
#define BACKOFF_MAX_MS 5000
#define TIMEOUTS_BEFORE_RECONNECT 2

struct fg_mb_link {
  fg_mb_link_config cfg; /* strings point into host/device below */
  char host[256], device[256], name[32], address[300];
  modbus_t *ctx;         /* NULL while disconnected */
  unsigned generation;
  int backoff_ms;        /* 0 after a success */
  double next_attempt_s; /* CLOCK_MONOTONIC */
  int timeouts_in_row;
  int stale;             /* a timed-out request's reply may still arrive */
  int said_down;         /* the log already says the peer is unreachable */
  int maybe_sent, exception;
  pthread_mutex_t lock;  /* guards st, the only part other threads read */
  fg_mb_link_state st;
};

/* Records the failure in the shared state and as the thread's detail; returns err. */
static int link_fail(fg_mb_link *l, int err, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static int link_fail(fg_mb_link *l, int err, const char *fmt, ...) {
  char msg[256];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  pthread_mutex_lock(&l->lock);
  snprintf(l->st.last_error, sizeof l->st.last_error, "%s", msg);
  l->st.last_error_s = fg_real_s();
  pthread_mutex_unlock(&l->lock);
  return fg_fail(err, "%s", msg);
}

static void set_connected(fg_mb_link *l, int connected) {
  pthread_mutex_lock(&l->lock);
  l->st.connected = connected;
  pthread_mutex_unlock(&l->lock);
}

int fg_mb_link_new(fg_mb_link **out, const fg_mb_link_config *cfg) {
  *out = NULL;
  if (cfg->transport != FG_MB_TCP && cfg->transport != FG_MB_RTU)
    return fg_fail(FG_EINVAL, "unknown Modbus transport %d", (int)cfg->transport);
  if (cfg->unit_id < 0 || cfg->unit_id > 247 || cfg->timeout_ms < 1)
    return fg_fail(FG_EINVAL, "unit id 0..247 and a positive timeout are needed");
  const char *addr = cfg->transport == FG_MB_TCP ? cfg->host : cfg->device;
  if (!addr || !addr[0] || strlen(addr) >= sizeof ((fg_mb_link *)0)->host)
    return fg_fail(FG_EINVAL, "a Modbus peer needs a host or device name under 256 bytes");
  fg_mb_link *l = calloc(1, sizeof *l);
  if (!l) return FG_ENOMEM;
  l->cfg = *cfg;
  snprintf(l->name, sizeof l->name, "%s", cfg->name ? cfg->name : "peer");
  l->cfg.name = l->name;
  if (cfg->transport == FG_MB_TCP) {
    snprintf(l->host, sizeof l->host, "%s", cfg->host);
    l->cfg.host = l->host;
    l->cfg.device = NULL;
    snprintf(l->address, sizeof l->address, strchr(l->host, ':') ? "[%s]:%d" : "%s:%d", l->host,
             cfg->port);
  } else {
    snprintf(l->device, sizeof l->device, "%s", cfg->device);
    l->cfg.device = l->device;
    l->cfg.host = NULL;
    snprintf(l->address, sizeof l->address, "%s", l->device);
  }
  pthread_mutex_init(&l->lock, NULL);
  *out = l;
  return 0;
}

void fg_mb_link_close(fg_mb_link *l) {
  if (!l->ctx) return;
  modbus_close(l->ctx);
  modbus_free(l->ctx);
  l->ctx = NULL;
  l->timeouts_in_row = 0;
  l->stale = 0;
  set_connected(l, 0);
}

void fg_mb_link_free(fg_mb_link *l) {
  if (!l) return;
  fg_mb_link_close(l);
  pthread_mutex_destroy(&l->lock);
  free(l);
}

/* The connection failed: wait before the next attempt. */
static void backoff(fg_mb_link *l) {
  l->backoff_ms = l->backoff_ms ? l->backoff_ms * 2 : BACKOFF_FIRST_MS;
  if (l->backoff_ms > BACKOFF_MAX_MS) l->backoff_ms = BACKOFF_MAX_MS;
  l->next_attempt_s = fg_mono_s() + l->backoff_ms * 1e-3;
}

int fg_mb_link_ensure(fg_mb_link *l) {
  if (l->ctx) return 0;
  const double t = fg_mono_s();
  if (t < l->next_attempt_s)
    return fg_fail(FG_EUNAVAIL, "%s %s is not connected (%s); next attempt in %.0f ms", l->name,
                   l->address, l->st.last_error[0] ? l->st.last_error : "not tried yet",
                   (l->next_attempt_s - t) * 1e3);
  modbus_t *ctx;
  if (l->cfg.transport == FG_MB_TCP) {
    char service[16];
    snprintf(service, sizeof service, "%d", l->cfg.port);
    ctx = modbus_new_tcp_pi(l->host, service);
  } else {
    ctx = modbus_new_rtu(l->device, l->cfg.baud, l->cfg.parity, 8, 1);
  }
  if (!ctx) {
    backoff(l);
    return link_fail(l, FG_EUNAVAIL, "%s %s: cannot create a Modbus context: %s", l->name,
                     l->address, modbus_strerror(errno));
  }
  modbus_set_slave(ctx, l->cfg.unit_id);
  modbus_set_response_timeout(ctx, (uint32_t)(l->cfg.timeout_ms / 1000),
                              (uint32_t)(l->cfg.timeout_ms % 1000) * 1000);
  modbus_set_error_recovery(ctx, MODBUS_ERROR_RECOVERY_NONE);
  if (modbus_connect(ctx) < 0) {
    const int e = errno;
    modbus_free(ctx);
    backoff(l);
    pthread_mutex_lock(&l->lock);
    l->st.connect_failures++;
    pthread_mutex_unlock(&l->lock);
    if (!l->said_down) /* once per outage, not at every attempt */
      fg_warn("modbus: %s %s unreachable (%s); retrying in the background", l->name,
              l->address, modbus_strerror(e));
    l->said_down = 1;
    return link_fail(l, FG_EUNAVAIL, "%s %s: %s", l->name, l->address, modbus_strerror(e));
  }
  l->ctx = ctx;
  l->said_down = 0;
  l->backoff_ms = 0;
  l->timeouts_in_row = 0;
  l->generation++;
  pthread_mutex_lock(&l->lock);
  l->st.connected = 1;
  l->st.reconnects += l->generation > 1;
  l->st.generation = l->generation;
  pthread_mutex_unlock(&l->lock);
  fg_info("modbus: %s %s connected (unit %d)", l->name, l->address, l->cfg.unit_id);
  return 0;
}

unsigned fg_mb_link_generation(const fg_mb_link *l) { return l->generation; }

int fg_mb_link_maybe_sent(const fg_mb_link *l) { return l->maybe_sent; }

int fg_mb_link_exception(const fg_mb_link *l) { return l->exception; }

const char *fg_mb_link_address(const fg_mb_link *l) { return l->address; }

const char *fg_mb_exception_name(int code) {
  switch (code) {
  case MODBUS_EXCEPTION_ILLEGAL_FUNCTION: return "illegal function";
  case MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS: return "illegal data address";
  case MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE: return "illegal data value";
  case MODBUS_EXCEPTION_SLAVE_OR_SERVER_FAILURE: return "server device failure";
  case MODBUS_EXCEPTION_ACKNOWLEDGE: return "acknowledge";
  case MODBUS_EXCEPTION_SLAVE_OR_SERVER_BUSY: return "server device busy";
  case MODBUS_EXCEPTION_NEGATIVE_ACKNOWLEDGE: return "negative acknowledge";
  case MODBUS_EXCEPTION_MEMORY_PARITY: return "memory parity error";
  case MODBUS_EXCEPTION_GATEWAY_PATH: return "gateway path unavailable";
  case MODBUS_EXCEPTION_GATEWAY_TARGET: return "gateway target device failed to respond";
  default: return "unknown exception";
  }
}

/* Sorts a failed request's errno into the codes of link.h, closing the connection where it
 * cannot be trusted any more. what names the request ("write 10 registers at 128"). */
static int request_failed(fg_mb_link *l, int e, const char *what) {
  pthread_mutex_lock(&l->lock);
  l->st.errors++;
  pthread_mutex_unlock(&l->lock);
  if (e > MODBUS_ENOBASE && e <= MODBUS_ENOBASE + MODBUS_EXCEPTION_GATEWAY_TARGET) {
    l->timeouts_in_row = 0;
    l->exception = e - MODBUS_ENOBASE;
    pthread_mutex_lock(&l->lock);
    l->st.exceptions++;
    pthread_mutex_unlock(&l->lock);
    return link_fail(l, FG_EPEER, "%s %s answered %s with exception %d (%s)", l->name,
                     l->address, what, l->exception, fg_mb_exception_name(l->exception));
  }
  if (e == ETIMEDOUT) {
    pthread_mutex_lock(&l->lock);
    l->st.timeouts++;
    pthread_mutex_unlock(&l->lock);
    /* a late reply must not be taken for the next request's: drop what has come of it, and
     * again before the next request, as the rest may still be on its way */
    modbus_flush(l->ctx);
    l->stale = 1;
    int rc = link_fail(l, FG_ETIMEDOUT, "%s %s did not answer %s within %d ms", l->name,
                       l->address, what, l->cfg.timeout_ms);
    if (++l->timeouts_in_row >= TIMEOUTS_BEFORE_RECONNECT) {
      fg_warn("modbus: %s %s: %d timeouts in a row; reconnecting", l->name, l->address,
              l->timeouts_in_row);
      fg_mb_link_close(l);
    }
    return rc;
  }
  if (e >= EMBBADCRC && e <= EMBBADSLAVE) {
    /* a garbled or mismatched frame: the stream cannot be trusted, start afresh */
    fg_mb_link_close(l);
    return link_fail(l, FG_EIO, "%s %s: bad reply to %s: %s", l->name, l->address, what,
                     modbus_strerror(e));
  }
  fg_mb_link_close(l);
  backoff(l);
  fg_warn("modbus: %s %s: connection lost during %s: %s", l->name, l->address, what,
          modbus_strerror(e));
  l->said_down = 1;
  return link_fail(l, FG_EUNAVAIL, "%s %s: connection lost during %s: %s", l->name, l->address,
                   what, modbus_strerror(e));
}

/* Common prologue: connected, counters, flags. */
static int request_begin(fg_mb_link *l) {
  l->maybe_sent = 0;
  l->exception = 0;
  FG_TRY(fg_mb_link_ensure(l));
  if (l->stale) {
    modbus_flush(l->ctx);
    l->stale = 0;
  }
  pthread_mutex_lock(&l->lock);
  l->st.requests++;
  pthread_mutex_unlock(&l->lock);
  l->maybe_sent = 1;
  return 0;
}

static void request_ok(fg_mb_link *l) {
  l->timeouts_in_row = 0;
  l->maybe_sent = 1;
}

/* Reads the next reply on the connection as the one to the request of function fn (3, 4 or
 * 16) for n registers at addr, and checks it as libmodbus would; a read's words go to
 * words. For a request whose reply libmodbus refused because another came first (see
 * request). Returns n, or -1 with errno set as libmodbus sets it. */
static int receive_own_reply(fg_mb_link *l, int fn, int addr, int n, uint16_t *words) {
  uint8_t rsp[MODBUS_MAX_ADU_LENGTH];
  const int len = modbus_receive_confirmation(l->ctx, rsp);
  if (len < 0) return -1;
  const int h = modbus_get_header_length(l->ctx); /* the function code's offset */
  if (len > h + 1 && rsp[h] == (fn | 0x80)) {
    errno = MODBUS_ENOBASE + rsp[h + 1];
    return -1;
  }
  if (len < h + 5 || rsp[h] != fn) {
    errno = EMBBADDATA;
    return -1;
  }
  if (fn == MODBUS_FC_WRITE_MULTIPLE_REGISTERS) {
    if ((rsp[h + 1] << 8 | rsp[h + 2]) != addr || (rsp[h + 3] << 8 | rsp[h + 4]) != n) {
      errno = EMBBADDATA;
      return -1;
    }
    return n;
  }
  if (rsp[h + 1] != 2 * n || len < h + 2 + 2 * n) {
    errno = EMBBADDATA;
    return -1;
  }
  for (int i = 0; i < n; i++) words[i] = (uint16_t)(rsp[h + 2 + 2 * i] << 8 | rsp[h + 3 + 2 * i]);
  return n;
}

/* One request of function fn (3, 4 or 16) through the common prologue and error sorting. */
static int request(fg_mb_link *l, int fn, int addr, int n, uint16_t *words) {
  const int after_timeout = l->stale;
  FG_TRY(request_begin(l));
  int got = fn == MODBUS_FC_READ_HOLDING_REGISTERS ? modbus_read_registers(l->ctx, addr, n, words)
            : fn == MODBUS_FC_READ_INPUT_REGISTERS
                ? modbus_read_input_registers(l->ctx, addr, n, words)
                : modbus_write_registers(l->ctx, addr, n, words);
  if (got != n && after_timeout && errno == EMBBADDATA) {
    /* The timed-out request's reply came after the flush and reached this request first
     * (a transaction id, or over RTU a function or a count, that is not this request's).
     * libmodbus has consumed it; the next message is this request's own, as at most one
     * reply is outstanding (a second timeout in a row closes the connection). */
    fg_info("modbus: %s %s: dropped a reply that came after its request timed out", l->name,
            l->address);
    got = receive_own_reply(l, fn, addr, n, words);
  }
  if (got != n) {
    const int e = errno;
    char what[64];
    snprintf(what, sizeof what, "a %s of %d %sregisters at %d",
             fn == MODBUS_FC_WRITE_MULTIPLE_REGISTERS ? "write" : "read", n,
             fn == MODBUS_FC_READ_HOLDING_REGISTERS ? "holding "
             : fn == MODBUS_FC_READ_INPUT_REGISTERS ? "input "
                                                     : "",
             addr);
    return request_failed(l, e, what);
  }
  request_ok(l);
  return 0;
}

int fg_mb_read_registers(fg_mb_link *l, int addr, int n, uint16_t *out) {
  return request(l, MODBUS_FC_READ_HOLDING_REGISTERS, addr, n, out);
}

int fg_mb_read_input_registers(fg_mb_link *l, int addr, int n, uint16_t *out) {
  return request(l, MODBUS_FC_READ_INPUT_REGISTERS, addr, n, out);
}

int fg_mb_write_registers(fg_mb_link *l, int addr, int n, const uint16_t *w) {
  /* libmodbus only reads the words of a write; its prototype takes them const */
  return request(l, MODBUS_FC_WRITE_MULTIPLE_REGISTERS, addr, n, (uint16_t *)w);
}

void fg_mb_link_state_get(fg_mb_link *l, fg_mb_link_state *st) {
  pthread_mutex_lock(&l->lock);
  *st = l->st;
  pthread_mutex_unlock(&l->lock);
}

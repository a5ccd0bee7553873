/* What a handler reads of its request and writes into its response (http.h): headers, query
 * arguments, multipart parts, and bodies whole or streamed. */
#include "http.h"

#include <microhttpd.h>

#include <arpa/inet.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- responses */

/* Frees a streamed body's producer that was never handed to libmicrohttpd. */
static void resp_drop_stream(fg_resp *resp) {
  if (resp->stream_ops && resp->stream_ops->free) resp->stream_ops->free(resp->stream_ctx);
  resp->stream_ops = NULL;
  resp->stream_ctx = NULL;
}

void fg_resp_take(fg_resp *resp, int status, const char *content_type, char *body, size_t len) {
  free(resp->body);
  resp_drop_stream(resp);
  resp->status = status;
  resp->content_type = content_type;
  resp->body = body;
  resp->len = len;
}

void fg_resp_json(fg_resp *resp, int status, json_t *obj) {
  char *text = obj ? json_dumps(obj, JSON_COMPACT | JSON_REAL_PRECISION(15)) : NULL;
  json_decref(obj);
  if (!text) {
    static const char oom[] =
      "{\"error\":{\"code\":\"internal_error\",\"message\":\"out of memory building the reply\"}}";
    fg_resp_take(resp, 500, "application/json", strdup(oom), sizeof oom - 1);
    return;
  }
  fg_resp_take(resp, status, "application/json", text, strlen(text));
}

int fg_resp_error(fg_resp *resp, int status, const char *code, const char *fmt, ...) {
  char msg[1024];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  fg_resp_json(resp, status, json_pack("{s:{s:s,s:s}}", "error", "code", code, "message", msg));
  return 0;
}

void fg_resp_stream(fg_resp *resp, int status, const char *content_type,
                    const fg_stream_ops *ops, void *ctx) {
  fg_resp_take(resp, status, content_type, NULL, 0);
  resp->stream_ops = ops;
  resp->stream_ctx = ctx;
}

const char *fg_req_header(const fg_req *req, const char *name) {
  return MHD_lookup_connection_value((struct MHD_Connection *)req->mhd_conn, MHD_HEADER_KIND, name);
}

char *fg_req_client(const fg_req *req, char *buf, size_t size) {
  buf[0] = '\0';
  const union MHD_ConnectionInfo *ci = MHD_get_connection_info(
      (struct MHD_Connection *)req->mhd_conn, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
  const struct sockaddr *sa = ci ? ci->client_addr : NULL;
  char host[INET6_ADDRSTRLEN];
  if (sa && sa->sa_family == AF_INET) {
    const struct sockaddr_in *in = (const struct sockaddr_in *)sa;
    if (inet_ntop(AF_INET, &in->sin_addr, host, sizeof host))
      snprintf(buf, size, "%s:%u", host, (unsigned)ntohs(in->sin_port));
  } else if (sa && sa->sa_family == AF_INET6) {
    const struct sockaddr_in6 *in6 = (const struct sockaddr_in6 *)sa;
    if (inet_ntop(AF_INET6, &in6->sin6_addr, host, sizeof host))
      snprintf(buf, size, "[%s]:%u", host, (unsigned)ntohs(in6->sin6_port));
  }
  return buf;
}

const char *fg_req_query(const fg_req *req, const char *name) {
  const char *v = MHD_lookup_connection_value((struct MHD_Connection *)req->mhd_conn,
                                              MHD_GET_ARGUMENT_KIND, name);
  if (v) return v;
  /* libmicrohttpd keeps "?name" without '=' as a key with a NULL value */
  return MHD_lookup_connection_value_n((struct MHD_Connection *)req->mhd_conn,
                                       MHD_GET_ARGUMENT_KIND, name, strlen(name), NULL,
                                       NULL) == MHD_YES ? "" : NULL;
}

typedef struct unknown_arg {
  const char *const *known;
  size_t n;
  const char *first; /* the first unknown name met */
} unknown_arg;

static enum MHD_Result find_unknown(void *cls, enum MHD_ValueKind kind, const char *key,
                                    const char *value) {
  unknown_arg *u = cls;
  for (size_t i = 0; i < u->n; i++)
    if (strcmp(key, u->known[i]) == 0) return MHD_YES;
  u->first = key;
  return MHD_NO; /* stop at the first */
}

const char *fg_req_query_unknown(const fg_req *req, const char *const *known, size_t n) {
  unknown_arg u = {known, n, NULL};
  MHD_get_connection_values((struct MHD_Connection *)req->mhd_conn, MHD_GET_ARGUMENT_KIND,
                            find_unknown, &u);
  return u.first;
}

int fg_query_number(const char *value, double *out) {
  if (!value || !*value) return -1;
  char *end;
  const double v = strtod(value, &end);
  if (*end || !isfinite(v)) return -1;
  *out = v;
  return 0;
}

const fg_part *fg_req_part(const fg_req *req, const char *name) {
  for (int i = 0; i < req->n_parts; i++)
    if (strcmp(req->parts[i].name, name) == 0) return &req->parts[i];
  return NULL;
}

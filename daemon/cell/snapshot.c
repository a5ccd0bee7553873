/* One image from a camera's source (cameras.h: fg_snapshot_fetch): an HTTP snapshot with
 * libcurl. */
#include "cameras.h"

#include <curl/curl.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"

typedef struct sink {
  uint8_t *buf;
  size_t len, max;
  int too_big;
} sink;

static size_t on_data(char *p, size_t size, size_t n, void *arg) {
  sink *s = arg;
  const size_t add = size * n;
  if (s->len + add > s->max) {
    s->too_big = 1;
    return 0; /* aborts the transfer */
  }
  uint8_t *b = realloc(s->buf, s->len + add + 1);
  if (!b) return 0;
  memcpy(b + s->len, p, add);
  s->buf = b;
  s->len += add;
  return add;
}

static int fetch_http(const char *url, int timeout_ms, size_t max_bytes, uint8_t **out,
                      size_t *len) {
  CURL *curl = curl_easy_init();
  if (!curl) return fg_fail(FG_ENOMEM, "libcurl");
  sink s = {.max = max_bytes};
  char err[CURL_ERROR_SIZE] = "";
  curl_easy_setopt(curl, CURLOPT_URL, url);
  curl_easy_setopt(curl, CURLOPT_PROTOCOLS_STR, "http,https");
  curl_easy_setopt(curl, CURLOPT_TIMEOUT_MS, (long)timeout_ms);
  curl_easy_setopt(curl, CURLOPT_CONNECTTIMEOUT_MS, (long)timeout_ms);
  curl_easy_setopt(curl, CURLOPT_NOSIGNAL, 1L);
  curl_easy_setopt(curl, CURLOPT_WRITEFUNCTION, on_data);
  curl_easy_setopt(curl, CURLOPT_WRITEDATA, &s);
  curl_easy_setopt(curl, CURLOPT_ERRORBUFFER, err);
  const CURLcode rc = curl_easy_perform(curl);
  long status = 0;
  curl_easy_getinfo(curl, CURLINFO_RESPONSE_CODE, &status);
  curl_easy_cleanup(curl);
  int ret = 0;
  if (s.too_big)
    ret = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s sent more than %zu bytes", url,
                     max_bytes);
  else if (rc == CURLE_OPERATION_TIMEDOUT)
    ret = fg_fail_as(FG_ETIMEDOUT, "camera_timeout", "%s did not answer within %d ms", url,
                     timeout_ms);
  else if (rc != CURLE_OK)
    ret = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s: %s", url,
                     err[0] ? err : curl_easy_strerror(rc));
  else if (status != 200)
    ret = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s answered HTTP %ld", url, status);
  if (ret < 0) {
    free(s.buf);
    return ret;
  }
  *out = s.buf;
  *len = s.len;
  return 0;
}

int fg_snapshot_fetch(const char *source, int timeout_ms, size_t max_bytes, uint8_t **out,
                      size_t *len) {
  *out = NULL;
  *len = 0;
  return fetch_http(source, timeout_ms, max_bytes, out, len);
}

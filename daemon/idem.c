#include "idem.h"

#include <ctype.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <jansson.h>

#include "core/digest.h"
#include "core/error.h"
#include "core/fsutil.h"

#define MAX_AGE_S (24 * 3600)
#define FILE_MAX (64u << 20)
/* 2: requests known by "sha256"; 1 (still read): by "hash", a 64-bit FNV-1a in hex */
#define FILE_VERSION 2

typedef struct entry {
  char key[FG_IDEM_KEY_MAX + 1];
  uint8_t sha256[FG_SHA256_BYTES]; /* of the path, a NUL and the body */
  int legacy;                      /* a version 1 key: legacy_hash instead of sha256 */
  uint64_t legacy_hash;
  int status;   /* 0 while running */
  char *body;   /* NULL while running */
  int64_t created;
} entry;

struct fg_idem {
  char *path;
  pthread_mutex_t lock;
  entry *e; /* oldest first */
  size_t n;
};

/* The identity of a request: SHA-256 of its path, a NUL (no path holds one) and its body. */
static void request_digest(const char *path, const void *body, size_t len,
                           uint8_t out[FG_SHA256_BYTES]) {
  const fg_span parts[] = {{path, strlen(path) + 1}, {body, len}};
  fg_sha256(parts, 2, out);
}

/* FNV-1a 64, only to compare a request with a key taken by a version 1 daemon. */
static uint64_t legacy_fnv(const void *data, size_t len) {
  const unsigned char *p = data;
  uint64_t h = 1469598103934665603ULL;
  for (size_t i = 0; i < len; i++) {
    h ^= p[i];
    h *= 1099511628211ULL;
  }
  return h;
}

/* Whether e was taken by the request to path with body [len]. */
static int entry_matches(const entry *e, const uint8_t digest[FG_SHA256_BYTES],
                         const char *path, const void *body, size_t len) {
  if (!e->legacy) return memcmp(e->sha256, digest, FG_SHA256_BYTES) == 0;
  return e->legacy_hash == (legacy_fnv(path, strlen(path)) ^ legacy_fnv(body, len) * 31);
}

/* Parses 64 hex digits into a digest. 1 on success. */
static int digest_parse(const char *hex, uint8_t out[FG_SHA256_BYTES]) {
  if (strlen(hex) != FG_SHA256_HEX) return 0;
  for (int i = 0; i < FG_SHA256_BYTES; i++) {
    unsigned v;
    if (!isxdigit((unsigned char)hex[2 * i]) || !isxdigit((unsigned char)hex[2 * i + 1]) ||
        sscanf(hex + 2 * i, "%2x", &v) != 1)
      return 0;
    out[i] = (uint8_t)v;
  }
  return 1;
}

int fg_idem_key_valid(const char *key) {
  size_t n = strlen(key);
  if (n == 0 || n > FG_IDEM_KEY_MAX) return 0;
  for (size_t i = 0; i < n; i++)
    if (key[i] < 0x20 || key[i] > 0x7E) return 0;
  return 1;
}

static const char interrupted[] =
    "{\"error\":{\"code\":\"outcome_unknown\",\"message\":\"the daemon stopped while the "
    "command of this Idempotency-Key ran; its outcome is unknown and it is not run again: check "
    "the robot\"}}";

/* Writes every entry to the file. Under the lock. */
static int save_locked(fg_idem *s) {
  json_t *arr = json_array();
  if (!arr) return FG_ENOMEM;
  for (size_t i = 0; i < s->n; i++) {
    const entry *e = &s->e[i];
    char hex[FG_SHA256_HEX + 1];
    if (e->legacy) snprintf(hex, sizeof hex, "%016" PRIx64, e->legacy_hash);
    else fg_sha256_to_hex(e->sha256, hex);
    json_array_append_new(arr, json_pack("{s:s, s:s, s:i, s:s?, s:I}", "key", e->key,
                                         e->legacy ? "hash" : "sha256", hex, "status",
                                         e->status, "body", e->body, "created",
                                         (json_int_t)e->created));
  }
  json_t *doc = json_pack("{s:i, s:o}", "version", FILE_VERSION, "keys", arr);
  char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
  json_decref(doc);
  if (!text) return fg_fail(FG_ENOMEM, "out of memory writing %s", s->path);
  int rc = fg_write_file_atomic(s->path, text, strlen(text));
  free(text);
  return rc;
}

static void entry_free(entry *e) { free(e->body); }

/* Drops keys past the age limit, and the oldest beyond room for one more. Under the lock. */
static void prune_locked(fg_idem *s) {
  const int64_t now = (int64_t)time(NULL);
  size_t drop = 0;
  while (drop < s->n && s->e[drop].status != 0 &&
         (now - s->e[drop].created > MAX_AGE_S || s->n - drop >= FG_IDEM_MAX))
    entry_free(&s->e[drop++]);
  if (!drop) return;
  memmove(s->e, s->e + drop, (s->n - drop) * sizeof *s->e);
  s->n -= drop;
}

static int load(fg_idem *s) {
  char *text;
  size_t len;
  int rc = fg_read_file(s->path, FILE_MAX, &text, &len);
  if (rc == FG_ENOENT) return 0;
  if (rc < 0) return rc;
  json_error_t jerr;
  json_t *doc = json_loadb(text, len, 0, &jerr);
  free(text);
  json_t *keys = json_object_get(doc, "keys");
  if (!json_is_array(keys)) {
    json_decref(doc);
    return fg_fail(FG_EFORMAT, "%s is not an idempotency key file (%s); move it away to start "
                   "afresh", s->path, doc ? "no \"keys\" list" : jerr.text);
  }
  size_t i;
  json_t *it;
  s->e = calloc(json_array_size(keys) + 1, sizeof *s->e);
  if (!s->e) {
    json_decref(doc);
    return FG_ENOMEM;
  }
  json_array_foreach(keys, i, it) {
    const char *key = NULL, *hash = NULL, *sha = NULL;
    json_t *jbody = NULL; /* null while the command ran: saved before it had an answer */
    int status = 0;
    json_int_t created = 0;
    entry *e = &s->e[s->n];
    memset(e, 0, sizeof *e);
    if (json_unpack(it, "{s:s, s?s, s?s, s:i, s?o, s:I}", "key", &key, "hash", &hash,
                    "sha256", &sha, "status", &status, "body", &jbody, "created",
                    &created) != 0 ||
        !fg_idem_key_valid(key) || !!hash == !!sha || (sha && !digest_parse(sha, e->sha256)) ||
        (jbody && !json_is_string(jbody) && !json_is_null(jbody))) {
      json_decref(doc);
      return fg_fail(FG_EFORMAT, "%s: entry %zu is malformed; move the file away to start "
                     "afresh", s->path, i);
    }
    s->n++;
    snprintf(e->key, sizeof e->key, "%s", key);
    e->legacy = hash != NULL;
    if (hash) e->legacy_hash = strtoull(hash, NULL, 16);
    e->created = created;
    const char *body = json_string_value(jbody);
    /* no answer yet, or only "accepted" (202): the command was cut short by the stop */
    const int final = status != 0 && status != 202 && body;
    e->status = final ? status : 504;
    e->body = strdup(final ? body : interrupted);
    if (!e->body) {
      json_decref(doc);
      return FG_ENOMEM;
    }
  }
  json_decref(doc);
  return 0;
}

int fg_idem_open(fg_idem **out, const char *path) {
  *out = NULL;
  fg_idem *s = calloc(1, sizeof *s);
  if (!s || !(s->path = strdup(path))) {
    free(s);
    return FG_ENOMEM;
  }
  pthread_mutex_init(&s->lock, NULL);
  int rc = load(s);
  if (rc < 0) {
    fg_idem_free(s);
    return rc;
  }
  *out = s;
  return 0;
}

void fg_idem_free(fg_idem *s) {
  if (!s) return;
  for (size_t i = 0; i < s->n; i++) entry_free(&s->e[i]);
  free(s->e);
  pthread_mutex_destroy(&s->lock);
  free(s->path);
  free(s);
}

static entry *find_locked(fg_idem *s, const char *key) {
  for (size_t i = s->n; i-- > 0;)
    if (strcmp(s->e[i].key, key) == 0) return &s->e[i];
  return NULL;
}

int fg_idem_begin(fg_idem *s, const char *key, const char *path, const void *req_body,
                  size_t req_len, int *status, char **body) {
  *body = NULL;
  uint8_t digest[FG_SHA256_BYTES];
  request_digest(path, req_body, req_len, digest);
  pthread_mutex_lock(&s->lock);
  entry *e = find_locked(s, key);
  int rc;
  if (e && !entry_matches(e, digest, path, req_body, req_len)) {
    rc = FG_IDEM_CONFLICT;
  } else if (e && e->status == 0) {
    rc = FG_IDEM_RUNNING;
  } else if (e) {
    *status = e->status;
    *body = strdup(e->body);
    rc = *body ? FG_IDEM_REPLAY : FG_ENOMEM;
  } else {
    prune_locked(s);
    entry *grown = realloc(s->e, (s->n + 1) * sizeof *s->e);
    if (!grown) {
      rc = FG_ENOMEM;
    } else {
      s->e = grown;
      e = &s->e[s->n++];
      memset(e, 0, sizeof *e);
      snprintf(e->key, sizeof e->key, "%s", key);
      memcpy(e->sha256, digest, sizeof digest);
      e->created = (int64_t)time(NULL);
      rc = save_locked(s);
      if (rc < 0) s->n--; /* not stored: the request must not run */
      else rc = FG_IDEM_NEW;
    }
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

int fg_idem_finish(fg_idem *s, const char *key, int status, const char *body) {
  pthread_mutex_lock(&s->lock);
  entry *e = find_locked(s, key);
  int rc = 0;
  if (e && e->status == 0) {
    char *copy = strdup(body);
    if (!copy) {
      rc = FG_ENOMEM;
    } else {
      e->body = copy;
      e->status = status;
      rc = save_locked(s);
    }
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

int fg_idem_cancel(fg_idem *s, const char *key) {
  pthread_mutex_lock(&s->lock);
  entry *e = find_locked(s, key);
  int rc = 0;
  if (e && e->status == 0) {
    memmove(e, e + 1, (size_t)(s->e + s->n - (e + 1)) * sizeof *e);
    s->n--;
    rc = save_locked(s);
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

int fg_idem_update(fg_idem *s, const char *key, int status, const char *body) {
  pthread_mutex_lock(&s->lock);
  entry *e = find_locked(s, key);
  int rc = e ? 0 : fg_fail(FG_ENOENT, "no Idempotency-Key %s", key);
  char *copy = e ? strdup(body) : NULL;
  if (e && !copy) rc = FG_ENOMEM;
  if (copy) {
    free(e->body);
    e->body = copy;
    e->status = status;
    rc = save_locked(s);
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

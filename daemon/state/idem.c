#include "idem.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <jansson.h>

#include "core/digest.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"

#define JOURNAL_NAME "idempotency.journal"
#define LEGACY_NAME "idempotency.json"
#define JOURNAL_VERSION 3
/* a new key needs room for itself and for an answer of this size (a command's view with its
 * registers is about 2 KiB), so that the keys already taken can always store theirs */
#define ANSWER_ROOM 4096
#define ENTRY_OVERHEAD 128

typedef enum {
  KIND_CANON = 0, /* sha256 of method, path and canonical body (journal version 3) */
  KIND_RAW,       /* sha256 of path and raw body (idempotency.json version 2) */
  KIND_FNV        /* 64-bit FNV-1a of path and raw body (idempotency.json version 1) */
} kind;

static const char *const kind_names[] = {"canon", "raw", "fnv"};

typedef struct entry {
  char key[FG_IDEM_KEY_MAX + 1];
  kind kind;
  uint8_t sha256[FG_SHA256_BYTES]; /* KIND_CANON, KIND_RAW */
  uint64_t fnv;                    /* KIND_FNV */
  int status;                      /* 0 while running */
  char *body;                      /* NULL while running */
  int64_t created;
} entry;

struct fg_idem {
  char *dir, *journal, *legacy;
  fg_idem_config cfg;
  pthread_mutex_t lock;
  entry **e;      /* in the order they were taken */
  size_t n, cap;
  /* key -> entry: jansson's object is a seeded hash table the daemon already links, so a
   * replay of 100,000 keys is not quadratic; the values are the entries' addresses */
  json_t *index;
  int fd;               /* the journal, opened for appending */
  size_t journal_bytes; /* its length: where a failed append is cut back to */
  size_t live_bytes;    /* what the live keys need, roughly, in memory and in the journal */
};

/* ---------------------------------------------------------------- requests */

static int64_t now_s(const fg_idem *s) {
  return s->cfg.now_s ? s->cfg.now_s(s->cfg.now_ctx) : (int64_t)time(NULL);
}

/* The identity of a request: SHA-256 of its method, a NUL, its path, a NUL (neither holds
 * one) and its body as canonical JSON. A body that is not JSON is taken as it is: it can
 * not equal a canonical text, which always parses. */
static int canon_digest(const fg_idem_request *rq, uint8_t out[FG_SHA256_BYTES]) {
  char *canon = NULL;
  if (rq->len == 0) {
    canon = strdup("{}"); /* a bare POST is the request {} */
    if (!canon) return FG_ENOMEM;
  } else {
    json_t *doc = json_loadb(rq->body, rq->len, JSON_DECODE_ANY, NULL);
    if (doc) {
      canon = json_dumps(doc, JSON_COMPACT | JSON_SORT_KEYS | JSON_ENCODE_ANY);
      json_decref(doc);
      if (!canon) return FG_ENOMEM;
    }
  }
  const fg_span parts[] = {{rq->method, strlen(rq->method) + 1},
                           {rq->path, strlen(rq->path) + 1},
                           {canon ? canon : rq->body, canon ? strlen(canon) : rq->len}};
  fg_sha256(parts, 3, out);
  free(canon);
  return 0;
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

/* Whether e was taken by request rq, whose canonical digest is canon. */
static int entry_matches(const entry *e, const uint8_t canon[FG_SHA256_BYTES],
                         const fg_idem_request *rq) {
  switch (e->kind) {
  case KIND_CANON: return memcmp(e->sha256, canon, FG_SHA256_BYTES) == 0;
  case KIND_RAW: {
    uint8_t raw[FG_SHA256_BYTES];
    const fg_span parts[] = {{rq->path, strlen(rq->path) + 1}, {rq->body, rq->len}};
    fg_sha256(parts, 2, raw);
    return memcmp(e->sha256, raw, FG_SHA256_BYTES) == 0;
  }
  default: {
    const uint64_t h = legacy_fnv(rq->path, strlen(rq->path)) ^ legacy_fnv(rq->body, rq->len) * 31;
    return e->fnv == h;
  }
  }
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

/* ---------------------------------------------------------------- the keys in memory */

static size_t entry_cost(const entry *e) {
  return sizeof *e + ENTRY_OVERHEAD + (e->body ? strlen(e->body) : 0);
}

static entry *find_locked(fg_idem *s, const char *key) {
  json_t *v = json_object_get(s->index, key);
  return v ? (entry *)(intptr_t)json_integer_value(v) : NULL;
}

/* Adds e (owned by the store from now on, even on failure). */
static int insert_locked(fg_idem *s, entry *e) {
  if (s->n == s->cap) {
    size_t cap = s->cap ? 2 * s->cap : 64;
    entry **grown = realloc(s->e, cap * sizeof *grown);
    if (!grown) {
      free(e->body);
      free(e);
      return FG_ENOMEM;
    }
    s->e = grown;
    s->cap = cap;
  }
  if (json_object_set_new(s->index, e->key, json_integer((json_int_t)(intptr_t)e)) != 0) {
    free(e->body);
    free(e);
    return FG_ENOMEM;
  }
  s->e[s->n++] = e;
  s->live_bytes += entry_cost(e);
  return 0;
}

static void remove_locked(fg_idem *s, entry *e) {
  size_t i = s->n;
  while (i-- > 0 && s->e[i] != e) {
  }
  memmove(s->e + i, s->e + i + 1, (s->n - i - 1) * sizeof *s->e);
  s->n--;
  json_object_del(s->index, e->key);
  s->live_bytes -= entry_cost(e);
  free(e->body);
  free(e);
}

/* Sets e's answer; body is copied. 0 or FG_ENOMEM. */
static int answer_set_locked(fg_idem *s, entry *e, int status, const char *body) {
  char *copy = strdup(body);
  if (!copy) return FG_ENOMEM;
  s->live_bytes -= entry_cost(e);
  free(e->body);
  e->body = copy;
  e->status = status;
  s->live_bytes += entry_cost(e);
  return 0;
}

static int expired(const fg_idem *s, const entry *e, int64_t now) {
  return e->status != 0 && now - e->created > FG_IDEM_MAX_AGE_S;
}

/* Forgets the keys past 24 hours (the journal forgets them at its next compaction). A
 * running key is kept whatever its age: its command may still answer. */
static void prune_locked(fg_idem *s) {
  const int64_t now = now_s(s);
  size_t kept = 0;
  for (size_t i = 0; i < s->n; i++) {
    entry *e = s->e[i];
    if (!expired(s, e, now)) {
      s->e[kept++] = e;
      continue;
    }
    json_object_del(s->index, e->key);
    s->live_bytes -= entry_cost(e);
    free(e->body);
    free(e);
  }
  s->n = kept;
}

/* ---------------------------------------------------------------- the journal */

static json_t *take_record(const entry *e) {
  char hex[FG_SHA256_HEX + 1];
  if (e->kind == KIND_FNV) snprintf(hex, sizeof hex, "%016" PRIx64, e->fnv);
  else fg_sha256_to_hex(e->sha256, hex);
  return json_pack("{s:s, s:s, s:s, s:s, s:I}", "op", "take", "key", e->key, "kind",
                   kind_names[e->kind], "digest", hex, "created", (json_int_t)e->created);
}

static json_t *answer_record(const entry *e) {
  return json_pack("{s:s, s:s, s:i, s:s}", "op", "answer", "key", e->key, "status", e->status,
                   "body", e->body);
}

/* Appends one record as a line and makes it durable. A line that was not wholly written is
 * cut off again, so that the next one does not land behind half a line. Under the lock. */
static int append_locked(fg_idem *s, json_t *rec) {
  char *text = rec ? json_dumps(rec, JSON_COMPACT) : NULL;
  json_decref(rec);
  if (!text) return fg_fail(FG_ENOMEM, "out of memory writing %s", s->journal);
  size_t len = strlen(text);
  text[len++] = '\n'; /* over the NUL: the line is written by length */
  size_t done = 0;
  int err = 0;
  while (done < len && !err) {
    ssize_t w = write(s->fd, text + done, len - done);
    if (w > 0) done += (size_t)w;
    else if (w < 0 && errno != EINTR) err = errno;
    else if (w == 0) err = EIO;
  }
  free(text);
  if (!err && fdatasync(s->fd) != 0) err = errno;
  if (err) {
    if (ftruncate(s->fd, (off_t)s->journal_bytes) != 0)
      fg_warn("idem: %s could not be cut back after a failed write: %s", s->journal,
              strerror(errno));
    return fg_fail(fg_io_error(err), "cannot write %s: %s", s->journal, strerror(err));
  }
  s->journal_bytes += len;
  return 0;
}

static int journal_reopen(fg_idem *s) {
  if (s->fd >= 0) close(s->fd);
  s->fd = open(s->journal, O_WRONLY | O_APPEND | O_CLOEXEC);
  if (s->fd < 0) return fg_fail(FG_EIO, "cannot open %s: %s", s->journal, strerror(errno));
  struct stat st;
  if (fstat(s->fd, &st) != 0) return fg_fail(FG_EIO, "cannot stat %s", s->journal);
  s->journal_bytes = (size_t)st.st_size;
  return 0;
}

/* Appends rec's line to buf. 0 or FG_ENOMEM. */
static int line_add(char **buf, size_t *len, size_t *cap, json_t *rec) {
  char *text = rec ? json_dumps(rec, JSON_COMPACT) : NULL;
  json_decref(rec);
  if (!text) return FG_ENOMEM;
  size_t n = strlen(text);
  if (*len + n + 2 > *cap) {
    size_t c = (*cap + n + 2) * 2;
    char *grown = realloc(*buf, c);
    if (!grown) {
      free(text);
      return FG_ENOMEM;
    }
    *buf = grown;
    *cap = c;
  }
  memcpy(*buf + *len, text, n);
  (*buf)[*len + n] = '\n';
  *len += n + 1;
  free(text);
  return 0;
}

/* Rewrites the journal atomically with the live keys only. Under the lock. */
static int compact_locked(fg_idem *s) {
  char *buf = NULL;
  size_t len = 0, cap = 0;
  int rc = line_add(&buf, &len, &cap, json_pack("{s:i}", "version", JOURNAL_VERSION));
  for (size_t i = 0; rc == 0 && i < s->n; i++) {
    rc = line_add(&buf, &len, &cap, take_record(s->e[i]));
    if (rc == 0 && s->e[i]->status) rc = line_add(&buf, &len, &cap, answer_record(s->e[i]));
  }
  if (rc == 0) rc = fg_write_file_atomic(s->journal, buf, len);
  else rc = fg_fail(rc, "out of memory compacting %s", s->journal);
  free(buf);
  return rc == 0 ? journal_reopen(s) : rc;
}

/* Compacts when the journal holds more than twice what its live keys need, plus a floor so
 * that a small store is not rewritten at every command. A failure leaves the journal as it
 * was, still whole: it is logged, and tried again at the next key. */
static void maybe_compact_locked(fg_idem *s) {
  const size_t floor = s->cfg.max_bytes / 64;
  if (s->journal_bytes <= 2 * s->live_bytes + floor) return;
  if (compact_locked(s) < 0) fg_warn("idem: cannot compact %s: %s", s->journal, fg_error_detail());
}

/* Applies one journal record. 0, or FG_EFORMAT (detail left to the caller). */
static int replay_record(fg_idem *s, json_t *rec) {
  const char *op = NULL, *key = NULL;
  if (json_unpack(rec, "{s:s, s:s}", "op", &op, "key", &key) != 0 || !fg_idem_key_valid(key))
    return FG_EFORMAT;
  entry *e = find_locked(s, key);
  if (strcmp(op, "take") == 0) {
    const char *kname = NULL, *hex = NULL;
    json_int_t created = 0;
    if (json_unpack(rec, "{s:s, s:s, s:I}", "kind", &kname, "digest", &hex, "created",
                    &created) != 0)
      return FG_EFORMAT;
    entry *n = calloc(1, sizeof *n);
    if (!n) return FG_ENOMEM;
    snprintf(n->key, sizeof n->key, "%s", key);
    n->created = created;
    int k = 0;
    while (k < 3 && strcmp(kname, kind_names[k]) != 0) k++;
    n->kind = (kind)k;
    char *end = NULL;
    if (k == KIND_FNV) n->fnv = strtoull(hex, &end, 16);
    if (k == 3 || (k == KIND_FNV ? (strlen(hex) != 16 || *end) : !digest_parse(hex, n->sha256))) {
      free(n);
      return FG_EFORMAT;
    }
    if (e) remove_locked(s, e); /* taken again after it expired */
    return insert_locked(s, n);
  }
  if (strcmp(op, "answer") == 0) {
    const char *body = NULL;
    int status = 0;
    if (json_unpack(rec, "{s:i, s:s}", "status", &status, "body", &body) != 0 || status <= 0)
      return FG_EFORMAT;
    return e ? answer_set_locked(s, e, status, body) : 0;
  }
  if (strcmp(op, "cancel") == 0) {
    if (e) remove_locked(s, e);
    return 0;
  }
  return FG_EFORMAT;
}

/* Replays the journal. *torn is set when its last line was half written (it is not applied:
 * the caller rewrites the journal without it). */
static int replay(fg_idem *s, int *torn) {
  *torn = 0;
  FILE *f = fopen(s->journal, "r");
  if (!f) return fg_fail(FG_EIO, "cannot open %s: %s", s->journal, strerror(errno));
  char *line = NULL;
  size_t cap = 0, no = 0;
  ssize_t n;
  int rc = 0;
  while (rc == 0 && (n = getline(&line, &cap, f)) > 0) {
    no++;
    json_t *rec = json_loadb(line, (size_t)n, 0, NULL);
    /* only the last line can be torn: every append ends with its newline before the next */
    if (!rec || line[n - 1] != '\n') {
      json_decref(rec);
      if (getc(f) == EOF) *torn = 1;
      else rc = FG_EFORMAT;
      break;
    }
    if (no == 1) {
      json_int_t version = 0;
      if (json_unpack(rec, "{s:I}", "version", &version) != 0 || version != JOURNAL_VERSION)
        rc = FG_EFORMAT;
    } else {
      rc = replay_record(s, rec);
    }
    json_decref(rec);
  }
  free(line);
  fclose(f);
  if (no == 0) *torn = 1; /* empty: killed before its version line was written */
  if (rc == FG_EFORMAT)
    return fg_fail(rc, "%s: line %zu is malformed; move the file away to start afresh (its "
                   "keys are then forgotten)", s->journal, no);
  return rc;
}

/* Loads the whole-file store of an earlier daemon (versions 1 and 2). */
static int legacy_load(fg_idem *s) {
  char *text;
  size_t len;
  int rc = fg_read_file(s->legacy, FG_IDEM_MAX_BYTES, &text, &len);
  if (rc < 0) return rc;
  json_error_t jerr;
  json_t *doc = json_loadb(text, len, 0, &jerr);
  free(text);
  json_t *keys = json_object_get(doc, "keys");
  if (!json_is_array(keys)) {
    json_decref(doc);
    return fg_fail(FG_EFORMAT, "%s is not an idempotency key file (%s); move it away to start "
                   "afresh", s->legacy, doc ? "no \"keys\" list" : jerr.text);
  }
  size_t i;
  json_t *it;
  json_array_foreach(keys, i, it) {
    const char *key = NULL, *hash = NULL, *sha = NULL;
    json_t *jbody = NULL; /* null while the command ran: saved before it had an answer */
    int status = 0;
    json_int_t created = 0;
    entry *e = calloc(1, sizeof *e);
    if (!e) {
      rc = FG_ENOMEM;
      break;
    }
    if (json_unpack(it, "{s:s, s?s, s?s, s:i, s?o, s:I}", "key", &key, "hash", &hash,
                    "sha256", &sha, "status", &status, "body", &jbody, "created",
                    &created) != 0 ||
        !fg_idem_key_valid(key) || !!hash == !!sha || (sha && !digest_parse(sha, e->sha256)) ||
        (jbody && !json_is_string(jbody) && !json_is_null(jbody))) {
      free(e);
      rc = fg_fail(FG_EFORMAT, "%s: entry %zu is malformed; move the file away to start "
                   "afresh", s->legacy, i);
      break;
    }
    snprintf(e->key, sizeof e->key, "%s", key);
    e->kind = hash ? KIND_FNV : KIND_RAW;
    if (hash) e->fnv = strtoull(hash, NULL, 16);
    e->created = created;
    const char *body = json_string_value(jbody);
    e->status = body ? status : 0;
    e->body = body ? strdup(body) : NULL;
    if (body && !e->body) {
      free(e);
      rc = FG_ENOMEM;
      break;
    }
    entry *old = find_locked(s, key);
    if (old) remove_locked(s, old);
    if ((rc = insert_locked(s, e)) < 0) break;
  }
  json_decref(doc);
  return rc;
}

/* ---------------------------------------------------------------- the store */

static int load(fg_idem *s) {
  int need_rewrite = 0;
  if (access(s->journal, F_OK) == 0) {
    FG_TRY(replay(s, &need_rewrite));
  } else if (access(s->legacy, F_OK) == 0) {
    FG_TRY(legacy_load(s));
    need_rewrite = 1;
  } else {
    need_rewrite = 1; /* a new store: the journal starts with its version line */
  }
  /* no answer yet, or only "accepted" (202): the command was cut short by the stop */
  for (size_t i = 0; i < s->n; i++) {
    entry *e = s->e[i];
    if ((e->status == 0 || e->status == 202) && answer_set_locked(s, e, 504, interrupted) < 0)
      return FG_ENOMEM;
  }
  prune_locked(s);
  if (!need_rewrite) FG_TRY(journal_reopen(s));
  if (need_rewrite || s->journal_bytes > 2 * s->live_bytes + s->cfg.max_bytes / 64)
    FG_TRY(compact_locked(s));
  /* migrated: the journal now holds its keys */
  if (unlink(s->legacy) == 0) FG_TRY(fg_fsync_dir(s->dir));
  return 0;
}

int fg_idem_open(fg_idem **out, const char *dir, const fg_idem_config *cfg) {
  *out = NULL;
  fg_idem *s = calloc(1, sizeof *s);
  if (!s) return FG_ENOMEM;
  s->fd = -1;
  pthread_mutex_init(&s->lock, NULL);
  if (cfg) s->cfg = *cfg;
  if (!s->cfg.max_keys) s->cfg.max_keys = FG_IDEM_MAX_KEYS;
  if (!s->cfg.max_bytes) s->cfg.max_bytes = FG_IDEM_MAX_BYTES;
  s->dir = strdup(dir);
  s->journal = fg_path_join(dir, JOURNAL_NAME);
  s->legacy = fg_path_join(dir, LEGACY_NAME);
  s->index = json_object();
  int rc = s->dir && s->journal && s->legacy && s->index ? load(s) : FG_ENOMEM;
  if (rc < 0) {
    fg_idem_free(s);
    return rc;
  }
  *out = s;
  return 0;
}

void fg_idem_free(fg_idem *s) {
  if (!s) return;
  for (size_t i = 0; i < s->n; i++) {
    free(s->e[i]->body);
    free(s->e[i]);
  }
  free(s->e);
  json_decref(s->index);
  if (s->fd >= 0) close(s->fd);
  pthread_mutex_destroy(&s->lock);
  free(s->dir);
  free(s->journal);
  free(s->legacy);
  free(s);
}

/* fg_idem_peek (take = 0) and fg_idem_begin (take = 1). */
static int lookup(fg_idem *s, const char *key, const fg_idem_request *rq, int take, int *status,
                  char **body) {
  *body = NULL;
  uint8_t digest[FG_SHA256_BYTES];
  FG_TRY(canon_digest(rq, digest));
  pthread_mutex_lock(&s->lock);
  entry *e = find_locked(s, key);
  if (e && expired(s, e, now_s(s))) e = NULL; /* gone: the next take prunes it */
  int rc;
  if (e && !entry_matches(e, digest, rq)) {
    rc = FG_IDEM_CONFLICT;
  } else if (e && e->status == 0) {
    rc = FG_IDEM_RUNNING;
  } else if (e) {
    *status = e->status;
    *body = strdup(e->body);
    rc = *body ? FG_IDEM_REPLAY : FG_ENOMEM;
  } else if (!take) {
    rc = FG_IDEM_NEW;
  } else {
    prune_locked(s);
    entry *n = calloc(1, sizeof *n);
    if (!n) {
      rc = FG_ENOMEM;
    } else if (s->n >= s->cfg.max_keys ||
               s->live_bytes + entry_cost(n) + ANSWER_ROOM > s->cfg.max_bytes) {
      free(n);
      rc = fg_fail(FG_ERANGE, "the Idempotency-Key store is full: %zu keys younger than 24 "
                   "hours (at most %zu, %zu bytes); retry when older keys have expired, or "
                   "send commands without a key", s->n, s->cfg.max_keys, s->cfg.max_bytes);
    } else {
      snprintf(n->key, sizeof n->key, "%s", key);
      memcpy(n->sha256, digest, sizeof digest);
      n->created = now_s(s);
      /* on disk before the request runs: a key not stored must not run */
      rc = append_locked(s, take_record(n));
      if (rc < 0) free(n);
      else if ((rc = insert_locked(s, n)) == 0) rc = FG_IDEM_NEW;
      if (rc == FG_IDEM_NEW) maybe_compact_locked(s);
    }
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

int fg_idem_peek(fg_idem *s, const char *key, const fg_idem_request *rq, int *status,
                 char **body) {
  return lookup(s, key, rq, 0, status, body);
}

int fg_idem_begin(fg_idem *s, const char *key, const fg_idem_request *rq, int *status,
                  char **body) {
  return lookup(s, key, rq, 1, status, body);
}

/* Sets the answer of key, when only_running, only while it has none yet. */
static int answer(fg_idem *s, const char *key, int status, const char *body, int only_running) {
  pthread_mutex_lock(&s->lock);
  entry *e = find_locked(s, key);
  int rc = e || only_running ? 0 : fg_fail(FG_ENOENT, "no Idempotency-Key %s", key);
  if (e && (!only_running || e->status == 0)) {
    rc = answer_set_locked(s, e, status, body);
    if (rc == 0) rc = append_locked(s, answer_record(e));
    if (rc == 0) maybe_compact_locked(s);
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

int fg_idem_finish(fg_idem *s, const char *key, int status, const char *body) {
  return answer(s, key, status, body, 1);
}

int fg_idem_update(fg_idem *s, const char *key, int status, const char *body) {
  return answer(s, key, status, body, 0);
}

int fg_idem_cancel(fg_idem *s, const char *key) {
  pthread_mutex_lock(&s->lock);
  entry *e = find_locked(s, key);
  int rc = 0;
  if (e && e->status == 0) {
    rc = append_locked(s, json_pack("{s:s, s:s}", "op", "cancel", "key", key));
    remove_locked(s, e);
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

void fg_idem_stats(fg_idem *s, size_t *keys, size_t *journal_bytes) {
  pthread_mutex_lock(&s->lock);
  *keys = s->n;
  *journal_bytes = s->journal_bytes;
  pthread_mutex_unlock(&s->lock);
}

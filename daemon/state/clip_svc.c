/* The CLIP model the daemon serves: loading, reference counts, reloads; see clip_svc.h. */
#include "clip_svc.h"

#include "conf/conf.h"
#include "decoder/decoder.h"

#include "core/error.h"
#include "core/log.h"
#include "core/ref.h"
#include "io/image.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* What identifies a file's contents without reading it. */
typedef struct file_id {
  dev_t dev;
  ino_t ino;
  off_t size;
  struct timespec mtime;
} file_id;

struct fg_clip_model {
  fg_ref ref;
  fg_clip *clip;       /* owned */
  fg_tokenizer *tok;   /* owned */
  char *weights_path;  /* owned, as configured */
  char *vocab_path;    /* owned */
  file_id weights_id, vocab_id;
  int threads;
};

struct fg_clip_svc {
  fg_ref_slot current;  /* the fg_clip_model requests take */
  pthread_mutex_t lock; /* guards last_error */
  char last_error[1024];
};

/* ---------------------------------------------------------------- models */

static void model_free(fg_clip_model *m) {
  if (!m) return;
  fg_clip_free(m->clip);
  fg_tokenizer_free(m->tok);
  free(m->weights_path);
  free(m->vocab_path);
  free(m);
}

void fg_clip_model_release(fg_clip_model *m) {
  if (m && fg_ref_put(&m->ref)) model_free(m);
}

fg_clip *fg_clip_model_clip(const fg_clip_model *m) { return m->clip; }
const fg_tokenizer *fg_clip_model_tokenizer(const fg_clip_model *m) { return m->tok; }
const fg_clip_info *fg_clip_model_info(const fg_clip_model *m) { return fg_clip_get_info(m->clip); }
int fg_clip_model_threads(const fg_clip_model *m) { return m->threads; }

static int stat_id(const char *path, file_id *id) {
  struct stat st;
  if (stat(path, &st) != 0) return -1;
  id->dev = st.st_dev;
  id->ino = st.st_ino;
  id->size = st.st_size;
  id->mtime = st.st_mtim;
  return 0;
}

static int same_id(const file_id *a, const file_id *b) {
  return a->dev == b->dev && a->ino == b->ino && a->size == b->size &&
         a->mtime.tv_sec == b->mtime.tv_sec && a->mtime.tv_nsec == b->mtime.tv_nsec;
}

/* "FILE:LINE: [clip] KEY" of a configuration, for messages about its files. */
static void where(const fg_conf *conf, int line, const char *key, char *buf, size_t n) {
  if (conf->path && line > 0) snprintf(buf, n, "%s:%d: [clip] %s", conf->path, line, key);
  else if (conf->path) snprintf(buf, n, "%s: [clip] %s", conf->path, key);
  else snprintf(buf, n, "[clip] %s", key);
}

/* detail without a leading "path: " (the message names the path once already). */
static const char *after_path(const char *detail, const char *path) {
  size_t n = strlen(path);
  return strncmp(detail, path, n) == 0 && detail[n] == ':' && detail[n + 1] == ' '
           ? detail + n + 2
           : detail;
}

/* The thread count [clip] asks for. */
static int clip_threads(const fg_conf *conf) {
  return conf->clip_threads > 0 ? conf->clip_threads : fg_conf_threads(conf);
}

/* Loads conf's [clip] files into a new model (one reference, the caller's). */
static int model_load(const fg_conf *conf, fg_clip_model **out) {
  *out = NULL;
  char at[PATH_MAX + 64];
  fg_clip_model *m = calloc(1, sizeof *m);
  if (!m) return fg_fail(FG_ENOMEM, "out of memory");
  fg_ref_init(&m->ref, 1);
  m->weights_path = strdup(conf->clip_weights);
  m->vocab_path = strdup(conf->clip_vocab);
  m->threads = clip_threads(conf);
  if (!m->weights_path || !m->vocab_path) {
    model_free(m);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  /* Identify the files before reading them: a file replaced while it loads then looks
   * changed at the next reload, never the other way round. */
  where(conf, conf->clip_weights_line, "weights", at, sizeof at);
  int rc = 0;
  if (stat_id(m->weights_path, &m->weights_id) != 0) {
    rc = fg_fail(errno == ENOENT ? FG_ENOENT : FG_EIO, "%s: cannot load %s: %s", at,
                 m->weights_path, strerror(errno));
  } else if ((rc = fg_clip_load(&m->clip, m->weights_path)) != 0) {
    char why[768];
    snprintf(why, sizeof why, "%s", after_path(fg_error_detail(), m->weights_path));
    rc = fg_fail(rc, "%s: cannot load %s: %s", at, m->weights_path, why);
  }
  if (rc != 0) {
    model_free(m);
    return rc;
  }
  where(conf, conf->clip_vocab_line, "vocab", at, sizeof at);
  if (stat_id(m->vocab_path, &m->vocab_id) != 0) {
    rc = fg_fail(errno == ENOENT ? FG_ENOENT : FG_EIO, "%s: cannot load %s: %s", at,
                 m->vocab_path, strerror(errno));
  } else if ((rc = fg_tokenizer_load(&m->tok, m->vocab_path)) != 0) {
    char why[768];
    snprintf(why, sizeof why, "%s", after_path(fg_error_detail(), m->vocab_path));
    rc = fg_fail(rc, "%s: cannot load %s: %s", at, m->vocab_path, why);
  } else {
    /* Every id the tokenizer can write must index the weights' token embedding. */
    const fg_clip_info *info = fg_clip_get_info(m->clip);
    int nv = fg_tokenizer_vocab_size(m->tok);
    if (nv > info->vocab_size)
      rc = fg_fail(FG_EFORMAT, "%s: %s has %d tokens but the token embedding of %s has %d "
                   "rows; use the vocabulary the weights were trained with", at, m->vocab_path,
                   nv, m->weights_path, info->vocab_size);
  }
  if (rc != 0) {
    model_free(m);
    return rc;
  }
  fg_clip_set_threads(m->clip, m->threads);
  *out = m;
  return 0;
}

/* ---------------------------------------------------------------- the service */

int fg_clip_svc_new(fg_clip_svc **out) {
  *out = NULL;
  fg_clip_svc *svc = calloc(1, sizeof *svc);
  if (!svc) return fg_fail(FG_ENOMEM, "out of memory");
  fg_ref_slot_init(&svc->current);
  pthread_mutex_init(&svc->lock, NULL);
  *out = svc;
  return 0;
}

void fg_clip_svc_free(fg_clip_svc *svc) {
  if (!svc) return;
  fg_clip_model_release(fg_ref_slot_destroy(&svc->current));
  pthread_mutex_destroy(&svc->lock);
  free(svc);
}

fg_clip_model *fg_clip_svc_acquire(fg_clip_svc *svc) {
  return fg_ref_slot_acquire(&svc->current);
}

void fg_clip_svc_unavailable(fg_clip_svc *svc, char *msg, size_t n) {
  pthread_mutex_lock(&svc->lock);
  snprintf(msg, n, "%s", svc->last_error);
  pthread_mutex_unlock(&svc->lock);
}

fg_clip_model *fg_clip_svc_acquire_explained(fg_clip_svc *svc, char *msg, size_t n) {
  fg_clip_model *m = svc ? fg_clip_svc_acquire(svc) : NULL;
  if (m) return m;
  char why[1024] = "";
  if (svc) fg_clip_svc_unavailable(svc, why, sizeof why);
  if (why[0])
    snprintf(msg, n, "this server has no CLIP model: the [clip] files of its configuration "
             "did not load (%s); fix them and reload the configuration (SIGHUP, or systemctl "
             "reload fieldgripd)", why);
  else
    snprintf(msg, n, "this server has no CLIP model: add a [clip] section with weights = "
             "/path/to/clip.safetensors and vocab = /path/to/bpe_simple_vocab_16e6.txt.gz to "
             "its configuration file and reload it (SIGHUP, or systemctl reload fieldgripd)");
  return NULL;
}

/* Whether m still matches conf: same paths, unchanged files, same threads. */
static int model_current(const fg_clip_model *m, const fg_conf *conf) {
  file_id w, v;
  return strcmp(m->weights_path, conf->clip_weights) == 0 &&
         strcmp(m->vocab_path, conf->clip_vocab) == 0 && m->threads == clip_threads(conf) &&
         stat_id(m->weights_path, &w) == 0 && same_id(&w, &m->weights_id) &&
         stat_id(m->vocab_path, &v) == 0 && same_id(&v, &m->vocab_id);
}

static void install(fg_clip_svc *svc, fg_clip_model *m) {
  fg_clip_model *old = fg_ref_slot_swap(&svc->current, m, m ? &m->ref : NULL);
  pthread_mutex_lock(&svc->lock);
  svc->last_error[0] = '\0';
  pthread_mutex_unlock(&svc->lock);
  fg_clip_model_release(old);
}

/* fg_clip_svc_configure with cur, a reference to the current model (or NULL). */
static int reconfigure(fg_clip_svc *svc, const fg_conf *conf, const fg_clip_model *cur,
                       int *changed) {
  if (changed) *changed = 0;
  if (!conf->clip_weights || !conf->clip_vocab) {
    if (cur) {
      install(svc, NULL);
      fg_info("[clip] is gone from the configuration: the CLIP model is unloaded (requests "
              "already running finish with it)");
      if (changed) *changed = 1;
    } else {
      pthread_mutex_lock(&svc->lock);
      svc->last_error[0] = '\0';
      pthread_mutex_unlock(&svc->lock);
    }
    return 0;
  }
  if (cur && model_current(cur, conf)) return 0;

  fg_clip_model *m = NULL;
  int rc = model_load(conf, &m);
  if (rc != 0) {
    pthread_mutex_lock(&svc->lock);
    snprintf(svc->last_error, sizeof svc->last_error, "%s", fg_error_detail());
    pthread_mutex_unlock(&svc->lock);
    return rc;
  }
  const fg_clip_info *info = fg_clip_get_info(m->clip);
  const char *same = cur && strcmp(fg_clip_get_info(cur->clip)->fingerprint,
                                   info->fingerprint) == 0 ? " (the same weights as before)" : "";
  fg_info("CLIP model loaded from %s%s: fingerprint %s, %s, embedding %d, image %d/%d, %d "
          "threads; vocabulary %s", m->weights_path, same, info->fingerprint, info->dtype,
          info->embed_dim, info->image_size, info->patch_size, m->threads, m->vocab_path);
  install(svc, m);
  if (changed) *changed = 1;
  return 0;
}

int fg_clip_svc_configure(fg_clip_svc *svc, const fg_conf *conf, int *changed) {
  fg_clip_model *cur = fg_clip_svc_acquire(svc);
  const int rc = reconfigure(svc, conf, cur, changed);
  fg_clip_model_release(cur);
  return rc;
}

json_t *fg_clip_model_json(const fg_clip_model *m) {
  const fg_clip_info *info = fg_clip_get_info(m->clip);
  return json_pack("{s:s,s:s,s:i,s:i,s:i,s:i,s:s}", "fingerprint", info->fingerprint, "dtype",
                   info->dtype, "embed_dim", info->embed_dim, "image_size", info->image_size,
                   "patch_size", info->patch_size, "context_length", info->context_length,
                   "naming", info->naming ? "hf" : "openai");
}

int fg_clip_model_embed_image(fg_clip_model *m, fg_decoder *dec, const void *bytes, size_t len,
                              int pooled, fg_clip_image_embedding *out) {
  memset(out, 0, sizeof *out);
  static const float white[3] = {1, 1, 1};
  fg_image img = {0};
  int rc = fg_decoder_decode(dec, bytes, len, white, &img);
  if (rc == FG_ENOENT || rc == FG_EIO || rc == FG_ENOMEM)
    return fg_fail_as(rc, "internal_error", "cannot decode the image: %s", fg_error_detail());
  if (rc != 0) return fg_fail_as(rc, "invalid_image", "%s", fg_error_detail());
  out->dim = fg_clip_model_info(m)->embed_dim;
  if (pooled) {
    out->data = malloc((size_t)out->dim * sizeof *out->data);
    rc = out->data ? fg_clip_pooled_embedding(m->clip, img.rgb, img.w, img.h, out->data)
                   : fg_fail(FG_ENOMEM, "out of memory");
  } else {
    rc = fg_clip_dense_features(m->clip, img.rgb, img.w, img.h, &out->data, &out->hp, &out->wp);
  }
  fg_image_release(&img);
  if (rc == 0) return 0;
  free(out->data);
  out->data = NULL;
  if (rc == FG_EINVAL || rc == FG_ERANGE)
    return fg_fail_as(rc, "invalid_image", "%s", fg_error_detail());
  return fg_fail_as(rc, "internal_error", "%s: %s", pooled ? "cannot embed the image"
                    : "cannot compute the features", fg_error_detail());
}

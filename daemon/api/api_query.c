/* Queries: JSON to unit vectors; see api_query.h. */
#include "api_query.h"

#include "state/app.h"
#include "state/clip_svc.h"
#include "state/json.h"

#include "core/error.h"
#include "io/frame.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const query_keys[] = {"text", "embedding", "negatives", "negative_embeddings",
                                         "temperature"};
#define N_QUERY_KEYS (sizeof query_keys / sizeof query_keys[0])


int fg_query_is_key(const char *key) {
  for (size_t i = 0; i < N_QUERY_KEYS; i++)
    if (strcmp(key, query_keys[i]) == 0) return 1;
  return 0;
}

const char *fg_query_unknown_key(json_t *body, const char *const *keys, size_t n) {
  const char *key;
  json_t *v;
  json_object_foreach(body, key, v) {
    int known = fg_query_is_key(key);
    for (size_t i = 0; !known && i < n; i++) known = strcmp(key, keys[i]) == 0;
    if (!known) return key;
  }
  return NULL;
}

int fg_query_present(json_t *body) {
  for (size_t i = 0; i < N_QUERY_KEYS; i++)
    if (json_object_get(body, query_keys[i])) return 1;
  return 0;
}

/* key of body, with JSON null read as absent. */
static json_t *get(json_t *body, const char *key) {
  json_t *v = json_object_get(body, key);
  return v && !json_is_null(v) ? v : NULL;
}

/* Reads v, an array of exactly D finite numbers (D < 0: any length 1..FG_FRAME_MAX_FEAT_D,
 * returned in *n), into the malloc'd *out as given: fg_query_init scales it. what names v in
 * messages. */
static int read_vector(json_t *v, int D, const char *what, float **out, int *n) {
  *out = NULL;
  if (!json_is_array(v) || json_array_size(v) == 0)
    return fg_fail(FG_EINVAL, "%s must be a non-empty array of numbers", what);
  size_t k = json_array_size(v);
  if (D < 0 && k > FG_FRAME_MAX_FEAT_D)
    return fg_fail(FG_EINVAL, "%s has %zu numbers; feature dimensions go up to %d", what, k,
                   FG_FRAME_MAX_FEAT_D);
  if (D >= 0 && k != (size_t)D)
    return fg_fail(FG_EINVAL, "%s has %zu numbers but the query's dimension is %d", what, k, D);
  float *x = malloc(k * sizeof *x);
  if (!x) return fg_fail(FG_ENOMEM, "out of memory");
  for (size_t i = 0; i < k; i++) {
    json_t *e = json_array_get(v, i);
    double d = json_is_number(e) ? json_number_value(e) : NAN;
    if (!isfinite(d) || fabs(d) > FLT_MAX) {
      free(x);
      return fg_fail(FG_EINVAL, "%s[%zu] must be a finite number (within float32's range)",
                     what, i);
    }
    x[i] = (float)d;
  }
  *out = x;
  if (n) *n = (int)k;
  return 0;
}

/* CLIP's text embeddings of the query's texts: positives first, then negatives, into the
 * malloc'd *out [n][E]. Answers the request itself on failure. */
static int embed_texts(fg_resp *resp, fg_clip_model *m, const char *const *pos, int n_pos,
                       const char *const *negs, int n_neg, float **out) {
  *out = NULL;
  const int E = fg_clip_model_info(m)->embed_dim;
  const char *texts[FG_QUERY_MAX_TEXTS + FG_QUERY_MAX_NEGATIVES];
  int n = 0;
  for (int i = 0; i < n_pos; i++) texts[n++] = pos[i];
  for (int i = 0; i < n_neg; i++) texts[n++] = negs[i];
  if (n == 0) return 0;
  float *emb = malloc((size_t)n * (size_t)E * sizeof *emb); /* [n][E] */
  if (!emb) return fg_resp_error(resp, 500, "internal_error", "out of memory"), -1;
  int bad = -1;
  int rc = fg_clip_embed_texts(fg_clip_model_clip(m), fg_clip_model_tokenizer(m), texts, n, 0, 0,
                               emb, &bad);
  if (rc != 0) {
    char name[32];
    if (bad >= 0 && bad < n_pos && n_pos == 1) snprintf(name, sizeof name, "\"text\"");
    else if (bad >= 0 && bad < n_pos) snprintf(name, sizeof name, "text[%d]", bad);
    else snprintf(name, sizeof name, "negatives[%d]", bad - n_pos);
    free(emb);
    if (rc == FG_ERANGE)
      return fg_resp_error(resp, 400, "text_too_long", "%s: %s; shorten it", name,
                           fg_error_detail()), -1;
    if (rc == FG_EINVAL && bad >= 0)
      return fg_resp_error(resp, 400, "invalid_text", "%s: %s", name, fg_error_detail()), -1;
    return fg_resp_error(resp, 500, "internal_error", "cannot embed the query: %s",
                         fg_error_detail()), -1;
  }
  *out = emb;
  return 0;
}

/* The query's vectors, as given or embedded, before fg_query_init resolves them. */
typedef struct raw_query {
  float *embedding;          /* (1, D) "embedding"; owned */
  float *negative_embeddings; /* (n_negative_embeddings, D); owned */
  int n_negative_embeddings;
  float *text_embeddings;    /* (n_pos_texts + n_neg_texts, D) from CLIP; owned */
} raw_query;

static void raw_query_free(raw_query *raw) {
  free(raw->embedding);
  free(raw->negative_embeddings);
  free(raw->text_embeddings);
}

/* Resolves the raw vectors into *out through the library's one rule (fg_query_init: each
 * vector scaled to unit length, the positives averaged and the mean scaled again), so that
 * heatmaps, renders and grasps score the same query the same way. Answers 400
 * invalid_query itself on failure. */
static int resolve(fg_resp *resp, const raw_query *raw, int D, int n_pos_texts,
                   int n_neg_texts, float temperature, fg_query *out) {
  const float *pos = raw->embedding ? raw->embedding : raw->text_embeddings;
  const int n_pos = raw->embedding ? 1 : n_pos_texts;
  const float *neg = raw->negative_embeddings;
  int n_neg = raw->n_negative_embeddings;
  if (n_neg_texts) {
    neg = raw->text_embeddings + (size_t)(raw->embedding ? 0 : n_pos_texts) * (size_t)D;
    n_neg = n_neg_texts;
  }
  int rc = fg_query_init(out, D, pos, n_pos, neg, n_neg, temperature);
  if (rc == FG_ENOMEM) return fg_resp_error(resp, 500, "internal_error", "out of memory"), -1;
  if (rc != 0)
    return fg_resp_error(resp, 400, "invalid_query", "%s (%s); a query needs non-zero "
                         "vectors, and the texts of \"text\" must describe the same thing, not "
                         "cancel out", fg_error_detail(),
                         raw->embedding ? "positive 0 is \"embedding\", negatives are "
                                          "\"negative_embeddings\" or \"negatives\" in order"
                                        : "positives are the texts of \"text\", negatives "
                                          "\"negatives\" or \"negative_embeddings\" in order"),
           -1;
  return 0;
}

static int invalid(fg_resp *resp) {
  return fg_resp_error(resp, 400, "invalid_query", "%s", fg_error_detail()), -1;
}

int fg_query_parse(fg_req *req, fg_resp *resp, json_t *body, int scene_dim, fg_query *out) {
  memset(out, 0, sizeof *out);
  json_t *text = get(body, "text"), *emb = get(body, "embedding");
  json_t *negs = get(body, "negatives"), *nembs = get(body, "negative_embeddings");
  raw_query raw = {0};
  fg_clip_model *m = NULL;
  int rc = -1;

  /* ---- shapes, before anything is embedded ---- */
  if (text && emb) {
    fg_fail(FG_EINVAL, "give either \"text\" or \"embedding\" as the query, not both");
    goto invalid;
  }
  if (!text && !emb) {
    fg_fail(FG_EINVAL, "the query needs \"text\": \"a mug\" (embedded with CLIP, needs "
            "[clip]) or \"embedding\": [D numbers] in the scene's feature space");
    goto invalid;
  }
  const char *pos_texts[FG_QUERY_MAX_TEXTS];
  int n_pos = 0;
  if (text && json_is_string(text) && json_string_length(text) > 0) {
    pos_texts[n_pos++] = json_string_value(text);
  } else if (text && json_is_array(text) && json_array_size(text) >= 1 &&
             json_array_size(text) <= FG_QUERY_MAX_TEXTS) {
    for (size_t i = 0; i < json_array_size(text); i++) {
      json_t *s = json_array_get(text, i);
      if (!json_is_string(s) || json_string_length(s) == 0) {
        fg_fail(FG_EINVAL, "text[%zu] must be a non-empty string", i);
        goto invalid;
      }
      pos_texts[n_pos++] = json_string_value(s);
    }
  } else if (text) {
    fg_fail(FG_EINVAL, "\"text\" must be a non-empty string, e.g. \"text\": \"a mug\", or a "
            "list of 1 to %d of them, averaged: [\"a mug\", \"a coffee cup\"]",
            FG_QUERY_MAX_TEXTS);
    goto invalid;
  }
  if (negs && nembs) {
    fg_fail(FG_EINVAL, "give either \"negatives\" (texts) or \"negative_embeddings\" "
            "(vectors), not both");
    goto invalid;
  }
  double t = FG_QUERY_DEFAULT_TEMPERATURE;
  int found = fg_json_number(body, "temperature", &t);
  if (found < 0 || (found > 0 && !(t > 0 && t <= FLT_MAX))) {
    fg_fail(FG_EINVAL, "\"temperature\" must be a positive number (default %g)",
            (double)FG_QUERY_DEFAULT_TEMPERATURE);
    goto invalid;
  }
  const char *neg_texts[FG_QUERY_MAX_NEGATIVES];
  int n_neg_texts = 0;
  if (negs) {
    if (!json_is_array(negs)) {
      fg_fail(FG_EINVAL, "\"negatives\" must be a list of strings, e.g. [\"object\", "
              "\"things\"] ([] for none)");
      goto invalid;
    }
    if (json_array_size(negs) > FG_QUERY_MAX_NEGATIVES) {
      fg_fail(FG_EINVAL, "\"negatives\" has %zu texts; at most %d", json_array_size(negs),
              FG_QUERY_MAX_NEGATIVES);
      goto invalid;
    }
    for (size_t i = 0; i < json_array_size(negs); i++) {
      json_t *s = json_array_get(negs, i);
      if (!json_is_string(s) || json_string_length(s) == 0) {
        fg_fail(FG_EINVAL, "negatives[%zu] must be a non-empty string", i);
        goto invalid;
      }
      neg_texts[n_neg_texts++] = json_string_value(s);
    }
  } else if (text && !nembs) {
    for (int i = 0; i < FG_QUERY_N_DEFAULT_NEGATIVES; i++)
      neg_texts[n_neg_texts++] = fg_query_default_negatives[i];
  }
  if (nembs && (!json_is_array(nembs) || json_array_size(nembs) > FG_QUERY_MAX_NEGATIVES)) {
    fg_fail(FG_EINVAL, "\"negative_embeddings\" must be a list of at most %d vectors "
            "([[D numbers], ...])", FG_QUERY_MAX_NEGATIVES);
    goto invalid;
  }

  /* ---- the dimension ---- */
  int D = -1;
  if (emb) {
    if (read_vector(emb, -1, "\"embedding\"", &raw.embedding, &D) != 0) goto invalid;
    if (scene_dim && D != scene_dim) {
      fg_fail(FG_EINVAL, "\"embedding\" has %d numbers but the scene's features have D = %d",
              D, scene_dim);
      goto invalid;
    }
  }
  if (text || n_neg_texts) {
    char why[1400];
    m = fg_clip_svc_acquire_explained(req->app->clip, why, sizeof why);
    if (!m) {
      fg_resp_error(resp, 409, "clip_not_configured", "%s", why);
      goto out;
    }
    int E = fg_clip_model_info(m)->embed_dim;
    if (scene_dim && E != scene_dim) {
      fg_resp_error(resp, 409, "feature_dim_mismatch", "the scene's features have D = %d but "
                    "the CLIP model's embeddings have %d numbers, so texts cannot query it; "
                    "give \"embedding\" (and \"negative_embeddings\") in the scene's feature "
                    "space instead, or train the scene on CLIP features", scene_dim, E);
      goto out;
    }
    if (D >= 0 && D != E) {
      fg_fail(FG_EINVAL, "\"embedding\" has %d numbers but the CLIP model that embeds "
              "\"negatives\" gives %d; give \"negative_embeddings\" of D = %d instead", D, E,
              D);
      goto invalid;
    }
    D = E;
  }
  const size_t n_nembs = nembs ? json_array_size(nembs) : 0;
  if (n_nembs) {
    raw.negative_embeddings = malloc(n_nembs * (size_t)D * sizeof *raw.negative_embeddings);
    if (!raw.negative_embeddings) {
      fg_resp_error(resp, 500, "internal_error", "out of memory");
      goto out;
    }
  }
  for (size_t i = 0; i < n_nembs; i++) {
    char what[48];
    snprintf(what, sizeof what, "negative_embeddings[%zu]", i);
    float *v = NULL;
    if (read_vector(json_array_get(nembs, i), D, what, &v, NULL) != 0) goto invalid;
    memcpy(raw.negative_embeddings + i * (size_t)D, v, (size_t)D * sizeof *v);
    free(v);
    raw.n_negative_embeddings++;
  }

  /* ---- texts through CLIP, then the one resolution rule ---- */
  if (m && embed_texts(resp, m, pos_texts, n_pos, neg_texts, n_neg_texts,
                       &raw.text_embeddings) != 0)
    goto out;
  rc = resolve(resp, &raw, D, n_pos, n_neg_texts, (float)t, out);
  goto out;

invalid:
  invalid(resp);
out:
  fg_clip_model_release(m);
  raw_query_free(&raw);
  if (rc != 0) fg_query_release(out);
  return rc;
}

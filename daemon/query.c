/* Queries: JSON to unit vectors; see query.h. */
#include "query.h"

#include "app.h"
#include "clip_svc.h"
#include "json.h"

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
 * returned in *n), into a malloc'd unit vector. what names v in messages. */
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
  if (fg_l2_normalize(x, (int)k) != 0) {
    free(x);
    return fg_fail(FG_EINVAL, "%s has length 0 (all zeros, or too small to normalise); a "
                   "direction needs a non-zero vector", what);
  }
  *out = x;
  if (n) *n = (int)k;
  return 0;
}

/* Embeds the query's positive texts (n_pos of them, first) and negatives into out->q (the
 * mean of the positives' unit embeddings, renormalised) and out->neg. Answers itself on
 * failure. */
static int embed_texts(fg_resp *resp, fg_clip_model *m, const char *const *pos, int n_pos,
                       const char *const *negs, int n_neg, fg_query *out) {
  const int E = fg_clip_model_info(m)->embed_dim;
  const char *texts[FG_QUERY_MAX_TEXTS + FG_QUERY_MAX_NEGATIVES];
  int n = 0;
  for (int i = 0; i < n_pos; i++) texts[n++] = pos[i];
  for (int i = 0; i < n_neg; i++) texts[n++] = negs[i];
  if (n == 0) return 0;
  float *emb = malloc((size_t)n * (size_t)E * sizeof *emb); /* [n][E] */
  if (!emb) return fg_resp_error(resp, 500, "internal_error", "out of memory"), -1;
  int bad = -1;
  int rc = fg_clip_model_embed_texts(m, texts, n, 0, 1, emb, &bad);
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
  if (n_pos) {
    out->q = calloc((size_t)E, sizeof *out->q);
    if (!out->q) {
      free(emb);
      return fg_resp_error(resp, 500, "internal_error", "out of memory"), -1;
    }
    /* Several texts: their unit embeddings averaged, then scaled back to unit length. */
    for (int i = 0; i < n_pos; i++)
      for (int k = 0; k < E; k++) out->q[k] += emb[(size_t)i * E + k];
    if (fg_l2_normalize(out->q, E) != 0) {
      free(emb);
      return fg_resp_error(resp, 400, "invalid_query", "the texts of \"text\" cancel out: "
                           "their embeddings' mean has length 0; give texts that describe "
                           "the same thing"), -1;
    }
  }
  if (n_neg) {
    out->neg = malloc((size_t)n_neg * (size_t)E * sizeof *out->neg);
    if (!out->neg) {
      free(emb);
      return fg_resp_error(resp, 500, "internal_error", "out of memory"), -1;
    }
    memcpy(out->neg, emb + (size_t)n_pos * E, (size_t)n_neg * (size_t)E * sizeof *emb);
    out->n_neg = n_neg;
  }
  free(emb);
  return 0;
}

static int invalid(fg_resp *resp, fg_query *out) {
  fg_query_release(out);
  return fg_resp_error(resp, 400, "invalid_query", "%s", fg_error_detail()), -1;
}

int fg_query_parse(fg_req *req, fg_resp *resp, json_t *body, int scene_dim, fg_query *out) {
  memset(out, 0, sizeof *out);
  out->temperature = FG_QUERY_DEFAULT_TEMPERATURE;
  json_t *text = get(body, "text"), *emb = get(body, "embedding");
  json_t *negs = get(body, "negatives"), *nembs = get(body, "negative_embeddings");

  /* ---- shapes, before anything is embedded ---- */
  if (text && emb)
    return fg_fail(FG_EINVAL, "give either \"text\" or \"embedding\" as the query, not both"),
           invalid(resp, out);
  if (!text && !emb)
    return fg_fail(FG_EINVAL, "the query needs \"text\": \"a mug\" (embedded with CLIP, needs "
                   "[clip]) or \"embedding\": [D numbers] in the scene's feature space"),
           invalid(resp, out);
  const char *pos_texts[FG_QUERY_MAX_TEXTS];
  int n_pos = 0;
  if (text && json_is_string(text) && json_string_length(text) > 0) {
    pos_texts[n_pos++] = json_string_value(text);
  } else if (text && json_is_array(text) && json_array_size(text) >= 1 &&
             json_array_size(text) <= FG_QUERY_MAX_TEXTS) {
    for (size_t i = 0; i < json_array_size(text); i++) {
      json_t *s = json_array_get(text, i);
      if (!json_is_string(s) || json_string_length(s) == 0)
        return fg_fail(FG_EINVAL, "text[%zu] must be a non-empty string", i),
               invalid(resp, out);
      pos_texts[n_pos++] = json_string_value(s);
    }
  } else if (text) {
    return fg_fail(FG_EINVAL, "\"text\" must be a non-empty string, e.g. \"text\": \"a mug\", "
                   "or a list of 1 to %d of them, averaged: [\"a mug\", \"a coffee cup\"]",
                   FG_QUERY_MAX_TEXTS), invalid(resp, out);
  }
  if (negs && nembs)
    return fg_fail(FG_EINVAL, "give either \"negatives\" (texts) or \"negative_embeddings\" "
                   "(vectors), not both"), invalid(resp, out);
  double t = FG_QUERY_DEFAULT_TEMPERATURE;
  int rc = fg_json_number(body, "temperature", &t);
  if (rc < 0 || (rc > 0 && !(t > 0 && t <= FLT_MAX)))
    return fg_fail(FG_EINVAL, "\"temperature\" must be a positive number (default %g)",
                   (double)FG_QUERY_DEFAULT_TEMPERATURE), invalid(resp, out);
  out->temperature = (float)t;
  const char *neg_texts[FG_QUERY_MAX_NEGATIVES];
  int n_neg_texts = 0;
  if (negs) {
    if (!json_is_array(negs))
      return fg_fail(FG_EINVAL, "\"negatives\" must be a list of strings, e.g. [\"object\", "
                     "\"things\"] ([] for none)"), invalid(resp, out);
    if (json_array_size(negs) > FG_QUERY_MAX_NEGATIVES)
      return fg_fail(FG_EINVAL, "\"negatives\" has %zu texts; at most %d", json_array_size(negs),
                     FG_QUERY_MAX_NEGATIVES), invalid(resp, out);
    for (size_t i = 0; i < json_array_size(negs); i++) {
      json_t *s = json_array_get(negs, i);
      if (!json_is_string(s) || json_string_length(s) == 0)
        return fg_fail(FG_EINVAL, "negatives[%zu] must be a non-empty string", i),
               invalid(resp, out);
      neg_texts[n_neg_texts++] = json_string_value(s);
    }
  } else if (text && !nembs) {
    for (int i = 0; i < FG_QUERY_N_DEFAULT_NEGATIVES; i++)
      neg_texts[n_neg_texts++] = fg_query_default_negatives[i];
  }
  if (nembs && (!json_is_array(nembs) || json_array_size(nembs) > FG_QUERY_MAX_NEGATIVES))
    return fg_fail(FG_EINVAL, "\"negative_embeddings\" must be a list of at most %d vectors "
                   "([[D numbers], ...])", FG_QUERY_MAX_NEGATIVES), invalid(resp, out);

  /* ---- the dimension ---- */
  int D = -1;
  if (emb) {
    if (read_vector(emb, -1, "\"embedding\"", &out->q, &D) != 0) return invalid(resp, out);
    if (scene_dim && D != scene_dim)
      return fg_fail(FG_EINVAL, "\"embedding\" has %d numbers but the scene's features have "
                     "D = %d", D, scene_dim), invalid(resp, out);
  }
  fg_clip_model *m = NULL;
  if (text || n_neg_texts) {
    char why[1400];
    m = fg_clip_svc_acquire_explained(req->app->clip, why, sizeof why);
    if (!m) {
      fg_query_release(out);
      return fg_resp_error(resp, 409, "clip_not_configured", "%s", why), -1;
    }
    int E = fg_clip_model_info(m)->embed_dim;
    if (scene_dim && E != scene_dim) {
      fg_clip_model_release(m);
      fg_query_release(out);
      return fg_resp_error(resp, 409, "feature_dim_mismatch", "the scene's features have D = "
                           "%d but the CLIP model's embeddings have %d numbers, so texts cannot "
                           "query it; give \"embedding\" (and \"negative_embeddings\") in the "
                           "scene's feature space instead, or train the scene on CLIP features",
                           scene_dim, E), -1;
    }
    if (D >= 0 && D != E) {
      fg_clip_model_release(m);
      return fg_fail(FG_EINVAL, "\"embedding\" has %d numbers but the CLIP model that embeds "
                     "\"negatives\" gives %d; give \"negative_embeddings\" of D = %d instead",
                     D, E, D), invalid(resp, out);
    }
    D = E;
  }
  for (size_t i = 0; nembs && i < json_array_size(nembs); i++) {
    char what[48];
    snprintf(what, sizeof what, "negative_embeddings[%zu]", i);
    float *v = NULL;
    if (read_vector(json_array_get(nembs, i), D, what, &v, NULL) != 0) {
      fg_clip_model_release(m);
      return invalid(resp, out);
    }
    if (!out->neg) {
      out->neg = malloc(json_array_size(nembs) * (size_t)D * sizeof *out->neg);
      if (!out->neg) {
        free(v);
        fg_clip_model_release(m);
        fg_query_release(out);
        return fg_resp_error(resp, 500, "internal_error", "out of memory"), -1;
      }
    }
    memcpy(out->neg + i * (size_t)D, v, (size_t)D * sizeof *v);
    free(v);
    out->n_neg++;
  }
  out->dim = D;

  /* ---- texts through CLIP ---- */
  if (m) {
    rc = embed_texts(resp, m, pos_texts, n_pos, neg_texts, n_neg_texts, out);
    fg_clip_model_release(m);
    if (rc != 0) {
      fg_query_release(out);
      return -1;
    }
  }
  return 0;
}

/* POST /v1/embed/text and POST /v1/embed/image: CLIP's text and image embeddings over HTTP,
 * from the model of [clip] (clip_svc.h). Both run on the offload pool. */
#include "api.h"
#include "api_decode.h"
#include "state/clip_svc.h"
#include "state/json.h"
#include "metrics/metrics.h"

#include "core/error.h"
#include "io/image.h"
#include "io/npy.h"

#include <stdlib.h>
#include <string.h>

fg_clip_model *fg_api_clip_model(fg_req *req, fg_resp *resp) {
  char why[1400];
  fg_clip_model *m = fg_clip_svc_acquire_explained(req->app->clip, why, sizeof why);
  if (!m) fg_resp_error(resp, 409, "clip_not_configured", "%s", why);
  return m;
}

/* An array of n floats as JSON numbers; NULL on allocation failure. */
static json_t *float_array(const float *v, int n) {
  json_t *a = json_array();
  for (int i = 0; a && i < n; i++) {
    if (json_array_append_new(a, json_real((double)v[i])) != 0) {
      json_decref(a);
      return NULL;
    }
  }
  return a;
}

/* Reads an optional boolean key: 1 present, 0 absent (or null), FG_EINVAL otherwise. */
static int json_flag(json_t *body, const char *key, int *out) {
  json_t *v = json_object_get(body, key);
  if (!v || json_is_null(v)) return 0;
  if (!json_is_boolean(v)) return fg_fail(FG_EINVAL, "\"%s\" must be true or false", key);
  *out = json_is_true(v);
  return 1;
}

/* ---------------------------------------------------------------- POST /v1/embed/text */

/* Collects the texts of the body: "text" a string or an array of 1..FG_CLIP_MAX_TEXTS
 * strings. texts (borrowed from body) has room for FG_CLIP_MAX_TEXTS. Answers 400 itself. */
static int collect_texts(json_t *body, const char **texts, int *n, fg_resp *resp) {
  json_t *t = json_object_get(body, "text");
  if (!t || json_is_null(t))
    return fg_resp_error(resp, 400, "invalid_request", "the body needs \"text\": a string or "
                         "a list of up to %d strings, e.g. {\"text\": [\"a mug\", \"a "
                         "spoon\"]}", FG_CLIP_MAX_TEXTS), -1;
  if (json_is_string(t)) {
    texts[0] = json_string_value(t);
    *n = 1;
    return 0;
  }
  if (!json_is_array(t))
    return fg_resp_error(resp, 400, "invalid_request", "\"text\" must be a string or a list of "
                         "strings"), -1;
  size_t k = json_array_size(t);
  if (k == 0)
    return fg_resp_error(resp, 400, "invalid_request", "\"text\" is an empty list; give 1 to "
                         "%d strings", FG_CLIP_MAX_TEXTS), -1;
  if (k > FG_CLIP_MAX_TEXTS)
    return fg_resp_error(resp, 400, "too_many_texts", "\"text\" has %zu strings; one request "
                         "takes at most %d (send several requests)", k, FG_CLIP_MAX_TEXTS), -1;
  for (size_t i = 0; i < k; i++) {
    json_t *s = json_array_get(t, i);
    if (!json_is_string(s))
      return fg_resp_error(resp, 400, "invalid_request", "text[%zu] is not a string; \"text\" "
                           "must be a list of strings", i), -1;
    texts[i] = json_string_value(s);
  }
  *n = (int)k;
  return 0;
}

int fg_api_parse_embed_text(json_t *body, fg_api_embed_text_req *r, fg_resp *resp) {
  static const char *const keys[] = {"text", "truncate", "normalize", NULL};
  const char *key = fg_json_unknown_key(body, keys);
  if (key)
    return fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; the body takes "
                         "\"text\" and, optionally, \"truncate\" and \"normalize\" (true "
                         "or false)", key), -1;
  r->truncate = r->normalize = 0;
  r->n = 0;
  if (json_flag(body, "truncate", &r->truncate) < 0 ||
      json_flag(body, "normalize", &r->normalize) < 0)
    return fg_resp_error(resp, 400, "invalid_request", "%s", fg_error_detail()), -1;
  return collect_texts(body, r->texts, &r->n, resp);
}

int fg_api_embed_text(fg_req *req, fg_resp *resp) {
  fg_clip_model *m = fg_api_clip_model(req, resp);
  if (!m) return 0;
  json_t *body = fg_api_body_object(req, resp);
  float *emb = NULL;
  if (!body) goto out;
  fg_api_embed_text_req r;
  if (fg_api_parse_embed_text(body, &r, resp) != 0) goto out;
  const int n = r.n, normalize = r.normalize;

  const fg_clip_info *info = fg_clip_model_info(m);
  const int E = info->embed_dim;
  emb = malloc((size_t)n * (size_t)E * sizeof *emb);
  if (!emb) {
    fg_resp_error(resp, 500, "internal_error", "out of memory");
    goto out;
  }
  int bad = -1;
  int rc = fg_clip_embed_texts(fg_clip_model_clip(m), fg_clip_model_tokenizer(m), r.texts, n,
                               r.truncate, normalize, emb, &bad);
  if (rc == FG_ERANGE) {
    fg_resp_error(resp, 400, "text_too_long", "text[%d]: %s; shorten it, or send \"truncate\": "
                  "true to embed its first %d tokens", bad, fg_error_detail(),
                  info->context_length - 2);
    goto out;
  }
  if (rc == FG_EINVAL && bad >= 0) {
    fg_resp_error(resp, 400, "invalid_text", "text[%d]: %s", bad, fg_error_detail());
    goto out;
  }
  if (rc != 0) {
    fg_resp_error(resp, 500, "internal_error", "cannot embed the texts: %s", fg_error_detail());
    goto out;
  }
  fg_metrics_add_clip_embeddings(FG_METRICS_CLIP_TEXT, (unsigned)n);
  json_t *rows = json_array();
  for (int i = 0; rows && i < n; i++) {
    json_t *row = float_array(emb + (size_t)i * E, E);
    if (!row || json_array_append_new(rows, row) != 0) {
      json_decref(rows);
      rows = NULL;
    }
  }
  json_t *model = fg_clip_model_json(m);
  if (!rows || !model) {
    json_decref(rows);
    json_decref(model);
    fg_resp_error(resp, 500, "internal_error", "out of memory building the reply");
    goto out;
  }
  fg_resp_json(resp, 200, json_pack("{s:o,s:i,s:b,s:o}", "embeddings", rows, "dim", E,
                                    "normalized", normalize, "model", model));
out:
  free(emb);
  json_decref(body);
  fg_clip_model_release(m);
  return 0;
}

/* ---------------------------------------------------------------- POST /v1/embed/image */

/* Reads ?output= (*pooled) and checks that the body is an image file; answers 400 or 415
 * itself and returns -1 otherwise. */
static int parse_embed_image(const fg_req *req, int *pooled, fg_resp *resp) {
  const char *output = fg_req_query(req, "output");
  *pooled = output && strcmp(output, "pooled") == 0;
  if (output && !*pooled && strcmp(output, "dense") != 0)
    return fg_resp_error(resp, 400, "invalid_request", "?output= must be \"dense\" (the "
                         "default: MaskCLIP features [h, w, E] as .npy) or \"pooled\" (the "
                         "image embedding as JSON), got \"%.40s\"", output), -1;
  if (req->body_len == 0)
    return fg_resp_error(resp, 400, "invalid_request", "the body is empty; send the image file "
                         "itself as the body (PNG, JPEG, OpenEXR or TIFF), e.g. curl "
                         "--data-binary @photo.png -H 'Content-Type: image/png'"), -1;
  if (!fg_image_sniff(req->body, req->body_len))
    return fg_resp_error(resp, 415, "unsupported_media_type", "the body is not PNG, JPEG, "
                         "OpenEXR or TIFF data; send the image file itself as the body (curl "
                         "--data-binary @photo.png), not a form (curl -F)"), -1;
  return 0;
}

/* Answers embedding e of model m: pooled as JSON, dense as .npy. */
static void send_embedding(fg_resp *resp, const fg_clip_model *m,
                           const fg_clip_image_embedding *e) {
  if (e->hp == 0) {
    json_t *arr = float_array(e->data, e->dim), *model = fg_clip_model_json(m);
    if (!arr || !model) {
      json_decref(arr);
      json_decref(model);
      fg_resp_error(resp, 500, "internal_error", "cannot embed the image: out of memory");
      return;
    }
    fg_metrics_add_clip_embeddings(FG_METRICS_CLIP_IMAGE_POOLED, 1);
    fg_resp_json(resp, 200, json_pack("{s:o,s:i,s:o}", "embedding", arr, "dim", e->dim, "model",
                                      model));
    return;
  }
  const size_t shape[3] = {(size_t)e->hp, (size_t)e->wp, (size_t)e->dim};
  uint8_t *npy = NULL;
  size_t npy_len = 0;
  if (fg_npy_encode(FG_DTYPE_F32, 3, shape, e->data, &npy, &npy_len) != 0) {
    fg_resp_error(resp, 500, "internal_error", "cannot encode the features: %s",
                  fg_error_detail());
    return;
  }
  fg_metrics_add_clip_embeddings(FG_METRICS_CLIP_IMAGE_DENSE, 1);
  fg_resp_take(resp, 200, "application/x-npy", (char *)npy, npy_len);
}

int fg_api_embed_image(fg_req *req, fg_resp *resp) {
  fg_clip_model *m = fg_api_clip_model(req, resp);
  if (!m) return 0;
  int pooled;
  fg_clip_image_embedding e = {0};
  if (parse_embed_image(req, &pooled, resp) == 0) {
    const int rc = fg_clip_model_embed_image(m, req->app->decoder, req->body, req->body_len,
                                             pooled, &e);
    if (rc != 0)
      fg_api_fail(resp, rc);
    else
      send_embedding(resp, m, &e);
  }
  free(e.data);
  fg_clip_model_release(m);
  return 0;
}

/* Queries of SPEC.md "A query": what a heatmap or a query render looks for, resolved into
 * unit vectors in the scene's feature space.
 *
 * The JSON keys, beside a request's own:
 *   "text": "mug"                 embedded with CLIP's text encoder (needs [clip]); a list
 *                                 ["mug", "coffee cup"] (1..FG_QUERY_MAX_TEXTS) is embedded
 *                                 text by text, averaged and scaled back to unit length; or
 *   "embedding": [D numbers]      a feature-space vector given directly;
 *   "negatives": ["object", ...]  texts (needs [clip]); default, when "text" is given,
 *                                 ["object", "things", "stuff", "texture"]; [] for none;
 *   "negative_embeddings": [[D]]  or vectors given directly (not both);
 *   "temperature": 0.1            > 0, of the softmax between query and negatives.
 * Every query, from texts or vectors, is resolved by the library's one rule, fg_query_init
 * (query/query.h): each vector scaled to unit L2 norm, the positives averaged and the mean
 * scaled again; a zero or non-finite vector, or positives that cancel out, are refused. An
 * "embedding" query has no negatives unless the request names some. */
#ifndef FG_DAEMON_API_QUERY_H
#define FG_DAEMON_API_QUERY_H

#include <stddef.h>

#include <jansson.h>

#include "http/http.h"
#include "query/query.h"

#define FG_QUERY_MAX_TEXTS 16 /* positive texts of one query */

/* The resolved query is the library's (query/query.h): unit q (D), n_neg unit negatives,
 * temperature; FG_QUERY_MAX_NEGATIVES and FG_QUERY_DEFAULT_TEMPERATURE come from there. */

/* 1 when key is one of the query keys above (for handlers that refuse unknown keys). */
int fg_query_is_key(const char *key);

/* The first key of body that is neither a query key nor one of keys (n of them), or NULL
 * when every key is known (for handlers that refuse unknown keys). The string is body's. */
const char *fg_query_unknown_key(json_t *body, const char *const *keys, size_t n);

/* 1 when body holds any query key. */
int fg_query_present(json_t *body);

/* Resolves the query keys of body into *out. scene_dim is the scene's feature dimension when
 * known (its trained field's, else its frames'), 0 otherwise: vectors of another D are
 * refused. Texts are embedded through the CLIP model of req's app. Answers the request
 * itself and returns -1 when the query cannot be used: 400 invalid_query (missing or
 * malformed keys, vectors of the wrong D, non-finite or zero vectors), 400 text_too_long or
 * invalid_text (a text CLIP cannot take), 409 clip_not_configured (texts without [clip]),
 * 409 feature_dim_mismatch (CLIP's E is not the scene's D). On success the caller owns *out
 * (fg_query_release); on failure it holds nothing. */
int fg_query_parse(fg_req *req, fg_resp *resp, json_t *body, int scene_dim, fg_query *out);


#endif

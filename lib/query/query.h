/* Resolved queries: the scoring rule of SPEC.md "A query".
 *
 * Scores. A resolved query holds a unit vector q (D), n_neg unit negatives (n_neg x D) and a
 * temperature T > 0. score(f) = cos(f, q) without negatives (in [-1, 1]); with negatives
 *   score(f) = min_n softmax([cos(f, q), cos(f, n)] / T)[0] = min_n 1 / (1 + exp((cos(f, n) -
 *   cos(f, q)) / T))
 * (F3RM's viewer rule, in [0, 1]). A feature of zero length has no direction and scores NaN.
 *
 * Threads: n_threads <= 0 takes the OpenMP default; every result is bit-identical for any
 * thread count. */
#ifndef FG_QUERY_QUERY_H
#define FG_QUERY_QUERY_H

#include <stdint.h>

#define FG_QUERY_MAX_NEGATIVES 64
#define FG_QUERY_DEFAULT_TEMPERATURE 0.1f
#define FG_QUERY_N_DEFAULT_NEGATIVES 4

/* The default negative texts of a text query: "object", "things", "stuff", "texture". */
extern const char *const fg_query_default_negatives[FG_QUERY_N_DEFAULT_NEGATIVES];

typedef struct fg_query {
  int dim;           /* D */
  float *q;          /* (D) unit positive, owned by the struct */
  int n_neg;         /* 0..FG_QUERY_MAX_NEGATIVES */
  float *neg;        /* (n_neg, D) unit negatives, owned by the struct; NULL when n_neg = 0 */
  float temperature; /* > 0, used only with negatives */
} fg_query;

/* Resolves a query from raw embeddings: pos (n_pos, D) positives, each normalised, averaged
 * and the mean renormalised (several positive texts); neg (n_neg, D) negatives, each
 * normalised (NULL when n_neg = 0); temperature > 0 and finite. On success *q owns its copies
 * (fg_query_release); the inputs stay with the caller. On failure *q holds nothing to
 * release. FG_EINVAL with a detail for D outside 1..FG_FIELD_MAX_FEATURE_DIM, n_pos < 1,
 * n_neg outside 0..FG_QUERY_MAX_NEGATIVES, a non-finite value, a zero vector (or positives
 * that cancel), a bad temperature; FG_ENOMEM. */
int fg_query_init(fg_query *q, int dim, const float *pos, int n_pos, const float *neg, int n_neg,
                  float temperature);

/* Frees what *q owns and zeroes it; accepts a zeroed struct. */
void fg_query_release(fg_query *q);

/* Checks a resolved query: dim in range, every vector finite and of unit length within 1e-3,
 * n_neg in range, temperature > 0 and finite. 0 or FG_EINVAL with a detail. */
int fg_query_check(const fg_query *q);

/* Scalar reference of the score rule for one feature f (D) of any length, in double:
 * NaN for a zero or non-finite f. */
double fg_query_score_ref(const fg_query *q, const float *f);

/* The score rule from cosines: cos_q = cos(f, q), cos_neg (n_neg) = cos(f, n). */
float fg_query_score_from_cos(const fg_query *q, float cos_q, const float *cos_neg);

/* Scores n features feat (n, D) (any length, e.g. a rendered feature image from
 * fg_field_render_camera in row-major pixel order) into scores (n). When opacity (n) is not
 * NULL, entries with opacity < min_opacity score NaN (empty pixels have no direction);
 * zero-length features score NaN. FG_EINVAL when D differs from q->dim or q fails
 * fg_query_check; FG_ENOMEM. */
int fg_query_score_features(const fg_query *q, const float *feat, int64_t n, int dim,
                            const float *opacity, float min_opacity, float *scores,
                            int n_threads);

#endif

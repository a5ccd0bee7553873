/* CLIP's BPE tokenizer against OpenAI's: the two known tokenizations, then every record of
 * data/tokenizer_golden.tsv (written once by gen_tokenizer_golden.py, a port of OpenAI's
 * SimpleTokenizer and clip.tokenize, on the real merges file) through fg_tokenizer_bpe,
 * fg_tokenizer_encode with and without truncation and fg_tokenizer_decode. The same ids from
 * a Hugging Face merges.txt and from memory; malformed merges files and invalid UTF-8 as
 * clear errors; two threads sharing one tokenizer. Prints the load and per-sentence times. */
#include <pthread.h>
#include <time.h>
#include <unistd.h>
#include <zlib.h>

#include "clip/tokenizer.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "test.h"

#define CONTEXT 77
#define MAX_IDS 512

static char tmpdir[] = "/tmp/fg-test-tokenizer-XXXXXX";
static fg_tokenizer *tok;
static char *gz;      /* the real merges file, gzip */
static size_t gz_len;
static char *hf;      /* the same merges as a Hugging Face merges.txt */
static size_t hf_len;

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- golden records ------------------------------------------------------------------- */

typedef struct golden {
  char *text, *decoded;  /* unescaped, owned */
  int32_t bpe[MAX_IDS];  /* SimpleTokenizer.encode */
  size_t n_bpe;
  int32_t tok77[CONTEXT]; /* clip.tokenize(truncate=True) without the padding */
  size_t n_tok77;
  int fits, round_trip;
} golden;

static golden goldens[256];
static size_t n_goldens;

/* Undoes the generator's escapes (\\ \t \n \r \xHH) of s[0, len) into a new string. */
static char *unescape(const char *s, size_t len) {
  char *o = malloc(len + 1);
  size_t w = 0;
  ASSERT(o);
  for (size_t i = 0; i < len; i++) {
    if (s[i] != '\\') {
      o[w++] = s[i];
      continue;
    }
    ASSERT(i + 1 < len);
    char c = s[++i];
    if (c == 'x') {
      ASSERT(i + 2 < len);
      char hex[3] = {s[i + 1], s[i + 2], 0};
      o[w++] = (char)strtol(hex, NULL, 16);
      i += 2;
    } else {
      o[w++] = c == 't' ? '\t' : c == 'n' ? '\n' : c == 'r' ? '\r' : c;
    }
  }
  o[w] = '\0';
  return o;
}

/* Parses a space-separated id list ("-" for none) of s[0, len) into ids[cap]. */
static size_t parse_ids(const char *s, size_t len, int32_t *ids, size_t cap) {
  if (len == 1 && s[0] == '-') return 0;
  size_t n = 0;
  char *end;
  for (const char *p = s; p < s + len; p = end) {
    long v = strtol(p, &end, 10);
    ASSERT(end > p && n < cap);
    ids[n++] = (int32_t)v;
  }
  return n;
}

static void load_goldens(void) {
  const char *src = getenv("FG_SOURCE_DIR");
  if (!src) FG_TEST_FAIL("FG_SOURCE_DIR is not set (run through meson test)");
  char *path = fg_path_join(src, "tests/clip/data/tokenizer_golden.tsv"), *buf;
  size_t len;
  ASSERT_OK(fg_read_file(path, 1 << 22, &buf, &len));
  for (char *line = buf; line < buf + len;) {
    char *nl = memchr(line, '\n', (size_t)(buf + len - line));
    ASSERT(nl);
    const char *f[6];
    size_t fl[6], nf = 0;
    for (char *p = line; nf < 6;) {
      char *tab = memchr(p, '\t', (size_t)(nl - p));
      char *e = tab ? tab : nl;
      f[nf] = p;
      fl[nf++] = (size_t)(e - p);
      if (!tab) break;
      p = tab + 1;
    }
    ASSERT_EQ(nf, 6);
    ASSERT(n_goldens < sizeof goldens / sizeof goldens[0]);
    golden *g = &goldens[n_goldens++];
    g->text = unescape(f[0], fl[0]);
    g->n_bpe = parse_ids(f[1], fl[1], g->bpe, MAX_IDS);
    g->n_tok77 = parse_ids(f[2], fl[2], g->tok77, CONTEXT);
    g->fits = f[3][0] == '1';
    g->decoded = unescape(f[4], fl[4]);
    g->round_trip = f[5][0] == '1';
    line = nl + 1;
  }
  free(buf);
  free(path);
  ASSERT(n_goldens >= 60);
}

/* ---- helpers -------------------------------------------------------------------------- */

static void write_file(const char *name, const void *data, size_t len, char **path_out) {
  char *path = fg_path_join(tmpdir, name);
  ASSERT_OK(fg_write_file_atomic(path, data, len));
  *path_out = path;
}

/* gzip of data[0, len) at level 9, malloc'd. */
static unsigned char *gzip_bytes(const void *data, size_t len, size_t *out_len) {
  z_stream zs;
  memset(&zs, 0, sizeof zs);
  ASSERT_EQ(deflateInit2(&zs, 9, Z_DEFLATED, 16 + MAX_WBITS, 9, Z_DEFAULT_STRATEGY), Z_OK);
  size_t cap = deflateBound(&zs, (uLong)len) + 64;
  unsigned char *o = malloc(cap);
  ASSERT(o);
  zs.next_in = (Bytef *)(uintptr_t)data;
  zs.avail_in = (uInt)len;
  zs.next_out = o;
  zs.avail_out = (uInt)cap;
  ASSERT_EQ(deflate(&zs, Z_FINISH), Z_STREAM_END);
  *out_len = cap - zs.avail_out;
  deflateEnd(&zs);
  return o;
}

/* A copy of text[0, len) with line number `line` (1-based) replaced by repl. */
static char *replace_line(const char *text, size_t len, int line, const char *repl,
                          size_t *out_len) {
  const char *b = text;
  for (int i = 1; i < line; i++)
    b = (const char *)memchr(b, '\n', len - (size_t)(b - text)) + 1;
  const char *e = memchr(b, '\n', len - (size_t)(b - text));
  size_t rl = strlen(repl), n = (size_t)(b - text) + rl + (len - (size_t)(e - text));
  char *o = malloc(n);
  ASSERT(o);
  memcpy(o, text, (size_t)(b - text));
  memcpy(o + (b - text), repl, rl);
  memcpy(o + (b - text) + rl, e, len - (size_t)(e - text));
  *out_len = n;
  return o;
}

/* Asserts that load_buffer refuses data with code and a detail containing substr. */
static void expect_load_error(const void *data, size_t len, int code, const char *substr) {
  fg_tokenizer *t = (fg_tokenizer *)&t; /* not NULL, so that the reset to NULL shows */
  ASSERT_ERR(fg_tokenizer_load_buffer(&t, data, len), code, substr);
  ASSERT(t == NULL);
}

/* BPE ids of text that must succeed and fit MAX_IDS; the count in *n. */
static void bpe_ok(const fg_tokenizer *t, const char *text, int32_t *ids, size_t *n) {
  ASSERT_OK(fg_tokenizer_bpe(t, text, ids, MAX_IDS, n));
  ASSERT(*n <= MAX_IDS);
}

static void assert_ids_eq(const char *what, const char *text, const int32_t *got, size_t ng,
                          const int32_t *want, size_t nw) {
  if (ng == nw && (nw == 0 || memcmp(got, want, nw * sizeof *got) == 0)) return;
  fprintf(stderr, "%s of \"%s\": got %zu ids:", what, text, ng);
  for (size_t i = 0; i < ng && i < 40; i++) fprintf(stderr, " %d", got[i]);
  fprintf(stderr, "\n  expected %zu:", nw);
  for (size_t i = 0; i < nw && i < 40; i++) fprintf(stderr, " %d", want[i]);
  FG_TEST_FAIL("ids differ");
}

/* ---- tests ---------------------------------------------------------------------------- */

static void test_known_ids(void) {
  ASSERT_EQ(fg_tokenizer_vocab_size(tok), 49408);
  int32_t ids[CONTEXT];
  int n;
  const int32_t fox[] = {49406, 320, 1125, 539, 320, 3240, 49407};
  const int32_t dog[] = {49406, 320, 1929, 49407};
  ASSERT_OK(fg_tokenizer_encode(tok, "a photo of a fox", CONTEXT, 0, ids, &n));
  assert_ids_eq("encode", "a photo of a fox", ids, (size_t)n, fox, 7);
  for (int i = n; i < CONTEXT; i++) ASSERT_EQ(ids[i], 0);
  ASSERT_OK(fg_tokenizer_encode(tok, "a dog", CONTEXT, 0, ids, &n));
  assert_ids_eq("encode", "a dog", ids, (size_t)n, dog, 4);
}

/* Every golden through bpe, encode (77, with and without truncation) and decode. */
static void check_goldens(const fg_tokenizer *t, int with_decode) {
  int32_t ids[MAX_IDS], enc[CONTEXT];
  for (size_t k = 0; k < n_goldens; k++) {
    const golden *g = &goldens[k];
    size_t n;
    bpe_ok(t, g->text, ids, &n);
    assert_ids_eq("bpe", g->text, ids, n, g->bpe, g->n_bpe);

    int nt = -1;
    ASSERT_OK(fg_tokenizer_encode(t, g->text, CONTEXT, 1, enc, &nt));
    assert_ids_eq("encode(truncate)", g->text, enc, (size_t)nt, g->tok77, g->n_tok77);
    for (int i = nt; i < CONTEXT; i++) ASSERT_EQ(enc[i], 0);
    int rc = fg_tokenizer_encode(t, g->text, CONTEXT, 0, enc, &nt);
    if (g->fits) {
      ASSERT_OK(rc);
      assert_ids_eq("encode", g->text, enc, (size_t)nt, g->tok77, g->n_tok77);
    } else {
      char want[96];
      snprintf(want, sizeof want, "is %zu tokens, the limit is 75", g->n_bpe);
      ASSERT_EQ(rc, FG_ERANGE);
      ASSERT_STRCONTAINS(fg_error_detail(), want);
      ASSERT_EQ(nt, 0);
      for (int i = 0; i < CONTEXT; i++) ASSERT_EQ(enc[i], 0);
    }
    if (!with_decode) continue;
    char *dec = fg_tokenizer_decode(t, g->bpe, g->n_bpe);
    ASSERT_STREQ(dec, g->decoded);
    if (g->round_trip) {
      bpe_ok(t, dec, ids, &n);
      assert_ids_eq("bpe of the decoded text", dec, ids, n, g->bpe, g->n_bpe);
    }
    free(dec);
  }
}

static void test_goldens(void) {
  check_goldens(tok, 1);
  size_t too_long = 0, rt = 0;
  for (size_t k = 0; k < n_goldens; k++) {
    too_long += !goldens[k].fits;
    rt += (size_t)goldens[k].round_trip;
  }
  ASSERT(too_long >= 2); /* the long inputs really are checked as errors */
  ASSERT(rt >= 60);
  printf("tokenizer: %zu golden strings match (%zu too long for 77, %zu round trips)\n",
         n_goldens, too_long, rt);
}

static void test_encode_edges(void) {
  int32_t ids[CONTEXT + 1];
  int n = -1;
  ids[5] = 12345; /* beyond the context: must stay */
  ASSERT_ERR(fg_tokenizer_encode(tok, "a photo of a fox", 5, 0, ids, &n), FG_ERANGE,
             "is 5 tokens, the limit is 3");
  ASSERT_OK(fg_tokenizer_encode(tok, "a photo of a fox", 5, 1, ids, &n));
  const int32_t cut[] = {49406, 320, 1125, 539, 49407};
  assert_ids_eq("encode(5, truncate)", "a photo of a fox", ids, (size_t)n, cut, 5);
  ASSERT_EQ(ids[5], 12345);
  ASSERT_OK(fg_tokenizer_encode(tok, "", 2, 0, ids, &n));
  ASSERT_EQ(n, 2);
  ASSERT_EQ(ids[0], FG_TOKEN_SOT);
  ASSERT_EQ(ids[1], FG_TOKEN_EOT);
  ASSERT_ERR(fg_tokenizer_encode(tok, "a", 1, 1, ids, &n), FG_EINVAL, "at least 2");
  ASSERT_ERR(fg_tokenizer_encode(NULL, "a", CONTEXT, 0, ids, &n), FG_EINVAL, "");
  ASSERT_ERR(fg_tokenizer_encode(tok, NULL, CONTEXT, 0, ids, &n), FG_EINVAL, "");

  /* bpe writes at most max ids but counts them all */
  const golden *g = NULL;
  for (size_t k = 0; k < n_goldens; k++)
    if (!goldens[k].fits) g = &goldens[k];
  ASSERT(g && g->n_bpe > 10);
  int32_t few[11];
  size_t total;
  few[10] = -7;
  ASSERT_OK(fg_tokenizer_bpe(tok, g->text, few, 10, &total));
  ASSERT_EQ(total, g->n_bpe);
  assert_ids_eq("bpe(max 10)", g->text, few, 10, g->bpe, 10);
  ASSERT_EQ(few[10], -7);
  ASSERT_OK(fg_tokenizer_bpe(tok, g->text, NULL, 0, &total));
  ASSERT_EQ(total, g->n_bpe);
}

static void test_decode(void) {
  const int32_t a[] = {FG_TOKEN_SOT, 320, FG_TOKEN_EOT};
  char *s = fg_tokenizer_decode(tok, a, 3);
  ASSERT_STREQ(s, "a ");
  free(s);
  /* id 127 is the byte 0xc3 alone: not UTF-8, so U+FFFD as Python's errors="replace" */
  const int32_t lone[] = {127, 320};
  s = fg_tokenizer_decode(tok, lone, 2);
  ASSERT_STREQ(s, "\xef\xbf\xbd" "a ");
  free(s);
  s = fg_tokenizer_decode(tok, a, 0);
  ASSERT_STREQ(s, "");
  free(s);
  const int32_t bad[] = {320, 49408};
  ASSERT(fg_tokenizer_decode(tok, bad, 2) == NULL);
  ASSERT_STRCONTAINS(fg_error_detail(), "outside the vocabulary");
  const int32_t neg[] = {-1};
  ASSERT(fg_tokenizer_decode(tok, neg, 1) == NULL);
}

static void test_invalid_utf8(void) {
  static const struct {
    const char *text, *detail;
  } cases[] = {
      {"\x80", "byte 0 (0x80): a continuation byte without a lead byte"},
      {"ab\xbf", "byte 2 (0xbf): a continuation byte"},
      {"caf\xc3", "byte 3 (0xc3): a sequence cut short"},
      {"\xe6\x97x", "byte 0 (0xe6): a sequence cut short"},
      {"\xf0\x9f\xa6", "a sequence cut short"},
      {"a\xc0\xaf", "byte 1 (0xc0): an overlong encoding"},
      {"\xe0\x80\xaf", "byte 0 (0xe0): an overlong encoding"},
      {"\xf0\x80\x80\xaf", "an overlong encoding"},
      {"x \xed\xa0\x80", "byte 2 (0xed): an encoded surrogate"},
      {"\xed\xbf\xbf", "an encoded surrogate"},
      {"\xf4\x90\x80\x80", "a code point beyond U+10FFFF"},
      {"\xff", "a byte that never occurs in UTF-8"},
  };
  int32_t ids[CONTEXT];
  size_t n;
  int nt;
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    ASSERT_ERR(fg_tokenizer_bpe(tok, cases[i].text, ids, CONTEXT, &n), FG_EINVAL,
               cases[i].detail);
    ASSERT_STRCONTAINS(fg_error_detail(), "not valid UTF-8");
    ASSERT_ERR(fg_tokenizer_encode(tok, cases[i].text, CONTEXT, 1, ids, &nt), FG_EINVAL,
               cases[i].detail);
  }
  /* the largest code point and the last before the surrogates are fine */
  ASSERT_OK(fg_tokenizer_bpe(tok, "\xf4\x8f\xbf\xbf \xed\x9f\xbf", ids, CONTEXT, &n));
}

static void test_hugging_face_file(void) {
  /* "#version: 0.2" + the merge lines, with a final newline, without, and with CRLF */
  char *path;
  write_file("merges.txt", hf, hf_len, &path);
  fg_tokenizer *t;
  ASSERT_OK(fg_tokenizer_load(&t, path));
  check_goldens(t, 1);
  fg_tokenizer_free(t);
  free(path);

  ASSERT_OK(fg_tokenizer_load_buffer(&t, hf, hf_len - 1));
  check_goldens(t, 0);
  fg_tokenizer_free(t);

  char *crlf = malloc(2 * hf_len);
  size_t cl = 0;
  for (size_t i = 0; i < hf_len; i++) {
    if (hf[i] == '\n') crlf[cl++] = '\r';
    crlf[cl++] = hf[i];
  }
  ASSERT_OK(fg_tokenizer_load_buffer(&t, crlf, cl));
  check_goldens(t, 0);
  fg_tokenizer_free(t);
  free(crlf);

  /* the gzip from memory, and a gzip of the merges.txt */
  ASSERT_OK(fg_tokenizer_load_buffer(&t, gz, gz_len));
  check_goldens(t, 0);
  fg_tokenizer_free(t);
  size_t zl;
  unsigned char *z = gzip_bytes(hf, hf_len, &zl);
  ASSERT_OK(fg_tokenizer_load_buffer(&t, z, zl));
  check_goldens(t, 0);
  fg_tokenizer_free(t);
  free(z);
}

static void test_malformed_files(void) {
  fg_tokenizer *t = (fg_tokenizer *)&t;
  char *path;

  ASSERT_ERR(fg_tokenizer_load(&t, "/nonexistent-folder/bpe_simple_vocab_16e6.txt.gz"),
             FG_ENOENT, "cannot open");
  ASSERT(t == NULL);
  ASSERT_ERR(fg_tokenizer_load(&t, tmpdir), FG_EIO, "not a regular file");
  write_file("empty.txt", "", 0, &path);
  ASSERT_ERR(fg_tokenizer_load(&t, path), FG_EFORMAT, "empty");
  ASSERT_STRCONTAINS(fg_error_detail(), path); /* the file is named */
  free(path);
  ASSERT_ERR(fg_tokenizer_load(NULL, "x"), FG_EINVAL, "");
  ASSERT_ERR(fg_tokenizer_load(&t, NULL), FG_EINVAL, "");
  expect_load_error(NULL, 0, FG_EFORMAT, "empty");

  /* gzip cut short: in the header, in the data, before and inside the trailer */
  const size_t cuts[] = {2, 9, 20, 1000, 300000, gz_len / 2, gz_len - 8, gz_len - 1};
  for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; i++)
    expect_load_error(gz, cuts[i], FG_EFORMAT, "gzip merges file is truncated");
  expect_load_error(gz, 1, FG_EFORMAT, "neither gzip");

  /* corrupt gzip: a reserved block type, a wrong CRC, an unknown method, trailing junk */
  const unsigned char reserved[] = {0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3, 0x07, 0x55, 0x55};
  expect_load_error(reserved, sizeof reserved, FG_EFORMAT, "gzip merges file is corrupt");
  char *bad = malloc(gz_len + 8);
  memcpy(bad, gz, gz_len);
  bad[gz_len - 6] ^= 0x40;
  expect_load_error(bad, gz_len, FG_EFORMAT, "incorrect data check");
  memcpy(bad, gz, gz_len);
  bad[2] = 7;
  expect_load_error(bad, gz_len, FG_EFORMAT, "gzip merges file is corrupt");
  memcpy(bad, gz, gz_len);
  memcpy(bad + gz_len, "garbage!", 8);
  expect_load_error(bad, gz_len + 8, FG_EFORMAT, "trailing garbage");
  free(bad);

  /* binary junk: as it is, and as a valid gzip of it */
  unsigned char junk[4096];
  uint32_t x = 12345;
  for (size_t i = 0; i < sizeof junk; i++) {
    x = x * 1103515245u + 12345u;
    junk[i] = (unsigned char)(x >> 24);
  }
  expect_load_error(junk, sizeof junk, FG_EFORMAT,
                    "neither gzip (magic 1f 8b) nor a merges.txt");
  size_t zl;
  unsigned char *z = gzip_bytes(junk, sizeof junk, &zl);
  expect_load_error(z, zl, FG_EFORMAT, "CLIP needs 48894");
  free(z);

  /* a gzip bomb: 17 MB of zeros */
  char *zeros = calloc(17u << 20, 1);
  z = gzip_bytes(zeros, 17u << 20, &zl);
  expect_load_error(z, zl, FG_EFORMAT, "unpacks to more than 16 MB");
  free(z);
  free(zeros);

  /* too few merges */
  const char few[] = "#version: 0.2\ni n\nt h\n";
  expect_load_error(few, strlen(few), FG_EFORMAT, "has 2 merges, CLIP needs 48894");
  expect_load_error("#version: 0.2", 13, FG_EFORMAT, "has 0 merges");
  const char *last = hf + hf_len - 1;
  while (last[-1] != '\n') last--; /* the start of the last merge line */
  expect_load_error(hf, (size_t)(last - hf), FG_EFORMAT, "has 48893 merges, CLIP needs 48894");
  z = gzip_bytes(hf, (size_t)(last - hf), &zl);
  expect_load_error(z, zl, FG_EFORMAT, "has 48893 merges");
  free(z);

  /* malformed lines, each named by its number */
  static const struct {
    int line;
    const char *repl, *detail;
  } lines[] = {
      {5, "in", "line 5 of the merges file is not two symbols separated by one space"},
      {7, "a b c", "line 7 of the merges file is not two symbols"},
      {9, "a  b", "line 9 of"},
      {11, " ab", "line 11 of"},
      {13, "ab ", "line 13 of"},
      {15, "", "line 15 of"},
      {48895, "x", "line 48895 of"},
      {3, "zzzq x", "line 3 of the merges file: \"zzzq\" is no symbol of the vocabulary"},
      {2, "in g", "line 2 of the merges file: \"in\" is no symbol"}, /* made by line 2 itself */
      {4, "a \xff", "line 4 of the merges file: \"\xff\" is no symbol"},
      {6, "a </w>", "line 6 of the merges file: \"</w>\" is no symbol"},
  };
  for (size_t i = 0; i < sizeof lines / sizeof lines[0]; i++) {
    size_t ml;
    char *m = replace_line(hf, hf_len, lines[i].line, lines[i].repl, &ml);
    expect_load_error(m, ml, FG_EFORMAT, lines[i].detail);
    free(m);
  }
}

/* ---- threads -------------------------------------------------------------------------- */

typedef struct worker {
  int rounds, failures;
} worker;

static void *worker_run(void *arg) {
  worker *w = arg;
  int32_t ids[MAX_IDS], enc[CONTEXT];
  for (int r = 0; r < w->rounds; r++) {
    for (size_t k = 0; k < n_goldens; k++) {
      const golden *g = &goldens[k];
      size_t n;
      int nt;
      if (fg_tokenizer_bpe(tok, g->text, ids, MAX_IDS, &n) != 0 || n != g->n_bpe ||
          (n && memcmp(ids, g->bpe, n * sizeof *ids) != 0))
        w->failures++;
      if (fg_tokenizer_encode(tok, g->text, CONTEXT, 1, enc, &nt) != 0 ||
          (size_t)nt != g->n_tok77 || memcmp(enc, g->tok77, g->n_tok77 * sizeof *enc) != 0)
        w->failures++;
    }
  }
  return NULL;
}

static void test_threads(void) {
  worker w[2] = {{20, 0}, {20, 0}};
  pthread_t th[2];
  for (int i = 0; i < 2; i++) ASSERT_EQ(pthread_create(&th[i], NULL, worker_run, &w[i]), 0);
  for (int i = 0; i < 2; i++) ASSERT_EQ(pthread_join(th[i], NULL), 0);
  ASSERT_EQ(w[0].failures, 0);
  ASSERT_EQ(w[1].failures, 0);
}

/* ---- timing (printed, not asserted) --------------------------------------------------- */

static void print_timing(const char *gz_path) {
  double best = 1e9;
  for (int i = 0; i < 3; i++) {
    fg_tokenizer *t;
    double t0 = now_s();
    ASSERT_OK(fg_tokenizer_load(&t, gz_path));
    double dt = now_s() - t0;
    best = dt < best ? dt : best;
    fg_tokenizer_free(t);
  }
  const char *sentence = "a photo of a red mug on the wooden table next to a screwdriver";
  int32_t ids[CONTEXT];
  const int reps = 20000;
  double t0 = now_s();
  for (int i = 0; i < reps; i++)
    ASSERT_OK(fg_tokenizer_encode(tok, sentence, CONTEXT, 0, ids, NULL));
  double per = (now_s() - t0) / reps;
  printf("tokenizer: load %.1f ms (best of 3), encode of a %zu-byte sentence %.2f us\n",
         1e3 * best, strlen(sentence), 1e6 * per);
}

int main(void) {
  const char *shared = getenv("FG_SHARED_DATA");
  if (!shared) FG_TEST_FAIL("FG_SHARED_DATA is not set (run through meson test)");
  char *gz_path = fg_path_join(shared, "clip/bpe_simple_vocab_16e6.txt.gz");
  ASSERT(mkdtemp(tmpdir));
  ASSERT_OK(fg_read_file(gz_path, 1 << 26, &gz, &gz_len));

  /* The Hugging Face merges.txt: the header replaced, lines 2 .. 48895, a final newline. */
  gzFile f = gzopen(gz_path, "rb");
  ASSERT(f);
  size_t cap = 8u << 20, got = 0;
  char *all = malloc(cap);
  int r;
  while ((r = gzread(f, all + got, (unsigned)(cap - got))) > 0) got += (size_t)r;
  ASSERT(r == 0 && got < cap);
  gzclose(f);
  const char *p = memchr(all, '\n', got) + 1, *e = p;
  for (int i = 0; i < 48894; i++) e = (const char *)memchr(e, '\n', got - (size_t)(e - all)) + 1;
  const char head[] = "#version: 0.2\n";
  hf_len = strlen(head) + (size_t)(e - p);
  hf = malloc(hf_len);
  memcpy(hf, head, strlen(head));
  memcpy(hf + strlen(head), p, (size_t)(e - p));
  free(all);

  ASSERT_OK(fg_tokenizer_load(&tok, gz_path));
  load_goldens();
  test_known_ids();
  test_goldens();
  test_encode_edges();
  test_decode();
  test_invalid_utf8();
  test_hugging_face_file();
  test_malformed_files();
  test_threads();
  print_timing(gz_path);

  fg_tokenizer_free(tok);
  for (size_t k = 0; k < n_goldens; k++) free(goldens[k].text), free(goldens[k].decoded);
  free(hf);
  free(gz);
  free(gz_path);
  fg_rmtree(tmpdir);
  printf("tokenizer: ok\n");
  return 0;
}

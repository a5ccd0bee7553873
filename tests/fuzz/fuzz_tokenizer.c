/* Fuzz target for the CLIP tokenizer. The first byte of the input picks what the rest is:
 *   even: a merges file for fg_tokenizer_load_buffer, which must fail cleanly (NULL handle, a
 *         detail) or yield a tokenizer with the full vocabulary;
 *   odd:  text for the real tokenizer ($FG_SHARED_DATA/clip/bpe_simple_vocab_16e6.txt.gz,
 *         loaded once), through fg_tokenizer_bpe, fg_tokenizer_encode with and without
 *         truncation and fg_tokenizer_decode, whose results must agree with each other:
 *         ids inside the vocabulary, the same count from bpe and encode, start and end tokens
 *         in place, zero padding, and invalid UTF-8 refused by every entry point alike.
 * Without FG_SHARED_DATA odd inputs are parsed as merges files as well.
 *
 * Built with tests/fuzz/fuzz_main.c by meson (suite 'fuzz'); with clang it also links as a
 * real libFuzzer binary against the library. */
#include "clip/tokenizer.h"
#include "core/error.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CONTEXT 77

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The real tokenizer, loaded on first use and kept for the process; NULL when unavailable. */
static fg_tokenizer *real_tokenizer(void) {
  static fg_tokenizer *tok;
  static int tried;
  if (!tried) {
    tried = 1;
    const char *shared = getenv("FG_SHARED_DATA");
    if (shared) {
      char path[4096];
      snprintf(path, sizeof path, "%s/clip/bpe_simple_vocab_16e6.txt.gz", shared);
      if (fg_tokenizer_load(&tok, path) != 0) abort(); /* the shared file must load */
    }
  }
  return tok;
}

static void fuzz_merges(const uint8_t *data, size_t size) {
  fg_tokenizer *t = NULL;
  if (fg_tokenizer_load_buffer(&t, data, size) != 0) {
    if (t || !fg_error_detail()[0]) abort();
    return;
  }
  if (fg_tokenizer_vocab_size(t) != 49408) abort();
  fg_tokenizer_free(t);
}

static void fuzz_text(const fg_tokenizer *tok, const uint8_t *data, size_t size) {
  char *text = malloc(size + 1);
  if (!text) return;
  memcpy(text, data, size);
  text[size] = '\0'; /* an embedded NUL ends the text early, as for any C string */
  size_t n = 0, n2 = 0;
  int rc = fg_tokenizer_bpe(tok, text, NULL, 0, &n);
  int32_t enc[CONTEXT];
  int nt = -1;
  int rc_enc = fg_tokenizer_encode(tok, text, CONTEXT, 1, enc, &nt);
  if ((rc == 0) != (rc_enc == 0)) abort();
  if (rc != 0) {
    if (rc != FG_EINVAL || nt != 0) abort();
    for (int i = 0; i < CONTEXT; i++)
      if (enc[i] != 0) abort();
    free(text);
    return;
  }
  int32_t *ids = malloc((n ? n : 1) * sizeof *ids);
  if (!ids) abort();
  if (fg_tokenizer_bpe(tok, text, ids, n, &n2) != 0 || n2 != n) abort();
  for (size_t i = 0; i < n; i++)
    if (ids[i] < 0 || ids[i] >= 49408) abort();
  size_t kept = n < CONTEXT - 2 ? n : CONTEXT - 2;
  if (nt != (int)kept + 2 || enc[0] != FG_TOKEN_SOT || enc[kept + 1] != FG_TOKEN_EOT) abort();
  if (kept && memcmp(enc + 1, ids, kept * sizeof *ids) != 0) abort();
  for (int i = nt; i < CONTEXT; i++)
    if (enc[i] != 0) abort();
  rc = fg_tokenizer_encode(tok, text, CONTEXT, 0, enc, &nt);
  if (n > CONTEXT - 2 ? rc != FG_ERANGE : rc != 0) abort();
  char *dec = fg_tokenizer_decode(tok, ids, n);
  if (!dec) abort();
  size_t m;
  if (fg_tokenizer_bpe(tok, dec, NULL, 0, &m) != 0) abort(); /* decode yields valid UTF-8 */
  free(dec);
  free(ids);
  free(text);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  if (size == 0) return 0;
  const fg_tokenizer *tok = (data[0] & 1) ? real_tokenizer() : NULL;
  if (tok)
    fuzz_text(tok, data + 1, size - 1);
  else
    fuzz_merges(data + 1, size - 1);
  return 0;
}

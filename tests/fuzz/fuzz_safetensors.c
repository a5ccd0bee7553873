/* Fuzz target for the safetensors reader: any input either fails to parse or yields tensors
 * whose views lie inside the input, agree with their own shapes, are found by name, and
 * convert without touching anything else.
 *
 * Built with tests/fuzz/fuzz_main.c by meson (suite 'fuzz'). It has no main of its own, so
 * with clang it also links as a real libFuzzer binary, e.g. from the source root:
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined -D_GNU_SOURCE -Ilib \
 *     tests/fuzz/fuzz_safetensors.c lib/io/safetensors.c lib/core/error.c lib/core/half.c \
 *     -ljansson -o fuzz_safetensors
 *   ./fuzz_safetensors -max_len=65536 tests/fuzz/corpus/safetensors */
#include "core/error.h"
#include "io/safetensors.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Element sizes by dtype, FG_ST_OTHER excluded (its size depends on the spelling). */
static size_t elem_size(fg_st_dtype d) {
  switch (d) {
  case FG_ST_F32: case FG_ST_I32: return 4;
  case FG_ST_F16: case FG_ST_BF16: case FG_ST_I16: return 2;
  case FG_ST_F64: case FG_ST_I64: return 8;
  case FG_ST_I8: case FG_ST_U8: case FG_ST_BOOL: return 1;
  default: return 0;
  }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fg_st *st = NULL;
  if (fg_st_parse(&st, data, size) != 0) {
    if (st) abort(); /* a failed parse leaves *out NULL */
    return 0;
  }
  int n = fg_st_count(st);
  size_t covered = 0;
  for (int i = 0; i < n; i++) {
    fg_st_tensor t, u;
    if (fg_st_tensor_at(st, i, &t) != 0) abort();
    const uint8_t *p = t.data;
    if (p < data || p > data + size || t.nbytes > (size_t)(data + size - p)) abort();
    if (t.ndim < 0 || t.ndim > FG_ST_MAX_DIMS || !t.name || !t.name[0]) abort();
    size_t count = 1;
    for (int k = 0; k < t.ndim; k++) {
      if (t.shape[k] < 0) abort();
      count *= (size_t)t.shape[k]; /* cannot wrap: the parser proved count * size fits */
    }
    if (count != t.count) abort();
    size_t es = elem_size(t.dtype);
    if (es && t.nbytes != count * es) abort();
    covered += t.nbytes;
    if (fg_st_find(st, t.name, &u) != 0 || u.data != t.data || strcmp(u.name, t.name) != 0)
      abort();

    if (t.dtype == FG_ST_F32 || t.dtype == FG_ST_F16 || t.dtype == FG_ST_BF16) {
      float *dst = malloc(t.count ? t.count * sizeof *dst : 1);
      if (!dst) abort();
      if (fg_st_read_f32(&t, dst, t.count) != 0) abort();
      if (t.count && fg_st_read_f32(&t, dst, t.count - 1) != FG_EINVAL) abort();
      if (t.ndim == 2 && t.shape[0] > 0) {
        size_t rows = (size_t)t.shape[0];
        if (fg_st_read_rows_f32(&t, rows - 1, 1, dst) != 0) abort();
        if (fg_st_read_rows_f32(&t, rows, 1, dst) != FG_EINVAL) abort();
      }
      free(dst);
    } else {
      float f;
      if (fg_st_read_f32(&t, &f, t.count) != FG_EFORMAT) abort();
    }
  }
  /* the tensors tile the data section: everything after the header, to the end */
  uint64_t hlen = 0;
  for (int k = 7; k >= 0; k--) hlen = hlen << 8 | data[k];
  if (covered != size - 8 - hlen) abort();
  fg_st_tensor none;
  if (fg_st_find(st, "\x01 not a tensor", &none) != FG_ENOENT) abort();
  (void)fg_st_metadata(st, "format");
  fg_st_close(st);
  return 0;
}

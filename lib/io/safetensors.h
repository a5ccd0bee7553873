/* safetensors files (https://huggingface.co/docs/safetensors): an 8-byte little-endian
 * header length N, N bytes of JSON {"name": {"dtype", "shape", "data_offsets": [b, e]},
 * ..., "__metadata__": {"key": "value"}}, then the data section; offsets are relative to
 * the start of the data section.
 *
 * The file is memory-mapped read-only and never copied. Every header field is validated
 * before any tensor is handed out: the header length against the file size and a 100 MB
 * limit, JSON syntax (no duplicate keys), known dtypes, shapes (at most FG_ST_MAX_DIMS
 * non-negative dimensions, no size overflow), byte sizes equal to product(shape) * element
 * size, offsets inside the data section, tensors that do not overlap and that cover the data
 * section, and string-valued metadata. A bad file is FG_EFORMAT with a detail that names the
 * file and the tensor; nothing reads outside the mapping. */
#ifndef FG_IO_SAFETENSORS_H
#define FG_IO_SAFETENSORS_H

#include <stddef.h>
#include <stdint.h>

#define FG_ST_MAX_DIMS 8
#define FG_ST_MAX_HEADER ((size_t)100 << 20)

typedef enum {
  FG_ST_F32 = 0,
  FG_ST_F16,
  FG_ST_BF16,
  FG_ST_F64,
  FG_ST_I64,
  FG_ST_I32,
  FG_ST_I16,
  FG_ST_I8,
  FG_ST_U8,
  FG_ST_BOOL,
  FG_ST_OTHER, /* a dtype this reader knows the size of but does not convert (U16, F8_*, ...) */
} fg_st_dtype;

typedef struct fg_st fg_st;

/* A view of one tensor; name and data point into the fg_st and live as long as it. */
typedef struct fg_st_tensor {
  const char *name;
  fg_st_dtype dtype;
  int ndim;
  int64_t shape[FG_ST_MAX_DIMS];
  size_t count;     /* product of shape */
  const void *data; /* little-endian elements, C order; not necessarily aligned */
  size_t nbytes;    /* count * element size */
} fg_st_tensor;

/* Maps and validates the file at path. On success the caller owns *out (fg_st_close);
 * on failure *out is NULL. FG_ENOENT / FG_EIO for an unreadable file, FG_EFORMAT for bad
 * content. */
int fg_st_open(fg_st **out, const char *path);

/* Validates an in-memory file of len bytes (what fg_st_open does after mapping; the fuzz
 * target's entry point). buf is borrowed: it must outlive *out, which the caller frees with
 * fg_st_close. */
int fg_st_parse(fg_st **out, const void *buf, size_t len);

/* Unmaps (for fg_st_open) and frees; NULL is a no-op. */
void fg_st_close(fg_st *st);

/* Number of tensors, and the i-th in header order (0 <= i < count). */
int fg_st_count(const fg_st *st);
int fg_st_tensor_at(const fg_st *st, int i, fg_st_tensor *out);

/* Looks a tensor up by name. FG_ENOENT (detail: "no tensor NAME in FILE") if absent. */
int fg_st_find(const fg_st *st, const char *name, fg_st_tensor *out);

/* The value of a __metadata__ key, or NULL; owned by st. */
const char *fg_st_metadata(const fg_st *st, const char *key);

/* Converts count elements of an F32, F16 or BF16 tensor to float32 into dst (caller-owned,
 * count floats). count must equal t->count (FG_EINVAL otherwise); other dtypes are
 * FG_EFORMAT naming the tensor and its dtype. */
int fg_st_read_f32(const fg_st_tensor *t, float *dst, size_t count);

/* Same for rows [row0, row0 + nrows) of a 2-D tensor [rows][cols]: dst holds nrows * cols
 * floats. */
int fg_st_read_rows_f32(const fg_st_tensor *t, size_t row0, size_t nrows, float *dst);

/* The whole file as mapped (or the buffer given to fg_st_parse): *base and *len stay valid
 * until fg_st_close. */
void fg_st_bytes(const fg_st *st, const void **base, size_t *len);

/* The name of a dtype as the file spells it ("F32", "BF16", ...). */
const char *fg_st_dtype_name(fg_st_dtype d);

#endif

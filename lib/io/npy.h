/* NumPy .npy files (format 1.0, 2.0 and 3.0 headers), little-endian float32 or float16,
 * C order. */
#ifndef FG_IO_NPY_H
#define FG_IO_NPY_H

#include <stddef.h>
#include <stdint.h>

typedef enum {
  FG_DTYPE_NONE = 0,
  FG_DTYPE_F32 = 1, /* "<f4" */
  FG_DTYPE_F16 = 2, /* "<f2" */
} fg_dtype;

#define FG_NPY_MAX_DIMS 8

typedef struct fg_npy {
  fg_dtype dtype;
  int ndim;
  size_t shape[FG_NPY_MAX_DIMS];
  size_t count;     /* product of shape */
  const void *data; /* points into the parsed buffer; count * element size bytes */
} fg_npy;

/* Bytes per element of a dtype (4, 2, or 0 for FG_DTYPE_NONE). */
size_t fg_dtype_size(fg_dtype t);

/* Parses an in-memory .npy without copying: out->data points into buf, which must outlive it.
 * Refuses (FG_EFORMAT, with a detail) a bad magic, an unknown version, a header that is not a
 * Python dict literal with 'descr', 'fortran_order' and 'shape', big-endian or other dtypes,
 * fortran_order True, more than FG_NPY_MAX_DIMS dimensions, a size overflow, and a data
 * section shorter or longer than the shape says. */
int fg_npy_parse(const void *buf, size_t len, fg_npy *out);

/* Encodes a C-order array as a version 1.0 .npy into a malloc'd buffer the caller owns.
 * dtype is FG_DTYPE_F32 or FG_DTYPE_F16; data holds product(shape) elements. */
int fg_npy_encode(fg_dtype dtype, int ndim, const size_t *shape, const void *data, uint8_t **out,
                  size_t *out_len);

#endif

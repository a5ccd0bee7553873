/* Checkpoints: a trained field on disk (".fgc"), loaded at start-up so that a trained scene
 * answers after a restart without retraining.
 *
 * The layout (little-endian) is documented in checkpoint.c: a fixed header with a magic, a
 * version, the field's configuration and the size of every section; the sections (parameter
 * groups in model.h's order, hash tables in float32 or float16, then the occupancy grid's
 * bits and its densities in float16); and a zlib crc32 of everything before it. A reader
 * refuses a wrong magic, an unknown version, a configuration that fg_field_config_check
 * refuses, sizes that disagree with the configuration or the file's length, non-finite
 * parameters, and a CRC mismatch, each with a detail that says which.
 *
 * Saving is atomic (temp file, fsync, rename; fsutil.h): a crash leaves the old file or the
 * new one. The bytes depend only on the field, so equal fields give equal files. */
#ifndef FG_FIELD_CHECKPOINT_H
#define FG_FIELD_CHECKPOINT_H

#include "field/model.h"

#define FG_CHECKPOINT_VERSION 1

/* Writes f to path (f is only read). half_tables = 1 stores the hash tables in float16 (half
 * the size; the loaded field then differs from f by the rounding of those tables, values
 * beyond +-65504 saturated). 0, FG_EIO, FG_ENOMEM, or FG_EINVAL for a NULL argument,
 * half_tables not 0 or 1, negative trained_steps, or a non-finite parameter (a file the loader
 * would refuse is not written: an existing one at path stays). */
int fg_checkpoint_save(const fg_field *f, const char *path, int half_tables);

/* Reads a field; on success the caller owns *out (fg_field_free), on failure *out is NULL.
 * FG_ENOENT (no file), FG_EIO (unreadable, not a regular file), FG_EFORMAT (with the detail
 * above), FG_ENOMEM. A field saved with half_tables = 0 loads bit-identical: parameters,
 * configuration, trained_steps, and the occupancy bits, threshold and mean (so it marches the
 * same samples); the occupancy densities come back rounded to float16. */
int fg_checkpoint_load(const char *path, fg_field **out);

#endif

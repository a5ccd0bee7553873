/* PLY writer and reader for the one layout of ply.h.
 *
 * Values are written and read byte by byte in little-endian order, so the files are the same
 * on any host. The reader accepts the header spellings other writers use for the same layout
 * (float32 for float, uint8 for uchar, int32/uint/uint32 for int, vertex_index for
 * vertex_indices, CRLF line ends, obj_info lines) so that a file round-tripped through a mesh
 * tool still reads. */
#include "io/ply.h"

#include "core/error.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- bytes -------------------------------------------------------------------------- */

static void put_u32_le(uint8_t *p, uint32_t u) {
  p[0] = (uint8_t)u;
  p[1] = (uint8_t)(u >> 8);
  p[2] = (uint8_t)(u >> 16);
  p[3] = (uint8_t)(u >> 24);
}

static uint32_t get_u32_le(const uint8_t *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static void put_f32_le(uint8_t *p, float v) {
  uint32_t u;
  memcpy(&u, &v, sizeof u);
  put_u32_le(p, u);
}

static float get_f32_le(const uint8_t *p) {
  uint32_t u = get_u32_le(p);
  float v;
  memcpy(&v, &u, sizeof v);
  return v;
}

#define FACE_BYTES 13 /* uchar 3, three int32 */

/* ---- writer ------------------------------------------------------------------------- */

int fg_ply_encode(const fg_ply *p, const char *comment, uint8_t **out, size_t *out_len) {
  if (!p || !out || !out_len) return fg_fail(FG_EINVAL, "ply: NULL argument");
  *out = NULL;
  *out_len = 0;
  if (p->n_vertices > FG_PLY_MAX_ELEMENTS || p->n_faces > FG_PLY_MAX_ELEMENTS)
    return fg_fail(FG_EINVAL, "ply: %zu vertices and %zu faces; at most %zu of each fit int32 "
                   "indices", p->n_vertices, p->n_faces, FG_PLY_MAX_ELEMENTS);
  if (p->n_vertices > 0 && !p->xyz) return fg_fail(FG_EINVAL, "ply: vertices without xyz");
  if (p->n_faces > 0 && (!p->faces || !p->has_faces))
    return fg_fail(FG_EINVAL, "ply: faces need the faces array and has_faces");
  for (size_t f = 0; f < 3 * p->n_faces; f++)
    if (p->faces[f] >= p->n_vertices)
      return fg_fail(FG_EINVAL, "ply: face %zu names vertex %u of %zu", f / 3,
                     (unsigned)p->faces[f], p->n_vertices);

  char header[1024];
  size_t hl = 0;
#define HEADER_ADD(...) \
  hl += (size_t)snprintf(header + (hl < sizeof header ? hl : 0),                             \
                        hl < sizeof header ? sizeof header - hl : 0, __VA_ARGS__)
  HEADER_ADD("ply\nformat binary_little_endian 1.0\n");
  if (comment) {
    const char *nl = strchr(comment, '\n');
    size_t k = nl ? (size_t)(nl - comment) : strlen(comment);
    HEADER_ADD("comment %.*s\n", k > 400 ? 400 : (int)k, comment);
  }
  HEADER_ADD("element vertex %zu\nproperty float x\nproperty float y\nproperty float z\n",
             p->n_vertices);
  if (p->rgb) HEADER_ADD("property uchar red\nproperty uchar green\nproperty uchar blue\n");
  if (p->has_faces)
    HEADER_ADD("element face %zu\nproperty list uchar int vertex_indices\n", p->n_faces);
  HEADER_ADD("end_header\n");
#undef HEADER_ADD
  if (hl >= sizeof header) return fg_fail(FG_EINVAL, "ply: header too long");
  const size_t vb = p->rgb ? 15 : 12;
  const size_t len = hl + p->n_vertices * vb + p->n_faces * FACE_BYTES;
  uint8_t *buf = malloc(len);
  if (!buf)
    return fg_fail(FG_ENOMEM, "ply: out of memory for %zu vertices and %zu faces",
                   p->n_vertices, p->n_faces);
  memcpy(buf, header, hl);
  uint8_t *q = buf + hl;
  for (size_t i = 0; i < p->n_vertices; i++, q += vb) {
    for (int k = 0; k < 3; k++) put_f32_le(q + 4 * k, p->xyz[3 * i + k]);
    if (p->rgb) memcpy(q + 12, p->rgb + 3 * i, 3);
  }
  for (size_t f = 0; f < p->n_faces; f++, q += FACE_BYTES) {
    q[0] = 3;
    for (int k = 0; k < 3; k++) put_u32_le(q + 1 + 4 * k, p->faces[3 * f + k]);
  }
  *out = buf;
  *out_len = len;
  return 0;
}

/* ---- reader ------------------------------------------------------------------------- */

void fg_ply_release(fg_ply *p) {
  if (!p) return;
  free(p->xyz);
  free(p->rgb);
  free(p->faces);
  memset(p, 0, sizeof *p);
}

/* A header line split into at most 8 space-separated words (in place). */
typedef struct words {
  char *w[8];
  int n;
} words;

static void split(char *line, words *ws) {
  char *save = NULL;
  ws->n = 0;
  for (char *s = strtok_r(line, " \t", &save); s && ws->n < 8; s = strtok_r(NULL, " \t", &save))
    ws->w[ws->n++] = s;
}

static int is_any(const char *s, const char *a, const char *b) {
  return strcmp(s, a) == 0 || (b && strcmp(s, b) == 0);
}

/* The element count of "element <name> <count>"; FG_EFORMAT when it is not a number in range. */
static int parse_count(const char *s, size_t *out) {
  char *end;
  unsigned long long v = strtoull(s, &end, 10);
  if (end == s || *end || s[0] == '-' || v > FG_PLY_MAX_ELEMENTS)
    return fg_fail(FG_EFORMAT, "ply: element count \"%.20s\" is not a number up to %zu", s,
                   FG_PLY_MAX_ELEMENTS);
  *out = (size_t)v;
  return 0;
}

/* Parses the header of buf (len bytes) into the counts, whether colours come, and the header's
 * length. */
static int parse_header(const char *buf, size_t len, size_t *nv, int *rgb, int *has_faces,
                        size_t *nf, size_t *header_len) {
  static const char end_tag[] = "end_header";
  if (len < 4 || memcmp(buf, "ply", 3) != 0 || (buf[3] != '\n' && buf[3] != '\r'))
    return fg_fail(FG_EFORMAT, "not a PLY file: it does not start with \"ply\"");
  /* The header ends at the line "end_header"; copy it out to split it in place. */
  size_t hl = 0;
  for (size_t i = 0; i + sizeof end_tag <= len && i < 65536; i++)
    if ((i == 0 || buf[i - 1] == '\n') && memcmp(buf + i, end_tag, sizeof end_tag - 1) == 0) {
      size_t j = i + sizeof end_tag - 1;
      if (j < len && buf[j] == '\r') j++;
      if (j < len && buf[j] == '\n') {
        hl = j + 1;
        break;
      }
    }
  if (!hl) return fg_fail(FG_EFORMAT, "ply: no \"end_header\" line in the first 64 KB");
  char *h = malloc(hl + 1);
  if (!h) return fg_fail(FG_ENOMEM, "ply: out of memory");
  memcpy(h, buf, hl);
  h[hl] = 0;

  /* Where the header stands: 0 before "element vertex", 1 in it, 2 in "element face". */
  int rc = 0, state = 0, line_no = 0, format_seen = 0, n_xyz = 0, n_rgb = 0, list_seen = 0;
  static const char *const xyz_names[3] = {"x", "y", "z"};
  static const char *const rgb_names[3] = {"red", "green", "blue"};
  char *save = NULL;
  *nv = *nf = 0;
  *has_faces = 0;
  for (char *line = strtok_r(h, "\n", &save); line && rc == 0; line = strtok_r(NULL, "\n", &save)) {
    size_t k = strlen(line);
    if (k && line[k - 1] == '\r') line[--k] = 0;
    if (line_no++ == 0) continue; /* "ply" */
    if (strncmp(line, "comment", 7) == 0 || strncmp(line, "obj_info", 8) == 0) continue;
    words ws;
    split(line, &ws);
    if (ws.n == 0) continue;
    if (strcmp(ws.w[0], "end_header") == 0) break;
    if (strcmp(ws.w[0], "format") == 0) {
      if (ws.n != 3 || strcmp(ws.w[1], "binary_little_endian") != 0 || strcmp(ws.w[2], "1.0") != 0)
        rc = fg_fail(FG_EFORMAT, "ply: only \"format binary_little_endian 1.0\" is read");
      format_seen = 1;
    } else if (!format_seen) {
      rc = fg_fail(FG_EFORMAT, "ply: the \"format\" line must come second");
    } else if (strcmp(ws.w[0], "element") == 0 && ws.n == 3) {
      if (state == 0 && strcmp(ws.w[1], "vertex") == 0) {
        rc = parse_count(ws.w[2], nv);
        state = 1;
      } else if (state == 1 && strcmp(ws.w[1], "face") == 0) {
        rc = parse_count(ws.w[2], nf);
        *has_faces = 1;
        state = 2;
      } else {
        rc = fg_fail(FG_EFORMAT, "ply: element \"%.40s\" where \"vertex\" then \"face\" were "
                     "expected", ws.w[1]);
      }
    } else if (strcmp(ws.w[0], "property") == 0 && state == 1 && ws.n == 3) {
      if (n_xyz < 3 && is_any(ws.w[1], "float", "float32") &&
          strcmp(ws.w[2], xyz_names[n_xyz]) == 0)
        n_xyz++;
      else if (n_xyz == 3 && n_rgb < 3 && is_any(ws.w[1], "uchar", "uint8") &&
               strcmp(ws.w[2], rgb_names[n_rgb]) == 0)
        n_rgb++;
      else
        rc = fg_fail(FG_EFORMAT, "ply: vertex property \"%.20s %.40s\" is not one of float x, "
                     "y, z then uchar red, green, blue", ws.w[1], ws.w[2]);
    } else if (strcmp(ws.w[0], "property") == 0 && state == 2 && ws.n == 5 && !list_seen &&
               strcmp(ws.w[1], "list") == 0 && is_any(ws.w[2], "uchar", "uint8") &&
               (is_any(ws.w[3], "int", "int32") || is_any(ws.w[3], "uint", "uint32")) &&
               is_any(ws.w[4], "vertex_indices", "vertex_index")) {
      list_seen = 1;
    } else {
      rc = fg_fail(FG_EFORMAT, "ply: unsupported header line \"%.60s\"", line);
    }
  }
  if (rc == 0 && !format_seen) rc = fg_fail(FG_EFORMAT, "ply: no \"format\" line");
  if (rc == 0 && state == 0) rc = fg_fail(FG_EFORMAT, "ply: no \"element vertex\"");
  if (rc == 0 && n_xyz != 3) rc = fg_fail(FG_EFORMAT, "ply: vertices need float x, y and z");
  if (rc == 0 && n_rgb != 0 && n_rgb != 3)
    rc = fg_fail(FG_EFORMAT, "ply: colours need all of red, green and blue");
  if (rc == 0 && *has_faces && !list_seen)
    rc = fg_fail(FG_EFORMAT, "ply: faces need \"property list uchar int vertex_indices\"");
  free(h);
  *rgb = n_rgb == 3;
  *header_len = hl;
  return rc;
}

int fg_ply_decode(const void *buf, size_t len, fg_ply *out) {
  if (!out) return fg_fail(FG_EINVAL, "ply: NULL argument");
  memset(out, 0, sizeof *out);
  if (!buf) return fg_fail(FG_EINVAL, "ply: NULL argument");
  size_t nv = 0, nf = 0, hl = 0;
  int rgb = 0, has_faces = 0;
  FG_TRY(parse_header(buf, len, &nv, &rgb, &has_faces, &nf, &hl));
  const size_t vb = rgb ? 15 : 12;
  const size_t body = nv * vb + nf * FACE_BYTES;
  if (len - hl != body)
    return fg_fail(FG_EFORMAT, "ply: the header declares %zu vertices and %zu faces (%zu "
                   "bytes) but %zu bytes follow it", nv, nf, body, len - hl);
  fg_ply p = {.n_vertices = nv, .n_faces = nf, .has_faces = has_faces};
  p.xyz = malloc((nv ? nv : 1) * 3 * sizeof *p.xyz);
  p.rgb = rgb ? malloc((nv ? nv : 1) * 3) : NULL;
  p.faces = nf ? malloc(nf * 3 * sizeof *p.faces) : NULL;
  if (!p.xyz || (rgb && !p.rgb) || (nf && !p.faces)) {
    fg_ply_release(&p);
    return fg_fail(FG_ENOMEM, "ply: out of memory for %zu vertices and %zu faces", nv, nf);
  }
  const uint8_t *q = (const uint8_t *)buf + hl;
  for (size_t i = 0; i < nv; i++, q += vb) {
    for (int k = 0; k < 3; k++) p.xyz[3 * i + k] = get_f32_le(q + 4 * k);
    if (rgb) memcpy(p.rgb + 3 * i, q + 12, 3);
  }
  for (size_t f = 0; f < nf; f++, q += FACE_BYTES) {
    if (q[0] != 3) {
      fg_ply_release(&p);
      return fg_fail(FG_EFORMAT, "ply: face %zu has %u vertices; only triangles are read", f,
                     (unsigned)q[0]);
    }
    for (int k = 0; k < 3; k++) {
      uint32_t v = get_u32_le(q + 1 + 4 * k);
      if (v >= nv) {
        fg_ply_release(&p);
        return fg_fail(FG_EFORMAT, "ply: face %zu names vertex %d of %zu", f, (int32_t)v, nv);
      }
      p.faces[3 * f + k] = v;
    }
  }
  *out = p;
  return 0;
}

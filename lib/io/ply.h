/* PLY files (Turk's Stanford polygon format) of a point cloud or a triangle mesh, in the one
 * layout fieldgrip writes and the mesh tools it hands files to (MeshLab, Open3D, Blender,
 * CloudCompare, trimesh) all read:
 *
 *   ply
 *   format binary_little_endian 1.0
 *   comment ...                                  (any number of lines)
 *   element vertex N
 *   property float x                             (y, z likewise)
 *   property uchar red                           (green, blue likewise; all three or none)
 *   element face M                               (meshes only; absent for a point cloud)
 *   property list uchar int vertex_indices
 *   end_header
 *   N vertices of 12 or 15 bytes, then M faces of 13 bytes: the count 3 and three int32.
 *
 * Coordinates are whatever the caller's frame and unit are (fieldgrip's geometry: world frame,
 * metres). Faces are triangles whose indices count from 0 into the vertex list. */
#ifndef FG_IO_PLY_H
#define FG_IO_PLY_H

#include <stddef.h>
#include <stdint.h>

typedef struct fg_ply {
  size_t n_vertices;
  size_t n_faces;
  float *xyz;      /* (n_vertices, 3) */
  uint8_t *rgb;    /* (n_vertices, 3) sRGB, or NULL: the file has no colour properties */
  uint32_t *faces; /* (n_faces, 3) vertex indices, or NULL when n_faces is 0 */
  int has_faces;   /* 1: the file has a face element (a mesh, even of 0 faces); 0: points */
} fg_ply;

/* Most vertices or faces a file may declare: indices are int32 on disk. */
#define FG_PLY_MAX_ELEMENTS ((size_t)INT32_MAX)

/* Encodes p as above into a malloc'd buffer the caller owns (*out, *out_len); p stays the
 * caller's. comment, when not NULL, becomes one "comment" line (a newline in it ends it
 * there). FG_EINVAL (with a detail) for NULL arrays that the counts need, more than
 * FG_PLY_MAX_ELEMENTS of either element, faces without has_faces, or a face index not below
 * n_vertices; FG_ENOMEM. */
int fg_ply_encode(const fg_ply *p, const char *comment, uint8_t **out, size_t *out_len);

/* Parses a file of the layout above from memory into *out, whose arrays are malloc'd copies
 * the caller owns (fg_ply_release; buf may be freed at once). Other PLY files are refused
 * with FG_EFORMAT and a detail saying what differs: ASCII or big-endian formats, other
 * elements or properties, faces that are not triangles, indices out of range, a body shorter
 * or longer than the header declares. FG_ENOMEM. On failure *out holds nothing. */
int fg_ply_decode(const void *buf, size_t len, fg_ply *out);

/* Frees what a decoded *p owns and zeroes it; accepts a zeroed struct. */
void fg_ply_release(fg_ply *p);

#endif

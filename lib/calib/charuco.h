/* ChArUco calibration boards ([calibration] of SPEC.md): a chessboard of squares_x by
 * squares_y squares of square_m metres with an ArUco marker of marker_m metres, from one of
 * OpenCV's predefined dictionaries, in each white square; what the board looks like, and
 * where its inner corners are found in an image.
 *
 * The board frame is OpenCV's for the same board: metres, the chessboard's inner corner i at
 * fg_charuco_corner(i), z = 0 on the printed face. fg_charuco_face_z says which way the
 * printed face looks along z (OpenCV 4.6 places the first row of markers at y = 0 with y
 * growing down the printed page, so the face looks along -z).
 *
 * Every function returns 0 or a negative FG_E* code with a detail; no C++ exception crosses
 * this header. */
#ifndef FG_CALIB_CHARUCO_H
#define FG_CALIB_CHARUCO_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct fg_charuco_board {
  int squares_x, squares_y; /* 3 .. 64 each */
  double square_m;          /* side of a chessboard square, metres */
  double marker_m;          /* side of a marker, below square_m */
  int dictionary;           /* fg_charuco_dictionary_parse */
} fg_charuco_board;

/* An OpenCV dictionary name ("DICT_5X5_100", ..., "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_36h11")
 * as its number; FG_EINVAL listing the names otherwise. */
int fg_charuco_dictionary_parse(const char *name, int *dictionary);
const char *fg_charuco_dictionary_name(int dictionary);

/* FG_EINVAL with a detail when b is no board OpenCV can make: squares out of range, sizes
 * not positive or the marker not smaller than the square, more markers than the dictionary
 * has. */
int fg_charuco_board_check(const fg_charuco_board *b);

/* Inner corners: (squares_x - 1) x (squares_y - 1); ids run row by row. */
int fg_charuco_corner_count(const fg_charuco_board *b);
void fg_charuco_corner(const fg_charuco_board *b, int id, double xyz[3]);

/* +1 or -1: the board-frame z of the normal of the printed face (pointing out of it). */
int fg_charuco_face_z(const fg_charuco_board *b);

/* The printed face in the board frame: texel (i, j) covers x in [i, i+1) / px_per_m and y in
 * [j, j+1) / px_per_m over the chessboard (squares_x * square_m wide); 0 black, 255 white.
 * *gray is malloc'd, w x h bytes, row j at gray + j * w. */
int fg_charuco_texture(const fg_charuco_board *b, double px_per_m, uint8_t **gray, int *w,
                       int *h);

/* The board to print: px_per_square pixels a square, a white margin of margin_px around it,
 * the face as seen from the front; 8-bit grey, *gray malloc'd, w x h bytes. (No codec here:
 * the daemon encodes it in its decoder's child process.) */
int fg_charuco_print(const fg_charuco_board *b, int px_per_square, int margin_px,
                     uint8_t **gray, int *w, int *h);

/* The board's inner corners found in an 8-bit grey image (w x h, rows of w bytes): markers
 * detected, corners interpolated between them and refined to subpixel. ids[k] and
 * px[2k], px[2k+1] for k < *n (room for fg_charuco_corner_count each). *n is 0 when the
 * board is not in view; that is not an error. */
int fg_charuco_detect(const fg_charuco_board *b, const uint8_t *gray, int w, int h, int *ids,
                      double *px, int *n);

#ifdef __cplusplus
}
#endif

#endif

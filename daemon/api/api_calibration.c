/* GET /v1/calibration/board.png: the [calibration] board to print. */
#include "api.h"

#include "decoder/decoder.h"

#include "calib/charuco.h"

#include <math.h>
#include <stdlib.h>

/* 300 dots per inch at the board's square size, so that a print at 100 % has it. */
#define PRINT_DPI 300.0

int fg_api_calibration_board(fg_req *req, fg_resp *resp) {
  const fg_charuco_board *b = &req->conf->board;
  const int px = (int)lround(b->square_m / 0.0254 * PRINT_DPI);
  uint8_t *gray, *png;
  size_t len;
  int w, h;
  int rc = fg_charuco_print(b, px < 8 ? 8 : px > 1000 ? 1000 : px, px / 2, &gray, &w, &h);
  if (rc < 0) return fg_api_fail(resp, rc);
  rc = fg_decoder_encode_png(req->app->decoder, gray, w, h, 1, 8, &png, &len);
  free(gray);
  if (rc < 0) return fg_api_fail(resp, rc);
  fg_resp_take(resp, 200, "image/png", (char *)png, len);
  return 0;
}

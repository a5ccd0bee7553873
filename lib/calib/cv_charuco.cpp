// ChArUco boards with OpenCV 4.6's aruco module (charuco.h). Every entry point catches all
// exceptions.
#include "calib/charuco.h"

#include <opencv2/aruco/charuco.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string>
#include <vector>

extern "C" {
#include "core/error.h"
}

namespace {

const char *const k_names[] = {
    "DICT_4X4_50",         "DICT_4X4_100",        "DICT_4X4_250",        "DICT_4X4_1000",
    "DICT_5X5_50",         "DICT_5X5_100",        "DICT_5X5_250",        "DICT_5X5_1000",
    "DICT_6X6_50",         "DICT_6X6_100",        "DICT_6X6_250",        "DICT_6X6_1000",
    "DICT_7X7_50",         "DICT_7X7_100",        "DICT_7X7_250",        "DICT_7X7_1000",
    "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_16h5",  "DICT_APRILTAG_25h9",  "DICT_APRILTAG_36h10",
    "DICT_APRILTAG_36h11"};
const int k_n_names = (int)(sizeof k_names / sizeof k_names[0]);

int markers_needed(const fg_charuco_board *b) { return b->squares_x * b->squares_y / 2; }

cv::Ptr<cv::aruco::CharucoBoard> make_board(const fg_charuco_board *b) {
  cv::Ptr<cv::aruco::Dictionary> dict = cv::aruco::getPredefinedDictionary(b->dictionary);
  return cv::aruco::CharucoBoard::create(b->squares_x, b->squares_y, (float)b->square_m,
                                         (float)b->marker_m, dict);
}

int fail_exception(const char *what, const std::exception &e) {
  return fg_fail(FG_EINVAL, "%s: OpenCV: %s", what, e.what());
}

// The marker's cells (border included) as a (bits + 2)^2 image, one byte a cell.
cv::Mat marker_cells(const cv::aruco::Board &board, int i) {
  const int cells = board.dictionary->markerSize + 2;
  cv::Mat m;
  cv::aruco::drawMarker(board.dictionary, board.ids[i], cells, m, 1);
  return m;
}

}  // namespace

extern "C" int fg_charuco_dictionary_parse(const char *name, int *dictionary) {
  for (int i = 0; i < k_n_names; i++)
    if (std::strcmp(name, k_names[i]) == 0) {
      *dictionary = i;
      return 0;
    }
  return fg_fail(FG_EINVAL, "unknown dictionary \"%s\": expected one of OpenCV's DICT_4X4_50 .. "
                 "DICT_7X7_1000, DICT_ARUCO_ORIGINAL, DICT_APRILTAG_16h5, DICT_APRILTAG_25h9, "
                 "DICT_APRILTAG_36h10, DICT_APRILTAG_36h11", name);
}

extern "C" const char *fg_charuco_dictionary_name(int dictionary) {
  return dictionary >= 0 && dictionary < k_n_names ? k_names[dictionary] : "?";
}

extern "C" int fg_charuco_board_check(const fg_charuco_board *b) {
  if (b->squares_x < 3 || b->squares_x > 64 || b->squares_y < 3 || b->squares_y > 64)
    return fg_fail(FG_EINVAL, "a board has 3 to 64 squares along each side, not %d x %d",
                   b->squares_x, b->squares_y);
  if (!(b->square_m > 0 && b->square_m <= 1))
    return fg_fail(FG_EINVAL, "square_m = %g: expected a size above 0 and at most 1 m",
                   b->square_m);
  if (!(b->marker_m > 0 && b->marker_m < b->square_m))
    return fg_fail(FG_EINVAL, "marker_m = %g: expected above 0 and below square_m (%g)",
                   b->marker_m, b->square_m);
  if (b->dictionary < 0 || b->dictionary >= k_n_names)
    return fg_fail(FG_EINVAL, "unknown dictionary %d", b->dictionary);
  try {
    const int have = cv::aruco::getPredefinedDictionary(b->dictionary)->bytesList.rows;
    if (markers_needed(b) > have)
      return fg_fail(FG_EINVAL, "a %d x %d board needs %d markers; %s has %d", b->squares_x,
                     b->squares_y, markers_needed(b), k_names[b->dictionary], have);
  } catch (const std::exception &e) {
    return fail_exception("board", e);
  }
  return 0;
}

extern "C" int fg_charuco_corner_count(const fg_charuco_board *b) {
  return (b->squares_x - 1) * (b->squares_y - 1);
}

extern "C" void fg_charuco_corner(const fg_charuco_board *b, int id, double xyz[3]) {
  // OpenCV 4.6's chessboardCorners: row by row from the corner at (square, square)
  const int per_row = b->squares_x - 1;
  xyz[0] = (id % per_row + 1) * b->square_m;
  xyz[1] = (id / per_row + 1) * b->square_m;
  xyz[2] = 0;
}

extern "C" int fg_charuco_face_z(const fg_charuco_board *b) {
  try {
    cv::Ptr<cv::aruco::CharucoBoard> board = make_board(b);
    const std::vector<cv::Point3f> &c = board->objPoints[0];
    const cv::Point3f down = c[3] - c[0], right = c[1] - c[0];
    return down.cross(right).z > 0 ? 1 : -1;
  } catch (...) {
    return -1;
  }
}

extern "C" int fg_charuco_texture(const fg_charuco_board *b, double px_per_m, uint8_t **gray,
                                  int *w, int *h) {
  *gray = NULL;
  FG_TRY(fg_charuco_board_check(b));
  const double W = b->squares_x * b->square_m, H = b->squares_y * b->square_m;
  if (!(px_per_m > 0) || W * px_per_m > 16384 || H * px_per_m > 16384)
    return fg_fail(FG_ERANGE, "a board texture of %g px/m: at most 16384 px a side", px_per_m);
  try {
    cv::Ptr<cv::aruco::CharucoBoard> board = make_board(b);
    const int tw = (int)std::ceil(W * px_per_m - 1e-6);
    const int th = (int)std::ceil(H * px_per_m - 1e-6);
    // squares without a marker are black, the rest white with the marker drawn in
    cv::Mat tex(th, tw, CV_8UC1, cv::Scalar(0));
    std::vector<char> has_marker((size_t)b->squares_x * b->squares_y, 0);
    for (size_t i = 0; i < board->objPoints.size(); i++) {
      const std::vector<cv::Point3f> &c = board->objPoints[i];
      const cv::Point3f mid = (c[0] + c[2]) * 0.5f;
      const int cx = (int)(mid.x / b->square_m), cy = (int)(mid.y / b->square_m);
      if (cx >= 0 && cx < b->squares_x && cy >= 0 && cy < b->squares_y)
        has_marker[(size_t)cy * b->squares_x + cx] = 1;
    }
    std::vector<cv::Mat> cells(board->objPoints.size());
    for (size_t i = 0; i < cells.size(); i++) cells[i] = marker_cells(*board, (int)i);
    const int n_cells = board->dictionary->markerSize + 2;
    for (int j = 0; j < th; j++) {
      uint8_t *row = tex.ptr<uint8_t>(j);
      const double y = (j + 0.5) / px_per_m;
      for (int i = 0; i < tw; i++) {
        const double x = (i + 0.5) / px_per_m;
        const int cx = (int)(x / b->square_m), cy = (int)(y / b->square_m);
        if (cx >= b->squares_x || cy >= b->squares_y ||
            !has_marker[(size_t)cy * b->squares_x + cx])
          continue;
        row[i] = 255;
        for (size_t k = 0; k < cells.size(); k++) {
          const std::vector<cv::Point3f> &c = board->objPoints[k];
          const cv::Point3f mid = (c[0] + c[2]) * 0.5f;
          if ((int)(mid.x / b->square_m) != cx || (int)(mid.y / b->square_m) != cy) continue;
          const cv::Point3f ex = c[1] - c[0], ey = c[3] - c[0];
          const double px = x - c[0].x, py = y - c[0].y;
          const double u = (px * ex.x + py * ex.y) / ex.dot(ex);
          const double v = (px * ey.x + py * ey.y) / ey.dot(ey);
          if (u >= 0 && u < 1 && v >= 0 && v < 1)
            row[i] = cells[k].at<uint8_t>((int)(v * n_cells), (int)(u * n_cells));
          break;
        }
      }
    }
    *gray = (uint8_t *)std::malloc((size_t)tw * th);
    if (!*gray) return fg_fail(FG_ENOMEM, "board texture %d x %d", tw, th);
    std::memcpy(*gray, tex.data, (size_t)tw * th);
    *w = tw;
    *h = th;
    return 0;
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "board texture");
  } catch (const std::exception &e) {
    return fail_exception("board texture", e);
  }
}

extern "C" int fg_charuco_print(const fg_charuco_board *b, int px_per_square, int margin_px,
                                uint8_t **gray, int *w, int *h) {
  *gray = NULL;
  if (px_per_square < 8 || px_per_square > 1000 || margin_px < 0 || margin_px > 10000)
    return fg_fail(FG_ERANGE, "a board image of %d px a square (8 .. 1000) and a margin of %d px "
                   "(0 .. 10000)", px_per_square, margin_px);
  uint8_t *tex;
  int tw, th;
  FG_TRY(fg_charuco_texture(b, px_per_square / b->square_m, &tex, &tw, &th));
  const int W = tw + 2 * margin_px, H = th + 2 * margin_px;
  uint8_t *img = (uint8_t *)std::malloc((size_t)W * H);
  if (!img) {
    std::free(tex);
    return fg_fail(FG_ENOMEM, "board image %d x %d", W, H);
  }
  std::memset(img, 255, (size_t)W * H);
  // seen from the front: the texture's rows as they are when the face looks along -z
  // (y runs down the page), upside down when it looks along +z
  const int flip = fg_charuco_face_z(b) > 0;
  for (int j = 0; j < th; j++)
    std::memcpy(img + (size_t)(margin_px + j) * W + margin_px,
                tex + (size_t)(flip ? th - 1 - j : j) * tw, (size_t)tw);
  std::free(tex);
  *gray = img;
  *w = W;
  *h = H;
  return 0;
}

extern "C" int fg_charuco_detect(const fg_charuco_board *b, const uint8_t *gray, int w, int h,
                                 int *ids, double *px, int *n) {
  *n = 0;
  FG_TRY(fg_charuco_board_check(b));
  try {
    cv::Ptr<cv::aruco::CharucoBoard> board = make_board(b);
    const cv::Mat img(h, w, CV_8UC1, const_cast<uint8_t *>(gray));
    std::vector<std::vector<cv::Point2f>> marker_corners;
    std::vector<int> marker_ids;
    cv::Ptr<cv::aruco::DetectorParameters> params = cv::aruco::DetectorParameters::create();
    params->cornerRefinementMethod = cv::aruco::CORNER_REFINE_SUBPIX;
    cv::aruco::detectMarkers(img, board->dictionary, marker_corners, marker_ids, params);
    if (marker_ids.empty()) return 0;
    std::vector<cv::Point2f> corners;
    std::vector<int> corner_ids;
    cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, img, board, corners,
                                         corner_ids);
    // OpenCV 4.6's interpolation leaves the corners about half a pixel off on a sharp image
    // (its marker corners come from contours through the boundary pixels' centres): refine
    // each again on the chessboard's saddle, with a window inside the squares around it
    for (size_t k = 0; k < corners.size(); k++) {
      double nearest = 1e9;
      for (size_t o = 0; o < corners.size(); o++)
        if (o != k) nearest = std::min(nearest, (double)cv::norm(corners[o] - corners[k]));
      const int half = std::max(2, std::min(6, (int)(0.25 * nearest)));
      std::vector<cv::Point2f> one{corners[k]};
      cv::cornerSubPix(img, one, cv::Size(half, half), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50,
                                        0.001));
      corners[k] = one[0];
    }
    const int max = fg_charuco_corner_count(b);
    for (size_t k = 0; k < corner_ids.size() && (int)k < max; k++) {
      ids[k] = corner_ids[k];
      px[2 * k] = corners[k].x;
      px[2 * k + 1] = corners[k].y;
      *n = (int)k + 1;
    }
    return 0;
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "board detection");
  } catch (const std::exception &e) {
    return fail_exception("board detection", e);
  }
}

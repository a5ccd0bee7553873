/* Shared by the crash-consistency tests (test_crash: kill -9 at random moments; test_diskfull:
 * a state dir on a full file system): frames whose content the test knows bit for bit, and the
 * checks that the state dir holds nothing half-written. They read the state dir's frame files
 * with the library (io/frame.h), which verifies each file's CRC, so that a torn or truncated
 * frame cannot pass for a listed one. Like the harness, every helper asserts. */
#ifndef FG_IT_CRASH_UTIL_H
#define FG_IT_CRASH_UTIL_H

#include "harness.h"

#define CU_W 48   /* the uploaded frames' size: small, so that a round stays short */
#define CU_H 36
#define CU_FEAT_D 8 /* features [4, 5, 8] float32 */

/* Uploads frame `seed` (a 16-bit RGB PNG whose pixels, features and pose follow from the
 * seed; its upload file name, listed as the frame's "source", is "u<seed>.png") to scene and
 * returns the reply (caller frees). No status is asserted: the daemon may be killed under
 * it, or the disk may be full. */
h_resp *cu_upload(const char *scene, unsigned seed);

/* The source name of frame seed's upload ("u<seed>.png"), in a static buffer. */
const char *cu_source(unsigned seed);

/* Asserts that listing entry e (one of GET /v1/scenes/{s}/frames) is upload seed's frame:
 * its source, pose, camera size and feature shape; and that the frame's file in the state
 * dir loads (CRC) and holds exactly the uploaded pixels and features. */
void cu_check_upload(const char *scene, json_t *e, unsigned seed);

/* Asserts that scene's listing and its frames folder agree: every listed frame has its
 * <6 digits>.fgf file, which loads whole (CRC checked) with the listed camera size, and every
 * .fgf file is listed. Returns the listing's "frames" array (caller decrefs). */
json_t *cu_check_scene_files(const char *scene);

/* Asserts that nothing under the state dir is an unfinished write or an undone delete
 * (".tmp.", ".incoming-", ".trash-", ".batch-" names), as after a clean start-up. */
void cu_check_no_leftovers(void);

/* Asserts that the daemon log after byte offset `from` (see cu_log_size) has no line saying
 * that the start-up left something out or could not read it. */
void cu_check_clean_start(size_t from);

/* The daemon log's size now, for cu_check_clean_start. */
size_t cu_log_size(void);

#endif

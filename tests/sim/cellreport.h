/* The physics cell's report (sim/cell_report.h: one JSON line a command, and more), read back
 * by the tests and the benchmarks. Fails the test (tests/test.h) where the report is not what
 * the simulator writes. */
#ifndef FG_TEST_CELLREPORT_H
#define FG_TEST_CELLREPORT_H

#include <jansson.h>

/* The last line of text that reports a command, about command seq (seq < 0: any), parsed;
 * the caller decrefs. what names the report in messages. A line that is not JSON, or no such
 * line, fails the test. */
json_t *cellreport_line(const char *text, int seq, const char *what);

#endif

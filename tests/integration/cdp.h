/* A headless Chromium driven through the Chrome DevTools Protocol, for the web viewer's
 * browser test: the browser talks CDP over a pair of pipes (--remote-debugging-pipe: it reads
 * JSON commands from fd 3 and writes replies and events to fd 4, each message ended by a NUL
 * byte), so there is no port, no WebSocket handshake and nothing to race for.
 *
 * Like the harness, every function asserts instead of returning an error, except cdp_start,
 * whose failure the test turns into a skip (exit 77: Chromium cannot run here). The browser
 * runs in its own process group, which an atexit hook kills, so no browser process outlives
 * the test. */
#ifndef FG_IT_CDP_H
#define FG_IT_CDP_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>

/* Starts Chromium (the program $FG_CHROMIUM names, else the first of chromium,
 * chromium-browser, google-chrome on the PATH) headless with a software GL
 * (SwiftShader), a profile in <tmp>/chromium and its output in <tmp>/chromium.log, and
 * waits up to timeout_s for it to answer Browser.getVersion. 0 when it answers (its product
 * string in version); -1 with the reason in why when no browser is installed or it does not
 * start. */
int cdp_start(double timeout_s, char *version, size_t version_len, char *why, size_t why_len);

/* Sends a command (params: a JSON object, stolen; NULL for none) to the browser (session
 * NULL) or to an attached page's session and waits up to timeout_s for its reply. Returns
 * its "result" (the caller decrefs); fails the test on an error reply, a timeout or a
 * browser that went away. Events that arrive meanwhile are kept (cdp_events). */
json_t *cdp_call(const char *session, const char *method, json_t *params, double timeout_s);

/* Opens a new page of width x height CSS pixels at device scale 1 and attaches to it;
 * enables its Page, Runtime and Log domains. Returns the session id (the caller frees). */
char *cdp_open_page(int width, int height);

/* Navigates the page to url and waits for its load event. */
void cdp_navigate(const char *session, const char *url, double timeout_s);

/* Evaluates a JavaScript expression in the page, waiting for it when it is a promise, and
 * returns its value (the caller decrefs; JSON null for undefined). Fails the test, with the
 * exception's text, when it throws or rejects. */
json_t *cdp_eval(const char *session, const char *expression, double timeout_s);

/* Every event received so far, oldest first: objects {"method", "params", "sessionId"}.
 * Borrowed. */
json_t *cdp_events(void);

/* A PNG screenshot of the page's viewport, decoded from the reply's base64 into *png (the
 * caller frees). */
void cdp_screenshot(const char *session, uint8_t **png, size_t *len);

/* Closes the browser and waits for it (kills its process group when it lingers). Also run
 * at exit. */
void cdp_stop(void);

#endif

/* Cross-site guards of the HTTP layer: what keeps a web page that the operator happens to
 * visit from driving the daemon (and the robot) through the operator's browser. A daemon
 * without a token on loopback is otherwise open to every page the browser shows:
 *
 * - Cross-site requests: a page of any origin may send a "simple" request without asking
 *   first (no CORS preflight): a POST with Content-Type text/plain,
 *   application/x-www-form-urlencoded or multipart/form-data, or with a body of no type. The
 *   browser hides the answer from the page, but the robot has moved. Browsers name the
 *   page's origin in an Origin header on every such request, so fg_guard_origin refuses
 *   methods that change something when Origin is neither the daemon's own nor listed in
 *   [http] allowed_origins; and fg_guard_body_type requires a JSON body to say
 *   application/json, a type a page of another origin can send only after a preflight the
 *   daemon never grants (it answers no OPTIONS request and sends no CORS headers).
 * - DNS rebinding: a page at http://evil.example:7070 whose name the attacker then points
 *   at 127.0.0.1 is, to the browser, same-origin with the daemon, and may read and write.
 *   Its requests say "Host: evil.example:7070", so fg_guard_host refuses a Host that names
 *   the daemon by a DNS name other than localhost and [http] allowed_hosts. IP literals pass:
 *   an address cannot be rebound, and a page served from another address is another origin.
 *
 * None of this stops a program that sends what it likes: [http] token does that, and a
 * daemon that moves a robot on a listen address other machines reach needs one
 * (fg_conf_check_exposure). All functions are pure: they read conf and the strings given. */
#ifndef FG_DAEMON_HTTP_GUARD_H
#define FG_DAEMON_HTTP_GUARD_H

struct fg_conf;

/* Whether a request whose Host header is host (NULL or "" when absent: HTTP/1.0 clients, no
 * browser) may be served: an IPv4 or [IPv6] literal, localhost, or a name of
 * conf->allowed_hosts (case-insensitive), with any port. 0, or FG_EPERM with a detail that
 * says how to allow the name. */
int fg_guard_host(const struct fg_conf *conf, const char *host);

/* Whether a request with this method from a page of origin (the Origin header; NULL when
 * absent) may proceed. GET, HEAD and other methods that change nothing always may (a page
 * of another origin cannot read the answer); POST, PUT, PATCH and DELETE may when there is
 * no Origin (not sent by a browser's page), when origin is "http://" or "https://" followed
 * by host (the request's Host, already accepted by fg_guard_host: the daemon's own page), or
 * when it is listed in conf->allowed_origins (case-insensitive). 0, or FG_EPERM with a
 * detail. */
int fg_guard_origin(const struct fg_conf *conf, const char *method, const char *host,
                    const char *origin);

/* Whether content_type (NULL when absent) fits what the route with these fg_route flags
 * takes: multipart/form-data for FG_ROUTE_MULTIPART routes (always: their body is required),
 * image/... or application/octet-stream for FG_ROUTE_IMAGE_BODY ones, and application/json
 * for all others; parameters (";charset=utf-8") and case do not matter. has_body: the
 * request announced a body (Content-Length above 0, or Transfer-Encoding); requests without
 * one, and methods other than POST, PUT, PATCH and DELETE, need no type (curl -X POST
 * .../gripper/close; the Origin check keeps pages out). 0, or FG_EFORMAT with a detail that
 * names the type expected. */
int fg_guard_body_type(int route_flags, const char *method, int has_body,
                       const char *content_type);

#endif

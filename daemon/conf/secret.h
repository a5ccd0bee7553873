/* Secrets kept in files of their own ([http] token_file), so that the configuration file
 * may stay world-readable while the token does not: the file is read at start-up and at each
 * reload, and refused when others could read it. */
#ifndef FG_DAEMON_SECRET_H
#define FG_DAEMON_SECRET_H

#include <stddef.h>

/* The largest secret file read, in bytes. */
#define FG_SECRET_MAX_BYTES 4096

/* Reads the one-line secret at path into *out (malloc'd, the caller owns it and should wipe
 * it with fg_secret_free). One trailing "\n" or "\r\n" is dropped. Refused, with a detail
 * that says how to fix it: a file that is not a regular file, that group or others may read
 * or write (FG_EPERM), an empty secret, one of more than FG_SECRET_MAX_BYTES bytes, more
 * than one line, or control characters (FG_EINVAL); FG_ENOENT/FG_EIO when it cannot be
 * read. On failure *out is NULL. */
int fg_secret_read(const char *path, char **out);

/* Overwrites a secret with zeros and frees it; NULL is fine. */
void fg_secret_free(char *secret);

#endif

/* The system call filter fieldgrip-decode installs on itself before it reads an image, so that
 * a codec taken over by a hostile image still cannot reach beyond the pipes it was given.
 *
 * It is a deny list, not an allow list: OpenImageIO and OpenCV start threads, map plugins and
 * read files on their own terms, so everything a decoder plausibly does stays allowed and
 * what only an attacker wants fails with EPERM:
 *   - starting programs or processes: execve, execveat, fork, vfork, and clone without
 *     CLONE_THREAD (threads stay allowed); clone3 fails with ENOSYS so that the C library
 *     falls back to clone, whose flags the filter can read;
 *   - the network: socket, socketpair, connect, bind, listen, accept, accept4;
 *   - changing files: open and openat with O_WRONLY, O_RDWR, O_CREAT or O_TRUNC (openat2
 *     fails with ENOSYS, for the same fallback), creat, unlink, rename, mkdir, rmdir, link,
 *     symlink, mknod, chmod, chown, truncate, ftruncate, fallocate, utimes, the *xattr
 *     writes; reading files stays allowed;
 *   - other processes: ptrace, process_vm_readv/writev, kill and tgkill except of itself,
 *     tkill, prlimit64 except of itself, the pidfd calls, kcmp;
 *   - the kernel's wider surfaces: io_uring (which would run the calls above behind the
 *     filter's back), bpf, perf_event_open, userfaultfd, keyctl, namespaces, mounts, modules,
 *     reboot, swap, and the terminal's TIOCSTI and TIOCLINUX ioctls (typing into the
 *     daemon's terminal when it runs in the foreground);
 *   - system calls of another architecture: an i386 call (int $0x80 on x86-64) kills the
 *     process, an x32 call fails with EPERM.
 * Under AddressSanitizer ptrace and non-thread clone and fork stay allowed: LeakSanitizer
 * stops the threads with them at exit (FG_DECODE_SECCOMP_SANITIZED). */
#ifndef FG_DAEMON_DECODE_SECCOMP_H
#define FG_DAEMON_DECODE_SECCOMP_H

#if defined(__SANITIZE_ADDRESS__)
#define FG_DECODE_SECCOMP_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(leak_sanitizer)
#define FG_DECODE_SECCOMP_SANITIZED 1
#endif
#endif
#ifndef FG_DECODE_SECCOMP_SANITIZED
#define FG_DECODE_SECCOMP_SANITIZED 0
#endif

/* Installs the filter on every thread of the calling process; no_new_privs must already be
 * set. 0 on success; FG_EUNAVAIL where the architecture has no filter here or the kernel has
 * no seccomp, FG_EIO when the kernel refuses it; both with a detail. */
int fg_decode_seccomp(void);

#endif

/* Unit tests of daemon/decode_seccomp: in a child of its own, with the filter installed, every
 * kind of call the filter forbids fails with EPERM (programs, processes, the network,
 * changing files, other processes, io_uring, typing into a terminal, x32 calls), clone3 and
 * openat2 fail with ENOSYS, an i386 call kills the process, and what a decoder needs still
 * works: threads, reading files, memory, signals to itself, its own limits. That the decoder
 * program installs it is checked by test_decoder (Seccomp_filters of a live child). */
#include "test.h"

#include "core/error.h"
#include "decoder/decode_seccomp.h"

#include <errno.h>
#include <fcntl.h>
#include <linux/io_uring.h>
#include <pthread.h>
#include <signal.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/ptrace.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

static char dir[] = "/tmp/fg-seccomp-XXXXXX";
static char readable[128], writable[128];

/* A call's result when the filter forbids it: -1 with errno EPERM (ENOSYS where asked). */
#define ASSERT_REFUSED(call, err)                                                          \
  do {                                                                                     \
    errno = 0;                                                                             \
    long fg_rc_ = (long)(call);                                                            \
    if (fg_rc_ != -1 || errno != (err))                                                    \
      FG_TEST_FAIL("%s: got %ld, errno %d (%s); wanted -1 with errno %d", #call, fg_rc_,    \
                   errno, strerror(errno), (err));                                         \
  } while (0)

/* Runs body in a forked child with no_new_privs and the filter; returns its wait status. */
static int in_filtered_child(void (*body)(void)) {
  fflush(NULL);
  pid_t pid = fork();
  ASSERT(pid >= 0);
  if (pid == 0) {
    if (prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0) FG_TEST_FAIL("no_new_privs refused");
    if (fg_decode_seccomp() != 0) FG_TEST_FAIL("fg_decode_seccomp: %s", fg_error_detail());
    body();
    fflush(NULL);
    _exit(0);
  }
  int status;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  return status;
}

static void assert_exited_0(int status) {
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    FG_TEST_FAIL("the filtered child ended with status %#x (exit %d, signal %d)", status,
                 WIFEXITED(status) ? WEXITSTATUS(status) : -1,
                 WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

static void *thread_main(void *arg) {
  int *v = arg;
  *v *= 3;
  return v;
}

static volatile sig_atomic_t got_usr1;
static void on_usr1(int sig) {
  (void)sig;
  got_usr1 = 1;
}

/* What a decoder does: all of it must still work under the filter. */
static void allowed_calls(void) {
  /* threads (clone with CLONE_THREAD, after clone3's ENOSYS) */
  int v = 7;
  pthread_t t;
  void *out = NULL;
  ASSERT_EQ(pthread_create(&t, NULL, thread_main, &v), 0);
  ASSERT_EQ(pthread_join(t, &out), 0);
  ASSERT(out == &v && v == 21);
  /* reading a file */
  int fd = open(readable, O_RDONLY | O_CLOEXEC);
  ASSERT(fd >= 0);
  char buf[16] = {0};
  ASSERT_EQ(read(fd, buf, sizeof buf - 1), 5);
  ASSERT_STREQ(buf, "pixel");
  close(fd);
  fd = openat(AT_FDCWD, "/proc/self/status", O_RDONLY);
  ASSERT(fd >= 0);
  close(fd);
  /* memory, and writing to a pipe */
  void *m = mmap(NULL, 1 << 20, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT(m != MAP_FAILED);
  ASSERT_EQ(mprotect(m, 4096, PROT_READ), 0);
  munmap(m, 1 << 20);
  int p[2];
  ASSERT_EQ(pipe(p), 0);
  ASSERT_EQ(write(p[1], "x", 1), 1);
  /* signals to itself (raise is tgkill on its own pid), its own limits */
  ASSERT_EQ(kill(getpid(), 0), 0);
  signal(SIGUSR1, on_usr1);
  ASSERT_EQ(raise(SIGUSR1), 0);
  ASSERT(got_usr1);
  struct rlimit rl;
  ASSERT_EQ(getrlimit(RLIMIT_CPU, &rl), 0);
  ASSERT_EQ(setrlimit(RLIMIT_CPU, &rl), 0);
  ASSERT_EQ(prlimit(getpid(), RLIMIT_NOFILE, NULL, &rl), 0);
  /* an ioctl other than the terminal's typing ones reaches the kernel */
  int n = 0;
  ASSERT_EQ(ioctl(p[0], FIONREAD, &n), 0);
  ASSERT_EQ(n, 1);
}

/* What only an attacker wants: each fails with EPERM (or ENOSYS where the C library falls
 * back). A file descriptor opened for writing before the filter stands for stderr pointed at
 * the daemon's log file. */
static int log_fd = -1;
static void forbidden_calls(void) {
  /* /bin/false: were the call let through, the child would end with 1 */
  char *argv[] = {"false", NULL}, *envp[] = {NULL};
  ASSERT_REFUSED(execve("/bin/false", argv, envp), EPERM);
  ASSERT_REFUSED(syscall(__NR_execveat, AT_FDCWD, "/bin/false", argv, envp, 0), EPERM);
#if !FG_DECODE_SECCOMP_SANITIZED
  ASSERT_REFUSED(fork(), EPERM);
  ASSERT_REFUSED(ptrace(PTRACE_TRACEME, 0, NULL, NULL), EPERM);
#else
  printf("fork, clone and ptrace: allowed under AddressSanitizer (LeakSanitizer needs them)\n");
#endif
  ASSERT_REFUSED(syscall(__NR_clone3, NULL, 0), ENOSYS);
  /* the network */
  ASSERT_REFUSED(socket(AF_INET, SOCK_STREAM, 0), EPERM);
  ASSERT_REFUSED(socket(AF_UNIX, SOCK_DGRAM, 0), EPERM);
  int sv[2];
  ASSERT_REFUSED(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), EPERM);
  /* changing files, through every door */
  ASSERT_REFUSED(open(writable, O_WRONLY | O_CREAT, 0600), EPERM);
  ASSERT_REFUSED(open(readable, O_RDWR), EPERM);
  ASSERT_REFUSED(openat(AT_FDCWD, readable, O_RDONLY | O_TRUNC), EPERM);
  ASSERT_REFUSED(syscall(__NR_openat, AT_FDCWD, readable, O_WRONLY | O_APPEND), EPERM);
  ASSERT_REFUSED(syscall(__NR_openat2, AT_FDCWD, readable, NULL, 0), ENOSYS);
  ASSERT(fopen(writable, "w") == NULL);
  ASSERT_REFUSED(unlink(readable), EPERM);
  ASSERT_REFUSED(rename(readable, writable), EPERM);
  ASSERT_REFUSED(mkdir(writable, 0700), EPERM);
  ASSERT_REFUSED(symlink(readable, writable), EPERM);
  ASSERT_REFUSED(link(readable, writable), EPERM);
  ASSERT_REFUSED(chmod(readable, 0666), EPERM);
  ASSERT_REFUSED(truncate(readable, 0), EPERM);
  ASSERT_REFUSED(ftruncate(log_fd, 0), EPERM);
  ASSERT_REFUSED(fchmod(log_fd, 0666), EPERM);
  ASSERT_REFUSED(fallocate(log_fd, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, 0, 1), EPERM);
  /* other processes: the parent stands for the daemon */
  ASSERT_REFUSED(kill(getppid(), 0), EPERM);
  ASSERT_REFUSED(kill(-1, 0), EPERM);
  ASSERT_REFUSED(syscall(__NR_tgkill, getppid(), getppid(), 0), EPERM);
  ASSERT_REFUSED(syscall(__NR_tkill, getppid(), 0), EPERM);
  struct rlimit rl;
  ASSERT_REFUSED(prlimit(getppid(), RLIMIT_NOFILE, NULL, &rl), EPERM);
  ASSERT_REFUSED(syscall(__NR_pidfd_open, getppid(), 0), EPERM);
  /* the kernel's wider surfaces */
  struct io_uring_params params;
  memset(&params, 0, sizeof params);
  ASSERT_REFUSED(syscall(__NR_io_uring_setup, 4, &params), EPERM);
  ASSERT_REFUSED(syscall(__NR_bpf, 0, NULL, 0), EPERM);
  ASSERT_REFUSED(syscall(__NR_unshare, 0), EPERM);
  char c = 'x';
  ASSERT_REFUSED(ioctl(0, TIOCSTI, &c), EPERM);
#if defined(__x86_64__)
  ASSERT_REFUSED(syscall(__NR_getpid | 0x40000000), EPERM); /* x32 */
#endif
  /* and nothing changed on disk */
  struct stat st;
  ASSERT(stat(writable, &st) != 0 && errno == ENOENT);
}

#if defined(__x86_64__)
/* getpid through the i386 entry point: int $0x80 with eax = 20. */
static long i386_getpid(void) {
  long ret = 20;
  __asm__ volatile("int $0x80" : "+a"(ret) : : "memory", "r8", "r9", "r10", "r11");
  return ret;
}

static void i386_call(void) {
  i386_getpid();
}

/* An i386 call kills the process (SIGSYS), where the kernel has i386 emulation at all. */
static void test_other_architecture(void) {
  fflush(NULL);
  pid_t pid = fork();
  ASSERT(pid >= 0);
  if (pid == 0) _exit(i386_getpid() == getpid() ? 0 : 1);
  int status;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    printf("i386 calls: not checked, this kernel does not run them (status %#x)\n", status);
    return;
  }
  status = in_filtered_child(i386_call);
  if (!WIFSIGNALED(status) || WTERMSIG(status) != SIGSYS)
    FG_TEST_FAIL("an i386 call under the filter ended with status %#x, not SIGSYS", status);
}
#endif

int main(void) {
  ASSERT(mkdtemp(dir));
  snprintf(readable, sizeof readable, "%s/readable", dir);
  snprintf(writable, sizeof writable, "%s/new", dir);
  FILE *f = fopen(readable, "w");
  ASSERT(f && fputs("pixel", f) >= 0 && fclose(f) == 0);
  struct stat before;
  ASSERT(stat(readable, &before) == 0);
  char log_path[128];
  snprintf(log_path, sizeof log_path, "%s/log", dir);
  log_fd = open(log_path, O_WRONLY | O_CREAT | O_CLOEXEC, 0600);
  ASSERT(log_fd >= 0 && write(log_fd, "daemon log\n", 11) == 11);

  assert_exited_0(in_filtered_child(allowed_calls));
  assert_exited_0(in_filtered_child(forbidden_calls));
#if defined(__x86_64__)
  test_other_architecture();
#endif

  /* the files the child tried to change are as they were */
  struct stat st;
  ASSERT(stat(readable, &st) == 0 && st.st_size == 5 && st.st_mode == before.st_mode);
  ASSERT(fstat(log_fd, &st) == 0 && st.st_size == 11 && (st.st_mode & 0777) == 0600);
  close(log_fd);
  unlink(log_path);
  unlink(readable);
  rmdir(dir);
  printf("decode_seccomp: all passed\n");
  return 0;
}

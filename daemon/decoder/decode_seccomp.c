/* The decoder's system call filter (decode_seccomp.h): a classic BPF program built at start,
 * since it names the process's own pid. */
#include "decode_seccomp.h"

#include "core/error.h"

#include <errno.h>
#include <fcntl.h>
#include <linux/audit.h>
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <sched.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <unistd.h>

#if defined(__x86_64__)
#define FILTER_ARCH AUDIT_ARCH_X86_64
#elif defined(__aarch64__)
#define FILTER_ARCH AUDIT_ARCH_AARCH64
#endif

#ifdef FILTER_ARCH

#define RET_ALLOW SECCOMP_RET_ALLOW
#define RET_EPERM (SECCOMP_RET_ERRNO | (EPERM & SECCOMP_RET_DATA))
#define RET_ENOSYS (SECCOMP_RET_ERRNO | (ENOSYS & SECCOMP_RET_DATA))

/* Calls that fail with EPERM whatever their arguments. */
static const long denied[] = {
  /* programs and processes */
  __NR_execve, __NR_execveat,
#if !FG_DECODE_SECCOMP_SANITIZED
  __NR_ptrace,
#ifdef __NR_fork
  __NR_fork, __NR_vfork,
#endif
#endif
  __NR_process_vm_readv, __NR_process_vm_writev, __NR_pidfd_open, __NR_pidfd_getfd,
  __NR_pidfd_send_signal, __NR_process_madvise, __NR_tkill, __NR_kcmp,
  /* the network */
  __NR_socket, __NR_socketpair, __NR_connect, __NR_bind, __NR_listen, __NR_accept,
  __NR_accept4,
  /* changing files */
  __NR_unlinkat, __NR_renameat2, __NR_mkdirat, __NR_linkat, __NR_symlinkat, __NR_mknodat,
  __NR_fchmod, __NR_fchmodat, __NR_fchown, __NR_fchownat, __NR_truncate, __NR_ftruncate,
  __NR_fallocate, __NR_utimensat, __NR_setxattr, __NR_lsetxattr, __NR_fsetxattr,
  __NR_removexattr, __NR_lremovexattr, __NR_fremovexattr, __NR_name_to_handle_at,
  __NR_open_by_handle_at,
#ifdef __NR_renameat
  __NR_renameat,
#endif
#ifdef __NR_fchmodat2
  __NR_fchmodat2,
#endif
#if defined(__x86_64__)
  __NR_creat, __NR_unlink, __NR_rename, __NR_mkdir, __NR_rmdir, __NR_link, __NR_symlink,
  __NR_mknod, __NR_chmod, __NR_chown, __NR_lchown, __NR_utime, __NR_utimes, __NR_futimesat,
  __NR_iopl, __NR_ioperm,
#endif
  /* the kernel's wider surfaces */
  __NR_io_uring_setup, __NR_io_uring_enter, __NR_io_uring_register, __NR_bpf,
  __NR_perf_event_open, __NR_userfaultfd, __NR_keyctl, __NR_add_key, __NR_request_key,
  __NR_unshare, __NR_setns, __NR_mount, __NR_umount2, __NR_pivot_root, __NR_chroot,
  __NR_open_tree, __NR_move_mount, __NR_fsopen, __NR_fsconfig, __NR_fsmount, __NR_fspick,
  __NR_mount_setattr, __NR_init_module, __NR_finit_module, __NR_delete_module,
  __NR_kexec_load, __NR_kexec_file_load, __NR_reboot, __NR_swapon, __NR_swapoff, __NR_acct,
  __NR_quotactl,
};

/* The program being built: 230 instructions on x86-64. */
enum { MAX_INSNS = 320 };
typedef struct {
  struct sock_filter insn[MAX_INSNS];
  unsigned short n;
} program;

static void emit(program *p, uint16_t code, uint32_t k, uint8_t jt, uint8_t jf) {
  if (p->n < MAX_INSNS) p->insn[p->n] = (struct sock_filter){code, jt, jf, k};
  p->n++; /* past MAX_INSNS the caller sees n too large and refuses */
}

static void ret(program *p, uint32_t value) {
  emit(p, BPF_RET | BPF_K, value, 0, 0);
}

/* Loads the low 32 bits of argument i: what the kernel reads of an int, a pid_t, the flags
 * of open and clone's CLONE_THREAD, and an ioctl's request number. */
static void load_arg_low(program *p, int i) {
  uint32_t at = (uint32_t)(offsetof(struct seccomp_data, args) + 8 * (size_t)i);
#if __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  at += 4;
#endif
  emit(p, BPF_LD | BPF_W | BPF_ABS, at, 0, 0);
}

/* The accumulator holds the call's number here; every block below keeps it so or returns. */
static void load_nr(program *p) {
  emit(p, BPF_LD | BPF_W | BPF_ABS, offsetof(struct seccomp_data, nr), 0, 0);
}

/* Call nr returns value. */
static void on_call(program *p, long nr, uint32_t value) {
  emit(p, BPF_JMP | BPF_JEQ | BPF_K, (uint32_t)nr, 0, 1);
  ret(p, value);
}

/* Call nr returns if_set when argument arg has any bit of mask, else if_clear. */
static void on_arg_bits(program *p, long nr, int arg, uint32_t mask, uint32_t if_set,
                        uint32_t if_clear) {
  emit(p, BPF_JMP | BPF_JEQ | BPF_K, (uint32_t)nr, 0, 4);
  load_arg_low(p, arg);
  emit(p, BPF_JMP | BPF_JSET | BPF_K, mask, 0, 1);
  ret(p, if_set);
  ret(p, if_clear);
}

/* Call nr returns if_in when argument arg is one of values[0..n), else if_other. */
static void on_arg_in(program *p, long nr, int arg, const uint32_t *values, int n,
                      uint32_t if_in, uint32_t if_other) {
  emit(p, BPF_JMP | BPF_JEQ | BPF_K, (uint32_t)nr, 0, (uint8_t)(n + 3));
  load_arg_low(p, arg);
  for (int j = 0; j < n; j++) emit(p, BPF_JMP | BPF_JEQ | BPF_K, values[j], (uint8_t)(n - j), 0);
  ret(p, if_other);
  ret(p, if_in);
}

/* Builds the whole filter for a process whose pid is self. */
static void build(program *p, uint32_t self) {
  static const uint32_t write_flags = O_WRONLY | O_RDWR | O_CREAT | O_TRUNC;
  const uint32_t just_self[] = {self}, self_or_zero[] = {self, 0};
  static const uint32_t terminal_typing[] = {TIOCSTI, TIOCLINUX};

  emit(p, BPF_LD | BPF_W | BPF_ABS, offsetof(struct seccomp_data, arch), 0, 0);
  emit(p, BPF_JMP | BPF_JEQ | BPF_K, FILTER_ARCH, 1, 0);
  ret(p, SECCOMP_RET_KILL_PROCESS);
  load_nr(p);
#if defined(__x86_64__)
  /* x32 calls: the same numbers with bit 30 set */
  emit(p, BPF_JMP | BPF_JGE | BPF_K, 0x40000000u, 0, 1);
  ret(p, RET_EPERM);
#endif
  for (size_t i = 0; i < sizeof denied / sizeof denied[0]; i++) on_call(p, denied[i], RET_EPERM);
  on_call(p, __NR_clone3, RET_ENOSYS);
  on_call(p, __NR_openat2, RET_ENOSYS);
  on_arg_bits(p, __NR_openat, 2, write_flags, RET_EPERM, RET_ALLOW);
#if defined(__x86_64__)
  on_arg_bits(p, __NR_open, 1, write_flags, RET_EPERM, RET_ALLOW);
#endif
#if !FG_DECODE_SECCOMP_SANITIZED
  on_arg_bits(p, __NR_clone, 0, CLONE_THREAD, RET_ALLOW, RET_EPERM);
#endif
  on_arg_in(p, __NR_kill, 0, just_self, 1, RET_ALLOW, RET_EPERM);
  on_arg_in(p, __NR_tgkill, 0, just_self, 1, RET_ALLOW, RET_EPERM);
  on_arg_in(p, __NR_prlimit64, 0, self_or_zero, 2, RET_ALLOW, RET_EPERM);
  on_arg_in(p, __NR_ioctl, 1, terminal_typing, 2, RET_EPERM, RET_ALLOW);
  ret(p, RET_ALLOW);
}

int fg_decode_seccomp(void) {
  static program p; /* a few KB: not on the stack */
  memset(&p, 0, sizeof p);
  build(&p, (uint32_t)getpid());
  if (p.n > MAX_INSNS)
    return fg_fail(FG_EIO, "the system call filter needs %u instructions, more than %d", p.n,
                   MAX_INSNS);
  struct sock_fprog prog = {.len = p.n, .filter = p.insn};
  /* TSYNC: the libraries may have started threads already, and each needs the filter */
  long rc = syscall(__NR_seccomp, SECCOMP_SET_MODE_FILTER, SECCOMP_FILTER_FLAG_TSYNC, &prog);
  if (rc > 0)
    return fg_fail(FG_EIO, "thread %ld could not take the system call filter", rc);
  if (rc == 0) return 0;
  if (errno == ENOSYS)
    return fg_fail(FG_EUNAVAIL, "this kernel has no seccomp filters");
  return fg_fail(FG_EIO, "the kernel refused the system call filter: %s", strerror(errno));
}

#else

int fg_decode_seccomp(void) {
  return fg_fail(FG_EUNAVAIL, "no system call filter is written for this architecture");
}

#endif

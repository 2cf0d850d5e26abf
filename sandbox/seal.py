"""The kernel's locks on a sandbox child, applied by the child to itself before it runs user code.

In order: user and network namespaces where the machine allows them (a network with no interfaces
up, so nothing can be reached even by a syscall that slipped through); resource limits (address
space, file size 0, no core dumps); then a seccomp allow-list with no_new_privs, after which the
process can read its request pipes, write its reply pipes and standard error, manage its memory
and time, signal and reap the children it names, and exit. Everything else (open, stat, socket,
fork, clone, execve, kill, ptrace, ...) fails with EPERM, which Python raises as
PermissionError, so misbehaving code gets an ordinary exception.

Nothing here runs in the worker: it imports no Django and is only called in the child.
"""

from __future__ import annotations

import ctypes
import errno
import os
import resource
import signal
from collections.abc import Callable

CLONE_NEWUSER = 0x10000000
CLONE_NEWNET = 0x40000000
PR_SET_PDEATHSIG = 1

# What a sealed process may do. Memory, time, signals for itself, and reading and writing its
# pipes (checked by file descriptor in install_seccomp); nothing that reaches a file, another
# process or the network. fstat on an open descriptor is here; newfstatat, which glibc also
# uses for it but which takes a path, is not: a path is the file system.
ALWAYS_ALLOWED = (
    "brk",
    "mmap",
    "munmap",
    "mremap",
    "mprotect",
    "madvise",
    "membarrier",
    "futex",
    "sched_yield",
    "sched_getaffinity",
    "getrandom",
    "clock_gettime",
    "clock_getres",
    "clock_nanosleep",
    "gettimeofday",
    "nanosleep",
    "time",
    "rt_sigaction",
    "rt_sigprocmask",
    "rt_sigreturn",
    "sigaltstack",
    "setitimer",
    "getitimer",
    "getpid",
    "gettid",
    "getppid",
    "getuid",
    "geteuid",
    "getgid",
    "getegid",
    "fstat",
    "lseek",
    "close",
    "ioctl",
    "fcntl",
    "poll",
    "ppoll",
    "exit",
    "exit_group",
    "restart_syscall",
    "getrusage",
    "sysinfo",
    "uname",
    "set_robust_list",
    "rseq",
)


def die_with(parent: int) -> None:
    """Be killed when ``parent`` goes (the kernel sends SIGKILL); exit now if it has already
    gone, before the request took effect."""
    ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:
        os._exit(0)


def escapes(attempts: dict[str, Callable[[], object]]) -> list[str]:
    """The names of ``attempts`` (each something a sealed process must not manage) that did not
    fail with OSError: what got through the seals."""
    escaped = []
    for name, attempt in attempts.items():
        try:
            attempt()
        except OSError:
            continue
        escaped.append(name)
    return escaped


def enter_namespaces() -> bool:
    """Move into new user and network namespaces; False where the machine does not allow it."""
    libc = ctypes.CDLL(None, use_errno=True)
    return libc.unshare(CLONE_NEWUSER | CLONE_NEWNET) == 0


def limit_resources(address_space: int) -> None:
    """Cap the address space at ``address_space`` bytes; forbid file growth and core dumps."""
    resource.setrlimit(resource.RLIMIT_AS, (address_space, address_space))
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    resource.setrlimit(resource.RLIMIT_NPROC, (0, 0))


def install_seccomp(
    *, read_fds: tuple[int, ...], write_fds: tuple[int, ...], children: tuple[int, ...] = ()
) -> None:
    """Allow only ``ALWAYS_ALLOWED`` syscalls, reads from ``read_fds``, writes to ``write_fds``,
    and killing and reaping ``children``; anything else fails with EPERM. Sets no_new_privs, so
    the filter cannot be shed."""
    import pyseccomp as seccomp

    rules = seccomp.SyscallFilter(defaction=seccomp.ERRNO(errno.EPERM))
    for name in ALWAYS_ALLOWED:
        try:
            rules.add_rule(seccomp.ALLOW, name)
        except (OSError, ValueError):
            continue  # a syscall this architecture does not have
    for fd in read_fds:
        rules.add_rule(seccomp.ALLOW, "read", seccomp.Arg(0, seccomp.EQ, fd))
    for fd in write_fds:
        rules.add_rule(seccomp.ALLOW, "write", seccomp.Arg(0, seccomp.EQ, fd))
    # Its own limits only, and signals only to itself (abort() and faulthandler use them).
    rules.add_rule(seccomp.ALLOW, "prlimit64", seccomp.Arg(0, seccomp.EQ, 0))
    pid = os.getpid()
    rules.add_rule(seccomp.ALLOW, "kill", seccomp.Arg(0, seccomp.EQ, pid))
    rules.add_rule(seccomp.ALLOW, "tgkill", seccomp.Arg(0, seccomp.EQ, pid))
    for child in children:
        rules.add_rule(seccomp.ALLOW, "kill", seccomp.Arg(0, seccomp.EQ, child))
        rules.add_rule(seccomp.ALLOW, "wait4", seccomp.Arg(0, seccomp.EQ, child))
    rules.load()


def current_address_space() -> int:
    """The bytes of address space this process maps now (its VmSize)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("cannot read VmSize from /proc/self/status")

"""The fence around a sandbox worker, the process that runs a student's code at grading time.

:func:`restrict_worker` fences the worker in before it loads the student's notebook:

* **resource limits**: CPU seconds, address space, file size, no core dumps, and death with
  the sandbox server;
* **reads** only of what the code needs (:func:`readable_roots`): the Python installation
  (``sys.prefix``, ``sys.base_prefix``, the standard library and site-packages folders), the
  system's shared libraries and the few system files that imports of NumPy, torch, PyBullet
  and Matplotlib open (:data:`SYSTEM_READS`: ``/usr/lib``, ``/lib``, ``/lib64``,
  ``/usr/share/zoneinfo``, ``/etc/ld.so.cache``, ``/proc/self``, ``/proc/cpuinfo`` (without it
  torch picks other CPU kernels, whose results differ from the grader's in the last bits),
  ``/dev/null``, ``/dev/urandom``, ...), the library's own folder ``dlo_course/`` and its data
  folder (``data/``: the mesh, the databases, the agents), the grading test file that holds
  the probe, the notebook being graded and the worker's scratch folder. So the student's code
  cannot read ``solutions/``, ``tests/grading/answers.py`` or anything else of the
  instructor's;
* **writes** only inside the scratch folder;
* **no new processes** (a seccomp filter: no fork, vfork, execve, clone without
  ``CLONE_THREAD``), no signals to other processes, no sockets, no ctypes, no walking the
  garbage collector (an audit hook).

Two mechanisms enforce the file-system fence, one behind the other:

1. **Linux Landlock** (kernel 5.13 and later, where it is enabled), the real boundary: the
   kernel itself refuses, for every system call of the process and of C extensions alike,
   to read a file (``LANDLOCK_ACCESS_FS_READ_FILE``) or list a folder
   (``LANDLOCK_ACCESS_FS_READ_DIR``) outside the readable roots, and to write, create,
   remove, rename or truncate outside the scratch folder. The ABI version the kernel reports
   decides what else is fenced (2: links across folders; 3: truncation; 4: TCP; 6: signals
   and abstract Unix sockets to processes outside).
2. **A Python audit hook** (:func:`_install_audit_hook`), always installed, and the only fence
   where Landlock is missing (another OS, an older or a Landlock-less kernel,
   ``DLO_COURSE_SANDBOX_LANDLOCK=0``): it refuses the ``open`` of a path outside the readable
   roots (by its name, made absolute with ``..`` folded, as Landlock-less checks must: a name
   under ``/proc/*/root`` is refused) and the listing of such a folder, as well as writes
   outside the scratch folder. An audit hook only sees what Python itself opens; it can be
   bypassed by code that calls the C library directly, which is why the same hook refuses
   every ``ctypes`` event (loading a library, calling a function, reading memory) and ``gc``
   introspection (the way to reach the hook's objects), and seccomp refuses new processes (a
   fresh interpreter would have no hook). What stays outside its sight is C and C++ code of
   the installed extensions that opens files by name itself (PyBullet's loaders,
   ``torch.from_file``); ``torch.save`` and ``torch.load`` by name are routed through the
   hook. Without Landlock, the read fence is therefore a strong fence for students, not a
   boundary against hostile code: grade untrusted work in a container.

A prefix that holds the repository itself (a Python installed inside the checkout's parent)
is never made readable as a whole: that would open ``solutions/`` again.
"""

from __future__ import annotations

import os
import sys
from typing import Iterable

RESULT_LIMIT = 64 * 2**20  # bytes of one result, or any file (RLIMIT_FSIZE of the worker)
SYSTEM_READS = ("/usr/lib", "/usr/lib64", "/lib", "/lib64", "/usr/share/zoneinfo",
                "/usr/share/fonts", "/etc/ld.so.cache", "/etc/localtime", "/etc/passwd",
                "/etc/group", "/etc/nsswitch.conf", "/etc/mime.types", "/etc/ssl/certs",
                "/proc/self", "/proc/thread-self", "/proc/cpuinfo", "/proc/meminfo",
                "/proc/stat", "/sys/devices/system/cpu", "/sys/devices/system/node", "/dev/null",
                "/dev/zero", "/dev/urandom", "/dev/random", "/dev/shm")
"""System files and folders the worker may read (those that exist)."""


def readable_roots(extra: Iterable[str] = ()) -> list[str]:
    """What a worker may read, symbolic links resolved: the Python installation, the
    :data:`SYSTEM_READS`, the ``dlo_course`` package and its data folder, and ``extra`` (the
    probe's test file, the notebook). A folder that contains the repository is left out."""
    import site
    import sysconfig

    from dlo_course.paths import DATA_DIR, REPO_ROOT

    roots = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix,
             *sysconfig.get_paths().values(), *site.getsitepackages(),
             os.path.dirname(os.path.dirname(os.path.abspath(__file__))),  # dlo_course/
             str(DATA_DIR), *SYSTEM_READS, *extra}
    if site.ENABLE_USER_SITE:
        roots.add(site.getusersitepackages())
    repo = os.path.realpath(REPO_ROOT) + "/"
    found = set()
    for root in roots:  # both the name (the audit hook's view) and the target (Landlock's)
        for name in (os.path.abspath(root), os.path.realpath(root)):
            if os.path.exists(name) and not repo.startswith(name.rstrip("/") + "/"):
                found.add(name)
    return sorted(found)


def _landlock(scratch: str, readable: Iterable[str] = ()) -> bool:
    """Allow reads only beneath ``scratch`` and ``readable`` (folders or files), writes only
    beneath ``scratch`` (and, kernel permitting, no TCP and no signals to processes outside),
    with Linux Landlock. False where the kernel lacks it."""
    import ctypes
    import stat

    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        abi = libc.syscall(444, None, ctypes.c_size_t(0), ctypes.c_uint32(1))
    except Exception:  # noqa: BLE001 - not Linux, or no syscall(): no Landlock
        return False
    if abi < 1:
        return False
    fs = sum(1 << bit for bit in (1, 4, 5, 6, 7, 8, 9, 10, 11, 12))  # write, remove, make
    read = (1 << 2) | (1 << 3)  # LANDLOCK_ACCESS_FS_READ_FILE, LANDLOCK_ACCESS_FS_READ_DIR
    file_rights = (1 << 0) | (1 << 1) | (1 << 2)  # execute, write, read: a file's own rights
    if abi >= 2:
        fs |= 1 << 13  # refer (link/rename across folders)
    if abi >= 3:
        fs |= 1 << 14  # truncate
        file_rights |= 1 << 14

    class Ruleset(ctypes.Structure):
        _fields_ = [("fs", ctypes.c_uint64), ("net", ctypes.c_uint64),
                    ("scoped", ctypes.c_uint64)]

    class PathBeneath(ctypes.Structure):
        _pack_ = 1
        _fields_ = [("allowed", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]

    ruleset = Ruleset(fs | read, 3 if abi >= 4 else 0, 3 if abi >= 6 else 0)
    size = 8 if abi < 4 else 16 if abi < 6 else 24
    fd = libc.syscall(444, ctypes.byref(ruleset), ctypes.c_size_t(size), ctypes.c_uint32(0))
    if fd < 0:
        return False

    def allow(path: str, access: int) -> bool:
        try:
            target = os.open(path, os.O_PATH | os.O_CLOEXEC)
        except OSError:  # gone since readable_roots() looked: nothing to allow
            return True
        try:
            if not stat.S_ISDIR(os.fstat(target).st_mode):
                access &= file_rights  # a rule on a file takes only a file's rights
            rule = PathBeneath(access, target)
            return libc.syscall(445, fd, 1, ctypes.byref(rule), ctypes.c_uint32(0)) == 0
        finally:
            os.close(target)

    ok = allow(scratch, fs | read)
    for path in readable:
        ok = ok and allow(path, read)
    ok = ok and libc.prctl(38, 1, 0, 0, 0) == 0  # PR_SET_NO_NEW_PRIVS
    ok = ok and libc.syscall(446, fd, ctypes.c_uint32(0)) == 0
    os.close(fd)
    if not ok:
        raise OSError(ctypes.get_errno(), "Landlock could not restrict the sandbox")
    return True


def _seccomp_no_processes() -> bool:
    """Forbid new processes and programs (fork, vfork, clone without CLONE_THREAD, execve)
    with a seccomp filter, so that nothing escapes the audit hook through a fresh process
    (``_posixsubprocess.fork_exec``, which multiprocessing and subprocess call, raises no
    audit event). Threads stay allowed. False where seccomp or the architecture is missing."""
    import ctypes
    import platform

    machine = platform.machine()
    if not sys.platform.startswith("linux"):
        return False
    if machine in ("x86_64", "AMD64"):
        arch, forbidden, clone, clone3 = 0xC000003E, (57, 58, 59, 322), 56, 435
    elif machine in ("aarch64", "arm64"):
        arch, forbidden, clone, clone3 = 0xC00000B7, (221, 281), 220, 435
    else:
        return False
    ld, jeq, jset, ret = 0x20, 0x15, 0x45, 0x06
    allow, eperm, enosys = 0x7FFF0000, 0x00050000 | 1, 0x00050000 | 38
    program = [(ld, 0, 0, 4), (jeq, 1, 0, arch), (ret, 0, 0, allow), (ld, 0, 0, 0)]
    if arch == 0xC000003E:  # the x32 ABI's system calls: none of ours
        program += [(0x35, 0, 1, 0x40000000), (ret, 0, 0, eperm)]  # jge
    for number in forbidden:
        program += [(jeq, 0, 1, number), (ret, 0, 0, eperm)]
    program += [(jeq, 0, 1, clone3), (ret, 0, 0, enosys)]  # libc falls back to clone
    program += [(jeq, 0, 4, clone), (ld, 0, 0, 16),  # clone: its flags, args[0]
                (jset, 0, 1, 0x00010000), (ret, 0, 0, allow), (ret, 0, 0, eperm)]
    program += [(ret, 0, 0, allow)]

    class Instruction(ctypes.Structure):
        _fields_ = [("code", ctypes.c_uint16), ("jt", ctypes.c_uint8), ("jf", ctypes.c_uint8),
                    ("k", ctypes.c_uint32)]

    class Program(ctypes.Structure):
        _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.POINTER(Instruction))]

    instructions = (Instruction * len(program))(*[Instruction(*i) for i in program])
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(38, 1, 0, 0, 0) != 0:  # PR_SET_NO_NEW_PRIVS
            return False
        fprog = Program(len(program), instructions)
        return libc.prctl(22, 2, ctypes.byref(fprog), 0, 0) == 0  # PR_SET_SECCOMP, FILTER
    except (OSError, AttributeError):
        return False


def _install_audit_hook(scratch: str, readable: Iterable[str] = ()) -> None:
    """An audit hook (it cannot be removed) that refuses, from here on: reading files or
    listing folders outside ``scratch`` and ``readable``; writing, creating, deleting or
    renaming files outside ``scratch``; subprocesses and forks; signals to other processes;
    sockets; ctypes; walking the garbage collector (to reach the hook)."""
    # Everything the hook uses is bound here, so that patching os, builtins or this module
    # afterwards changes nothing.
    fspath, getcwd, getpid, stat, s_isdir = os.fspath, os.getcwd, os.getpid, os.stat, \
        __import__("stat").S_ISDIR
    from pathlib import PosixPath, PurePosixPath

    path_types = (str, bytes, PosixPath, PurePosixPath)
    type_of, str_type, int_type = type, str, int
    denied_error = PermissionError
    root = scratch.rstrip("/") + "/"
    readable_prefixes = (root, *(name.rstrip("/") + "/" for name in readable))
    write_flags = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND
    directory_flag = getattr(os, "O_DIRECTORY", 0)
    own_pid = getpid()
    refused = frozenset({
        "os.system", "os.exec", "os.posix_spawn", "os.spawn", "os.fork", "os.forkpty",
        "subprocess.Popen", "pty.spawn", "os.symlink", "os.link", "os.mkfifo", "os.mknod",
        "ctypes.dlopen", "ctypes.dlsym", "ctypes.call_function", "ctypes.cdata",
        "ctypes.addressof", "ctypes.PyObj_FromPtr", "ctypes.string_at", "ctypes.wstring_at",
        "ctypes.cdata/buffer", "gc.get_objects", "gc.get_referrers", "gc.get_referents",
        "socket.connect", "socket.bind", "socket.sendto", "socket.sendmsg",
        "resource.setrlimit", "resource.prlimit", "sys.remote_exec", "os.setpgid"})
    path_events = {"os.remove": 1, "os.rmdir": 1, "os.rename": 2, "os.mkdir": 1,
                   "os.truncate": 1, "os.chmod": 1, "os.chown": 1, "os.utime": 1,
                   "os.chflags": 1, "os.lchflags": 1, "os.setxattr": 1, "os.removexattr": 1,
                   "shutil.rmtree": 1, "sqlite3.connect": 1, "shutil.move": 2,
                   "shutil.copyfile": 2, "shutil.copytree": 2}

    def normalised(path):
        if type_of(path) is bytes:
            path = path.decode("utf-8", "surrogateescape")
        elif type_of(path) is not str_type:
            path = fspath(path)
        if not path.startswith("/"):
            path = getcwd() + "/" + path
        parts = []
        for part in path.split("/"):
            if part in ("", "."):
                continue
            if part == "..":
                if parts:
                    parts.pop()
            else:
                parts.append(part)
        return "/" + "/".join(parts) + "/"

    def inside(path):
        if type_of(path) is int_type:  # an already opened file descriptor
            return True
        if type_of(path) not in path_types:
            return False
        return normalised(path).startswith(root)

    def may_read(path):
        if type_of(path) is int_type:
            return True
        if type_of(path) not in path_types:  # a PathLike of its own could change its mind
            return False
        name = normalised(path)
        if name.startswith("/proc/") and ("/root/" in name or "/cwd/" in name):
            return False  # /proc/self/root/... is a way out of every readable folder
        return name.startswith(readable_prefixes)

    def hook(event, args):
        if event == "open":
            path, mode, flags = args
            if type_of(mode) is str_type:
                writing = "w" in mode or "a" in mode or "x" in mode or "+" in mode
            else:
                writing = bool(flags & write_flags)
            if writing and not inside(path):
                raise denied_error(f"the grader's sandbox refuses to write {path!r}: write "
                                   "only inside the current (scratch) folder")
            if not writing and not may_read(path):
                raise denied_error(f"the grader's sandbox refuses to read {path!r}: only "
                                   "Python, the dlo_course library and its data, and the "
                                   "current (scratch) folder are readable")
            if mode is None and not inside(path) and type_of(path) in path_types:
                # os.open of a folder outside could serve as dir_fd= for a write there
                try:
                    is_folder = (flags & directory_flag) or s_isdir(stat(path).st_mode)
                except OSError:
                    is_folder = False
                if is_folder:
                    raise denied_error(f"the grader's sandbox refuses to open the folder "
                                       f"{path!r}")
        elif event in refused:
            raise denied_error(f"the grader's sandbox refuses {event}")
        elif event in ("os.listdir", "os.scandir"):
            if args[0] is not None and not may_read(args[0]):
                raise denied_error(f"the grader's sandbox refuses to list {args[0]!r}")
        elif event in path_events:
            for path in args[:path_events[event]]:
                if not inside(path):
                    raise denied_error(f"the grader's sandbox refuses {event} on {path!r} "
                                       "(outside the scratch folder)")
        elif event in ("os.kill", "os.killpg"):
            if args[0] not in (own_pid, 0) or event == "os.killpg":
                raise denied_error("the grader's sandbox refuses signals to other processes")
        elif event == "signal.pthread_kill":
            pass

    sys.addaudithook(hook)


def restrict_worker(scratch: str, timeout: float, memory_mb: float,
                    readable: Iterable[str] = ()) -> None:
    """Fence the calling process in (see the module's docstring): it may then read only
    :func:`readable_roots` (with the files ``readable``) and ``scratch``, and write only
    inside ``scratch``. ``DLO_COURSE_SANDBOX_LANDLOCK=0`` leaves Landlock out (the tests of
    the audit hook alone)."""
    import resource

    readable = readable_roots(readable)

    def vm_bytes() -> int:
        try:
            with open("/proc/self/statm") as f:
                return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError):
            return 0

    if sys.platform.startswith("linux"):  # die with the server, even while sleeping
        import ctypes

        try:
            ctypes.CDLL(None).prctl(1, 9, 0, 0, 0)  # PR_SET_PDEATHSIG, SIGKILL
        except (OSError, AttributeError):
            pass
    limits = [(resource.RLIMIT_CPU, int(timeout) + 2),
              (resource.RLIMIT_FSIZE, RESULT_LIMIT), (resource.RLIMIT_CORE, 0)]
    if memory_mb > 0:
        limits.append((resource.RLIMIT_AS, vm_bytes() + int(memory_mb * 2**20)))
    for which, value in limits:
        try:
            resource.setrlimit(which, (value, value))
        except (ValueError, OSError):
            pass
    if os.environ.get("DLO_COURSE_SANDBOX_LANDLOCK", "1") != "0":  # "0": tests of the hook
        try:
            _landlock(scratch, readable)
        except OSError:
            pass
    _seccomp_no_processes()
    torch_c = sys.modules.get("torch._C")
    for name, mode in (("PyTorchFileWriter", "wb"), ("PyTorchFileReader", "rb")):
        if torch_c is not None and hasattr(torch_c, name):
            # torch.save(obj, path) writes from C++, unseen by the audit hook: ask it first
            setattr(torch_c, name, _audited(getattr(torch_c, name), mode))
    _install_audit_hook(scratch, readable)


def _audited(opener, mode: str):
    """``opener`` (a C++ class that opens a file by name), raising the audit event ``open``
    first, so that the audit hook sees the name."""
    audit = sys.audit

    def checked(name, *args, **kwargs):
        if not hasattr(name, "write") and not hasattr(name, "read"):
            audit("open", name, mode, 0)
        return opener(name, *args, **kwargs)

    return checked

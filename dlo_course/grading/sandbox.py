"""The grading sandbox: students' code never runs in the grader's process.

A *server* process (:func:`sandbox_server`) imports the heavy libraries once and never runs
anything of a student; for every question the grader asks ("run probe P of test file F on
exercise E of this notebook"), it forks a *worker* that fences itself in
(:func:`dlo_course.grading.fence.restrict_worker`: memory, CPU time, file size; reads only of
the Python installation, the library and its data; writes only inside a fresh scratch folder;
no new processes, no signals to other processes, no sockets, no ctypes), runs the notebook's
setup cells and exercise cells (:class:`dlo_course.grading.runner.ExerciseNotebook`), calls
the probe on the student's object and writes what it returns, as plain data
(:mod:`dlo_course.grading.data`), to a result file. The grader's side, :class:`Sandbox`,
decodes that data (JSON: it cannot carry code) and checks it against references it computes
in its own, untouched process. A worker that hangs is killed at its time limit; one that
crashes, patches a library or exits early only loses its own exercise.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any, Iterable

from dlo_course.grading.data import decode_data, encode_data
from dlo_course.grading.fence import restrict_worker
from dlo_course.grading.runner import ExerciseError, ExerciseNotebook
from dlo_course.snapshot import fork_flushed

SANDBOX_PRELOAD = (
    "numpy", "torch", "torch.nn", "torch.nn.functional", "gymnasium", "matplotlib",
    "matplotlib.pyplot", "pytest", "dlo_course", "dlo_course.ddpg", "dlo_course.replay_buffer",
    "dlo_course.noise", "dlo_course.env", "dlo_course.simulation", "dlo_course.mesh",
    "dlo_course.database", "dlo_course.evaluation", "dlo_course.trainer", "dlo_course.mpi",
    "dlo_course.plots", "dlo_course.demo", "dlo_course.notebook")
SANDBOX_MEMORY_MB = float(os.environ.get("DLO_COURSE_GRADING_MEMORY_MB", 3072))
_HERE = os.path.dirname(os.path.abspath(__file__))  # the grading package: not the student's


def preload() -> None:
    """Import :data:`SANDBOX_PRELOAD` (before the fence: every worker forked afterwards finds
    them loaded) and keep torch to one thread."""
    import importlib

    for name in SANDBOX_PRELOAD:
        try:
            importlib.import_module(name)
        except Exception as err:  # noqa: BLE001
            print(f"sandbox: could not preload {name}: {err}", file=sys.stderr)
    try:
        import torch

        torch.set_num_threads(1)
        # the CPU's kernels are chosen on first use, from /proc/cpuinfo: choose them here, so
        # that a worker computes exactly as the grader does
        torch.backends.cpu.get_cpu_capability()
    except (ImportError, AttributeError):
        pass


GRADER_ONLY = ("reference_", "library_", "check_")  # test-file helpers never sent to a sandbox


def _load_probe(path: str, name: str):
    """The probe ``name`` of the test file ``path``, loaded in the worker without the file's
    grader-only helpers (:data:`GRADER_ONLY`: reference answers, checks), which the student's
    code could otherwise reach through the probe's globals."""
    import importlib.util

    module_name = "_dlo_probe_" + re.sub(r"\W", "_", Path(path).stem)
    module = sys.modules.get(module_name)
    if module is None:
        spec = importlib.util.spec_from_file_location(module_name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module
        spec.loader.exec_module(module)
        for key in [k for k in vars(module) if k.startswith(GRADER_ONLY)]:
            delattr(module, key)
    obj = module
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def _resolve(dotted: str) -> Any:
    import importlib

    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for part in parts[k:]:
            obj = getattr(obj, part)
        return obj
    raise ImportError(dotted)


def _poison(references: Iterable[str]) -> None:
    """Make the library's reference implementations raise when called (all their aliases,
    since the code of the function objects themselves is replaced)."""
    for dotted in references:
        try:
            obj = _resolve(dotted)
        except (ImportError, AttributeError):
            continue
        functions = [obj]
        if isinstance(obj, type):
            functions = [v for v in vars(obj).values()]
        for fn in functions:
            if isinstance(fn, property):
                fn = fn.fget
            fn = getattr(fn, "__func__", getattr(fn, "func", fn))
            code = getattr(fn, "__code__", None)
            if code is None or code.co_freevars:
                continue
            text = (f"def stub(*args, **kwargs):\n    raise RuntimeError("
                    f"{('the answer calls ' + dotted + ', the library reference of this exercise: write it yourself')!r})\n")
            scope: dict[str, Any] = {}
            exec(text, scope)  # noqa: S102 - our own, fixed text
            fn.__code__ = scope["stub"].__code__


def run_worker(request: dict[str, Any], result_fd: int) -> None:
    """In the forked worker: fence it in, load the exercise, run the probe, write the result.
    Beyond the Python installation and the library, it may read only the probe's test file
    and the notebook (a copy in its scratch folder, or beside the MPI ranks' folders)."""
    scratch = request["scratch"]
    os.chdir(scratch)
    tmp = os.path.join(scratch, "tmp")
    os.makedirs(tmp, exist_ok=True)
    os.environ.update(TMPDIR=tmp, MPLCONFIGDIR=tmp, HOME=scratch)
    tempfile.tempdir = tmp
    readable = [request["probe_file"]] + ([request["notebook"]] if request["notebook"] else [])
    restrict_worker(scratch, request["timeout"], request["memory_mb"], readable)
    response: dict[str, Any]
    try:
        probe = _load_probe(request["probe_file"], request["probe"])
        args = decode_data(request["args"])
        if request["notebook"] is None:  # a reference run (MPI): the probe uses the library
            response = {"status": "ok", "value": encode_data(probe(None, *args))}
        else:
            book = ExerciseNotebook.from_path(request["notebook"])
            try:
                obj = book.load(request["exercise"], earlier_timeout=request["timeout"] / 10)
            except ExerciseError as err:
                response = {"status": "not loaded", "message": str(err)}
            else:
                _poison(request.get("references", ()))
                value = probe(obj, *args)
                response = {"status": "ok", "value": encode_data(value)}
    except BaseException as err:  # noqa: BLE001 - anything the student's code raises
        import traceback

        frames = traceback.extract_tb(err.__traceback__)
        student = [f for f in frames if os.path.dirname(f.filename) != _HERE] or frames[-3:]
        text = "".join(traceback.format_list(student)) + \
            "".join(traceback.format_exception_only(type(err), err))
        response = {"status": "error", "message": text.strip()}
    payload = json.dumps(response).encode()
    view = memoryview(payload)
    while view:
        view = view[os.write(result_fd, view):]
    os.close(result_fd)


def sandbox_server() -> None:
    """The sandbox server's main loop (``python -c 'from dlo_course.grading.sandbox import
    sandbox_server; sandbox_server()'``): one JSON request per line on stdin, one JSON reply
    per line on stdout. It never runs a student's code itself."""
    import select
    import signal
    import time

    proto_in = os.fdopen(os.dup(0), "r")
    proto_out = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)  # whatever the libraries print goes to stderr, not into the protocol
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    preload()
    proto_out.write(json.dumps({"ready": True}) + "\n")
    proto_out.flush()
    private = {proto_in.fileno(), proto_out.fileno()}
    for line in proto_in:
        request = json.loads(line)
        scratch = request["scratch"]
        result_path = os.path.join(os.path.dirname(scratch), os.path.basename(scratch) + ".json")
        log_path = os.path.join(scratch, "output.txt")
        pid = fork_flushed()
        if pid == 0:  # the worker
            code = 0
            try:
                os.setpgid(0, 0)
                for fd in private:
                    os.close(fd)
                log = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
                os.dup2(log, 1)
                os.dup2(log, 2)
                os.close(log)
                result_fd = os.open(result_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
                run_worker(request, result_fd)
            except BaseException:  # noqa: BLE001
                code = 3
            finally:
                try:
                    sys.stdout.flush()
                    sys.stderr.flush()
                finally:
                    os._exit(code)
        deadline = time.monotonic() + float(request["timeout"])
        status = None
        while True:
            done, wait_status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            if time.monotonic() > deadline:
                for kill in (lambda: os.killpg(pid, signal.SIGKILL),
                             lambda: os.kill(pid, signal.SIGKILL)):
                    try:
                        kill()
                    except OSError:
                        pass
                os.waitpid(pid, 0)
                status = "timeout"
                break
            select.select([], [], [], 0.005)
        if status is None:
            if os.WIFSIGNALED(wait_status):
                sig = os.WTERMSIG(wait_status)
                status = "killed" if sig != signal.SIGXCPU else "timeout"
                reason = f"killed by signal {sig}"
            else:
                status, reason = "exited", f"exit code {os.WEXITSTATUS(wait_status)}"
        else:
            reason = "time limit"
        try:  # a process group member left behind (the hook refuses forks; just in case)
            os.killpg(pid, signal.SIGKILL)
        except OSError:
            pass
        proto_out.write(json.dumps({"status": status, "reason": reason,
                                    "result": result_path, "log": log_path}) + "\n")
        proto_out.flush()


def read_result(text: str, result: dict[str, Any]) -> None:
    """Update ``result`` (``status``, ``message``, ``value``) from a worker's result file."""
    try:
        data = json.loads(text)
        result.update(status=str(data["status"]), message=str(data.get("message", "")))
        if result["status"] == "ok":
            result["value"] = decode_data(data["value"])
    except (ValueError, KeyError, TypeError, RecursionError) as err:
        result.update(status="error", message=f"unreadable result: {err!r:.300}")


class SandboxError(Exception):
    """The sandbox itself failed (it could not start, or it stopped answering)."""


class Sandbox:
    """The grader's side of the sandbox: starts the server lazily, asks it to run probes,
    restarts it if it ever dies, and decodes the results.

    Args:
        timeout: wall-clock (and CPU) seconds of one probe.
        memory_mb: address space a worker may add to what the server has mapped.
    """

    def __init__(self, timeout: float = 60.0, memory_mb: float = SANDBOX_MEMORY_MB):
        self.timeout, self.memory_mb = float(timeout), float(memory_mb)
        self._tmp = tempfile.TemporaryDirectory(prefix="dlo-grading-")
        self.root = Path(self._tmp.name).resolve()
        self._proc: subprocess.Popen | None = None
        self._count = 0

    def _start(self) -> None:
        env = dict(os.environ, MPLBACKEND="Agg", DLO_COURSE_FAST="1", OMP_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONDONTWRITEBYTECODE="1",
                   MPLCONFIGDIR=str(self.root / "mpl"),
                   DLO_COURSE_OUTPUT=str(self.root / "output"))
        env.pop("PYTHONSTARTUP", None)
        log = open(self.root / "server.log", "ab")
        self._proc = subprocess.Popen(
            [sys.executable, "-c", "from dlo_course.grading.sandbox import sandbox_server; "
                                   "sandbox_server()"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, cwd=self.root, env=env)
        log.close()
        reply = self._read(max(120.0, self.timeout))
        if not reply.get("ready"):
            raise SandboxError("the grading sandbox did not start")

    def _read(self, timeout: float) -> dict[str, Any]:
        import select

        assert self._proc is not None and self._proc.stdout is not None
        ready, _, _ = select.select([self._proc.stdout], [], [], timeout)
        line = self._proc.stdout.readline() if ready else b""
        if not line:
            self.close()
            tail = ""
            if (self.root / "server.log").is_file():
                tail = (self.root / "server.log").read_text(errors="replace")[-2000:]
            raise SandboxError(f"the grading sandbox stopped answering\n{tail}")
        return json.loads(line)

    def run(self, notebook: str | Path | None, exercise: str, probe_file: str | Path,
            probe: str, args: tuple = (), references: Iterable[str] = (),
            timeout: float | None = None) -> dict[str, Any]:
        """Run ``probe(obj, *args)`` in a fresh worker, ``obj`` being what the exercise cell
        of ``notebook`` defines (``notebook`` None: ``probe(None, *args)``, no student code
        run, e.g. to evaluate an actor file handed in, passed as bytes), within ``timeout``
        seconds (default: the sandbox's). Returns ``status`` ("ok", "not loaded", "error",
        "timeout", "killed", "exited"), ``value`` (decoded data, if ok), ``message`` and
        ``output`` (what the worker printed)."""
        timeout = self.timeout if timeout is None else float(timeout)
        if self._proc is None or self._proc.poll() is not None:
            self._start()
        self._count += 1
        scratch = self.root / f"scratch{self._count:04d}"
        scratch.mkdir()
        copy_path = None if notebook is None else scratch / Path(notebook).name
        if copy_path is not None:
            copy_path.write_bytes(Path(notebook).read_bytes())
        request = {"scratch": str(scratch), "notebook": copy_path and str(copy_path),
                   "exercise": exercise,
                   "probe_file": str(Path(probe_file).resolve()), "probe": probe,
                   "args": encode_data(tuple(args)), "references": list(references),
                   "timeout": timeout, "memory_mb": self.memory_mb}
        assert self._proc is not None and self._proc.stdin is not None
        try:
            self._proc.stdin.write((json.dumps(request) + "\n").encode())
            self._proc.stdin.flush()
        except OSError as err:
            self.close()
            raise SandboxError(f"the grading sandbox is gone: {err}") from err
        reply = self._read(timeout + 60)
        output = ""
        log = Path(reply["log"])
        if log.is_file():
            output = log.read_bytes()[-20_000:].decode(errors="replace")
        result: dict[str, Any] = {"status": reply["status"], "output": output, "value": None,
                                  "message": ""}
        path = Path(reply["result"])
        if reply["status"] == "timeout":
            result["message"] = f"the exercise ran longer than its time limit ({timeout:g} s)"
        elif path.is_file() and path.stat().st_size and reply["status"] == "exited":
            read_result(path.read_text(), result)
        else:
            result.update(status="error" if reply["status"] == "exited" else reply["status"],
                          message=f"the exercise's process ended without a result "
                                  f"({reply['reason']})")
        path.unlink(missing_ok=True)
        import shutil

        shutil.rmtree(scratch, ignore_errors=True)
        return result

    def close(self) -> None:
        if self._proc is not None:
            for stream in (self._proc.stdin, self._proc.stdout):
                try:
                    stream.close()
                except (OSError, AttributeError):
                    pass
            try:
                self._proc.kill()
                self._proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                pass
            self._proc = None

    def __del__(self):
        self.close()

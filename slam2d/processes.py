"""Child processes that never outlive their parent, and folders that name the process owning them."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
import pickle
import signal
import socket
import subprocess
import sys
from pathlib import Path

PR_SET_PDEATHSIG = 1  # linux/prctl.h
OWNER_FILE = ".owner"  # in a hidden work folder: "PID HOST" of the process filling it


def die_with_parent(parent: int, sig: int = signal.SIGKILL) -> None:
    """In a child process: receive ``sig`` when the parent thread that made it exits (Linux ``prctl``;
    a no-op elsewhere), and exit now if ``parent`` (the pid it was made by) is already gone."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(128 + int(sig))


def call_forked(fn, *args):
    """``fn(*args)`` computed in a forked child process and its (picklable) result returned through a pipe; an
    exception there is raised here. Whatever interrupts the wait here (the KeyboardInterrupt of a SIGINT or
    SIGTERM) kills the child at once (SIGKILL) and reaps it, so a long C++ call that holds the interpreter
    (a GTSAM solve) stops as soon as the signal arrives. The child dies with this process (:func:`die_with_parent`).
    Where ``os.fork`` is missing, ``fn(*args)`` runs here. Cost: 7 ms for an empty call, plus the copy-on-write
    of the memory the child writes (a solve over M3500: +10 %)."""
    if not hasattr(os, "fork"):
        return fn(*args)
    parent = os.getpid()
    read, write = os.pipe()
    pid = _fork(parent)
    if pid == 0:
        _child(read, write, parent, fn, args)
    os.close(write)
    try:
        with os.fdopen(read, "rb") as pipe:
            data = pipe.read()
    except BaseException:
        os.kill(pid, signal.SIGKILL)
        raise
    finally:
        os.waitpid(pid, 0)
    if not data:
        raise RuntimeError(f"the worker process of {getattr(fn, '__qualname__', fn)} died without a result")
    ok, value = pickle.loads(data)
    if not ok:
        raise value
    return value


def _fork(parent: int) -> int:
    """``os.fork()`` from ``parent`` (this process), its objects frozen meanwhile: the child's collector then leaves
    them alone, so fewer pages are copied on write."""
    gc.freeze()
    try:
        return os.fork()
    finally:
        if os.getpid() == parent:
            gc.unfreeze()


def _child(read: int, write: int, parent: int, fn, args) -> None:
    """In :func:`call_forked`'s child: compute, send ``(ok, result or exception)``, exit without clean-up."""
    try:
        os.close(read)
        _detach(parent)
        try:
            out = (True, fn(*args))
        except BaseException as err:  # noqa: BLE001 (raised again in the parent)
            out = (False, err)
        with os.fdopen(write, "wb") as pipe:
            pipe.write(_pickled(out))
    finally:
        os._exit(0)


class Worker:
    """A forked child process that computes the calls sent to it (``call``, ``submit``), one at a time, after
    ``prepare()``, which runs there while this process goes on (an import it would otherwise wait for). Calls and
    results go through pipes, pickled: a call's function must be importable by name. As in :func:`call_forked`,
    whatever interrupts a wait kills the child at once, an exception there is raised here, and the child dies with
    this process; ``close`` (the end of a with block) kills and reaps it. Where ``os.fork`` is missing, ``prepare``
    and the calls run here."""

    def __init__(self, prepare=None) -> None:
        self.pid = None
        if not hasattr(os, "fork"):
            if prepare is not None:
                prepare()
            return
        parent = os.getpid()
        down, up = os.pipe(), os.pipe()  # (read, write) of the calls, of the results
        pid = _fork(parent)
        if pid == 0:
            os.close(down[1])
            os.close(up[0])
            _serve(down[0], up[1], parent, prepare)
        os.close(down[0])
        os.close(up[1])
        self.pid, self._calls, self._results = pid, os.fdopen(down[1], "wb"), os.fdopen(up[0], "rb")

    def call(self, fn, *args):
        """``fn(*args)`` computed in the child (here once it is closed or where there is no fork)."""
        return self.submit(fn, *args)()

    def submit(self, fn, *args):
        """Send ``fn(*args)`` to the child and return a function that waits for its result: this process goes
        on meanwhile. One call at a time: wait for a result before the next call."""
        if self.pid is None:
            value = fn(*args)
            return lambda: value
        try:
            _send(self._calls, pickle.dumps((fn, args)))
        except BaseException:
            self.close()
            raise
        return lambda: self._result(fn)

    def _result(self, fn):
        try:
            data = _receive(self._results)
        except BaseException:
            self.close()
            raise
        if data is None:
            self.close()
            raise RuntimeError(f"the worker process of {getattr(fn, '__qualname__', fn)} died without a result")
        ok, value = pickle.loads(data)
        if not ok:
            raise value
        return value

    def close(self) -> None:
        if self.pid is None:
            return
        pid, self.pid = self.pid, None
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        for pipe in (self._calls, self._results):
            with contextlib.suppress(OSError):
                pipe.close()
        os.waitpid(pid, 0)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _send(pipe, data: bytes) -> None:
    pipe.write(len(data).to_bytes(8, "little") + data)
    pipe.flush()


def _receive(pipe) -> bytes | None:
    """The next message of ``pipe``; None at its end (the other process has gone)."""
    head = pipe.read(8)
    if len(head) < 8:
        return None
    data = pipe.read(int.from_bytes(head, "little"))
    return data if len(data) == int.from_bytes(head, "little") else None


def _serve(read: int, write: int, parent: int, prepare) -> None:
    """In a :class:`Worker`'s child: ``prepare()``, then compute each call and send ``(ok, result or exception)``
    until the calls' pipe closes; exit without clean-up."""
    try:
        _detach(parent)
        if prepare is not None:
            with contextlib.suppress(Exception):  # the calls that need it fail, and say why
                prepare()
        with os.fdopen(read, "rb") as calls, os.fdopen(write, "wb") as results:
            while (data := _receive(calls)) is not None:
                try:
                    fn, args = pickle.loads(data)
                    out = (True, fn(*args))
                except BaseException as err:  # noqa: BLE001 (raised again in the parent)
                    out = (False, err)
                _send(results, _pickled(out))
    finally:
        os._exit(0)


def _detach(parent: int) -> None:
    """In a forked child: SIGINT / SIGTERM at their default (the parent's Python handlers would wait for a long
    C++ call), death with ``parent``, no garbage collection (fewer pages copied on write)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) not in (signal.SIG_IGN, signal.SIG_DFL):  # an ignored signal stays ignored
            signal.signal(sig, signal.SIG_DFL)
    die_with_parent(parent)
    gc.disable()


def _pickled(out) -> bytes:
    try:
        return pickle.dumps(out)
    except Exception:  # noqa: BLE001 (an exception that does not pickle)
        return pickle.dumps((False, RuntimeError(repr(out[1]))))


_REAPER = """
import os, signal, sys, time
parent, markers = int(sys.argv[1]), [m.encode() for m in sys.argv[2:]]

def table():
    links = {}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/stat") as stat:
                fields = stat.read().rsplit(")", 1)[1].split()
            links[int(pid)] = (int(fields[1]), fields[19])  # parent, start time
        except (OSError, IndexError, ValueError):
            pass
    return links

def watchdog(pid):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
            return b"def watchdog(pid)" in cmdline.read()
    except OSError:
        return False

def family(links, roots):
    found, todo = {}, list(roots)
    while todo:
        p = todo.pop()
        for pid, (ppid, start) in links.items():
            if ppid == p and pid not in found and not watchdog(pid):
                found[pid] = start
                todo.append(pid)
    return found

def marked(links):
    found = {}
    for pid, (_, start) in links.items():
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
                if any(m in cmdline.read() for m in markers) and not watchdog(pid):
                    found[pid] = start
        except OSError:
            pass
    return found

known = {}
while os.getppid() == parent:
    known.update(family(table(), [parent]))  # kept: a look just after the parent's death finds none
    time.sleep(0.5)
def send(pids, sig, links):
    for pid, start in pids.items():
        if links.get(pid, (0, None))[1] == start:
            try:
                os.kill(pid, sig)
            except OSError:
                pass

for _ in range(3):  # frozen first, so that none starts another process while the others are killed
    links = table()
    known.update(family(links, known))  # started since the last look
    known.update(marked(links) if markers else {})
    send(known, signal.SIGSTOP, links)
    time.sleep(0.05)
send(known, signal.SIGKILL, table())
"""
_WATCHING: set[str] = set()  # the markers this process's watchdogs look for ("" : its descendants only)


def reap_when_gone(marker: str = "") -> None:
    """Start a watchdog that, within a second of this process's exit (``kill -9`` included), kills what were
    its descendants then and, with ``marker``, every process whose command line holds it: processes a library
    starts that do not watch their parent (a local Ray instance's servers and agents, some of which leave
    the process tree; ``marker``: its session folder). A marker counts only if a child of this process holds
    it (an instance it started, not one it joined). Once per marker; Linux, a no-op elsewhere."""
    if marker in _WATCHING or not sys.platform.startswith("linux") or (marker and not _children_with(marker)):
        return
    _WATCHING.add(marker)
    subprocess.Popen([sys.executable, "-c", _REAPER, str(os.getpid()), *([marker] if marker else [])],
                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                     start_new_session=True)


def _children_with(marker: str) -> bool:
    """Whether a child of this process has ``marker`` in its command line (Linux /proc)."""
    me, wanted = str(os.getpid()), marker.encode()
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            ppid = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1]
            if ppid == me and wanted in Path(f"/proc/{pid}/cmdline").read_bytes():
                return True
        except (OSError, IndexError):
            pass
    return False


def parent_gone(parent: int, owner: int | None = None) -> bool:
    """Whether this process's parent is no longer ``parent`` (it died and this one was adopted), or
    ``owner`` (the process that started the work, further up) no longer runs."""
    return os.getppid() != parent or (owner is not None and not alive(owner))


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (one that has exited but is not yet reaped does not); True if unknowable."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return not _zombie(pid)


def claim(folder: Path) -> None:
    """Record in ``folder`` that this process fills it (see :func:`stale`)."""
    (folder / OWNER_FILE).write_text(f"{os.getpid()} {socket.gethostname()}\n")


def release(folder: Path) -> None:
    """Remove the owner record of ``folder`` (before it is published)."""
    (folder / OWNER_FILE).unlink(missing_ok=True)


def stale(folder: Path, ownerless: bool = False) -> bool:
    """Whether ``folder``'s owner (:func:`claim`) is a process of this host that no longer runs;
    ``ownerless``: a folder without an owner record counts as stale too."""
    try:
        pid, host = (folder / OWNER_FILE).read_text().split()
        pid = int(pid)
    except FileNotFoundError:
        return ownerless
    except (OSError, ValueError):
        return False
    if host != socket.gethostname():
        return False  # a folder on a shared disk, filled on another machine
    return not alive(pid)


def _zombie(pid: int) -> bool:
    """Whether ``pid`` has exited but not been reaped yet (Linux; False elsewhere)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except (OSError, IndexError):
        return False

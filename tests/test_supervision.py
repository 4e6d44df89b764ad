"""Nothing outlives its command: child processes die with it, signals exit 130 / 143 without a traceback,
and a later run removes the hidden folders a killed one left."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import psutil
import pytest
import yaml

from slam2d import processes
from slam2d.runs.results import remove_stale, results_folder


def _cli(*args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "slam2d.cli", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kwargs)


def _wait_for(predicate, timeout=120.0):
    end = time.monotonic() + timeout
    while not (found := predicate()):
        assert time.monotonic() < end, "timed out"
        time.sleep(0.1)
    return found


def _living(procs) -> list:
    return [p for p in procs if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]


def _state(root) -> dict:
    """Every file under ``root`` with its size and modification time."""
    return {str(p): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*") if p.is_file()}


def _sweep(tmp_path, variants, workers=1):
    path = tmp_path / "sweep.yaml"
    config = {"output": {"root": str(tmp_path / "res")}, "mapping": {"resolution": 0.1}}
    path.write_text(yaml.safe_dump({"workers": workers, "config": config, "variants": variants}))
    return path


def _kill_9_leaves_nothing_running(proc, root, grandchildren: int) -> None:
    """Wait until ``proc`` has ``grandchildren`` descendants, kill -9 it; check none of them runs 2 s later
    and that nothing under ``root`` changes after that."""
    parent = psutil.Process(proc.pid)
    family = _wait_for(lambda: (kids := parent.children(recursive=True)) and len(kids) >= grandchildren and kids)
    time.sleep(0.5)
    proc.kill()
    proc.wait(timeout=30)
    time.sleep(2.0)
    assert [(p.pid, p.cmdline()) for p in _living(family)] == []
    before = _state(root)
    time.sleep(1.5)
    assert _state(root) == before


def test_kill_9_run_takes_its_frontend_worker_along(tmp_path):
    root = tmp_path / "results"
    proc = _cli("run", "-q", "--set", f"output.root={root}")
    _kill_9_leaves_nothing_running(proc, tmp_path, 1)
    (hidden,) = root.iterdir()  # killed outright: its hidden folder stays, owned by a dead process
    assert hidden.name.startswith(".sim-") and processes.stale(hidden)


def test_kill_9_ablate_takes_its_pool_along(tmp_path):
    sweep = _sweep(tmp_path, [{"name": f"v{i}", "set": {"seed": i}} for i in range(3)], workers=2)
    proc = _cli("ablate", "-q", sweep)
    # the forkserver, two workers, their frontend workers
    _kill_9_leaves_nothing_running(proc, tmp_path / "res", 5)


def test_kill_9_ablate_on_ray_takes_its_local_ray_along(tmp_path):
    """Ray's servers, agents and task workers do not watch their parent; the sweep's watchdog kills them."""
    if os.environ.get("CI") != "true" and os.environ.get("SLAM2D_REQUIRE_DATA") != "1":
        pytest.importorskip("ray")  # CI installs the [ray] extra: there a missing ray fails the test
    sweep = _sweep(tmp_path, [{"name": f"v{i}", "set": {"seed": i}} for i in range(3)], workers=2)
    proc = _cli("ablate", "-q", sweep, "--executor", "ray")
    parent = psutil.Process(proc.pid)

    def running():  # Ray's processes once its task workers run variants
        family = parent.children(recursive=True)
        return any("_run_variant" in " ".join(p.cmdline()) for p in _living(family)) and family

    _wait_for(running, timeout=180)
    time.sleep(1.0)
    family = parent.children(recursive=True)
    assert any("Agent" in " ".join(p.cmdline()) for p in family)  # their titles no longer name the session
    proc.kill()
    proc.wait(timeout=30)
    time.sleep(2.0)
    assert [(p.pid, p.cmdline()) for p in _living(family)] == []


def test_a_later_run_removes_only_folders_of_dead_owners(tmp_path, caplog):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale, alive, foreign = (tmp_path / n for n in (".sim-aaaa", ".sim-bbbb", ".git-cccc"))
    for folder in (stale, alive, foreign):
        folder.mkdir()
    (stale / processes.OWNER_FILE).write_text(f"{dead.pid} {processes.socket.gethostname()}\n")
    (alive / processes.OWNER_FILE).write_text(f"{os.getpid()} {processes.socket.gethostname()}\n")
    with caplog.at_level("INFO", logger="slam2d"):
        with results_folder(tmp_path, "sim") as (work, published):
            assert (work / processes.OWNER_FILE).is_file()
    assert not stale.exists() and alive.exists() and foreign.exists()
    assert "removed 1 hidden folder left by killed runs" in caplog.text
    assert not (published[0] / processes.OWNER_FILE).exists()
    assert remove_stale(tmp_path, ownerless=True) == 1 and not foreign.exists()


def test_die_with_parent_exits_when_the_parent_is_already_gone():
    code = "import os; from slam2d import processes; processes.die_with_parent(os.getppid() + 1); print('alive')"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 128 + signal.SIGKILL and done.stdout == ""


# ---------------------------------------------------------------- signals: 130, 143, no traceback


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_signal_to_the_group_during_run(tmp_path, sig, code):
    root = tmp_path / "results"
    proc = _cli("run", "-q", "--set", f"output.root={root}", start_new_session=True)
    _wait_for(lambda: psutil.Process(proc.pid).children())
    time.sleep(1.0)
    os.killpg(proc.pid, sig)  # as a terminal's Ctrl-C or a scheduler does: every process of the group
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert "Traceback" not in err and "stopped: no results folder written" in err
    assert list(root.iterdir()) == []


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_signal_to_the_group_during_ablate(tmp_path, sig, code):
    sweep = _sweep(tmp_path, [{"name": "a", "set": {"seed": 1}}, {"name": "b", "set": {"seed": 2}}], workers=2)
    proc = _cli("ablate", "-q", sweep, start_new_session=True)
    runs = lambda: list((tmp_path / "res").glob("ablate-sweep-*/runs/.*"))  # noqa: E731
    _wait_for(lambda: len(runs()) == 2)
    family = psutil.Process(proc.pid).children(recursive=True)
    time.sleep(0.5)
    os.killpg(proc.pid, sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert "Traceback" not in err and "0 of 2 variants finished" in err
    assert runs() == []
    time.sleep(1.0)
    assert _living(family) == []


def test_python_dash_m_slam2d_is_the_command():
    done = subprocess.run([sys.executable, "-m", "slam2d", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.startswith("slam2d "), done.stderr


def test_interrupt_python_cannot_raise_is_quiet_and_raised_later(monkeypatch):
    """A signal landing in a ``__del__`` (or an at-fork callback) prints no traceback; the next check stops."""
    from slam2d.runs import signals

    monkeypatch.setattr(signals, "_STOPPED", False)
    monkeypatch.setattr(signals, "_SIGNAL", 0)
    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)  # where Python prints "Exception ignored"

    class SignalledWhileCollected:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(10_000):  # the handler runs here, inside __del__
                pass

    with pytest.raises(KeyboardInterrupt), signals.stop_on_signals():
        SignalledWhileCollected()
        assert signals.stopped()
        signals.check_stop()
    assert unraisable == []

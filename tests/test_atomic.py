"""Atomic file writes and result directories: complete or absent, never half-written."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from clothlab.atomic import atomic_directory, atomic_write_bytes, atomic_write_text
from clothlab.errors import ResultExistsError


def hidden(directory):
    return sorted(p.name for p in directory.iterdir() if p.name.startswith("."))


def test_write_text_creates_and_replaces(tmp_path):
    path = tmp_path / "sub" / "a.txt"
    assert atomic_write_text(path, "first\n") == path
    assert path.read_text() == "first\n"
    atomic_write_text(path, "second ü\r\n")
    assert path.read_bytes() == "second ü\r\n".encode()
    assert hidden(path.parent) == []


def test_written_file_has_normal_permissions(tmp_path):
    path = atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01")
    mask = os.umask(0o022)
    os.umask(mask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~mask


def test_failed_write_leaves_old_file_and_no_temp(tmp_path, monkeypatch):
    path = tmp_path / "c.txt"
    path.write_text("old")

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        atomic_write_text(path, "new")
    assert path.read_text() == "old"
    assert hidden(tmp_path) == []


def test_directory_created_on_success(tmp_path):
    dest = tmp_path / "fits" / "run"
    with atomic_directory(dest) as work:
        assert work.parent == dest.parent and work.name.startswith(".")
        assert not dest.exists()
        (work / "params.json").write_text("{}")
    assert (dest / "params.json").read_text() == "{}"
    assert hidden(dest.parent) == []


def test_existing_directory_refused_before_any_work(tmp_path):
    dest = tmp_path / "run"
    dest.mkdir()
    (dest / "keep").write_text("old")
    ran = []
    with pytest.raises(ResultExistsError, match="--force") as info:
        with atomic_directory(dest):
            ran.append(True)
    assert not ran
    assert str(dest) in str(info.value)
    assert (dest / "keep").read_text() == "old"
    assert hidden(tmp_path) == []


def test_force_replaces_only_after_completion(tmp_path):
    dest = tmp_path / "run"
    dest.mkdir()
    (dest / "old").write_text("old")
    with atomic_directory(dest, force=True) as work:
        assert (dest / "old").read_text() == "old"  # still there while the new result is built
        (work / "new").write_text("new")
    assert sorted(p.name for p in dest.iterdir()) == ["new"]
    assert hidden(tmp_path) == []


@pytest.mark.parametrize("existing", [False, True])
def test_exception_leaves_old_result_and_no_temp_dirs(tmp_path, existing):
    dest = tmp_path / "run"
    if existing:
        dest.mkdir()
        (dest / "old").write_text("old")
    with pytest.raises(RuntimeError, match="fit diverged"):
        with atomic_directory(dest, force=True) as work:
            (work / "partial").write_text("half")
            raise RuntimeError("fit diverged")
    if existing:
        assert sorted(p.name for p in dest.iterdir()) == ["old"]
        assert (dest / "old").read_text() == "old"
    else:
        assert not dest.exists()
    assert hidden(tmp_path) == []


def test_directory_appearing_during_work_is_not_clobbered(tmp_path):
    dest = tmp_path / "run"
    with pytest.raises(ResultExistsError):
        with atomic_directory(dest) as work:
            (work / "new").write_text("new")
            dest.mkdir()
            (dest / "other").write_text("someone else's")
    assert sorted(p.name for p in dest.iterdir()) == ["other"]
    assert hidden(tmp_path) == []


# ---------------------------------------------------------------------------------------------------------
# Safe at every instant: fault injection, recovery, the per-result lock, output checks

CHILD = r"""
import os, signal, sys
from pathlib import Path
import clothlab.atomic as atomic
dest, step, exchange = Path(sys.argv[1]), sys.argv[2], sys.argv[3] == "1"
if not exchange:
    atomic._exchange = lambda a, b: False
def kill(name):
    if name == step:
        os.kill(os.getpid(), signal.SIGKILL)
atomic._step = kill
with atomic.atomic_directory(dest, force=True) as tmp:
    for i in range(5):
        (tmp / f"f{i}").write_text("new")
        if step == f"write{i}":
            os.kill(os.getpid(), signal.SIGKILL)
"""

FILES = [f"f{i}" for i in range(5)]


def _content(dest):
    names = sorted(p.name for p in dest.iterdir())
    assert names == FILES, names  # complete: every file of one result
    texts = {(dest / n).read_text() for n in names}
    assert len(texts) == 1, texts  # and not a mix of two
    return texts.pop()


@pytest.mark.parametrize("exchange", [True, False], ids=["exchange", "rename-aside"])
@pytest.mark.parametrize("step", ["write0", "write2", "write4", "built", "exchanged", "aside", "renamed", "none"])
def test_sigkill_anywhere_in_the_swap_leaves_old_or_new_complete(tmp_path, exchange, step):
    import signal
    import subprocess
    import sys

    from clothlab.atomic import result_lock

    dest = tmp_path / "fits" / "run"
    dest.mkdir(parents=True)
    for name in FILES:
        (dest / name).write_text("old")
    child = subprocess.run([sys.executable, "-c", CHILD, str(dest), step, "1" if exchange else "0"],
                           capture_output=True, text=True, timeout=120)
    assert child.returncode in (0, -signal.SIGKILL), child.stderr
    with result_lock(dest):  # what the next command does first: recover an interrupted swap
        pass
    text = _content(dest)
    killed_before_commit = step.startswith("write") or step == "built" or step == "aside"
    if child.returncode == 0 or not killed_before_commit:
        assert text == "new"
    else:
        assert text == "old"
    assert hidden(dest.parent) == []  # no stale .tmp-*, .old-* or lock left behind


def test_recover_restores_an_orphaned_old_result_and_removes_stale_temporaries(tmp_path):
    from clothlab.atomic import recover

    dest = tmp_path / "run"
    old = tmp_path / ".run.old-0123456789ab"
    old.mkdir()
    (old / "fit.json").write_text("{}")
    stale = tmp_path / ".run.tmp-abc"
    stale.mkdir()
    (stale / "half").write_text("half")
    actions = recover(dest)
    assert (dest / "fit.json").read_text() == "{}"
    assert hidden(tmp_path) == [] and len(actions) == 2
    assert any("restored" in a for a in actions)


LOCK_HOLDER = r"""
import sys, time
from clothlab.atomic import result_lock
with result_lock(sys.argv[1]):
    print("held", flush=True)
    time.sleep(60)
"""


@pytest.fixture
def lock_held_elsewhere(tmp_path):
    import subprocess
    import sys

    dest = tmp_path / "fits" / "run"
    holder = subprocess.Popen([sys.executable, "-c", LOCK_HOLDER, str(dest)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        yield dest
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()


def test_second_writer_of_one_result_is_refused_before_any_work(lock_held_elsewhere):
    from clothlab.errors import ResultBusyError

    ran = []
    with pytest.raises(ResultBusyError, match="another clothlab command") as info:
        with atomic_directory(lock_held_elsewhere, force=True):
            ran.append(True)
    assert not ran and info.value.path == str(lock_held_elsewhere)
    assert not lock_held_elsewhere.exists()


def test_concurrent_fit_of_one_name_is_refused_before_it_runs(lock_held_elsewhere, tmp_path, capsys, monkeypatch):
    import clothlab.fit.runner as runner
    from clothlab.cli.main import main

    table = ["# clothlab-table: 1", "# angle_unit: deg", "# quantity: brdf", "# azimuth_zero: weft",
             "# azimuth_sense: ccw", "# channels: [Y]", "theta_i,phi_i,theta_o,phi_o,Y",
             "30,0,30,180,0.1", "40,0,30,180,0.2", "50,0,30,90,0.3"]
    (tmp_path / "m.csv").write_text("\n".join(table) + "\n")
    (tmp_path / "fabric.yaml").write_text(
        "name: run\nmeasurement: {path: m.csv}\nmodel: {kind: irawan, weave: preset:cotton-denim}\n"
        "output: {fits: fits, reports: reports}\n")
    monkeypatch.setattr(runner, "run_fit", lambda *a, **k: pytest.fail("the fit ran"))
    assert main(["fit", str(tmp_path / "fabric.yaml")]) == 2
    assert "another clothlab command is writing" in capsys.readouterr().err


@pytest.mark.parametrize("case", ["file-parent", "nul", "long-name", "proc"])
def test_unusable_output_paths_are_refused_naming_the_path(tmp_path, case):
    from clothlab.errors import OutputError

    if case == "file-parent":
        (tmp_path / "fits").write_text("a file")
        dest = tmp_path / "fits" / "run"
    elif case == "nul":
        dest = tmp_path / "ru\x00n"
    elif case == "long-name":
        dest = tmp_path / ("n" * 250)
    else:
        dest = Path("/proc/clothlab-test/run")
    with pytest.raises(OutputError) as info:
        with atomic_directory(dest):
            pytest.fail("work ran")
    assert info.value.path is not None
    assert hidden(tmp_path) == []


def test_interrupt_recorded_but_swallowed_never_commits(tmp_path):
    import signal

    import clothlab.atomic as atomic

    dest = tmp_path / "run"
    dest.mkdir()
    (dest / "f").write_text("old")
    previous = signal.getsignal(signal.SIGINT)
    try:
        _interrupted_build(atomic, dest)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert (dest / "f").read_text() == "old" and hidden(tmp_path) == []


def _interrupted_build(atomic, dest):
    import signal

    with atomic.interrupts_recorded():
        with pytest.raises(KeyboardInterrupt):
            with atomic_directory(dest, force=True) as work:
                (work / "f").write_text("new")
                try:  # a Ctrl-C that a C callback swallows (as llvmlite does during numba compilation)
                    signal.raise_signal(signal.SIGINT)
                except KeyboardInterrupt:
                    pass
                signal.raise_signal(signal.SIGINT)  # a second Ctrl-C while stopping is ignored, not raised


def test_paper_examples_into_an_existing_set_writes_nothing(tmp_path):
    from clothlab.simulate.examples import EXAMPLE_FILES, YARN_COLOURS, write_paper_examples

    name = list(YARN_COLOURS)[2]
    (tmp_path / name).mkdir()
    (tmp_path / name / EXAMPLE_FILES[-1]).write_text("mine")
    with pytest.raises(ResultExistsError, match="nothing was written"):
        write_paper_examples(tmp_path)
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted([name, EXAMPLE_FILES[-1]])


def test_ctrl_c_swallowed_by_a_callback_is_delivered_again_to_the_main_flow(capsys):
    import gc
    import signal
    import time
    import weakref

    import clothlab.atomic as atomic

    class Node:
        pass

    previous = signal.getsignal(signal.SIGINT)
    loops = 0
    try:
        with atomic.interrupts_recorded(), pytest.raises(KeyboardInterrupt):
            node = Node()
            ref = weakref.ref(node, lambda r: signal.raise_signal(signal.SIGINT))  # Python can only "ignore" it
            del node
            gc.collect()
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                loops += 1
        assert ref() is None
    finally:
        signal.signal(signal.SIGINT, previous)
    assert "Exception ignored" not in capsys.readouterr().err  # and the loop did not run its 30 s

"""The record-and-replay patch store: persistence, refusal of foreign files, crash safety."""

import hashlib
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import pytest

from rehabkit.store import Action, Patch, PatchStore, StoreError


def target(i: float) -> Patch:
    return Patch(kind="target", robot="arm", joints_rad=[i, 0.1, 0.2, 0.3, 0.4, 0.5],
                 pose=[[1, 0, 0, 0.3], [0, 1, 0, 0.0], [0, 0, 1, 0.2], [0, 0, 0, 1]])


def test_patches_persist_across_processes(tmp_path):
    path = tmp_path / "patches.sqlite"
    store = PatchStore(path)
    store.save(1, target(0.7))
    store.save(2, Patch(kind="sequence", robot="arm", actions=[Action(command="lift-up", duration_s=2.0),
                                                               Action(command="gripper-close")]))
    store.close()
    again = PatchStore(path)
    assert again.load(1).joints_rad[0] == 0.7
    assert [a.command for a in again.load(2).actions] == ["lift-up", "gripper-close"]
    assert again.load(3) is None and sorted(again.all()) == [1, 2]
    again.save(1, target(0.9))  # replacing a patch
    assert again.load(1).joints_rad[0] == 0.9
    with pytest.raises(ValueError, match="1..12"):
        again.save(13, target(0.0))


def test_default_location_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("REHABKIT_DATA", str(tmp_path / "data"))
    store = PatchStore()
    assert store.path == tmp_path / "data" / "patches.sqlite"


@pytest.mark.parametrize("kind", ["garbage", "foreign-sqlite"])
def test_foreign_or_corrupt_files_are_refused_and_left_untouched(tmp_path, kind):
    path = tmp_path / "patches.sqlite"
    if kind == "garbage":
        path.write_bytes(os.urandom(8192))
    else:
        db = sqlite3.connect(path)
        db.execute("CREATE TABLE notes (text TEXT)")
        db.execute("INSERT INTO notes VALUES ('someone else''s data')")
        db.commit()
        db.close()
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(StoreError) as refused:
        PatchStore(path)
    assert refused.value.path == path
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before


def test_killing_the_process_mid_write_keeps_earlier_patches(tmp_path):
    path = tmp_path / "patches.sqlite"
    writer = textwrap.dedent(f"""
        import sys
        from rehabkit.store import Patch, PatchStore
        store = PatchStore({str(path)!r})
        big = [float(i) for i in range(20000)]  # a large patch makes each write take a while
        i = 0
        while True:
            slot = i % 12 + 1
            store.save(slot, Patch(kind="target", robot="arm", joints_rad=[i] + big))
            print(slot, i, flush=True)
            i += 1
    """)
    proc = subprocess.Popen([sys.executable, "-c", writer], stdout=subprocess.PIPE, text=True)
    confirmed = {}
    for _ in range(40):  # let it commit 40 patches, then kill it in the middle of the next
        slot, i = map(int, proc.stdout.readline().split())
        confirmed[slot] = i
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    store = PatchStore(path)  # integrity checked on open
    saved = store.all()
    assert set(saved) == set(range(1, 13))
    for slot, i in confirmed.items():
        # every confirmed write is there (a later, unconfirmed one may have committed too: never older)
        assert saved[slot].joints_rad[0] >= i
        assert len(saved[slot].joints_rad) == 20001

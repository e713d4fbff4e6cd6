"""harness/executors/: every task done exactly once under its key, in this process or on a local pool;
the tasks of a lost worker run again, the culprit alone; per-worker state kept across tasks; files
given once reach every task; a task's own error is its outcome, not a lost worker.  A study's stream of
keyed items (stream.py): each key once, what is done skipped, several items per task, the items read as
the work goes, a batch whose worker dies split so that only its culprit is lost.

(The Dask pool runs against separately started scheduler and worker processes in tests/test_cluster.py.)
"""
from __future__ import annotations

import os
import time
from collections import Counter

import pytest

from harness.executors import (Done, ExecutorError, InlinePool, LocalPool, WorkerLost, open_executor,
                               stream_tasks, worker_state)
from harness.executors import tasks


def square(item):
    return item * item


def square_slowly(item):
    time.sleep(0.02)
    return item * item, os.getpid()


def fail_on_three(item):
    if item == 3:
        raise ValueError(f"no {item}")
    return item


def crash_on_seven(item):
    """Dies as on a crash inside an FMU (no exception, the process is gone) on item 7."""
    if item == 7:
        os._exit(3)
    time.sleep(0.05)
    return item


def crash_once(item):
    """Item 0 dies the first time it runs (its marker file absent, as a worker the system kills), and
    runs when run again; the others always run."""
    path, value = item
    if value == 0 and not os.path.exists(path):
        open(path, "w").close()
        os._exit(9)
    time.sleep(0.05)
    return value


class Counted:
    made = 0

    def __init__(self):
        Counted.made += 1
        self.calls = 0

    def close(self):
        pass


def use_state(item):
    state = worker_state("counted", Counted)
    state.calls += 1
    return os.getpid(), id(state), state.calls, Counted.made


def read_file(item, files):
    with open(files["data"]) as stream:
        return stream.read() + str(item)


def check_every_task_once(executor, tmp_path):
    """Keys, values, a task's own error, the files: what every executor must give."""
    data = tmp_path / "data.txt"
    data.write_text("x")
    for item in range(20):
        executor.submit(square, item, key=f"k{item}")
    assert executor.pending() == 20
    done = list(executor.as_completed())
    assert executor.pending() == 0
    assert Counter(d.key for d in done) == Counter(f"k{i}" for i in range(20))  # each once
    assert all(d.ok and d.value == int(d.key[1:]) ** 2 for d in done)
    for item in range(6):
        executor.submit(fail_on_three, item, key=item)
    done = {d.key: d for d in executor.as_completed()}
    assert sorted(done) == list(range(6))  # the others go on
    assert isinstance(done[3].error, ValueError) and str(done[3].error) == "no 3"  # its own error, not lost
    assert all(done[k].value == k for k in done if k != 3)
    executor.files = {"data": str(data)}
    for item in range(4):
        executor.submit(read_file, item, key=item)
    assert sorted(d.value for d in executor.as_completed()) == ["x0", "x1", "x2", "x3"]


def test_inline_every_task_is_done_once_under_its_key(tmp_path):
    with InlinePool() as pool:
        check_every_task_once(pool, tmp_path)


def test_a_local_pool_does_every_task_once_under_its_key(tmp_path):
    with LocalPool(2) as pool:
        check_every_task_once(pool, tmp_path)


def test_a_task_that_kills_its_worker_is_lost_alone_and_every_other_is_done_once():
    with LocalPool(2) as pool:
        for item in range(12):
            pool.submit(crash_on_seven, item, key=item)
        done = list(pool.as_completed())
    keys = Counter(d.key for d in done)
    assert keys == Counter(range(12)), keys  # nothing lost but 7, nothing twice
    lost = [d for d in done if not d.ok]
    assert [d.key for d in lost] == [7] and isinstance(lost[0].error, WorkerLost)
    assert "died twice, the second time running it alone (exited with status 3)" in str(lost[0].error)
    assert all(d.value == d.key for d in done if d.ok)


def test_the_task_of_a_lost_worker_runs_again(tmp_path):
    items = [(str(tmp_path / "marker"), i) for i in range(6)]
    with LocalPool(2) as pool:
        for item in items:
            pool.submit(crash_once, item, key=item[1])
        done = list(pool.as_completed())
    assert sorted((d.key, d.value) for d in done) == [(i, i) for i in range(6)]  # 0 ran again; none twice
    assert pool.lost_workers == 1


def test_worker_state_is_made_once_per_worker_and_kept_across_tasks():
    with LocalPool(1) as pool:
        for item in range(5):
            pool.submit(use_state, item, key=item)
        done = sorted(pool.as_completed(), key=lambda d: d.key)
    pids, ids, calls, made = zip(*(d.value for d in done))
    assert len(set(pids)) == 1 and len(set(ids)) == 1  # one worker, one object
    assert calls == (1, 2, 3, 4, 5) and set(made) == {1}  # made by the first task, reused by the others


def test_inline_worker_state_is_kept_until_the_executor_closes():
    inline = InlinePool()
    inline.submit(use_state, 0)
    first = inline.next_done()[0].value
    inline.submit(use_state, 1)
    assert inline.next_done()[0].value[1:3] == (first[1], 2)
    inline.close()  # forgets the state
    inline.submit(use_state, 2)
    assert inline.next_done()[0].value[2] == 1


def test_shipped_files_are_named_by_their_hash_and_written_once(tmp_path, monkeypatch):
    monkeypatch.setattr(tasks, "cache_dir", lambda: tmp_path / "cache")
    source = tmp_path / "model.fmu"
    source.write_bytes(b"FMU bytes")
    shipment, blobs = tasks.Shipment.of({"plant": source})
    assert list(blobs.values()) == [b"FMU bytes"]
    try:
        first = tasks.run_task(read_file, 1, {**blobs}, tasks.Shipment(((("data",) + shipment.files[0][1:]),)))
        assert first == "FMU bytes1"
        local = tasks.local_files(shipment, blobs)["plant"]
        assert local.parent.name == shipment.files[0][1][:20] and local.read_bytes() == b"FMU bytes"
        local.write_bytes(b"changed")  # checked once per worker: a later task reuses the worker's copy as it is
        assert tasks.local_files(shipment, blobs)["plant"] == local
    finally:
        tasks.forget_worker_state()


def test_open_executor_gives_what_the_options_ask():
    one = open_executor(1, inline_single=True)
    assert isinstance(one, InlinePool) and one.describe() == "this process"
    pool = open_executor(8, tasks=2)
    try:
        assert isinstance(pool, LocalPool) and pool.slots == 2 and pool.describe() == "local pool, 2 processes"
    finally:
        pool.close()
    with pytest.raises(ValueError, match="at least one worker"):
        LocalPool(0)
    assert issubclass(ExecutorError, ValueError) and Done("k", 1).ok and not Done("k", error=WorkerLost()).ok


def drawn(count: int, pulled: list):
    """(key, item) of ``count`` draws, noting in ``pulled`` how many were read."""
    for index in range(count):
        pulled.append(index)
        yield f"s{index}", index


@pytest.mark.parametrize("batch, window", [(1, None), (4, 2), (5, 1)])
def test_a_stream_gives_each_key_once_skips_what_is_done_and_reads_the_items_as_it_goes(batch, window):
    pulled, done_before = [], {"s0", "s5", "s29"}
    with InlinePool() as pool:
        stream = stream_tasks(pool, fail_on_three, drawn(30, pulled), done=done_before, batch=batch, window=window)
        first = next(stream)
        # the window's batches and the next one (submitted before the first is handed over), plus the
        # recorded keys skipped on the way
        assert len(pulled) <= ((window or 2) + 1) * batch + len(done_before), pulled
        finished = [first, *stream]
    keys = Counter(d.key for d in finished)
    assert keys == Counter(f"s{i}" for i in range(30) if f"s{i}" not in done_before)  # each once, none done again
    assert all(d.value == int(d.key[1:]) for d in finished if d.key != "s3")
    failed = [d for d in finished if not d.ok]
    assert [d.key for d in failed] == ["s3"] and str(failed[0].error) == "no 3"  # its own error; its batch went on


def test_a_stream_refuses_a_key_given_twice_and_an_empty_batch():
    with InlinePool() as pool:
        with pytest.raises(ValueError, match="the key 'a' is given twice"):
            list(stream_tasks(pool, square, [("a", 1), ("b", 2), ("a", 3)]))
        with pytest.raises(ValueError, match="at least one item, not 0"):
            list(stream_tasks(pool, square, [("a", 1)], batch=0))
        with pytest.raises(ValueError, match="at least one task, not 0"):
            list(stream_tasks(pool, square, [("a", 1)], window=0))
        assert list(stream_tasks(pool, square, [("a", 1)], done={"a"})) == []


def test_a_batch_whose_worker_dies_is_split_and_only_its_culprit_is_lost():
    with LocalPool(2) as pool:
        finished = list(stream_tasks(pool, crash_on_seven, ((item, item) for item in range(16)), batch=4))
    assert Counter(d.key for d in finished) == Counter(range(16))  # every item once, none twice
    lost = [d for d in finished if not d.ok]
    assert [d.key for d in lost] == [7] and isinstance(lost[0].error, WorkerLost)
    assert all(d.value == d.key for d in finished if d.ok)

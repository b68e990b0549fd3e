"""Independent calls over processes: results in order whatever the number of processes, and a
worker that dies is one clear error, not a traceback."""

import os
from functools import partial

import pytest

from trustseek.errors import TrustseekError
from trustseek.parallel import beside, in_processes


@pytest.mark.parametrize("jobs", [1, 2])
def test_results_come_in_order_and_every_call_is_reported(jobs):
    finished = []
    out = in_processes([partial(pow, i, 2) for i in range(7)], jobs, lambda i, n: finished.append((i, n)))
    assert out == [i * i for i in range(7)]
    assert sorted(i for i, _ in finished) == list(range(7)) and [n for _, n in finished] == list(range(1, 8))


def test_a_worker_that_dies_is_one_clear_error():
    """A worker killed (by the kernel's out-of-memory killer, or kill -9) ended `select`, `predict`,
    `sensitivity` and the bootstrap with a BrokenProcessPool traceback and exit code 1."""
    calls = [partial(pow, 2, 3), partial(os._exit, 9), partial(pow, 3, 2)]
    with pytest.raises(TrustseekError, match=r"a worker process ended abruptly .* run again, or with --jobs 1"):
        in_processes(calls, 2, lambda i, n: None)


@pytest.mark.parametrize("jobs", [1, 2])
def test_beside_runs_the_calls_in_other_processes_while_the_body_runs_here(jobs):
    calls = {f"{i} squared": partial(pow, i, 2) for i in range(5)} | {"pid": os.getpid}
    with beside(calls, jobs) as result:
        here = os.getpid()
        out = {name: result(name) for name in reversed(calls)}
    assert [out[f"{i} squared"] for i in range(5)] == [i * i for i in range(5)]
    assert (out["pid"] == here) == (jobs == 1)  # the calls ran in other processes, unless one job


def test_beside_a_worker_that_dies_is_one_clear_error():
    with (
        pytest.raises(TrustseekError, match=r"a worker process ended abruptly .*beside this one"),
        beside({"dies": partial(os._exit, 9)}, 2) as result,
    ):
        result("dies")


def test_beside_an_error_in_the_body_is_that_error():
    with pytest.raises(ZeroDivisionError), beside({"a": partial(pow, 2, 3), "b": partial(pow, 3, 3)}, 2):
        raise ZeroDivisionError


def _sleep_in(path, seconds):
    import time

    tmp = path.with_suffix(".tmp")
    tmp.write_text(str(os.getpid()))
    tmp.rename(path)  # whole, when the test sees it
    time.sleep(seconds)


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rpartition(")")[2].split()[0] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="reads /proc")
def test_beside_an_interrupted_body_stops_the_calls(tmp_path):
    """Ctrl-C during `reproduce` left the steps running beside it to finish (15 s) before the
    command ended: their results are not wanted, so the workers are stopped."""
    import time

    pid_file = tmp_path / "pid"
    with pytest.raises(KeyboardInterrupt), beside({"sleeps": partial(_sleep_in, pid_file, 120)}, 2):
        while not pid_file.exists():
            time.sleep(0.05)
        raise KeyboardInterrupt
    pid = int(pid_file.read_text())
    deadline = time.monotonic() + 30
    while _running(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _running(pid)

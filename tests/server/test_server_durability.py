"""The decision API's durability promise: a decision or trial the server acknowledged (answered
200) is committed to the database before the answer is sent, so it survives the server process
being killed (SIGKILL) at any moment.  Robots post through a real ``trustseek serve`` process;
the process is killed while their requests are in flight; after a restart on the same database
every acknowledged trial is there, once and unchanged, and every acknowledged pending decision
is answered again as it was (on PostgreSQL: ``tests/server/test_server_postgres.py``)."""

from __future__ import annotations

import sqlite3

from server_checks import check_acknowledged_trials_survive


def test_acknowledged_trials_survive_a_killed_server(tmp_path):
    path = tmp_path / "durable.sqlite"

    def stored(sid: str) -> dict[int, dict]:
        with sqlite3.connect(path) as con:
            con.row_factory = sqlite3.Row
            return {r["trial"]: dict(r) for r in con.execute("SELECT * FROM trials WHERE session_id = ?", (sid,))}

    check_acknowledged_trials_survive(f"sqlite:///{path}", stored)

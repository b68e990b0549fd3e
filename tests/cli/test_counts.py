"""--counts (schedule, simulate) and --block (compare-types): one rule and one message.

Every command takes ``17,17`` in the task's order and ``low=17,high=17`` by name, and refuses
a negative number, a number that is not whole, a wrong count of numbers, an unknown or repeated
name, a mix of the two forms and no trials at all, naming the option and the value."""

from __future__ import annotations

import json

import pytest

from cli_runner import run_cli
from trustseek.errors import TrustseekError

PAPER = ("low", "high")

#: a command line before its counts option, and that option
COMMANDS = {
    "schedule": (["schedule"], "--counts"),
    "simulate": (["simulate", "-n", "1", "--grid", "11"], "--counts"),
    "compare-types": (["compare-types", "-n", "1"], "--block"),
}

#: values every command refuses, and the reason its message gives
BAD = {
    "3,-1": "'-1' is negative",
    "3": "1 number for 2 complexities",
    "3,3,3": "3 numbers for 2 complexities",
    "3,,3": "3 numbers for 2 complexities",
    "+3,3": "'+3' is not a whole number",
    "1_0,3": "'1_0' is not a whole number",
    "3,x": "'x' is not a whole number",
    "0,0": "no trials",
    "low=3,mid=2": "'mid' is not a complexity of the task",
    "low=3,low=4": "a complexity is named twice",
    "low=3,4": "mixes numbers and names",
    "17/17": "1 number for 2 complexities",
}


@pytest.mark.parametrize(
    ("text", "counts"),
    [("17,17", (17, 17)), (" 4 , 0 ", (4, 0)), ("low=4,high=3", (4, 3)), ("high=5", (0, 5)), ("high=2, low=1", (1, 2))],
)
def test_both_forms_read_in_the_tasks_order(text, counts):
    from trustseek.cli._options import parse_counts

    assert parse_counts(text, PAPER) == counts


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("text", list(BAD))
def test_every_command_refuses_the_same_values_with_the_same_message(command, text):
    line, option = COMMANDS[command]
    code, err = run_cli([*line, f"{option}={text}"], stdout=False)
    expected = f"{option} {text!r}: {BAD[text]}; expected a whole number 0 or more per complexity (low, high)"
    assert code == 2 and expected in err and "e.g. 17,17 or low=17,high=17" in err and "Traceback" not in err, err


def test_the_message_gives_examples_for_the_tasks_complexities():
    from trustseek.cli._options import parse_counts

    with pytest.raises(TrustseekError, match=r"\(a, b, c\).*e\.g\. 17,17,17 or a=17,b=17,c=17"):
        parse_counts("1,2", ("a", "b", "c"))


def test_simulate_takes_counts_by_name():
    code, out = run_cli(["simulate", "-n", "2", "-p", "never-ask", "--counts", "high=2,low=3", "--json"], stdout=True)
    assert code == 0, out
    assert json.loads(out)["trials"] == 10


def test_schedule_takes_counts_by_name():
    code, out = run_cli(["schedule", "--counts", "high=2", "--json"])
    assert code == 0, out
    assert json.loads(out)["problem"].startswith("0 low + 2 high items")


def test_compare_types_takes_blocks_by_name():
    line = ["compare-types", "-n", "40", "--fit-participants", "10", "--restarts", "1", "--gap", "0.5", "--json"]
    code, out = run_cli([*line, "-b", "low=3,high=1"])
    assert code == 0, out
    numbers, _ = json.JSONDecoder().raw_decode(out)  # stdout's one JSON object (stderr may follow)
    assert numbers["participants"] == 40 and {p["trials"] for p in numbers["populations"]} == {4}


@pytest.mark.parametrize(
    ("line", "needle"),
    [
        (["schedule", "--counts", "1000000000,1"], "more than 50,000,000"),
        (["schedule", "--counts", "2000,2000", "--representation", "alpha"], "more than 20,000,000"),
        (["compare-types", "--block", "1000000000,1", "-n", "2"], "more than 100,000,000 simulated trials"),
        (["simulate", "--counts", "1000000000,1", "-n", "1"], "more than 100,000,000 simulated trials"),
    ],
)
def test_counts_too_large_to_compute_are_refused_before_the_work(line, needle):
    """A schedule of 10^9 items, and blocks of 10^9 trials in compare-types, ran until killed; the
    schedule solver and the simulation's schedules refuse them (exit 2), whoever calls them."""
    code, err = run_cli(line, stdout=False)
    assert code == 2 and needle in err, err

"""Checkpoints that cannot be used after a host crash (docs/DRIVERS.md
"Recovery after a restart"): one older than recover_max_age_s, or of an
unknown age (the clock set back since), makes the washer drain and unlock,
saying why; a damaged one is refused with the
reason and the washer starts afresh, its door still held over the water.
The kill to outputs-off time is checked only loosely here (test_recovery.py's
50 crashes check it tightly)."""

import os
import sqlite3
import time

from harness import until
from test_kitchen_cycles import DOOR_LEVEL_L, DOOR_LOCKED_BIT, LOCK_BIT, door_guard
from test_recovery import (CLEANUP_STEPS, RESTART_S, SHORT_LOCK_RELEASE_S, TUB_EMPTY_BIT, assert_safe_board, crash,
                           level_l, recovery_host, start_programme, var, washer, washer_board)

# Judged by the board's own clock; a board that cannot have real-time
# scheduling may still be held off the CPU while other tests load the
# machine. The crash test measures it 50 times, tightly.
LATE_S = 2.0
# The PTC lock's delay once the restarted host holds the door again: the
# board's SHORT_LOCK_RELEASE_S held it through the kill, the 2 s wait and
# the restart; from then on a short one shows the door released sooner.
QUICK_RELEASE_S = 1


def wash_with_water(host, board, guard):
    """Start the programme and wait for its wash with the water above the door."""
    start_programme(host, board, guard)
    return host.wait_status(lambda s: var(host, s, "step") == "wash" and level_l(host, s) > DOOR_LEVEL_L
                            and abs(var(host, s, "drum_rpm") or 0) > 10, 60, "the drum washing in water", guard)


def test_a_checkpoint_too_old_drains_the_washer(t):
    host = recovery_host(t)
    board = washer_board(t, SHORT_LOCK_RELEASE_S)
    host.wait_running(["washer-1"])
    wash_with_water(host, board, door_guard(host))
    crash(t, host, board, "killed mid-wash", late_s=LATE_S)
    time.sleep(2)  # not a synchronisation: the checkpoint ages past recover_max_age_s
    host = recovery_host(t, {"driver.washer.param.recover_max_age_s": 1})
    guard = door_guard(host)
    why = host.wait_event("driver", "washer-1", "more than 1 s: cancelling quick", timeout_s=RESTART_S,
                          invariant=guard)
    assert "checkpoint" in why["text"] and "old" in why["text"], "the event does not say why: %r" % why["text"]
    host.wait_status(lambda s: var(host, s, "state") == "cancelling", 10, "the programme cancelling", guard)
    host.wait_status(lambda s: washer(host, s)["outputs"]["digital"][LOCK_BIT], 10,
                     "the cancelling washer holding the door locked", guard)
    board.send("washer-1 lock_release_s %d" % QUICK_RELEASE_S)
    board.wait_line(r"^washer-1: lock_release_s %d$" % QUICK_RELEASE_S, 10, what="the lock's delay set")
    steps = []

    def follow(s):
        guard(s)
        step = var(host, s, "step")
        if var(host, s, "state") == "cancelling" and step and (not steps or steps[-1] != step):
            steps.append(step)

    s = host.wait_status(lambda s: var(host, s, "state") == "cancelled", 90, "the cancel done", follow)
    assert "drain" in steps and steps == [x for x in CLEANUP_STEPS if x in steps], \
        "the cancel's steps: %s, expected stop, drain, unlock" % steps
    d = washer(host, s)
    assert d["inputs"]["digital"][TUB_EMPTY_BIT], "cancelled with %.1f l in the tub" % level_l(host, s)
    # The lock solenoid off, and the PTC lock releasing the door after its delay.
    host.wait_status(lambda s: not washer(host, s)["outputs"]["digital"][LOCK_BIT]
                     and not washer(host, s)["inputs"]["digital"][DOOR_LOCKED_BIT], QUICK_RELEASE_S + 10,
                     "the door unlocked after the cancel", guard)
    assert_safe_board(board, "after the old checkpoint")


def test_a_checkpoint_from_before_the_clock_was_set_back_drains_the_washer(t):
    """The host's wall clock set back while it was down (a box without a
    battery-backed clock, its time set by NTP after boot): the checkpoint's
    time is then in the future and its age unknown. The washer takes it as
    too old, well within recover_max_age_s (600) as it would look, and
    cancels, saying why (docs/DRIVERS.md, "Recovery after a restart")."""
    host = recovery_host(t)
    board = washer_board(t, SHORT_LOCK_RELEASE_S)
    host.wait_running(["washer-1"])
    wash_with_water(host, board, door_guard(host))
    crash(t, host, board, "killed mid-wash", late_s=LATE_S)
    # An hour ahead of the clock: as if the clock had been set back an hour.
    con = sqlite3.connect(os.path.join(t.logdir, "vmac.db"), timeout=10)
    try:
        with con:
            moved = con.execute("UPDATE checkpoints SET time = ? WHERE machine = 'washer-1'",
                                (time.time() + 3600,)).rowcount
    finally:
        con.close()
    assert moved == 1, "no checkpoint of washer-1 in the store after the crash"
    host = recovery_host(t)
    guard = door_guard(host)
    why = host.wait_event("driver", "washer-1", "checkpoint of unknown age", timeout_s=RESTART_S, invariant=guard)
    assert "more than 600 s: cancelling quick" in why["text"], "the event does not say why: %r" % why["text"]
    host.wait_status(lambda s: var(host, s, "state") == "cancelling", 10, "the programme cancelling", guard)
    host.wait_status(lambda s: washer(host, s)["outputs"]["digital"][LOCK_BIT], 10,
                     "the cancelling washer holding the door locked over the water", guard)


def checkpoint_row(t):
    """(driver, length of data, data) of washer-1's checkpoint in the store, or None."""
    con = sqlite3.connect("file:%s?mode=ro" % os.path.join(t.logdir, "vmac.db"), uri=True, timeout=10)
    try:
        return con.execute("SELECT driver, length(data), data FROM checkpoints WHERE machine = 'washer-1'").fetchone()
    finally:
        con.close()


def test_a_damaged_checkpoint_is_refused_cleanly(t):
    host = recovery_host(t)
    board = washer_board(t)
    host.wait_running(["washer-1"])
    wash_with_water(host, board, door_guard(host))
    crash(t, host, board, "killed mid-wash", late_s=LATE_S)
    row = checkpoint_row(t)
    assert row and row[0] == "washer" and row[1] > 8, "no checkpoint of the washer in the store: %r" % (row,)
    # Damaged inside: the header is intact, the body cut in the middle of its values.
    damaged = row[2][:row[1] // 2]
    con = sqlite3.connect(os.path.join(t.logdir, "vmac.db"), timeout=10)
    with con:
        con.execute("UPDATE checkpoints SET data = ? WHERE machine = 'washer-1'", (damaged,))
    con.close()

    host = recovery_host(t)
    guard = door_guard(host)
    warning = host.wait_event("warning", "washer-1", "checkpoint damaged", timeout_s=RESTART_S, invariant=guard)
    assert "not offered" in warning["text"], "the warning: %r" % warning["text"]
    s = host.wait_status(lambda s: var(host, s, "state") == "idle", RESTART_S, "the washer attached afresh", guard)
    assert not host.find_events("recovered", "washer-1", "recover() ran"), \
        "recover() ran with a damaged checkpoint: %s" % host.find_events("recovered", "washer-1")
    assert not host.find_events("driver_error", "washer-1"), host.find_events("driver_error", "washer-1")
    # Fresh, it knows no programme, but its door guard holds the lock over the water.
    if level_l(host, s) > DOOR_LEVEL_L:
        host.wait_status(lambda s: washer(host, s)["outputs"]["digital"][LOCK_BIT], 5,
                         "the fresh washer holding the door locked over %.1f l" % level_l(host, s), guard)

    def replaced():
        if checkpoint_row(t)[2] != damaged:
            return True
        host.wait_status(lambda s: True, 1, "a status", guard)
        return False

    # And its next checkpoint replaces the damaged one.
    until(replaced, 10, "the damaged checkpoint replaced", poll_s=0.1)
    assert host.alive(), "vmacd died after the damaged checkpoint"
    assert_safe_board(board, "after the damaged checkpoint")

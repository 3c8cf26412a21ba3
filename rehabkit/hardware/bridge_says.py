"""What the bridge's status tells the host's people: why it holds the robot on its own, and how to clear its latched
e-stop (in the words of the run's refusal and its stop)."""

from __future__ import annotations

from rehabkit.core.safety.limit_breach import first_breach
from rehabkit.hardware.link.protocol import CLEAR_AT_KEYPAD, CLEAR_BY_KEY, ESTOPPED, LIMIT, WATCHDOG


def hold_breach(link, status: int):
    """The limit the bridge's own check saw broken, from the state it held at (a margin wider than the host's), if
    that is why it holds (a :class:`~rehabkit.core.setup.limits.LimitBreach`), else None."""
    if not status & LIMIT or status & (WATCHDOG | ESTOPPED):
        return None
    return first_breach(link.limits, link.joint_names, link.q, link.qd, tol=0.0, revolute=link.revolute)


def hold_reason(link, status: int) -> str:
    """Why the bridge behind the hardware backend ``link`` holds the robot, from the status bits it sent."""
    if status & WATCHDOG:
        why = f"its watchdog saw no valid command for {link.config.bridge_watchdog_ms:g} ms" \
            if link.config.spawn_bridge else "its watchdog saw no valid command within its --watchdog-ms (a bridge " \
            "started by hand sets its own)"
    elif status & ESTOPPED:
        why = "an e-stop at the robot"
    elif status & LIMIT:
        breach = hold_breach(link, status)
        why = f"its own limit check: {breach.describe()}" if breach else "its own limit check"
    else:
        why = "status holding"
    return why + "; it stays latched until a reset: the next run sends one"


def clear_right(status: int) -> str:
    """Who may clear the bridge's latched e-stop, as its states declare: "key" (a session under its clearing key,
    --clear-key), "keypad" (its keypad only, --clear-with keypad), "link" (any session)."""
    return "key" if status & CLEAR_BY_KEY else "keypad" if status & CLEAR_AT_KEYPAD else "link"


def latched_message(link) -> str:
    """Why no session starts at a latched robot, and what clears it, as the bridge declares (:func:`clear_right`):
    a command with the link's key, or with the bridge's clearing key, or the bridge's keypad only."""
    where = f"udp://{link.addr[0]}:{link.addr[1]}"
    name = link.estop_name
    command = f"`rehabkit estop clear {name} --by NAME --bridge {link.addr[0]}:{link.addr[1]}"
    right = clear_right(link.status)
    if link.process is not None:
        how = f"`rehabkit estop clear {name} --by NAME` (the bridge this run starts reads its latch from this machine)"
    elif right == "keypad":
        how = "the bridge's keypad at the robot (c): it takes no clear over the link (--clear-with keypad)"
    elif right == "key":
        how = (f"{command} --key CLEAR_KEY_FILE` while it runs (the bridge's clearing key, its --clear-key file: it "
               "takes no clear under the robot's key), or the bridge's keypad")
    else:
        how = f"{command}{f' --key {link.key.path}' if link.key else ''}` while it runs, or the bridge's keypad"
    return f"the e-stop of the robot behind the bridge at {where} is latched: deal with its cause, then clear it " \
           f"with {how}"

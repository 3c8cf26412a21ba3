"""The ARM keypad's menus (after Stuyt et al., Fig. 6): which key does what in which menu.

MAIN chooses a mode: J (joint), C (Cartesian), R (record), P (play), and the
preprogrammed fold / unfold motions. Every submenu has ``main`` (the lower-left
button) to go back. JOINT moves one joint (or the lift, or the gripper) while its
key is held; CARTESIAN moves the gripper along the base axes or turns it about its
own axes, keeping everything else. RECORD selects a patch (1–12), stores the current
target when ``store`` is held 2 s, and records a timed action sequence between
``circle`` (start) and ``square`` (stop, store); J and C lead to the jogging menus
while recording. PLAY runs a patch (1–12); C is its shortcut to the Cartesian menu.
"""

from __future__ import annotations

PATCH_KEYS = [str(i) for i in range(1, 13)]
JOINT_JOGS = [f"{j}{s}" for j in ("lift", "j1", "j2", "j3", "j4", "j5", "j6") for s in "+-"] + ["open", "close"]
CARTESIAN_JOGS = [f"{a}{s}" for a in ("x", "y", "z", "roll", "pitch", "yaw", "lift") for s in "+-"] + ["open", "close"]
STORE_HOLD_S = 2.0

MENUS: dict[str, dict[str, str]] = {  # key -> what it does: 'go:MENU', 'jog', 'fold', 'unfold', 'select', ...
    "MAIN": {"J": "go:JOINT", "C": "go:CARTESIAN", "R": "go:RECORD", "P": "go:PLAY", "fold": "fold",
             "unfold": "unfold"},
    "JOINT": {"main": "go:MAIN", **{k: "jog" for k in JOINT_JOGS}},
    "CARTESIAN": {"main": "go:MAIN", **{k: "jog" for k in CARTESIAN_JOGS}},
    "RECORD": {"main": "go:MAIN", "J": "go:JOINT", "C": "go:CARTESIAN", "store": "store", "circle": "record-start",
               "square": "record-stop", **{k: "select" for k in PATCH_KEYS}},
    "PLAY": {"main": "go:MAIN", "C": "go:CARTESIAN", **{k: "play" for k in PATCH_KEYS}},
}
JOG_KEYS = set(JOINT_JOGS) | set(CARTESIAN_JOGS)


def check_timeline(keys: list[tuple[float, str, float]]) -> list[tuple[int, str]]:
    """Problems (press index, message) with a timeline of (time, key, hold) presses, walking the menus from MAIN."""
    problems, menu, selected, recording = [], "MAIN", None, False
    for i, (at, key, hold) in enumerate(keys):
        where = f"keys[{i}] (t = {at} s, '{key}')"
        if i and at < keys[i - 1][0] + keys[i - 1][2]:
            problems.append((i, f"{where}: pressed while keys[{i - 1}] is still held (until "
                            f"{keys[i - 1][0] + keys[i - 1][2]:g} s)"))
        action = MENUS[menu].get(key)
        if action is None:
            problems.append((i, f"{where}: not a key of the {menu} menu; its keys: {', '.join(MENUS[menu])}"))
            continue
        if action.startswith("go:"):
            menu = action[3:]
        elif action == "select":
            selected = key
        elif action == "store" and (selected is None or hold < STORE_HOLD_S):
            problems.append((i, f"{where}: " + ("select a patch (1-12) first" if selected is None
                                                else f"hold it {STORE_HOLD_S:g} s to store (hold_s is {hold:g})")))
        elif action == "record-start":
            if selected is None:
                problems.append((i, f"{where}: select a patch (1-12) before recording"))
            recording = True
        elif action == "record-stop":
            if not recording:
                problems.append((i, f"{where}: no recording to stop (press 'circle' first)"))
            recording = False
    return problems

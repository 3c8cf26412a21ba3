"""What the drives a run left behind send for a while after it (wall time: that is the question): each node's
heartbeat state bytes and every EMCY, as one line of JSON.

    python tests/listen_can.py INTERFACE CHANNEL SECONDS
"""

import json
import sys
import time

import can


def main() -> None:
    interface, channel, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    bus = can.Bus(interface=interface, channel=channel, receive_own_messages=False)
    beats: dict[int, set[int]] = {}
    emcy: list[list] = []
    end = time.monotonic() + seconds  # (from the bus open: the listening itself is that long)
    try:
        while (left := end - time.monotonic()) > 0 and (msg := bus.recv(left)) is not None:
            cob = msg.arbitration_id
            if 0x701 <= cob <= 0x77F and msg.data:
                beats.setdefault(cob - 0x700, set()).add(msg.data[0])
            elif 0x081 <= cob <= 0x0FF:  # (0x080: SYNC)
                emcy.append([cob - 0x80, bytes(msg.data).hex()])
    finally:
        bus.shutdown()
    print(json.dumps({"heartbeats": {n: sorted(b) for n, b in sorted(beats.items())}, "emcy": emcy}), flush=True)


if __name__ == "__main__":
    main()

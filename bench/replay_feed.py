"""Replays the telemetry of many vehicles for bench/cluster.exs
(BENCH_FEED=replay) and bench/intake.exs (FEED=replay), started by
bench/replay_feed.exs: frames encoded beforehand by the bench, each vehicle
from its own UDP socket on 127.0.0.1 to its ground station's link, at
FRAMES_PER_SECOND a vehicle, evenly spread. No simulation runs here: sending
a datagram is all it costs, so a machine of two cores can feed thousands of
vehicles to several ground stations.

    python3 replay_feed.py FILE FRAMES_PER_SECOND

FILE, little-endian, for each vehicle: its station link's port (u16), the
length N of its cycle (u16), then N frames of its normal cycle and N of its
low-battery cycle, each frame a length (u16) and its bytes. Frame i of both
cycles has the same sequence number, so a vehicle switched to its other
cycle goes on without a gap.

Standard input, a command a line: "low I" switches vehicle I (0-based, in
the file's order) to its low-battery cycle; "quit", or the end of input,
stops the feed.
Prints "feeding N vehicles" once every socket is open, and the number of
frames sent when it stops.
"""
import os
import select
import socket
import struct
import sys
import time


def read_vehicles(path):
    with open(path, "rb") as f:
        data = f.read()
    vehicles, at = [], 0
    while at < len(data):
        port, n = struct.unpack_from("<HH", data, at)
        at += 4
        cycles = []
        for _ in range(2):
            frames = []
            for _ in range(n):
                (size,) = struct.unpack_from("<H", data, at)
                frames.append(data[at + 2 : at + 2 + size])
                at += 2 + size
            cycles.append(frames)
        vehicles.append((port, cycles))
    return vehicles


def main():
    path, rate = sys.argv[1], float(sys.argv[2])
    vehicles = read_vehicles(path)
    n = len(vehicles)
    socks = []
    for _ in vehicles:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        s.setblocking(False)
        socks.append(s)
    # Which cycle each vehicle sends from (0 normal, 1 low battery) and where it is in it.
    cycle = [0] * n
    position = [0] * n
    print("feeding %d vehicles" % n, flush=True)

    stdin = sys.stdin.fileno()
    sent, due, nxt = 0, 0.0, 0
    last = time.monotonic()
    running = True
    while running:
        ready, _, _ = select.select([stdin], [], [], 0.005)
        if ready:
            line = os.read(stdin, 4096)
            if not line:
                break
            for command in line.decode().splitlines():
                words = command.split()
                if len(words) == 2 and words[0] == "low":
                    cycle[int(words[1])] = 1
                elif words == ["quit"]:
                    running = False
        now = time.monotonic()
        # (Behind by more than a second: the rest is dropped, not sent in a burst.)
        due = min(due + (now - last) * rate * n, rate * n)
        last = now
        while due >= 1:
            port, cycles = vehicles[nxt]
            frames = cycles[cycle[nxt]]
            try:
                socks[nxt].sendto(frames[position[nxt]], ("127.0.0.1", port))
                sent += 1
            except (BlockingIOError, ConnectionRefusedError):
                # A full buffer, or nobody listening yet: lost, as on a radio.
                pass
            position[nxt] = (position[nxt] + 1) % len(frames)
            nxt = (nxt + 1) % n
            due -= 1
    try:
        print(sent, flush=True)
    except BrokenPipeError:
        # The bench closed its end first: nobody to tell.
        pass


if __name__ == "__main__":
    main()

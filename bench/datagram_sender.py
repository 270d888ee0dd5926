"""Datagrams for bench/datagram_floor.exs: one MAVLink frame (a fixed
GLOBAL_POSITION_INT) per datagram to 127.0.0.1:PORT, RATE a second, for
SECONDS, from SOCKETS sockets in turn (as that many vehicles would). Prints
the number sent.

    python3 datagram_sender.py PORT RATE SECONDS [SOCKETS]
"""
import socket
import sys
import time

# A GLOBAL_POSITION_INT frame (MAVLink 2, 28 bytes of payload); its content
# does not matter to a receiver that only counts.
FRAME = bytes.fromhex("fd1c0000a801012100008c2a0e00a6c31c18c00f6cfbd4110300f7f90000fefffbff0000c8ff0000e5c0")


def main():
    port, rate, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    count = int(sys.argv[4]) if len(sys.argv) > 4 else 100
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(count)]
    start, sent = time.monotonic(), 0
    while True:
        now = time.monotonic() - start
        if now >= seconds:
            break
        while sent < int(now * rate):
            socks[sent % count].sendto(FRAME, ("127.0.0.1", port))
            sent += 1
        time.sleep(0.001)
    print("sent", sent)


if __name__ == "__main__":
    main()

"""Telemetry of N ArduCopter-like vehicles for bench/mission_upload.exs: each
vehicle from its own UDP socket to 127.0.0.1:PORT, a HEARTBEAT at 1 Hz and
GLOBAL_POSITION_INT, ATTITUDE, VFR_HUD and SYS_STATUS at RATE Hz, for SECONDS.
Prints the number of frames sent.

    python telemetry_sender.py PORT N RATE SECONDS
"""
import socket
import sys
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink


class Sink:
    def __init__(self):
        self.buf = b""

    def write(self, data):
        self.buf = data


def main():
    port, n, rate, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
    vehicles = []
    for i in range(n):
        sink = Sink()
        mav = mavlink.MAVLink(sink, srcSystem=1 + i, srcComponent=1)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        vehicles.append((mav, sink, sock))

    target = ("127.0.0.1", port)
    sent = 0
    start = time.time()
    tick = 0
    while time.time() - start < seconds:
        for i, (mav, sink, sock) in enumerate(vehicles):
            msgs = [
                mav.global_position_int_encode(tick, 411780000 + i * 100, -85960000, 132000, 20000, 0, 0, 0, 9000),
                mav.attitude_encode(tick, 0.01, -0.02, 1.57, 0.0, 0.0, 0.0),
                mav.vfr_hud_encode(0.0, 0.0, 90, 40, 20.0, 0.0),
                mav.sys_status_encode(0, 0, 0, 0, 12100, 2800, 77, 0, 0, 0, 0, 0, 0),
            ]
            if tick % int(rate) == 0:
                msgs.append(mav.heartbeat_encode(2, 3, 0x81, 4, 4))
            for msg in msgs:
                mav.send(msg)
                sock.sendto(sink.buf, target)
                sent += 1
        tick += 1
        next_at = start + tick / rate
        delay = next_at - time.time()
        if delay > 0:
            time.sleep(delay)
    print(sent)


if __name__ == "__main__":
    main()

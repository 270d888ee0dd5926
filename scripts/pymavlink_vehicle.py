"""A small vehicle made with pymavlink, the reference MAVLink implementation,
for Dolphin's interop tests and demo: it talks to a ground station listening on
127.0.0.1:PORT as ArduCopter does (heartbeat, telemetry, COMMAND_ACK, the
mission upload asked for item by item with MISSION_REQUEST), and prints on
stdout, as JSON lines, what it received: commands and the uploaded mission.

    python pymavlink_vehicle.py PORT SYSID SECONDS
"""
import json
import sys
import time

from pymavlink import mavutil


def main():
    port, sysid, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    m = mavutil.mavlink_connection("udpout:127.0.0.1:%d" % port, source_system=sysid, source_component=1, dialect="ardupilotmega")
    mav = m.mav
    end = time.time() + seconds
    next_tick = 0.0
    upload = None  # {"count": n, "items": [...]}

    def emit(obj):
        print(json.dumps(obj), flush=True)

    while time.time() < end:
        now = time.time()
        if now >= next_tick:
            next_tick = now + 0.1
            mav.heartbeat_send(2, 3, 0x81, 4, 4)  # quad, ArduPilot, armed + custom, GUIDED, ACTIVE
            mav.sys_status_send(0, 0, 0, 0, 12100, 2800, 77, 0, 0, 0, 0, 0, 0)
            mav.global_position_int_send(1000, 411780000, -85960000, 132000, 20000, 0, 0, 0, 9000)
        msg = m.recv_match(blocking=True, timeout=0.02)
        if msg is None:
            continue
        t = msg.get_type()
        if t == "COMMAND_LONG":
            emit({"command": msg.command, "param1": msg.param1, "confirmation": msg.confirmation})
            mav.command_ack_send(msg.command, 0)
        elif t == "MISSION_COUNT" and msg.mission_type == 0:
            upload = {"count": msg.count, "items": []}
            mav.mission_request_send(msg.get_srcSystem(), msg.get_srcComponent(), 0, 0)
        elif t == "MISSION_ITEM_INT" and upload is not None:
            if msg.seq == len(upload["items"]):
                upload["items"].append({"seq": msg.seq, "command": msg.command, "frame": msg.frame, "x": msg.x, "y": msg.y, "z": msg.z})
            if len(upload["items"]) == upload["count"]:
                mav.mission_ack_send(msg.get_srcSystem(), msg.get_srcComponent(), 0, 0)
                emit({"mission": upload["items"]})
                upload = None
            else:
                mav.mission_request_send(msg.get_srcSystem(), msg.get_srcComponent(), len(upload["items"]), 0)
    emit({"done": True})


if __name__ == "__main__":
    main()

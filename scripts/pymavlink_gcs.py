#!/usr/bin/env python3
"""A small ground station written with pymavlink (the reference implementation),
used to fly Dolphin's simulator from outside: discover a vehicle, request its
streams, upload a mission, GUIDED + arm + MISSION_START, and watch it complete.

usage: pymavlink_gcs.py PORT SYSID SPEEDUP

It listens on udpin:127.0.0.1:PORT (where `mix dolphin.sim --gcs
udpout:127.0.0.1:PORT` sends) and prints one JSON object per line: "ready" once
listening, then what it saw, then {"done": ...} with the summary. Timeouts are
in vehicle time (divided by SPEEDUP), as a ground station at speed-up must.
"""
import json
import math
import socket
import sys
import time

from pymavlink import mavutil

port, sysid, speedup = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
mav = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port, source_system=255, source_component=190, dialect="ardupilotmega")
# A sped-up vehicle sends fast and this reader is slow: a large receive
# buffer keeps a busy machine from dropping what it has not read yet.
mav.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 1024 * 1024)
m = mavutil.mavlink


def say(**obj):
    print(json.dumps(obj), flush=True)


def real(seconds):
    return seconds / speedup


def answer(seconds):
    """How long to wait for an answer: `seconds` of vehicle time, but never
    under 5 s of real time -- a round trip through a loaded machine's scheduler
    does not get faster with the speed-up (as Dolphin.Clock.retry_real_ms)."""
    return max(real(seconds), 5.0)


def fail(why):
    say(done=False, error=why)
    sys.exit(1)


say(ready=True)
hb = mav.wait_heartbeat(timeout=10)
if hb is None:
    fail("no heartbeat")
say(heartbeat={"sysid": mav.target_system, "type": hb.type, "autopilot": hb.autopilot, "custom_mode": hb.custom_mode})
mav.target_system, mav.target_component = sysid, 1


def command(cmd, *params, accept_failure=False, tries=5):
    params = list(params) + [0] * (7 - len(params))
    for attempt in range(tries):
        mav.mav.command_long_send(sysid, 1, cmd, attempt, *params)
        ack = mav.recv_match(type="COMMAND_ACK", blocking=True, timeout=answer(2))
        while ack is not None and ack.command != cmd:
            ack = mav.recv_match(type="COMMAND_ACK", blocking=True, timeout=answer(2))
        if ack is not None:
            if ack.result != 0 and not accept_failure:
                fail("command %d refused with %d" % (cmd, ack.result))
            return ack.result
    fail("command %d not acknowledged" % cmd)


# Streams, as a ground station asks for them: at 1 Hz of the vehicle's time,
# which a speed-up multiplies (at 4 Hz and 20x, a few hundred frames a second
# that this reader, on a loaded machine, fell ever further behind).
mav.mav.request_data_stream_send(sysid, 1, m.MAV_DATA_STREAM_ALL, 1, 1)
command(m.MAV_CMD_SET_MESSAGE_INTERVAL, 245, 1000000)
command(m.MAV_CMD_REQUEST_MESSAGE, 242, accept_failure=True)  # refused until home is set
home = None
deadline = time.time() + max(real(120), 60.0)  # a loaded machine slows the vehicle's clock, not ours
while home is None and time.time() < deadline:
    msg = mav.recv_match(type="HOME_POSITION", blocking=True, timeout=real(5))
    if msg is None:
        command(m.MAV_CMD_REQUEST_MESSAGE, 242, accept_failure=True)
    else:
        home = (msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1000)
if home is None:
    fail("no HOME_POSITION")
pos = mav.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=answer(5))
if pos is None:
    fail("no GLOBAL_POSITION_INT after REQUEST_DATA_STREAM")
say(home=home)

# The mission: home, take off to 15 m, a waypoint 50 m north, RTL.
north = home[0] + 50 / 111_111.0
items = [
    (m.MAV_CMD_NAV_WAYPOINT, home[0], home[1], 0),
    (m.MAV_CMD_NAV_TAKEOFF, 0, 0, 15),
    (m.MAV_CMD_NAV_WAYPOINT, north, home[1], 15),
    (m.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0),
]
mav.mav.mission_count_send(sysid, 1, len(items), 0)
requests = []
while True:
    msg = mav.recv_match(type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=answer(5))
    if msg is None:
        fail("upload stalled")
    if msg.get_type() == "MISSION_ACK":
        # INVALID_SEQUENCE answers an item it did not ask for (the answer to a
        # request it repeated while a loaded machine held this script back):
        # ArduCopter goes on asking, so does this ground station.
        if msg.type == m.MAV_MISSION_INVALID_SEQUENCE:
            continue
        if msg.type != 0:
            fail("upload refused: %d" % msg.type)
        break
    requests.append(msg.get_type())
    cmd, lat, lon, alt = items[msg.seq]
    mav.mav.mission_item_int_send(sysid, 1, msg.seq, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1, 0, 0, 0, 0, int(lat * 1e7), int(lon * 1e7), alt, 0)
say(uploaded=len(items), requests=sorted(set(requests)))

command(m.MAV_CMD_DO_SET_MODE, 1, 4)
deadline = time.time() + max(real(120), 60.0)  # a loaded machine slows the vehicle's clock, not ours
while command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1, accept_failure=True) != 0:
    if time.time() > deadline:
        fail("never armed")
    time.sleep(real(1))
command(m.MAV_CMD_MISSION_START, 0, 0)

reached, modes, texts, disarmed = [], [], [], False
deadline = time.time() + real(300)
while time.time() < deadline and not disarmed:
    msg = mav.recv_match(type=["MISSION_ITEM_REACHED", "HEARTBEAT", "STATUSTEXT"], blocking=True, timeout=real(5))
    if msg is None:
        continue
    if msg.get_type() == "MISSION_ITEM_REACHED":
        if not reached or reached[-1] != msg.seq:
            reached.append(msg.seq)
    elif msg.get_type() == "STATUSTEXT":
        texts.append(msg.text)
    elif msg.get_srcComponent() == 1:
        mode = mavutil.mode_string_v10(msg)
        if not modes or modes[-1] != mode:
            modes.append(mode)
        armed = msg.base_mode & m.MAV_MODE_FLAG_SAFETY_ARMED
        # Done once disarmed after the last item (a datagram of an earlier
        # one may be lost on a busy machine: UDP, and this reader is slow).
        if not armed and reached and reached[-1] == len(items) - 1:
            disarmed = True

# What the vehicle said as it disarmed may come after the heartbeat that shows it.
until = time.time() + real(2)
while time.time() < until:
    msg = mav.recv_match(type="STATUSTEXT", blocking=True, timeout=real(1))
    if msg is not None:
        texts.append(msg.text)

last = mav.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=answer(5))
distance = math.hypot((last.lat / 1e7 - home[0]) * 111_111, (last.lon / 1e7 - home[1]) * 111_111 * math.cos(math.radians(home[0])))
say(done=disarmed, reached=reached, modes=modes, texts=texts, distance_from_home=distance)

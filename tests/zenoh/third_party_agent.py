"""A remote agent written with the official Zenoh binding (PyPI `eclipse-zenoh`), from iwsim's
documented wire layouts alone (`ipc_types::remote` and the structs it names): no iwsim code.

It says hello, registers one robot at a pose, says it is ready, then answers every tick with
its motors at POWER until the run ends. It prints what it saw, one `key value` per line.

    python third_party_agent.py ENDPOINT SESSION NAME X Y POWER [--junk]

The bridge answers the hello with a secret (the reply's attachment); every later request and
every actions payload carries it as its attachment, which ties them to this agent.

With --junk it first says hello with a layout list of its own (which the bridge must refuse),
and on the first tick also sends a payload too short to be actions, actions for a robot that
is not its own, and actions without the secret (which the bridge must count and drop).
"""

import os
import queue
import struct
import sys

import zenoh

# The layouts, by their versioned names: sent with the hello, which a bridge built with other
# layouts refuses.
SCHEMA = " ".join([
    "iwsim::RegisterRequest.v4", "iwsim::RegisterResponse.v1", "iwsim::TickHeader.v2",
    "iwsim::SensorBlock.v5", "iwsim::ActionHeader.v1", "iwsim::ActionBlock.v2",
    "iwsim::MapHeader.v5", "iwsim::MapItem.v1",
])
HELLO, ROBOT, READY = 0, 1, 2
REG_HAS_POSE = 1
ACT_MOTORS = 1
FINISHED = 3
SENSOR_BLOCK = 864
ACTION_BLOCK = 232
TICK_HEADER = struct.Struct("<QdIIQII")          # 40 bytes
RESPONSE = struct.Struct("<IIIIII64s")           # 88 bytes
ACTION_HEADER = struct.Struct("<QII")            # 16 bytes


def registration(name, x, y):
    """RobotRegistration.v3, 656 bytes: a 1 m x 1 m chair at (x, y), heading 0."""
    head = struct.pack("<IIII5d3d", 0, 0, REG_HAS_POSE, 0, 1.0, 1.0, 0.5, 0.5, 0.5, x, y, 0.0)
    sensors = bytes(8 * 40)
    return head + sensors + name.encode().ljust(256, b"\0")


def request(kind, agent_id, robot=None):
    """RegisterRequest.v4, 688 bytes."""
    return struct.pack("<IIII2Q", kind, os.getpid(), agent_id, 0, 0, 0) + (robot or bytes(656))


def ask(session, key, payload, attachment):
    """One request; its answer's agent id, robot id and attachment (the secret, after a hello)."""
    replies = session.get(key, payload=payload, attachment=attachment, timeout=20.0)
    for reply in replies:
        if reply.ok is None:
            sys.exit(f"the bridge said: {reply.err.payload.to_bytes()!r}")
        status, agent_id, robot_id, sensors, _pid, _tick, detail = RESPONSE.unpack(reply.ok.payload.to_bytes())
        if status != 0:
            sys.exit(f"refused ({status}): {detail.rstrip(bytes(1)).decode()}")
        secret = reply.ok.attachment.to_bytes() if reply.ok.attachment is not None else None
        return agent_id, robot_id, secret
    sys.exit("no bridge answered")


def main():
    endpoint, session_name, name, x, y, power = sys.argv[1:7]
    junk = "--junk" in sys.argv[7:]
    prefix = f"iwsim/{session_name}"
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", f'["{endpoint}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    # The binding is built with Zenoh's shared-memory transport, which leaves a segment in
    # /dev/shm behind; nothing here needs it.
    conf.insert_json5("transport/shared_memory/enabled", "false")
    with zenoh.open(conf) as session:
        if junk:
            replies = list(session.get(f"{prefix}/register", payload=request(HELLO, 0),
                                       attachment="iwsim::RegisterRequest.v3", timeout=20.0))
            assert replies and replies[0].ok is None, "a hello with other layouts is refused"
            print("refused", replies[0].err.payload.to_bytes().decode(), flush=True)
        agent_id, _, secret = ask(session, f"{prefix}/register", request(HELLO, 0), SCHEMA)
        assert secret is not None and len(secret) == 16, "the welcome carries the agent's secret"
        print("agent", agent_id, flush=True)
        token = session.liveliness().declare_token(f"{prefix}/agent/{agent_id}/alive")
        frames = queue.Queue()
        sub = session.declare_subscriber(
            f"{prefix}/agent/{agent_id}/sensors", lambda s: frames.put(s.payload.to_bytes()))
        robot = registration(name, float(x), float(y))
        _, robot_id, _ = ask(session, f"{prefix}/register", request(ROBOT, agent_id, robot), secret)
        print("robot", robot_id, flush=True)
        ask(session, f"{prefix}/register", request(READY, agent_id), secret)
        actions = session.declare_publisher(f"{prefix}/agent/{agent_id}/actions")
        answered, mine = 0, 0
        while True:
            frame = frames.get(timeout=30)
            tick, _sim, state, count, _t, _spin, _flags = TICK_HEADER.unpack_from(frame)
            assert len(frame) == TICK_HEADER.size + count * SENSOR_BLOCK, f"a frame of {len(frame)} bytes"
            # SensorBlock.v5 starts with its tick (u64) and its robot's id (u32).
            blocks = [struct.unpack_from("<QI", frame, TICK_HEADER.size + k * SENSOR_BLOCK) for k in range(count)]
            mine += blocks == [(tick, robot_id)]
            if state == FINISHED:
                break
            block = struct.pack("<II2d3dII", robot_id, ACT_MOTORS, float(power), float(power), 0, 0, 0, 0, 0)
            block = block.ljust(ACTION_BLOCK, b"\0")
            if junk and answered == 0:
                actions.put(b"\x01\x02\x03", attachment=secret)
                stranger = struct.pack("<II2d3dII", robot_id + 1000, ACT_MOTORS, 1.0, 1.0, 0, 0, 0, 0, 0)
                actions.put(ACTION_HEADER.pack(tick, agent_id, 1) + stranger.ljust(ACTION_BLOCK, b"\0"),
                            attachment=secret)
                # In its own name, but as another session would: without the secret.
                actions.put(ACTION_HEADER.pack(tick, agent_id, 1) + block)
            actions.put(ACTION_HEADER.pack(tick, agent_id, 1) + block, attachment=secret)
            answered += 1
        print("answered", answered, flush=True)
        print("own_blocks", mine, flush=True)
        del sub, token


if __name__ == "__main__":
    main()

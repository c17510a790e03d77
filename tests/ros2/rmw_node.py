"""A ROS 2 node on Zenoh as rmw_zenoh makes one, written from rmw_zenoh's `docs/design.md`
(rolling) with the official Zenoh binding (PyPI `eclipse-zenoh`) and ROS 2's own message
definitions, CDR and type hashes from PyPI `rosbags`: no iwsim code, no ROS 2 install.

What a node does on the wire:
- a topic's samples travel on `<domain>/<name without its outer slashes>/<pkg>::msg::dds_::<Type>_/<RIHS01 hash>`;
- the node and each of its publishers and subscriptions hold a liveliness token
  `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS>/%/<namespace>/<node>[/<topic>/<type>/<hash>/<qos>]`,
  `/` written `%`, so that the graph (`ros2 node list`, `ros2 topic list`) sees them;
- every sample carries a 33-byte attachment: sequence number and source time (i64 little-endian
  each), 16, and the publisher's 16-byte id;
- a transient-local topic's last samples are fetched from the publisher's cache with a query
  on `<key>/@adv/**?_max=<depth>` that accepts replies on any key.
"""

import os
import struct
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

TYPES = get_typestore(Stores.ROS2_JAZZY)
QOS_DEFAULT = "::,10:,:,:,,"        # reliable, volatile, keep-last 10 (rclcpp's QoS(10))
QOS_SENSOR = "2::,5:,:,:,,"         # rmw_qos_profile_sensor_data
QOS_LATCHED = ":1:,1:,:,:,,"        # reliable, transient-local, keep-last 1


def open_session(endpoint):
    """A Zenoh client session to `endpoint` (a router, as rmw_zenoh nodes use one)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", f'["{endpoint}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    # The binding's own shared-memory transport would leave a segment in /dev/shm.
    conf.insert_json5("transport/shared_memory/enabled", "false")
    return zenoh.open(conf)


def dds_name(typename):
    """`geometry_msgs/msg/Twist` -> `geometry_msgs::msg::dds_::Twist_`."""
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def data_key(domain, topic, typename):
    return f"{domain}/{topic.strip('/')}/{dds_name(typename)}/{TYPES.hash_rihs01(typename)}"


def mangle(name):
    return name.replace("/", "%") if name else "%"


class Node:
    """A node `name` in `namespace` (`/` for the root) on `session`."""

    def __init__(self, session, domain, namespace, name):
        self.session, self.domain = session, domain
        self.namespace, self.name = namespace, name
        self.zid = str(session.zid())
        self.next_id = 1
        self.tokens = []
        self.tokens.append(session.liveliness().declare_token(self._prefix(0, "NN")))
        self.keep = []

    def _prefix(self, entity, kind):
        ns = mangle("" if self.namespace == "/" else self.namespace)
        return f"@ros2_lv/{self.domain}/{self.zid}/0/{entity}/{kind}/%/{ns}/{self.name}"

    def _token(self, kind, topic, typename, qos):
        entity = self.next_id
        self.next_id += 1
        key = f"{self._prefix(entity, kind)}/{mangle(topic)}/{dds_name(typename)}/{TYPES.hash_rihs01(typename)}/{qos}"
        self.tokens.append(self.session.liveliness().declare_token(key))
        return key

    def publisher(self, topic, typename, qos=QOS_DEFAULT):
        return Publisher(self, topic, typename, qos)

    def subscribe(self, topic, typename, callback, qos=QOS_DEFAULT):
        """Calls `callback(message, attachment_ok)` for each sample, decoded by rosbags."""
        self._token("MS", topic, typename, qos)

        def on_sample(sample):
            a = sample.attachment
            raw = a.to_bytes() if a is not None else b""
            ok = len(raw) == 33 and raw[16] == 16
            callback(TYPES.deserialize_cdr(sample.payload.to_bytes(), typename), ok)

        sub = self.session.declare_subscriber(data_key(self.domain, topic, typename), on_sample)
        self.keep.append(sub)
        return sub

    def on_publisher_gone(self, topic, callback):
        """Calls `callback()` when a publisher of `topic` leaves the graph (its liveliness
        token goes), as `ros2 topic info` would see it go."""
        key = f"@ros2_lv/{self.domain}/**/MP/**/{mangle(topic)}/**"

        def on_token(sample):
            if sample.kind == zenoh.SampleKind.DELETE:
                callback()

        self.keep.append(self.session.liveliness().declare_subscriber(key, on_token))

    def latched(self, topic, typename, depth=1, timeout=10.0):
        """What a late transient-local subscription gets: the publishers' cached samples."""
        key = data_key(self.domain, topic, typename)
        replies = self.session.get(
            f"{key}/@adv/**?_max={depth}",
            accept_replies=zenoh.ReplyKeyExpr.ANY,
            target=zenoh.QueryTarget.ALL,
            timeout=timeout,
        )
        out = []
        for r in replies:
            if r.ok is not None:
                out.append(TYPES.deserialize_cdr(r.ok.payload.to_bytes(), typename))
        return out


class Publisher:
    def __init__(self, node, topic, typename, qos):
        self.typename = typename
        node._token("MP", topic, typename, qos)
        # Any id unique to the publisher (rmw_zenoh hashes its token; subscribers only compare).
        self.gid = os.urandom(16)
        self.seq = 0
        self.pub = node.session.declare_publisher(data_key(node.domain, topic, typename))

    def put(self, msg):
        self.seq += 1
        attachment = struct.pack("<qqB", self.seq, time.time_ns(), 16) + self.gid
        self.pub.put(bytes(TYPES.serialize_cdr(msg, self.typename)), attachment=attachment)


def twist(v, w):
    T = TYPES.types
    V = T["geometry_msgs/msg/Vector3"]
    return T["geometry_msgs/msg/Twist"](linear=V(x=v, y=0.0, z=0.0), angular=V(x=0.0, y=0.0, z=w))


class Latest:
    """The newest message of a topic, and a count, shared with Zenoh's thread."""

    def __init__(self):
        self.lock = threading.Condition()
        self.msg, self.count, self.bad_attachments = None, 0, 0

    def __call__(self, msg, attachment_ok):
        with self.lock:
            self.msg = msg
            self.count += 1
            self.bad_attachments += 0 if attachment_ok else 1
            self.lock.notify_all()

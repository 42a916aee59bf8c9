"""``lili-odom play BAG``: publish a bag's messages on ROS topics, with ``/clock``.

A small stand-in for ``ros2 bag play`` where no ros2cli exists (the pip ROS stack). Messages
are published *raw*: the CDR bytes stored in the bag go to ``Publisher.publish(bytes)``
unchanged, so nothing is deserialised; a publisher still needs the Python message class to
exist (topics whose package is not installed, e.g. ``tf2_msgs`` in the pip wheels, are skipped
with a warning).

Timing follows the bag's *log* time scaled by ``--rate`` (``--rate 0`` or ``--fast``: as fast
as possible). ``/clock`` carries the bag log time of the playback position at ``--clock-hz``
(wall rate), so nodes with ``use_sim_time`` follow the bag. With ``--loop`` the clock jumps
back to the start on every pass, as ``ros2 bag play --loop`` does.

``--restamp`` shifts every ``header.stamp`` (of the messages that start with a
``std_msgs/Header``: clouds, IMU, odometry; not ``/tf_static``) and ``/clock`` by the system
clock's time at the start of playback minus the bag's start, as a live driver stamps: a node
without ``use_sim_time`` then sees the stamps on its own clock (e.g. to measure its latency).
Meant for ``--rate 1``; the shift is taken once, so ``--loop`` still jumps back.

QoS (``--qos``): ``reliable`` (default): every publisher is RELIABLE (so reliable *and*
best-effort subscribers match) with KEEP_LAST depth ``--qos-depth``, a lossless replay;
``sensor-data``: data topics are published BEST_EFFORT as a LiDAR driver does (ouster-ros's
sensor-data QoS), so the replay shows what the node sees on the robot. Latched topics
(``/tf_static`` and topics recorded as transient-local) are always RELIABLE +
TRANSIENT_LOCAL.

DDS: like ``lili_odom_node``, the player loads the package's Fast DDS profile
(:mod:`lili_odom.ros.dds`: a shared-memory segment large enough for full-resolution clouds)
unless the environment already names one.
"""
from __future__ import annotations

import argparse
import struct
import sys
import time

from lili_odom.errors import UserError

help = "publish a rosbag2 bag's messages on ROS topics with /clock (no ros2cli needed)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="rosbag2 directory or .mcap file")
    parser.add_argument("--rate", type=float, default=1.0,
                        help="playback speed factor (0 = as fast as possible)")
    parser.add_argument("--fast", action="store_true", help="as fast as possible (= --rate 0)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    parser.add_argument("--loop", action="store_true", help="replay until interrupted")
    parser.add_argument("--start", type=float, default=0.0, metavar="S",
                        help="skip the first S seconds of the bag")
    parser.add_argument("--clock-hz", type=float, default=100.0,
                        help="/clock publish rate in wall Hz (0 = no /clock)")
    parser.add_argument("--delay", type=float, default=1.0, metavar="S",
                        help="wait up to S wall seconds after creating publishers, until every "
                        "topic has a matched subscriber, before the first message")
    parser.add_argument("--qos-depth", type=int, default=20, help="publisher history depth")
    parser.add_argument("--qos", choices=("reliable", "sensor-data"), default="reliable",
                        help="publisher reliability: reliable (lossless replay, default) or "
                        "sensor-data (best effort, like a LiDAR driver)")
    parser.add_argument("--restamp", action="store_true",
                        help="shift header stamps and /clock so the bag starts now on the "
                        "system clock, as a live driver stamps (for --rate 1)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")


def _stamp_endian(data: bytes) -> str:
    if len(data) < 12:
        raise ValueError(f"{len(data)} bytes cannot hold a CDR header stamp")
    return "<" if data[1] & 1 else ">"  # encapsulation kind: odd = little endian


def header_stamp_ns(data: bytes) -> int:
    """``header.stamp`` [ns] of the CDR-serialised message ``data`` (4-byte encapsulation
    header, then a message whose first field is a ``std_msgs/Header``).

    Raises ValueError for data too short to hold a stamp."""
    sec, nanosec = struct.unpack_from(_stamp_endian(data) + "iI", data, 4)
    return sec * 1_000_000_000 + nanosec


def shift_header_stamp(data: bytes, offset_ns: int) -> bytes:
    """The CDR-serialised message ``data`` (as :func:`header_stamp_ns` reads it) with
    ``header.stamp`` moved by ``offset_ns`` [ns].

    Raises ValueError for data too short to hold a stamp or a stamp moved before 0."""
    endian = _stamp_endian(data)
    total = header_stamp_ns(data) + int(offset_ns)
    if total < 0:
        raise ValueError(f"stamp {total * 1e-9:.3f} s before the epoch")
    stamp = struct.pack(endian + "iI", *divmod(total, 1_000_000_000))
    view = memoryview(data)
    return b"".join((view[:4], stamp, view[12:]))


def _starts_with_header(cls: type) -> bool:
    """True when the message class's first field is a ``std_msgs/Header``."""
    try:
        fields = list(cls.get_fields_and_field_types().items())
    except AttributeError:
        return False
    return bool(fields) and fields[0][1] in ("std_msgs/Header", "std_msgs/msg/Header")


def _validate(args: argparse.Namespace) -> float:
    rate = 0.0 if args.fast else float(args.rate)
    if not rate >= 0.0:
        raise UserError(f"--rate must be >= 0, got {args.rate}")
    if not args.start >= 0.0:
        raise UserError(f"--start must be >= 0, got {args.start}")
    if not args.clock_hz >= 0.0:
        raise UserError(f"--clock-hz must be >= 0, got {args.clock_hz}")
    if args.qos_depth < 1:
        raise UserError(f"--qos-depth must be >= 1, got {args.qos_depth}")
    return rate


def run(args: argparse.Namespace) -> int:
    from lili_odom.bagio.reader import BagReader

    rate = _validate(args)
    reader = BagReader(args.bag, topics=args.topics, required=(), expected_types={})
    with reader:
        if reader.missing_topics:
            raise UserError(f"{args.bag}: topic(s) not in bag: {', '.join(reader.missing_topics)}")
        if not reader.selected_topics:
            raise UserError(f"{args.bag}: bag has no messages to play")
        return _play(reader, args, rate)


def _play(reader, args: argparse.Namespace, rate: float) -> int:
    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from lili_odom.ros.dds import apply_dds_defaults
    from lili_odom.ros.factory import MessageTypeError, message_class

    def log(text: str) -> None:
        if not args.quiet:
            print(text, file=sys.stderr, flush=True)

    apply_dds_defaults()
    context = rclpy.Context()
    rclpy.init(args=None, context=context)
    node = None
    try:
        node = rclpy.create_node("lili_odom_player", context=context,
                                 start_parameter_services=False)
        latched = reader.latched_topics
        publishers = {}
        stamped = set()  # topics whose messages start with a header (--restamp)
        for topic, msgtype in reader.topic_types.items():
            if topic not in reader.selected_topics:
                continue
            try:
                cls = message_class(msgtype)
            except MessageTypeError as exc:
                log(f"lili-odom play: skipping {topic}: {exc}")
                continue
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST,
                # small messages get a deep history so a reliable reader that falls behind
                # (or a lost packet to repair) does not lose samples; clouds keep --qos-depth
                depth=(args.qos_depth if msgtype == "sensor_msgs/msg/PointCloud2"
                       else max(args.qos_depth, 1000)),
                reliability=(ReliabilityPolicy.BEST_EFFORT
                             if args.qos == "sensor-data" and topic not in latched
                             else ReliabilityPolicy.RELIABLE),
                durability=(DurabilityPolicy.TRANSIENT_LOCAL if topic in latched
                            else DurabilityPolicy.VOLATILE),
            )
            publishers[topic] = node.create_publisher(cls, topic, qos)
            if _starts_with_header(cls):
                stamped.add(topic)
        if not publishers:
            raise UserError(f"{args.bag}: none of the bag's message types can be published here")
        clock_pub = None
        if args.clock_hz > 0:
            clock_pub = node.create_publisher(
                Clock, "/clock", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        if args.delay > 0:
            # Discovery takes a variable time; a fixed sleep loses the first messages on a
            # loaded machine. Stop waiting as soon as every data topic has a subscriber.
            deadline = time.monotonic() + args.delay
            while time.monotonic() < deadline and not all(
                    p.get_subscription_count() > 0 for p in publishers.values()):
                time.sleep(0.02)
            # the subscriber side may learn of our writer slightly later than we learnt of it
            time.sleep(min(0.5, args.delay))

        bag_start = int(reader.start_time * 1e9) + int(args.start * 1e9)
        offset_ns = time.time_ns() - bag_start if args.restamp else 0

        def publish_clock(t_ns: int) -> None:
            if clock_pub is not None:
                msg = Clock()
                msg.clock.sec, msg.clock.nanosec = divmod(max(0, int(t_ns) + offset_ns),
                                                          1_000_000_000)
                clock_pub.publish(msg)

        def restamp(topic: str, data: bytes) -> bytes:
            return shift_header_stamp(data, offset_ns) if topic in stamped else data

        clock_period = 1.0 / args.clock_hz if args.clock_hz > 0 else float("inf")
        total = 0
        passes = 0
        wall0 = time.monotonic()
        while True:
            passes += 1
            n = _one_pass(reader, publishers, publish_clock, bag_start, rate, clock_period,
                          context, restamp if args.restamp else None)
            total += n
            if not args.loop or n == 0 or not context.ok():
                break
        # Reliable delivery needs the writers alive until the readers acknowledged (a lost
        # packet is repaired from the writer's history); do not exit before that.
        from rclpy.duration import Duration

        unacked = [t for t, p in publishers.items()
                   if args.qos == "reliable" and p.get_subscription_count()
                   and not p.wait_for_all_acked(Duration(seconds=2.0))]
        if args.qos == "sensor-data":
            time.sleep(0.5)  # best effort: let the last samples leave before the writers go
        if unacked:
            log(f"lili-odom play: not acknowledged by every subscriber: {', '.join(unacked)}")
        log(f"lili-odom play: published {total} messages on {len(publishers)} topics "
            f"in {time.monotonic() - wall0:.2f} s ({passes} pass{'es' if passes > 1 else ''})")
        return 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def _one_pass(reader, publishers, publish_clock, bag_start: int, rate: float,
              clock_period: float, context, restamp=None) -> int:
    """Publish every message once (``restamp(topic, data)``, when given, rewrites the raw
    bytes first); returns the count."""
    wall_start = time.monotonic()
    next_clock = wall_start
    last_clock_bag = None
    count = 0
    for raw in reader.raw_messages(start=bag_start * 1e-9):
        if not context.ok():
            break
        pub = publishers.get(raw.topic)
        if pub is None:
            continue
        if rate > 0:
            target = wall_start + (raw.log_time_ns - bag_start) * 1e-9 / rate
            while True:
                now = time.monotonic()
                if now >= next_clock:
                    publish_clock(bag_start + int((now - wall_start) * rate * 1e9))
                    next_clock = now + clock_period
                if now >= target:
                    break
                time.sleep(max(0.0, min(target, next_clock) - now))
        elif last_clock_bag is None or (raw.log_time_ns - last_clock_bag) * 1e-9 >= clock_period:
            publish_clock(raw.log_time_ns)
            last_clock_bag = raw.log_time_ns
        pub.publish(raw.data if restamp is None else restamp(raw.topic, raw.data))
        count += 1
    return count

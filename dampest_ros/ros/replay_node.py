"""replay_node: plays a rosbag2 bag (MCAP or SQLite3) with its timing (as ``ros2 bag play``).

Publishes every message's serialized bytes unchanged (bit-identical to the bag) at its log
time, the intervals divided by rate, from start_offset seconds into the bag; optionally
loops, publishes /clock with the bag time (for use_sim_time listeners; at the end, once
with the time of the last message played), plays only some
topics (or all but exclude_topics) and renames them. Publishers use the QoS recorded in the
bag (reliable only when every recorded publisher was; override with reliability) and keep
queue_depth messages. A topic
whose message type is not installed is skipped with a warning. Before playing it waits until
every played topic has wait_for_subscribers subscribers (1 by default: a message published
before a subscriber is matched reaches no one), at most wait_for_subscribers_timeout seconds,
then warns naming the topics without and plays. Progress is logged every progress_period
seconds, counting the messages published and those published while their topic had a matched
subscriber; when the bag has been played (and loop is false) the node waits up to
wait_for_acked seconds until reliable subscribers have acknowledged every message, then exits.
A name in topics, exclude_topics or remap that is not a topic of the bag (the closest is
suggested), a remap to an invalid topic name and a start_offset past the last message are
refused at start (one line, status 2); a loop that finds no message to play ends.
"""

from __future__ import annotations

import difflib
import threading
import time
from pathlib import Path
from typing import Any

from builtin_interfaces.msg import Time
from rclpy.duration import Duration
from rclpy.exceptions import InvalidTopicNameException
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import Reader
from rosgraph_msgs.msg import Clock

from dampest_ros.io.bag import Bag, BagError, bag_summary, is_ros1_bag
from dampest_ros.ros.bag_interop import compatible_qos, import_message_type
from dampest_ros.ros.common import Param, ParamNode, main_for


def _bag_ok(value: Any) -> str | None:
    if not str(value):
        return "bag: give the bag directory (or .mcap/.db3 file) to play"
    if not Path(str(value)).exists():
        return f"bag {value} does not exist"
    try:
        bag_summary(str(value))  # a truncated bag: the reason and the reindex hint
    except BagError as exc:
        return str(exc)
    if is_ros1_bag(Path(str(value))):
        return (f"bag {value} is a ROS 1 bag: replay plays rosbag2 bags; dampest identify "
                "reads it as it is, or convert it first with rosbags-convert --src BAG --dst DIR")
    return None


def _remap_ok(value: Any) -> str | None:
    bad = [r for r in value if r and (":=" not in r or not all(r.split(":=", 1)))]
    return f"remap entries must read 'from:=to', got {bad}" if bad else None


def _not_in_bag(option: str, names: Any, bag: list[str]) -> str | None:
    """Why the topics of ``option`` that ``bag`` (its topic names) lacks are refused (a
    typo would otherwise play, exclude or rename nothing), naming the closest; None when
    every name is in the bag."""
    missing = [n for n in names if n not in bag]
    if not missing:
        return None
    close = difflib.get_close_matches(missing[0], bag, n=1)
    hint = f"did you mean {close[0]}? " if close else ""
    return (f"{option}: {', '.join(missing)} not in the bag; {hint}its topics: "
            f"{', '.join(sorted(bag))}")


def _past_the_end(offset: float, reader: Reader) -> str | None:
    """Why a start_offset (s) at or past the last message of the bag is refused, or None."""
    length = max(reader.duration - 1, 0) / 1e9
    if reader.message_count and offset > length:
        return (f"start_offset {offset:g} s is past the end of the bag ({length:.3f} s from its "
                f"first to its last message); give a smaller start_offset")
    return None


class ReplayNode(ParamNode):
    """Replay node (see the module docstring)."""

    NODE_NAME = "replay_node"
    PARAMS = (
        Param("bag", "", "rosbag2 directory (MCAP or SQLite3) or a single .mcap/.db3 file",
              check=_bag_ok, read_only=True),
        Param("rate", 1.0, "playback speed: bag seconds per wall-clock second", low=0.01,
              high=1000.0),
        Param("topics", [""], "bag topics to play (with or without the leading /); [''] "
              "or empty names: all", read_only=True),
        Param("exclude_topics", [""], "bag topics not to play (with or without the leading "
              "/); applied after topics", read_only=True),
        Param("remap", [""], "renamed topics, 'from:=to' per entry (bag name := published "
              "name)", check=_remap_ok, read_only=True),
        Param("start_offset", 0.0, "seconds after the first message of the bag to start at",
              low=0.0, high=1e9),
        Param("loop", False, "play again from start_offset after the end"),
        Param("clock", False, "publish /clock with the bag time"),
        Param("clock_rate", 40.0, "/clock messages per wall-clock second", low=1.0,
              high=10000.0),
        Param("reliability", "bag", "publisher reliability: as recorded, or forced",
              choices=("bag", "reliable", "best_effort"), read_only=True),
        Param("queue_depth", 1000, "publisher queue (messages)", low=1, high=1_000_000,
              read_only=True),
        Param("wait_for_subscribers", 1, "before playing, wait until every played topic has "
              "this many matched subscribers; 0: play at once", low=0, high=1000,
              read_only=True),
        Param("wait_for_subscribers_timeout", 10.0, "seconds to wait for them; then a warning "
              "names the topics without and playback starts", low=0.0, high=3600.0,
              read_only=True),
        Param("delay", 0.0, "seconds to wait before playing (after wait_for_subscribers)",
              low=0.0, high=3600.0, read_only=True),
        Param("wait_for_acked", 5.0, "after the last message, seconds to wait until reliable "
              "subscribers have acknowledged every message before exiting; 0: exit at once",
              low=0.0, high=3600.0, read_only=True),
        Param("progress_period", 5.0, "seconds between progress lines in the log; 0: none",
              low=0.0, high=3600.0),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        self.bag = Bag(Path(str(self.p("bag"))))  # read as identify reads it: chunks checked
        assert isinstance(self.bag.reader, Reader)  # a ROS 1 bag is refused by _bag_ok
        self.reader: Reader = self.bag.reader
        wanted = {"/" + t.lstrip("/") for t in self.p("topics") if t}
        excluded = {"/" + t.lstrip("/") for t in self.p("exclude_topics") if t}
        remap = dict(("/" + a.strip().lstrip("/"), b.strip())
                     for a, b in (r.split(":=", 1) for r in self.p("remap") if r))
        in_bag = [c.topic for c in self.reader.connections]
        reason = (_not_in_bag("topics", wanted, in_bag)
                  or _not_in_bag("exclude_topics", excluded, in_bag)
                  or _not_in_bag("remap", remap, in_bag)
                  or _past_the_end(float(self.p("start_offset")), self.reader))
        if reason is not None:  # a refusal at start: one line, status 2 (main_for)
            self.reader.close()
            raise ValueError(f"{self.p('bag')}: {reason}")
        depth = int(self.p("queue_depth"))
        forced = {"bag": "auto"}.get(str(self.p("reliability")), str(self.p("reliability")))
        self.pubs: dict[int, Publisher] = {}
        self.skipped: list[str] = []
        by_topic: dict[str, Publisher] = {}
        for conn in self.reader.connections:
            if (wanted and conn.topic not in wanted) or conn.topic in excluded:
                continue
            try:
                cls = import_message_type(conn.msgtype)
            except ImportError as exc:
                self.get_logger().warning(f"skipping {conn.topic}: {exc}")
                self.skipped.append(conn.topic)
                continue
            name = remap.get(conn.topic, conn.topic)
            if name not in by_topic:
                offered = getattr(conn.ext, "offered_qos_profiles", [])  # rosbag2 bags
                qos = compatible_qos(offered, depth, forced)
                by_topic[name] = self._publisher(cls, name, qos)
            self.pubs[conn.id] = by_topic[name]
        self.connections = [c for c in self.reader.connections if c.id in self.pubs]
        self.total = sum(int(c.msgcount) for c in self.connections)
        self.clock_pub = None
        if self.p("clock"):
            self.clock_pub = self.create_publisher(
                Clock, "/clock", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                            durability=DurabilityPolicy.VOLATILE))
        self.published = 0
        self.heard = 0  # published while the topic had a matched subscriber
        self.bag_time = 0
        self._anchor: tuple[float, int] | None = None  # (wall time, bag time) of the pace
        self._stop = threading.Event()
        self._done = threading.Event()
        self._last_progress = time.monotonic()
        self._last_clock = 0.0
        self._cpu0 = time.process_time()
        self.get_logger().info(
            f"playing {self.total} messages on {len(by_topic)} topics of {self.p('bag')} "
            f"at rate {self.p('rate')}" + (f", skipping {self.skipped}" if self.skipped else ""))
        self.thread = threading.Thread(target=self._run, name="replay", daemon=True)
        # started from the executor, so that its end (which shuts the context down) always
        # finds spin() running
        self._starter = self.create_timer(0.0, self._start_playback)

    def _publisher(self, cls: Any, name: str, qos: QoSProfile) -> Publisher:
        """A publisher of ``name``; a name ROS refuses (a remap target) is a ValueError."""
        try:
            return self.create_publisher(cls, name, qos)
        except InvalidTopicNameException as exc:
            self.reader.close()
            detail = str(exc).splitlines()[0].removeprefix("Invalid topic name: ").rstrip(":")
            raise ValueError(f"remap: {name!r} is not a valid topic name ({detail}); write "
                             "'from:=to' with to made of letters, digits, _ and /") from None

    def _start_playback(self) -> None:
        self._starter.cancel()
        if not self.thread.is_alive() and not self._done.is_set():
            self.thread.start()

    def on_parameters(self, names: list[str]) -> None:
        """A new rate or start_offset takes effect from the current message on."""
        if "rate" in names:
            self._anchor = None

    # -- playback (its own thread; publishing is thread safe in rclpy) --

    def _run(self) -> None:
        try:
            if self._wait_to_start():
                self._play()
                self._publish_last_clock()
                self._wait_for_acked()
        except Exception as exc:  # a shut-down context while publishing: stop quietly
            if not self._stop.is_set() and self.context.ok():
                self.exit_status = 1  # the bag was not played whole: say so in the status
                why = (str(exc) if isinstance(exc, BagError) else  # names the repair
                       f"{type(exc).__name__}: {exc}; if the bag is damaged, 'dampest reindex "
                       f"{self.p('bag')}' rebuilds its index from the intact chunks")
                self.get_logger().error(
                    f"playback of {self.p('bag')} failed after {self.published} messages: {why}")
        finally:
            self._done.set()
            if not self._stop.is_set():
                try:
                    self._log_progress(final=True)
                finally:
                    self.context.try_shutdown()  # ends spin(): the node has done its job

    def _wait_to_start(self) -> bool:
        """Wait for the subscribers (at most wait_for_subscribers_timeout s, then warn) and
        the delay; False when stopped."""
        need = int(self.p("wait_for_subscribers"))
        pubs = set(self.pubs.values())
        deadline = time.monotonic() + float(self.p("wait_for_subscribers_timeout"))
        while need and any(p.get_subscription_count() < need for p in pubs):
            if time.monotonic() >= deadline:
                lacking = sorted(p.topic_name for p in pubs if p.get_subscription_count() < need)
                self.get_logger().warning(
                    f"fewer than {need} subscriber(s) after "
                    f"{float(self.p('wait_for_subscribers_timeout')):g} s on {lacking}; "
                    "playing anyway: what they publish now reaches no one (play only the "
                    "others with topics, or wait longer with wait_for_subscribers_timeout)")
                break
            if self._stop.wait(0.05):
                return False
        return not self._stop.wait(float(self.p("delay")))

    def _play(self) -> None:
        if not self.connections:  # (rosbags reads every topic for an empty selection)
            return
        start = self.reader.start_time + round(float(self.p("start_offset")) * 1e9)
        while not self._stop.is_set():
            self._anchor = None
            played = 0
            for conn, t, data in self.bag.messages(self.connections, start=start):
                if not self._sleep_until(t):
                    return
                pub = self.pubs[conn.id]
                pub.publish(bytes(data))
                played += 1
                self.published += 1
                self.heard += pub.get_subscription_count() > 0
                self.bag_time = t
            if not self.p("loop"):
                return
            if not played:  # looping over nothing would spin a core until stopped
                self.get_logger().warning(
                    f"loop: no message of the played topics after start_offset "
                    f"{float(self.p('start_offset')):g} s in {self.p('bag')}; playback ends")
                return

    def _wait_for_acked(self) -> None:
        """Hold the publishers until reliable subscribers have every message (a reliable
        message still in flight when the node exits is lost), at most wait_for_acked s."""
        timeout = float(self.p("wait_for_acked"))
        if self._stop.is_set() or timeout <= 0:
            return
        deadline = time.monotonic() + timeout
        late = [p.topic_name for p in set(self.pubs.values())
                if not p.wait_for_all_acked(
                    Duration(seconds=max(deadline - time.monotonic(), 0.0)))]
        if late:
            self.get_logger().warning(
                f"not every message was acknowledged within {timeout:g} s on {sorted(late)} "
                "(a subscriber too slow or gone); raise wait_for_acked to wait longer")

    def _sleep_until(self, t: int) -> bool:
        """Wait for the wall time of bag time ``t`` (publishing /clock meanwhile); False
        when stopped."""
        while True:
            if self._anchor is None:
                self._anchor = (time.perf_counter(), t)
            wall0, bag0 = self._anchor
            rate = float(self.p("rate"))
            now = time.perf_counter()
            due = wall0 + (t - bag0) / 1e9 / rate
            if self.clock_pub is not None:
                self._publish_clock(now, bag0 + round((now - wall0) * rate * 1e9), t)
            self._maybe_progress(now)
            if now >= due:
                return not self._stop.is_set()
            step = due - now
            if self.clock_pub is not None:
                step = min(step, 1.0 / float(self.p("clock_rate")))
            if self._stop.wait(min(step, 0.5)):
                return False

    def _publish_clock(self, now: float, bag_now: int, next_t: int) -> None:
        if now - self._last_clock >= 1.0 / float(self.p("clock_rate")):
            self._last_clock = now
            self._send_clock(min(bag_now, next_t))

    def _publish_last_clock(self) -> None:
        """/clock at the last message played: a listener's clock reaches the end of what it
        was given (while playing, /clock trails the messages by up to 1 / clock_rate)."""
        if self.clock_pub is not None and self.published and not self._stop.is_set():
            self._send_clock(self.bag_time)

    def _send_clock(self, ns: int) -> None:
        assert self.clock_pub is not None
        self.clock_pub.publish(Clock(clock=Time(sec=ns // 1_000_000_000,
                                                nanosec=ns % 1_000_000_000)))

    def _maybe_progress(self, now: float) -> None:
        period = float(self.p("progress_period"))
        if period > 0 and time.monotonic() - self._last_progress >= period:
            self._log_progress()

    def _log_progress(self, final: bool = False) -> None:
        self._last_progress = time.monotonic()
        into = max(self.bag_time - self.reader.start_time, 0) * 1e-9
        length = max(self.reader.duration - 1, 0) * 1e-9
        pct = 100.0 * self.published / max(self.total, 1)
        heard = 100.0 * self.heard / max(self.published, 1)
        what = "finished" if final else "playing"
        cpu = time.process_time() - self._cpu0
        text = (f"{what}: published {self.published}/{self.total} messages ({pct:.1f} %), "
                f"{self.heard} ({heard:.1f} %) while their topic had a subscriber, bag time "
                f"{into:.1f} of {length:.1f} s, CPU {cpu:.1f} s")
        # one call site per severity: rclpy refuses a second severity at the same line
        if final and self.heard < self.published:
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)

    def destroy_node(self) -> None:
        """Stop playback, close the bag, destroy the node."""
        self._stop.set()
        if self.thread.is_alive():
            self.thread.join(timeout=5.0)
        self.reader.close()
        super().destroy_node()


main = main_for(ReplayNode, __doc__ or "")

if __name__ == "__main__":
    main()

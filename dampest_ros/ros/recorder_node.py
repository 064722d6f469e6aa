"""recorder_node: records topics to a rosbag2 MCAP bag (as ``ros2 bag record``).

Subscribes to each topic as soon as a publisher of it appears in the graph (looked for every
0.02 s during the first seconds, then every discovery_period), with a QoS compatible with
every publisher (reliable only if all of them are). A thread of its own waits on the
subscriptions alone and takes every queued message as serialized bytes (no
deserialisation, no executor round per message), so the bag keeps pace with publishers in
bursts; it writes each message with its receive time (the time the middleware received it;
the node clock, i.e. simulation time, under use_sim_time) through
dampest_ros.io.recorder.BagRecorder. The QoS each publisher offers is stored in the bag
metadata. Chunks reach the disk every chunk_size bytes or flush_period seconds (checked
every flush_period / 4); each message of the chunk in progress is also appended at once to
the file's journal, so a killed recorder loses no message it had received. Besides the
topics named, those regex matches are recorded as they appear in the graph; topics that
exclude_regex matches are never recorded. silence_warning seconds after the start, a
warning names each wanted topic that no one publishes while others are, and the closest
topic that someone publishes (a typo); when no message has arrived by then, a warning says
so (the usual cause: the pipeline is not running, or runs on another ROS_DOMAIN_ID).
SIGINT/SIGTERM take what is still queued and close the bag (summary, metadata.yaml). A
killed recording is recovered with 'dampest reindex BAG'. While recording, the bag holds a
lock that reindex and another recorder respect. A full disk stops the recording: the bag
is closed with every message received (from the space the recorder keeps in reserve), an
error line gives the count and the node exits with status 1.
"""

from __future__ import annotations

import difflib
import re
import sys
import threading
import time
from datetime import datetime
from functools import partial
from pathlib import Path
from typing import Any

from rclpy.clock import Clock, ClockType, ROSClock
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.subscription import Subscription

from dampest_ros.io.bag_metadata import message_definition
from dampest_ros.io.recorder import (
    DEFAULT_CHUNK_INTERVAL,
    DEFAULT_CHUNK_SIZE,
    BagRecorder,
    RecorderError,
    StorageError,
)
from dampest_ros.ros.bag_interop import compatible_qos, import_message_type, to_bag_qos
from dampest_ros.ros.common import (
    DRAIN_LIMIT,
    Param,
    ParamNode,
    TakenElsewhere,
    main_for,
    signals_held,
)

#: The topics of docs/architecture.md §3 (relative: resolved in the node's namespace).
DEFAULT_TOPICS = ["truth/odom", "imu/data", "dvl/twist", "pressure", "thrusters/state",
                  "dampest/velocity", "dampest/acceleration", "dampest/wrench", "dampest/model",
                  "/diagnostics"]
#: Seconds after the start during which the graph is looked at every :data:`EARLY_LOOK` s
#: (Fast DDS discovers a running publisher between 0.05 and 3 s after the start).
EARLY_WINDOW, EARLY_LOOK = 5.0, 0.02


def _output_ok(value: Any) -> str | None:
    if str(value) and Path(str(value)).exists():
        return f"output {value} exists; the recorder never overwrites a bag"
    return None


def _regex_ok(value: Any) -> str | None:
    try:
        re.compile(str(value))
    except re.error as exc:
        return f"not a regular expression: {exc}"
    return None


def _topics_ok(value: Any) -> str | None:
    names = [t for t in value if t]
    if "all" in names and len(names) > 1:
        return "topics: 'all' records every topic and takes no other name"
    return None


class RecorderNode(ParamNode):
    """Recorder node (see the module docstring)."""

    NODE_NAME = "recorder_node"
    PARAMS = (
        Param("output", "", "bag directory to create (must not exist); empty: "
              "rosbag2_YYYY_MM_DD-HH_MM_SS in the working directory", check=_output_ok,
              read_only=True),
        Param("topics", DEFAULT_TOPICS, "topics to record (relative names are resolved in "
              "the node namespace); ['all']: every topic found in the graph",
              check=_topics_ok, read_only=True),
        Param("regex", "", "also record every topic whose resolved name this regular "
              "expression matches (anywhere in the name; not those of exclude); empty: none",
              check=_regex_ok, read_only=True),
        Param("exclude", ["/rosout", "/parameter_events"], "topics never recorded by 'all'",
              read_only=True),
        Param("exclude_regex", "", "topics whose resolved name this regular expression "
              "matches (anywhere in the name) are never recorded; empty: none",
              check=_regex_ok, read_only=True),
        Param("max_bag_size", 0, "start a new storage file after this many bytes; 0: never",
              low=0, high=2**62, read_only=True),
        Param("max_bag_duration", 0.0, "start a new storage file after this many seconds of "
              "log time; 0: never", low=0.0, high=1e9, read_only=True),
        Param("chunk_size", DEFAULT_CHUNK_SIZE, "bytes of messages per MCAP chunk; each "
              "chunk is flushed to disk when complete", low=1024, high=2**30, read_only=True),
        Param("flush_period", DEFAULT_CHUNK_INTERVAL, "a chunk is also flushed once it is this "
              "many seconds old (checked every quarter of it; until then its messages are in "
              "the file's journal); 0: by size only", low=0.0, high=3600.0, read_only=True),
        Param("compression", "none", "chunk compression", choices=("none", "zstd", "lz4"),
              read_only=True),
        Param("queue_depth", 2000, "subscription queue (messages) absorbing bursts",
              low=1, high=1_000_000, read_only=True),
        Param("discovery_period", 0.5, "seconds between looks at the graph for publishers "
              "of topics not yet subscribed (every 0.02 s during the first 5 s)",
              low=0.05, high=60.0),
        Param("status_period", 10.0, "seconds between status lines in the log; 0: none",
              low=0.0, high=3600.0),
        Param("silence_warning", 5.0, "seconds after the start at which a warning is logged "
              "if no message has arrived on any topic; 0: none", low=0.0, high=3600.0,
              read_only=True),
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, self.PARAMS, **kwargs)
        output = str(self.p("output")) or datetime.now().strftime("rosbag2_%Y_%m_%d-%H_%M_%S")
        self.recorder = BagRecorder(
            output, chunk_size=int(self.p("chunk_size")),
            chunk_interval=float(self.p("flush_period")),
            max_bag_size=int(self.p("max_bag_size")),
            max_bag_duration=float(self.p("max_bag_duration")),
            compression=str(self.p("compression")))
        wanted = [t for t in self.p("topics") if t]
        self.regex = re.compile(str(self.p("regex"))) if self.p("regex") else None
        if not wanted and self.regex is None:
            raise ValueError("topics must name at least one topic, or be ['all'], or regex "
                             "select them")
        try:
            self.recorder.open()
            self._start(wanted)
        except (OSError, RecorderError) as exc:  # a refusal at start: one line, status 2
            raise ValueError(f"output {output}: {exc}") from None
        except BaseException:  # e.g. a Ctrl-C while starting: no bag left open or half made
            with signals_held(self.get_name()):
                self._abandon()
            raise

    def _start(self, wanted: list[str]) -> None:
        """Everything after the bag is open: the subscriptions' state, the take thread, the
        timers; ``wanted``: the topics parameter."""
        self.all_topics = wanted == ["all"]
        self.wanted = [] if self.all_topics else [self.resolve_topic_name(t) for t in wanted]
        self.exclude = {self.resolve_topic_name(t) for t in self.p("exclude") if t}
        self.exclude_regex = re.compile(str(self.p("exclude_regex"))) \
            if self.p("exclude_regex") else None
        self.subs: dict[str, Subscription] = {}
        self.lost: dict[str, int] = {}
        self.single: dict[int, bool] = {}      # connection → exactly one publisher
        self.span: dict[int, list[int]] = {}   # → [first, last sequence number, received]
        self.gaps: dict[int, int] = {}         # → messages missing from closed spans
        self.skipped: set[str] = set()
        self._cpu0, self._wall0 = time.process_time(), time.monotonic()
        # the take thread (see _take_loop) and what it shares with the executor's thread
        self._lock = threading.Lock()            # the bag recorder and the span counters
        self._elsewhere = TakenElsewhere()       # the subscriptions' group: no executor
        self._taken: tuple[Subscription, ...] = ()
        self._wake = GuardCondition(None, None, context=self.context)
        self._failure: BaseException | None = None
        self._sim_time = False                   # the node clock runs on /clock (use_sim_time)
        self._failed = self.create_guard_condition(self._raise_failure)
        self._running = True
        self._taker = threading.Thread(target=self._take_loop, name="recorder take",
                                       daemon=True)
        self._taker.start()
        self._discover()
        self.discovery_timer = self.create_timer(float(self.p("discovery_period")),
                                                 self._discover)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._early_end = time.monotonic() + EARLY_WINDOW
        self.early_timer = self.create_timer(EARLY_LOOK, self._discover_early, clock=steady)
        self.silence_timer = None
        if self.p("silence_warning") > 0:
            self.silence_timer = self.create_timer(float(self.p("silence_warning")),
                                                   self._warn_if_silent, clock=steady)
        self.status_timer = None
        if self.p("status_period") > 0:
            self.status_timer = self.create_timer(float(self.p("status_period")), self._status)
        what = "every topic" if self.all_topics else ", ".join(
            [*self.wanted, *([f"the topics matching {self.regex.pattern!r}"]
                             if self.regex is not None else [])])
        self.get_logger().info(f"recording {what} to {self.recorder.path}")

    def _abandon(self) -> None:
        """End what an interrupted start began: the take thread if it runs, then close the
        bag (summary, metadata.yaml, lock released), or discard it if its open was cut
        short."""
        self._running = False
        taker = getattr(self, "_taker", None)
        if taker is not None and taker.is_alive():
            self._wake.trigger()
            taker.join()
        if not self.recorder.opened:
            self.recorder.discard()
        elif not self.recorder.closed:
            self.recorder.close()

    def on_parameters(self, names: list[str]) -> None:
        """discovery_period and status_period apply at once."""
        if "discovery_period" in names:
            self.discovery_timer.timer_period_ns = int(self.p("discovery_period") * 1e9)
        if "status_period" in names and self.status_timer is not None:
            self.status_timer.timer_period_ns = int(max(self.p("status_period"), 0.05) * 1e9)

    def _candidates(self) -> list[str]:
        names = list(self.wanted)
        if self.all_topics or self.regex is not None:
            graph = [name for name, _ in self.get_topic_names_and_types()
                     if name not in self.exclude]
            names += [t for t in graph if self.all_topics or (
                self.regex is not None and self.regex.search(t) and t not in names)]
        return [t for t in names if t not in self.subs
                and not (self.exclude_regex and self.exclude_regex.search(t))]

    def _warn_if_silent(self) -> None:
        """Once, silence_warning s after the start: warn about the wanted topics that no one
        publishes (the closest topic of the graph suggested: a typo records nothing), and if
        no message has arrived."""
        assert self.silence_timer is not None
        self.silence_timer.cancel()
        self._warn_unpublished()
        with self._lock:
            if any(t.count for t in self.recorder.topics):
                return
        what = (f"any of the {len(self.wanted)} topics" if not self.all_topics
                and self.regex is None
                else f"any of the {len(self.subs)} topics found" if self.subs else "any topic")
        self.get_logger().warning(
            f"no message on {what} after {float(self.p('silence_warning')):g} s "
            f"({len(self.subs)} with a publisher): is the pipeline running, on this "
            f"ROS_DOMAIN_ID ({self.context.get_domain_id()})?")

    def _warn_unpublished(self) -> None:
        """Warn about each wanted topic without a publisher, naming the closest topic that
        has one (none of them with one: the silence warning says it all)."""
        if not self.subs:
            return
        graph = [name for name, _ in self.get_topic_names_and_types()]
        for topic in self.wanted:
            if topic in self.subs or topic in self.skipped:
                continue
            close = difflib.get_close_matches(topic, graph, n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            self.get_logger().warning(
                f"topics: no publisher of {topic} after "
                f"{float(self.p('silence_warning')):g} s (nothing recorded from it){hint}")

    def _discover_early(self) -> None:
        """Look at the graph often while the node is young and topics are missing."""
        self._discover()
        if time.monotonic() > self._early_end or (not self.all_topics and self.regex is None
                                                  and not self._candidates()):
            self.early_timer.cancel()

    def _discover(self) -> None:
        for topic in self.subs:  # drops are counted while one publisher sends
            conn = self.recorder.connection(topic)
            if conn is not None:
                single = self.count_publishers(topic) == 1
                if single != self.single[conn]:
                    with self._lock:
                        self._close_span(conn)
                        self.single[conn] = single
        for topic in self._candidates():
            pubs = self.get_publishers_info_by_topic(topic)
            if not pubs or topic in self.skipped:
                continue
            msgtype = pubs[0].topic_type
            try:
                cls = import_message_type(msgtype)
            except ImportError as exc:
                self.get_logger().warning(f"not recording {topic}: {exc}")
                self.skipped.add(topic)
                continue
            offered = [p.qos_profile for p in pubs if p.topic_type == msgtype]
            with self._lock:
                conn = self.recorder.add_connection(
                    topic, msgtype, [to_bag_qos(q) for q in offered],
                    type_hash=str(getattr(pubs[0], "topic_type_hash", "")) or None)
                self.single[conn], self.span[conn], self.gaps[conn] = (len(pubs) == 1,
                                                                       [0, 0, 0], 0)
            self.lost[topic] = 0
            events = SubscriptionEventCallbacks(message_lost=partial(self._on_lost, topic))
            # raw: the take thread hands the callback the serialized bytes and the info
            callback: Any = partial(self._write, conn)
            self.subs[topic] = sub = self.create_subscription(
                cls, topic, callback, compatible_qos(offered, int(self.p("queue_depth"))),
                raw=True, event_callbacks=events, drain=0, callback_group=self._elsewhere)
            self._taken = (*self._taken, sub)
            self._wake.trigger()  # the take thread waits on it from now on
            self.get_logger().info(f"recording {topic} ({msgtype}, "
                                   f"{len(offered)} publisher(s))")

    def _take_loop(self) -> None:
        """The take thread: wait on the subscriptions (and :attr:`_wake`) alone, take every
        queued message in turns, one per subscription, and hand it to the subscription's
        callback (:meth:`_write`); flush a chunk that is due. An error (a full disk) ends
        the thread and is raised in the executor's thread (:meth:`_raise_failure`).

        The subscriptions belong to a callback group executors never wait on; they are
        destroyed only after this thread has ended (:meth:`destroy_node`)."""
        timeout = int(max(float(self.p("flush_period")) / 4, 0.05) * 1e9)
        subs: tuple[Subscription, ...] | None = None
        wait_set: Any = None
        try:
            self._prepare()
            while self._running:
                if subs is not self._taken:
                    subs = self._taken
                    wait_set = _rclpy.WaitSet(len(subs), 1, 0, 0, 0, 0, self.context.handle)
                wait_set.clear_entities()
                for sub in subs:
                    wait_set.add_subscription(sub.handle)
                wait_set.add_guard_condition(self._wake.handle)
                wait_set.wait(timeout)
                with self._lock:
                    if self._running:
                        self._take(subs, DRAIN_LIMIT)
                        self.recorder.flush_if_due()
        except BaseException as exc:  # (StorageError: the recorder closed the bag)
            self._failure = exc
            self._failed.trigger()

    def _prepare(self) -> None:
        """While discovery runs: load the message classes and definitions of the wanted
        topics of the dampest contract (docs/architecture.md §3), so that subscribing once
        their publishers are found costs no import (~0.15 s cold). A type that does not load
        is left to :meth:`_discover`, which reports it."""
        from dampest_ros.core.signals.measurements import TOPIC_TYPES

        for name in self.p("topics"):
            msgtype = TOPIC_TYPES.get(name, ("", None))[0]
            try:
                if msgtype:
                    import_message_type(msgtype)
                    message_definition(msgtype)
            except (ImportError, KeyError):
                continue

    def _take(self, subs: tuple[Subscription, ...], turns: int) -> None:
        """Take the queued messages of ``subs``, one per subscription and turn, for at most
        ``turns`` turns (all of them when ``turns`` is 0)."""
        clock = self.get_clock()  # (whether it runs on /clock: once per batch, it takes a lock)
        self._sim_time = isinstance(clock, ROSClock) and clock.ros_time_is_active
        turn = 0
        while not turns or turn < turns:
            took = False
            for sub in subs:
                taken = sub.handle.take_message(sub.msg_type, True)
                if taken is not None:
                    sub.callback(*taken)
                    took = True
            if not took:
                return
            turn += 1

    def _raise_failure(self) -> None:
        """In the executor's thread: the take thread ended on an error; a refused write
        (the recorder closed the bag) is said in one line and ends the node with status 1,
        anything else is raised."""
        exc = self._failure
        if isinstance(exc, StorageError):
            self.get_logger().error(f"{exc}")
            raise SystemExit(1)
        if exc is not None:
            raise exc

    def _write(self, conn: int, data: bytes, info: dict[str, Any]) -> None:
        seq = int(info.get("publication_sequence_number") or 0)
        if seq and self.single[conn]:  # one publisher: what its sequence skipped is lost
            span = self.span[conn]
            if span[0] == 0:
                span[0] = seq
            span[1] = max(span[1], seq)
            span[2] += 1
        if self._sim_time:
            received = self.get_clock().now().nanoseconds
        else:  # the system clock when the middleware received it
            received = int(info.get("received_timestamp") or 0) or time.time_ns()
        self.recorder.write(conn, received, data,
                            publish_time=int(info.get("source_timestamp") or 0) or None,
                            sequence=seq)

    def _on_lost(self, topic: str, info: Any) -> None:
        self.lost[topic] = int(info.total_count)
        self.get_logger().warning(f"{topic}: {info.total_count_change} message(s) lost in "
                                  f"transport ({info.total_count} in all)")

    def _close_span(self, conn: int) -> None:
        self.gaps[conn] = self._missing(conn)
        self.span[conn] = [0, 0, 0]

    def _missing(self, conn: int) -> int:
        first, last, received = self.span[conn]
        return self.gaps[conn] + (max(last - first + 1 - received, 0) if first else 0)

    def stats(self) -> dict[str, Any]:
        """Messages written per topic; messages lost: reported by the middleware, or missing
        from a single publisher's sequence numbers (a full queue); CPU seconds used."""
        return {"messages": {t.topic: t.count for t in self.recorder.topics},
                "lost": sum(self.lost.values()) + sum(map(self._missing, self.gaps)),
                "cpu": time.process_time() - self._cpu0,
                "wall": time.monotonic() - self._wall0}

    def _describe(self, s: dict[str, Any]) -> str:
        n = sum(s["messages"].values())
        per = f", {1e6 * s['cpu'] / n:.0f} µs per message" if n else ""
        return (f"{s['lost']} lost, CPU {s['cpu']:.1f} s in {s['wall']:.1f} s "
                f"({100 * s['cpu'] / max(s['wall'], 1e-9):.0f} % of one core{per})")

    def _status(self) -> None:
        s = self.stats()
        self.get_logger().info(
            f"{sum(s['messages'].values())} messages on {len(s['messages'])} topics, "
            f"{self.recorder.bytes_written / 1e6:.1f} MB, {self._describe(s)}")

    def destroy_node(self) -> None:
        """End the take thread, take what is still queued, close the bag (last chunk,
        summary, metadata.yaml), then destroy the node."""
        self._running = False
        self._wake.trigger()
        self._taker.join()
        if not self.recorder.closed and self._failure is None:
            try:
                self._take(self._taken, 0)
            except StorageError as exc:  # the recorder closed the bag
                self.get_logger().error(f"{exc}")
        if not self.recorder.closed:
            s = self.stats()
            path = self.recorder.close()
            counts = ", ".join(f"{t} {n}" for t, n in s["messages"].items())
            text = (f"closed {path}: {sum(s['messages'].values())} messages "
                    f"({counts or 'none'}), {self._describe(s)}")
            if self.context.ok():
                self.get_logger().info(text)
            else:  # after SIGINT/SIGTERM: /rosout is gone, the console is not
                print(f"[INFO] [{self.get_name()}]: {text}", file=sys.stderr, flush=True)
        self._wake.destroy()
        super().destroy_node()


main = main_for(RecorderNode, __doc__ or "")

if __name__ == "__main__":
    main()

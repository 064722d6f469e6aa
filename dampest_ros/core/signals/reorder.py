"""Deterministic merge of several message streams into stamp order.

Messages of different topics reach a subscriber in an order that depends on the transport
and on the executor's scheduling (a single-threaded rclpy executor takes one message per
subscription per round, so under load a slow topic runs ahead of a fast one). A causal
preprocessor whose state depends on that interleaving would give a different result live,
in a replay and offline. :class:`StampOrder` removes the dependence: it holds the messages
and releases them in (stamp, role) order, the order in which
:meth:`dampest_ros.core.online.preprocessor.OnlinePreprocessor.messages` feeds a whole
recording, so every path feeds the preprocessor the identical sequence.

A held message (stamp t, role k) is released as soon as nothing that can still arrive may
precede it, which is decided from stamps alone (no wall clock):

- **watermark**: every role has already delivered a stamp after t (or equal to t, for the
  roles ranked at or after k), and the stamps of each topic increase; or
- **latency**: the newest stamp seen on any topic is more than ``latency`` seconds after t
  (a topic that has gone quiet, a dropout, a topic that never comes).

A message that arrives after a message it should precede has been released is **late**: it
is counted and passed on at once (the preprocessor's own order and staleness checks then
apply), so only a run with no late message is guaranteed to equal the offline order. A
stamp more than ``clock_jump`` seconds behind its topic's newest one is a clock jump (a
restarted simulator, a looped bag): everything held is released and the watermarks start
again.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from typing import Any

from dampest_ros.core.physics.rigid_body import ConfigError

#: A released message: (role, stamp (s), payload as pushed).
Message = tuple[str, float, Any]


class StampOrder:
    """Reorder buffer for messages of named roles (see the module docstring).

    Parameters
    ----------
    roles : sequence of str
        The roles in tie order: of two messages with equal stamps the one whose role comes
        first is released first.
    latency : float
        Stamp-time horizon (s): a message is released at the latest when a stamp more than
        this after it has been seen. It bounds how far one topic may lag another without
        its messages being late; under load a single-threaded executor lets a 200 Hz topic
        fall behind the slow ones by its whole queue (SENSOR_QOS: 2000 messages, 10 s).
        It is also how long a topic that has gone quiet holds the others up.
    clock_jump : float
        A stamp this much (s) behind its role's newest stamp restarts the buffer.

    Notes
    -----
    ``counts`` holds ``received``, ``released`` (late ones included), ``late`` and
    ``clock_jumps``; ``max_lag`` is the largest lag (s) of a message behind the newest stamp
    seen when it arrived (a latency below it would have made that message late). Each push
    costs O(log n + roles) for n messages held.
    """

    def __init__(self, roles: Sequence[str], latency: float = 5.0,
                 clock_jump: float = 1.0) -> None:
        if not roles or len(set(roles)) != len(roles):
            raise ConfigError("roles", f"must be distinct names, got {list(roles)}")
        for name, v in (("latency", latency), ("clock_jump", clock_jump)):
            if not math.isfinite(v) or v < 0:
                raise ConfigError(name, f"must be a finite number ≥ 0, got {v}")
        self.roles = tuple(roles)
        self.rank = {r: k for k, r in enumerate(self.roles)}
        self.latency = float(latency)
        self.clock_jump = float(clock_jump)
        self.counts = {"received": 0, "released": 0, "late": 0, "clock_jumps": 0}
        self.max_lag = 0.0
        self._heap: list[tuple[float, int, int, str, Any]] = []
        self._seq = 0
        self._restart()

    def _restart(self) -> None:
        self._newest_by_role = [-math.inf] * len(self.roles)
        self._newest = -math.inf
        self._released = (-math.inf, -1)  # key (stamp, rank) of the last release

    @property
    def newest(self) -> float:
        """The newest stamp (s) seen since the start or the last clock jump (−∞: none)."""
        return self._newest

    def __len__(self) -> int:
        """Messages held."""
        return len(self._heap)

    def push(self, role: str, t: float, payload: Any = None) -> list[Message]:
        """Take one message; return the messages released by it, in release order.

        Parameters
        ----------
        role : str
            One of ``roles``.
        t : float
            Header stamp (s).
        payload : any
            Carried along unchanged (e.g. the arguments of the preprocessor's method).
        """
        k = self.rank[role]
        self.counts["received"] += 1
        out: list[Message] = []
        if t < self._newest_by_role[k] - self.clock_jump:
            self.counts["clock_jumps"] += 1
            out = self.flush()
            self._restart()
        self.max_lag = max(self.max_lag, self._newest - t)
        if (t, k) < self._released:
            self.counts["late"] += 1
            self.counts["released"] += 1
            out.append((role, t, payload))
        else:
            heapq.heappush(self._heap, (t, k, self._seq, role, payload))
            self._seq += 1
        self._newest_by_role[k] = max(self._newest_by_role[k], t)
        self._newest = max(self._newest, t)
        return out + self._release()

    def flush(self) -> list[Message]:
        """Release everything held, in order (at the end of the data, or when idle)."""
        return self._release(everything=True)

    def _release(self, everything: bool = False) -> list[Message]:
        out: list[Message] = []
        heap = self._heap
        horizon = self._newest - self.latency
        while heap:
            t, k = heap[0][0], heap[0][1]
            if not (everything or t < horizon or self._passed(t, k)):
                break
            _, _, _, role, payload = heapq.heappop(heap)
            self._released = (t, k)
            out.append((role, t, payload))
        self.counts["released"] += len(out)
        return out

    def _passed(self, t: float, k: int) -> bool:
        """True when every role has delivered past (t, k) (watermark rule)."""
        for j, newest in enumerate(self._newest_by_role):
            if newest < t or (newest == t and j < k):
                return False
        return True

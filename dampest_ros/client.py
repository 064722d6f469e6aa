"""Client of the model service: what a controller imports to use the identified damping
(:class:`ModelClient`) or an arm's identified dynamics (:class:`ArmModelClient`: the
joint-torque feed-forward; both follow a server through :class:`ServedModelClient`).

Fetches ``model.*`` (docs/architecture.md §3) from a node (``estimator_node``,
``model_server_node``) with the standard ``list_parameters`` and ``get_parameters`` services,
follows ``/parameter_events`` to refresh when ``model.version`` changes, and evaluates D(ν),
the damping force D(ν)ν, its standard deviation and C(ν)ν (FRD body frame, SI units), the
latter with the plant's added-mass switches and zeroed C_A entries (``model.added_mass_terms``,
``model.M_A``) when the server has them.
Without ROS, :meth:`ModelClient.from_yaml` reads a model file. rclpy is imported only by the
ROS methods.

:attr:`ModelClient.identified` says per coefficient whether the data determined it
(``model.identified``; :attr:`ModelClient.held` gives the reason for those that hold their
prior). An update whose numbers are not finite (θ, M, the σ of an identified coefficient) is
refused: the client keeps the last good model and says why (:attr:`ModelClient.errors`, the
node's log).

:meth:`ModelClient.wait` that times out says why: the node named is on the graph but declares no
``model.*`` parameters (what it publishes, and where a model comes from), or no node of that
name is there (the nodes that do declare ``model.*``, closest name first, and the
``ROS_DOMAIN_ID`` looked on).

:attr:`ModelClient.age` is the time since the model in hand arrived. A server gone from the
graph (its parameter services) for ``timeout`` seconds is lost: :attr:`ModelClient.lost` is
true, :attr:`ModelClient.available` false (the last model is kept and still evaluated), a
warning is logged; when the server is back the model is fetched again.

Every static damping term is evaluated (linear, quadratic, cross, added mass, residual): the
structure comes from ``model.terms.*`` when the server declares them (estimator_node and
model_server_node do, as the model file has them), otherwise it is rebuilt from the
parameter names, which is enough for linear and quadratic terms. A fluid-memory term needs
its filter states and is refused.

The service is called with ``call_async``; the caller's node must be spun by an executor
(its own, or the background thread :meth:`ModelClient.standalone` starts). Blocking on
``rclpy.spin_until_future_complete`` is avoided: in this rclpy it slows down with every call
(docs/architecture.md §6).

Example::

    client = ModelClient.standalone("estimator_node")   # node + spin thread
    client.wait(10.0)                                    # first model
    tau_ff = client.feedforward(nu)                     # D(ν)ν + C(ν)ν
"""

from __future__ import annotations

import difflib
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, Generic, Protocol, Self, TypeVar

import numpy as np
from numpy.typing import NDArray

from dampest_ros.core.arm.base import base_parameters
from dampest_ros.core.arm.identify import IdentifyConfig, predict
from dampest_ros.core.arm.model import arm_model_identity
from dampest_ros.core.arm.online import ArmEstimate
from dampest_ros.core.identification.model import Model
from dampest_ros.core.physics.identity import Identity, mismatch, unchecked
from dampest_ros.core.physics.rigid_body import ConfigError
from dampest_ros.io.arm import (
    ArmDescription,
    arm_model_from_parameters,
    load_arm,
    read_arm_model,
)
from dampest_ros.io.yaml_io import load_model, model_from_parameters

FloatArray = NDArray[np.float64]

#: The parameters every model server holds (docs/architecture.md §3); ``model.terms.*`` may
#: come too.
MODEL_PARAMETERS = ("model.parameter_names", "model.theta", "model.theta_std", "model.M",
                    "model.version")


def _evaluable(m: Model) -> Model:
    """The model with its structure (from its terms, else rebuilt from the names); a memory
    term, which needs its filter states, is refused (ConfigError)."""
    structure = m.structure
    if structure.term("freq") is not None:
        raise ConfigError("model.terms", "a memory (freq) term needs its filter states; "
                                         "evaluate it with DampingModel.force")
    return replace(m, damping=structure)


#: Lists repeated in a row when a get answers nothing because the names changed meanwhile.
STALE_RETRIES = 3
#: Seconds :meth:`ModelClient.wait` spends, after a timeout, asking the nodes of the graph
#: which of them declare ``model.*``.
PROBE_TIME = 2.0
#: Where a model comes from, for messages.
SERVERS = ("model_server_node (serves a saved model file) or estimator_node (identifies the "
           "model live)")
#: The parameters of an arm's model (the contract of arm_estimator_node, docs/architecture.md
#: §3).
ARM_MODEL_PARAMETERS = ("model.kind", "model.joint_names", "model.parameter_names",
                        "model.theta", "model.theta_std", "model.version")

class ModelUnavailableError(RuntimeError):
    """No model yet (the server has not answered, or its model is invalid)."""


class _Served(Protocol):
    """What every served model has (a vehicle's :class:`Model`, an arm's ArmEstimate)."""

    @property
    def version(self) -> int: ...

    @property
    def identified(self) -> NDArray[np.bool_]: ...


ServedT = TypeVar("ServedT", bound=_Served)


class ServedModelClient(Generic[ServedT]):
    """The ``model.*`` of one server node, kept up to date: the fetching, following and
    watching that :class:`ModelClient` (a vehicle's damping) and :class:`ArmModelClient` (an
    arm's base parameters) share; each subclass says which parameters it needs
    (:attr:`REQUIRED`), where such a model comes from (:attr:`SERVERS`) and how the values
    become its model (:meth:`_accept`).

    Parameters
    ----------
    node : rclpy.node.Node, optional
        The node whose service client and subscription are used (None: YAML only).
    server : str
        Name of the node that holds ``model.*`` (relative names follow the node's namespace).
    follow : bool
        Refresh on ``/parameter_events`` of the server.
    on_update : callable, optional
        Called with the new model after each refresh.
    timeout : float
        Seconds the server may be missing from the graph before it counts as lost
        (:attr:`lost`; checked every ``min(timeout / 4, 0.5)`` s of wall-clock time).
    """

    #: The parameters the server must hold.
    REQUIRED: tuple[str, ...] = MODEL_PARAMETERS
    #: Where the model comes from, for messages.
    SERVERS: str = SERVERS

    def __init__(self, node: Any = None, server: str = "estimator_node", follow: bool = True,
                 on_update: Callable[[ServedT], None] | None = None,
                 timeout: float = 5.0) -> None:
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout}")
        self.node = node
        self.server = server
        self.on_update = on_update
        self.timeout = float(timeout)
        self._received_at = math.nan     # time.monotonic() when the model in hand arrived
        self._missing_since: float | None = None  # since when the server is not in the graph
        self._lost_logged = False
        self._model: ServedT | None = None
        self._lock = threading.Lock()
        self._got = threading.Event()
        self.refreshes = 0
        self.errors: list[str] = []
        self._executor: Any = None
        self._thread: threading.Thread | None = None
        self._pending = False
        self._stale = 0  # lists repeated in a row because the names changed meanwhile
        if node is not None:
            from rcl_interfaces.msg import ParameterEvent
            from rcl_interfaces.srv import GetParameters, ListParameters
            self._list = node.create_client(ListParameters, f"{server}/list_parameters")
            self._cli = node.create_client(GetParameters, f"{server}/get_parameters")
            # fully qualified server name, as /parameter_events reports it
            ns = node.get_namespace().rstrip("/")
            self._full_name = server if server.startswith("/") else f"{ns}/{server}"
            if follow:
                node.create_subscription(ParameterEvent, "/parameter_events", self._on_event,
                                         100)
            from rclpy.clock import Clock, ClockType
            # the wall clock: a node on simulation time still notices a lost server
            self._watch = node.create_timer(min(self.timeout / 4, 0.5), self._check_server,
                                            clock=Clock(clock_type=ClockType.STEADY_TIME))
            self.request()

    def _accept(self, values: dict[str, Any]) -> ServedT:
        """The model of the server's ``model.*`` values (dotted name → value), checked;
        raises why it is refused."""
        raise NotImplementedError

    # --- with ROS ------------------------------------------------------------------------

    @classmethod
    def standalone(cls, server: str = "estimator_node", name: str = "dampest_model_client",
                   **kwargs: Any) -> Self:
        """A client with its own node, spun by a background thread (rclpy must be initialised;
        call :meth:`close` at the end)."""
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        node = rclpy.create_node(name)
        client = cls(node, server, **kwargs)
        client._executor = SingleThreadedExecutor()
        client._executor.add_node(node)
        client._thread = threading.Thread(target=client._executor.spin, daemon=True)
        client._thread.start()
        return client

    def close(self) -> None:
        """Stop the background thread and destroy the node (standalone clients)."""
        if self._executor is not None:
            self._executor.shutdown()
            self._executor = None
            if self._thread is not None:
                self._thread.join(timeout=5.0)
            self.node.destroy_node()

    def request(self) -> Any:
        """Ask the server for ``model.*`` (asynchronous: the names under ``model``, then their
        values; the answer updates the model). Returns the first future, or None while the
        server is not discovered yet (the request is then sent when it is)."""
        from rcl_interfaces.srv import ListParameters
        if self.node is None:
            raise ModelUnavailableError("this client reads a YAML file; it has no ROS node")
        if not (self._list.service_is_ready() and self._cli.service_is_ready()):
            # not discovered yet: try again when it is (the timer stops after the request)
            if not self._pending:
                self._pending = True
                self._retry = self.node.create_timer(0.2, self._retry_request)
            return None
        future = self._list.call_async(ListParameters.Request(prefixes=["model"], depth=0))
        future.add_done_callback(self._on_list)
        return future

    def _retry_request(self) -> None:
        if self._list.service_is_ready() and self._cli.service_is_ready():
            self._retry.cancel()
            self.node.destroy_timer(self._retry)
            self._pending = False
            self.request()

    def _on_list(self, future: Any) -> None:
        from rcl_interfaces.srv import GetParameters
        try:
            names = list(future.result().result.names)
            missing = sorted(set(self.REQUIRED) - set(names))
            if not names:
                raise ModelUnavailableError(self._not_a_server())
            if missing:
                raise ModelUnavailableError(f"{self.server} has no {', '.join(missing)}")
        except Exception as exc:  # a bad answer must not kill the caller's executor
            self._refuse(exc)
            return
        get = self._cli.call_async(GetParameters.Request(names=names))
        get.add_done_callback(lambda f: self._on_response(names, f))

    def _on_response(self, names: list[str], future: Any) -> None:
        from rclpy.parameter import parameter_value_to_python
        try:
            values = future.result().values
            if not values and names and self._stale < STALE_RETRIES and \
                    self._list.service_is_ready() and self._cli.service_is_ready():
                # a server that is there answers nothing when a name listed is gone: the
                # model's names changed between the list and the get (a new structure, new
                # provenance entries); list again
                self._stale += 1
                self.request()
                return
            if not values and names:  # a server going away answers with nothing
                self._stale = 0
                self.node.get_logger().warning(
                    f"model server {self.server} answered none of the {len(names)} model "
                    f"parameters (stopping?); keeping "
                    + (f"version {self._model.version}" if self._model else "no model yet"))
                return
            if len(values) != len(names):
                raise ModelUnavailableError(f"{self.server} answered {len(values)} of "
                                            f"{len(names)} model parameters")
            m = self._accept({n: parameter_value_to_python(v)
                              for n, v in zip(names, values, strict=True)})
            self._stale = 0
            self._set(m)
        except Exception as exc:  # a bad answer must not kill the caller's executor
            self._refuse(exc)

    def _refuse(self, exc: Exception) -> None:
        """Keep the last good model; record and log why an update was refused."""
        kept = (f"keeping version {self._model.version}" if self._model is not None
                else "no model yet")
        text = f"{type(exc).__name__}: {exc}"
        self.errors.append(text)
        self.node.get_logger().error(f"model from {self.server} refused ({kept}): {text}")

    def _check_server(self) -> None:
        """Note when the server's services leave or come back to the graph."""
        if self._list.service_is_ready() and self._cli.service_is_ready():
            if self._missing_since is not None:
                self._missing_since = None
                if self._lost_logged:
                    self._lost_logged = False
                    self.node.get_logger().info(f"model server {self.server} is back")
                    self.request()
            return
        if self._missing_since is None:
            self._missing_since = time.monotonic()
        if self.lost and not self._lost_logged:
            self._lost_logged = True
            if self._model is None:
                what = "not found in the graph; waiting for it"
            else:
                what = (f"lost: not in the graph for {self.timeout:g} s (keeping version "
                        f"{self.version}, {self.age:.1f} s old); available is false until "
                        "it is back")
            self.node.get_logger().warning(f"model server {self.server} {what}")

    def _on_event(self, event: Any) -> None:
        if event.node != self._full_name:
            return
        changed = [p.name for p in (*event.new_parameters, *event.changed_parameters)]
        if "model.version" in changed:
            self.request()

    def _set(self, model: ServedT) -> None:
        with self._lock:
            self._model = model
            self._received_at = time.monotonic()
            self.refreshes += 1
        self._got.set()
        if self.on_update is not None:
            self.on_update(model)

    def wait(self, timeout: float = 10.0) -> ServedT:
        """Block until a model is available (the node must be spun elsewhere).

        Raises
        ------
        ModelUnavailableError
            None within ``timeout`` s, saying why: the last refusal (e.g. the node declares
            no ``model.*``), else whether a node of that name is on the graph at all
            (:meth:`why`).
        """
        if not self._got.wait(timeout):
            raise ModelUnavailableError(f"no model from {self.server} within {timeout:g} s: "
                                        f"{self.why()}")
        return self.model

    def why(self, probe: bool = True) -> str:
        """Why there is no model: the last refusal, else whether the server is on the graph.

        Parameters
        ----------
        probe : bool
            When the server is not on the graph, ask the nodes that are which of them serve
            a model (up to :data:`PROBE_TIME` s, the node spun elsewhere); False: answer at
            once, as a callback of the client's own node must.
        """
        if self.errors:
            return self.errors[-1]
        if self.node is None:
            return "this client reads a YAML file; it has no ROS node"
        if self._full_name not in self._graph():
            return self._not_on_graph(probe)
        return f"{self._full_name} is on the graph but has not answered list_parameters"

    def _graph(self) -> list[str]:
        """Fully qualified names of the nodes on the graph, this client's own node aside."""
        own = self.node.get_fully_qualified_name()
        names = (f"{ns.rstrip('/')}/{n}" for n, ns in self.node.get_node_names_and_namespaces())
        return sorted({n for n in names if n != own})

    def _not_a_server(self) -> str:
        """The server answered with no ``model.*`` parameter: what it is and where to look."""
        ns, _, name = self._full_name.rpartition("/")
        try:
            topics = sorted(t for t, _ in self.node.get_publisher_names_and_types_by_node(
                name, ns or "/") if not t.startswith(("/rosout", "/parameter_events")))
        except Exception:  # the node left the graph meanwhile
            topics = []
        shown = (f"; it publishes {', '.join(topics[:6])}" + (" …" if len(topics) > 6 else "")
                 if topics else "")
        return (f"{self._full_name} declares no model.* parameters: it is not a model "
                f"server{shown}. Point the client at {self.SERVERS}")

    def _not_on_graph(self, probe: bool = True) -> str:
        """No node of the server's name: the nodes that declare ``model.*``, closest name
        first (asked within :data:`PROBE_TIME` s; without ``probe``, the nodes on the graph),
        and the domain looked on."""
        domain = os.environ.get("ROS_DOMAIN_ID") or "0 (unset)"
        if not probe:
            return (f"no node {self._full_name} on the graph of ROS_DOMAIN_ID {domain} (nodes "
                    f"there: {', '.join(self._graph()) or 'none'}); start {self.SERVERS}")
        servers = self._model_servers(self._graph(), PROBE_TIME)
        target = self._full_name.rsplit("/", 1)[-1]
        servers.sort(key=lambda n: -difflib.SequenceMatcher(
            None, target, n.rsplit("/", 1)[-1]).ratio())
        seen = (f"nodes with model.* parameters: {', '.join(servers)}" if servers else
                f"no node here declares model.* parameters (start {self.SERVERS})")
        return (f"no node {self._full_name} on the graph of ROS_DOMAIN_ID {domain}; {seen}. "
                "A server on another ROS_DOMAIN_ID (or beyond "
                "ROS_AUTOMATIC_DISCOVERY_RANGE) is not seen")

    def _model_servers(self, nodes: list[str], budget: float) -> list[str]:
        """The ``nodes`` that answer list_parameters with ``model.*`` names within ``budget``
        seconds (the caller's node must be spun elsewhere)."""
        from rcl_interfaces.srv import ListParameters
        end = time.monotonic() + budget
        clients = {n: self.node.create_client(ListParameters, f"{n}/list_parameters")
                   for n in nodes}
        futures: dict[str, Any] = {}
        try:
            while time.monotonic() < end and not (
                    len(futures) == len(clients) and all(f.done() for f in futures.values())):
                for n, c in clients.items():
                    if n not in futures and c.service_is_ready():
                        futures[n] = c.call_async(ListParameters.Request(prefixes=["model"],
                                                                         depth=0))
                time.sleep(0.05)
            return [n for n, f in futures.items() if f.done() and f.result() is not None
                    and f.result().result.names]
        finally:
            for c in clients.values():
                self.node.destroy_client(c)

    # --- the model in hand ----------------------------------------------------------------

    @property
    def available(self) -> bool:
        """True when a model was received and its server is not :attr:`lost`."""
        return self._model is not None and not self.lost

    @property
    def lost(self) -> bool:
        """True when the server has been missing from the graph for ``timeout`` seconds."""
        return (self._missing_since is not None
                and time.monotonic() - self._missing_since >= self.timeout)

    @property
    def age(self) -> float:
        """Seconds (wall clock) since the model in hand arrived; NaN without a model."""
        return time.monotonic() - self._received_at

    @property
    def model(self) -> ServedT:
        """The latest model."""
        with self._lock:
            if self._model is None:
                raise ModelUnavailableError(f"no model from {self.server} yet")
            return self._model

    @property
    def version(self) -> int:
        """model.version of the latest model (-1: none)."""
        return self._model.version if self._model is not None else -1

    @property
    def identified(self) -> NDArray[np.bool_]:
        """Per coefficient of the latest model (θ order), True when the data determined it;
        False: its value is the prior (``model.identified``)."""
        return self.model.identified


class ModelClient(ServedModelClient[Model]):
    """The identified damping model of one server node, kept up to date (the parameters
    of :class:`ServedModelClient`).

    Parameters
    ----------
    vehicle : Identity, optional
        The vehicle the caller controls: a model of another hull is refused (kept out,
        recorded in :attr:`errors`, logged with both names), as a wrong feed-forward would
        be worse than none.
    """

    def __init__(self, node: Any = None, server: str = "estimator_node", follow: bool = True,
                 on_update: Callable[[Model], None] | None = None,
                 timeout: float = 5.0, vehicle: Identity | None = None) -> None:
        self.vehicle = vehicle
        super().__init__(node, server, follow, on_update, timeout)

    @classmethod
    def from_yaml(cls, path: str | Path) -> ModelClient:
        """A client holding the model of a model file (no ROS needed)."""
        client = cls(None)
        client._set(_evaluable(load_model(path)))
        return client

    def _accept(self, values: dict[str, Any]) -> Model:
        m = model_from_parameters(values)
        if self.vehicle is not None:
            m.belongs_to(self.vehicle, f"the model of {self.server}")
        return _evaluable(m)

    @property
    def held(self) -> dict[str, str]:
        """The coefficients of the latest model held at their prior, with the reason."""
        return dict(self.model.held)

    def D(self, nu: FloatArray) -> FloatArray:
        """D(ν) (6, 6) for ν (6,), FRD."""
        return self.model.D(nu)

    def damping_force(self, nu: FloatArray) -> FloatArray:
        """D(ν)ν (N, N·m)."""
        return self.model.damping_force(nu)

    def damping_force_std(self, nu: FloatArray) -> FloatArray:
        """Standard deviation of D(ν)ν from model.theta_std."""
        return self.model.damping_force_std(nu)

    def feedforward(self, nu: FloatArray) -> FloatArray:
        """D(ν)ν + C(ν)ν."""
        return self.model.feedforward(nu)


class ArmModelClient(ServedModelClient[ArmEstimate]):
    """The base parameters of the arm a controller drives, from a model server, kept up to
    date: the joint-torque feed-forward τ(q, q̇, q̈) = Y_b(q, q̇, q̈) θ, rigid body, armature,
    viscous and Coulomb friction (in the Coulomb form the model was identified with,
    ``model.coulomb_width``) and, on request, the torque offsets.

    Parameters
    ----------
    node, server, follow, on_update, timeout
        As :class:`ServedModelClient`; ``server`` defaults to ``arm_estimator_node``
        (``model_server_node`` serves a saved arm model file).
    arm : str or ArmDescription
        The arm the caller drives (preset or URDF path, or a loaded description, e.g. with
        locked joints): the regressor's kinematics. A model of another arm (identity, joints
        or base parameters) is refused with both names, kept out and recorded in
        :attr:`errors`.
    """

    REQUIRED = ARM_MODEL_PARAMETERS
    SERVERS = ("model_server_node (serves a saved arm model file) or arm_estimator_node "
               "(identifies the arm live)")

    def __init__(self, node: Any = None, server: str = "arm_estimator_node",
                 follow: bool = True, on_update: Callable[[ArmEstimate], None] | None = None,
                 timeout: float = 5.0, *, arm: str | ArmDescription) -> None:
        self.arm = load_arm(arm) if isinstance(arm, str) else arm
        self.base = base_parameters(self.arm.model)
        self._kept = [self.base.names[i] for i in self.base.independent]
        self.owner = arm_model_identity(self.arm.source, self.arm.model, self._kept)
        super().__init__(node, server, follow, on_update, timeout)

    @classmethod
    def from_yaml(cls, path: str | Path, arm: str | ArmDescription) -> ArmModelClient:
        """A client holding the arm model of a model file (no ROS needed; refused as from a
        server)."""
        client = cls(None, arm=arm)
        est, _ = read_arm_model(path)
        client._set(client._checked(est, str(path)))
        return client

    def _accept(self, values: dict[str, Any]) -> ArmEstimate:
        est, _ = arm_model_from_parameters(values)
        return self._checked(est, f"the model of {self.server}")

    def _checked(self, est: ArmEstimate, source: str) -> ArmEstimate:
        """``est`` if it holds this arm's base parameters (ConfigError naming both arms
        otherwise; a model without an identity is checked by its names, with a warning)."""
        why = mismatch(est.identity, self.owner, source)
        if why is not None:
            raise ConfigError("model.identity", why)
        if est.joint_names != self.arm.model.names or est.parameter_names != self._kept:
            raise ConfigError("model.parameter_names", (
                f"{source} holds the base parameters of joints {list(est.joint_names)} "
                f"({len(est.parameter_names)}), not those of the arm in use "
                f"{self.arm.source!r} (joints {list(self.arm.model.names)}, "
                f"{len(self._kept)}): use the arm the model was made for"))
        warning = unchecked(est.identity, self.owner, source)
        if warning is not None and self.node is not None:
            self.node.get_logger().warning(warning)
        return est

    def feedforward(self, q: FloatArray, qd: FloatArray, qdd: FloatArray,
                    offsets: bool = False) -> FloatArray:
        """Joint torques τ = Y_b(q, q̇, q̈) θ of the latest model.

        Parameters
        ----------
        q, qd, qdd : ndarray, shape (n,) or (N, n)
            Joint positions (rad), velocities (rad/s), accelerations (rad/s²), in the
            model's joint order (:attr:`ArmEstimate.joint_names`).
        offsets : bool
            Include the torque offsets (base parameters ``<joint>.off``: a bias of the
            measured effort, which a motor need not produce; default False).

        Returns
        -------
        ndarray, shape of q
            N m.
        """
        est = self.model
        theta = est.theta if offsets else np.where(
            [n.endswith(".off") for n in est.parameter_names], 0.0, est.theta)
        q2, qd2, qdd2 = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
        tau = predict(self.arm.model, self.base, theta, q2, qd2, qdd2,
                      IdentifyConfig(coulomb_width=est.coulomb_width))
        return tau.reshape(np.shape(q))

"""The station's OPC UA face: an asyncua server beside the REST API (docs/opcua.md).

A plant's SCADA and MES that speak OPC UA read the station here and order inspections,
as the MES does over REST. It is another face of the same :class:`StationRuntime`: it
reads what the REST routes read (``station_status()``, the job, the record cache) and
starts and stops jobs through the same runtime calls (``start_inspection``,
``command``), never the engine's own attributes. It runs on the API's event loop,
started by the app's lifespan after the runtime opens and stopped before it closes.

The information model is named and structured after the OPC UA companion
specifications, in our own namespace (:data:`NAMESPACE_URI`; the official nodesets are
not loaded, so the types are plain objects and folders):

* OPC 40001-1 (Machinery): ``Objects/Machines/BoreStation`` with ``Identification``,
  ``MachineryBuildingBlocks/MachineryItemState`` and ``MachineryOperationMode``, and
  ``Monitoring/OperationCounters``;
* OPC 40100 (Machine Vision): ``BoreStation/VisionSystem`` with its
  ``VisionStateMachine``, the current job, ``ResultManagement/Results/LastResult``
  (one child object per characteristic) and the methods ``StartJob``, ``Stop``, ``Abort``;
* the station's alarms (``Alarms``: the active ones and the drift monitor's
  "needs a check"), with an event on the machine object whenever they change.

Values come from the runtime by one small task: every :data:`REFRESH_S`, and at once
when the runtime's event hub tells of a job that started or ended. Only changed values
are written.

Security: anonymous sessions browse, read and subscribe; every write and every method
call is refused (BadUserAccessDenied) by the permission ruleset, for every session
(nothing here is writable). A method call needs a user-name session whose password is a
REST API token: the user manager verifies it at activation (``TokenRepository.verify``)
and each method checks the session's token again (revoked or expired: refused) and its
role against the REST route's rule (:data:`START_ROLES`, :data:`STOP_ROLES`).
asyncua does not hand a method the calling session; :class:`_CallerSession` puts it in
a context variable for the duration of the session's Call service.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import logging
import socket
import time
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from asyncua import Node, Server, ua
from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, User, UserRole
from asyncua.server.internal_server import InternalServer
from asyncua.server.internal_session import InternalSession
from asyncua.server.user_managers import UserManager
from pydantic import ValidationError

from api.auth import known_token
from api.routes.common import in_api_thread
from api.routes.inspections import JobOrder, job_response
from api.routes.parts import load_by_number
from api.runtime import Busy, StationRuntime
from station import __version__
from station.parts import PartSpecError
from station.sequencer.engine import EngineStateError, State
from station.store.models import utcnow

log = logging.getLogger("api.opcua")

#: our namespace (the companion specifications' names, not their nodesets)
NAMESPACE_URI = "urn:bore-station:opcua"
#: how often the values are refreshed from the runtime (s); a job's start and end at once
REFRESH_S = 0.5
#: longest a login's token check may hold the API loop (s): asyncua's user manager is
#: called synchronously on the loop, so the check runs in a thread and is waited for
LOGIN_TIMEOUT_S = 5.0
#: longest a store read, a token check or a runtime call of a method may take (s)
IO_TIMEOUT_S = 15.0
#: StartJob waits for the inspection's record (the runtime itself gives up after 30 s)
START_TIMEOUT_S = 40.0
#: starting and stopping the server (s)
SERVER_START_TIMEOUT_S = 30.0
SERVER_STOP_TIMEOUT_S = 10.0

#: who may call StartJob: the roles of POST /api/v1/job-orders (api.auth.job_orders), admin too
START_ROLES = frozenset({"mes", "operator", "admin"})
#: who may call Stop and Abort: the roles of POST /api/v1/station/{command} (api.auth.operator)
STOP_ROLES = frozenset({"operator", "admin"})

MANUFACTURER = "bore-station project"
MODEL = "Bore inspection station (endoscope on a Z axis, rotary table C, vision)"

#: OPC 40001-1 MachineryItemState from the engine's state (docs/opcua.md)
MACHINERY_ITEM_STATE = {
    State.IDLE: "NotExecuting", State.READY: "NotExecuting", State.PAUSED: "NotExecuting",
    State.HOMING: "Executing", State.RUNNING: "Executing", State.STOPPING: "Executing",
    State.ABORTING: "Executing",
    State.FAULTED: "OutOfService", State.ESTOPPED: "OutOfService",
}
#: OPC 40100 VisionStateMachine (top level) from the engine's state (docs/opcua.md)
VISION_STATE = {
    State.IDLE: "Preoperational", State.HOMING: "Preoperational",
    State.READY: "Operational", State.RUNNING: "Operational", State.PAUSED: "Operational",
    State.STOPPING: "Operational", State.ABORTING: "Operational",
    State.FAULTED: "Error", State.ESTOPPED: "Halted",
}
#: OPC 40001-1 MachineryOperationMode from the running job's kind
JOB_MODE = {"inspection": "Processing", "check": "Maintenance", "home": "Setup"}


class OpcUaStartError(RuntimeError):
    """The OPC UA server could not start (the message names the endpoint)."""


# ---------------------------------------------------------------------- the endpoint
@dataclass(frozen=True)
class Endpoint:
    url: str
    host: str
    port: int


def parse_endpoint(url: str) -> Endpoint:
    """``opc.tcp://HOST:PORT[/path]``; ValueError naming the endpoint and what is wrong."""
    what = f"OPC UA endpoint {url!r}"
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"{what} is not a URL opc.tcp://HOST:PORT ({exc})") from None
    if parts.scheme != "opc.tcp":
        raise ValueError(f"{what} must start with opc.tcp:// (e.g. opc.tcp://0.0.0.0:4840)")
    if not parts.hostname:
        raise ValueError(f"{what} names no host (e.g. opc.tcp://0.0.0.0:4840)")
    if port is None or port == 0:
        raise ValueError(f"{what} names no port (e.g. opc.tcp://{parts.hostname}:4840)")
    if parts.query or parts.fragment or parts.username or parts.password:
        raise ValueError(f"{what}: only opc.tcp://HOST:PORT and a path are allowed")
    return Endpoint(url, parts.hostname, port)


def check_endpoint_free(url: str) -> None:
    """Bind and release the endpoint's address (as asyncio's server will, SO_REUSEADDR)
    so that a taken port or an unknown host is reported with the endpoint's name before
    anything starts. OpcUaStartError when it cannot be bound."""
    ep = parse_endpoint(url)
    try:
        infos = socket.getaddrinfo(ep.host, ep.port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        for family, kind, proto, _, address in infos:
            with socket.socket(family, kind, proto) as s:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                s.bind(address)
    except OSError as exc:
        raise OpcUaStartError(f"cannot listen for OPC UA on {url}: {exc.strerror or exc}") from None


# ---------------------------------------------------------------------- who is calling
@dataclass
class TokenUser(User):
    """A session opened with a REST API token as its password."""

    token_role: str = ""
    token_id: int = 0
    token: str = field(default="", repr=False)


#: the user of the session whose Call service is running (set by _CallerSession.call)
_CALLER: contextvars.ContextVar[User | None] = contextvars.ContextVar("opcua_caller", default=None)


class _CallerSession(InternalSession):
    """An external session that tells the method it calls who called (asyncua passes a
    method only its object and arguments)."""

    async def call(self, params):
        reset = _CALLER.set(self.user)
        try:
            return await super().call(params)
        finally:
            _CALLER.reset(reset)


class _StationInternalServer(InternalServer):
    def create_session(self, name: str, user: User = User(role=UserRole.Anonymous), external: bool = False):
        return _CallerSession(self, self.aspace, self.subscription_service, name, user=user, external=external)


class TokenUserManager(UserManager):
    """Anonymous sessions as such; a user name with a password only when the password
    is a valid REST API token (any user name: the token says who it is). Anything else
    is refused at activation (BadUserAccessDenied)."""

    def __init__(self, verify, timeout_s: float = LOGIN_TIMEOUT_S):
        self._verify = verify
        self._timeout_s = timeout_s
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="opcua-login")

    def get_user(self, iserver, username=None, password=None, certificate=None):
        if username is None and password is None:  # anonymous (the channel's certificate is no identity here)
            return User(role=UserRole.Anonymous)
        if not password:
            return None
        try:
            record = self._pool.submit(self._verify, password).result(timeout=self._timeout_s)
        except FutureTimeout:
            log.warning("OPC UA login refused: the token check took longer than %g s", self._timeout_s)
            return None
        except Exception:  # noqa: BLE001 - a store in trouble refuses the login, the server goes on
            log.exception("OPC UA login refused: the token check failed")
            return None
        if record is None:
            log.warning("OPC UA login refused: the password is not a valid API token (user name %r)", username)
            return None
        return TokenUser(role=UserRole.User, name=record.name, token_role=record.role, token_id=record.id,
                         token=password)

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


#: what an anonymous session may ask: browse, read, subscribe (no Write, no Call, no node management)
_READ_TYPES = frozenset(ua.NodeId(t) for t in USER_TYPES) - {
    ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary),
    ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)}
_CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)


class StationRuleset(PermissionRuleset):
    """Anonymous: read only. A token session: read, and call methods (each method checks
    the role). Writes and node management: nobody (nothing here is writable)."""

    def check_validity(self, user, action_type_id, body) -> bool:
        if action_type_id in _READ_TYPES:
            return True
        return action_type_id == _CALL and isinstance(user, TokenUser)


# ---------------------------------------------------------------------- the station's values
def station_id(rt: StationRuntime) -> str:
    """The station's id: the station's (its config's ``station_id`` or name, or ``serve
    --station-id``), else the settings', else the config file's name ("default": the
    embedded simulated station)."""
    for holder in (getattr(rt.session, "station", None), rt, rt.settings):
        value = getattr(holder, "station_id", None)
        if value:
            return str(value)
    config = rt.settings.config
    return Path(config).stem if config else "default"


def operation_mode(state: State, job_kind: str | None) -> str:
    """MachineryOperationMode: the running job's (inspection: Processing, master check:
    Maintenance, homing: Setup); without one, Processing when the station is ready for
    job orders, Setup while it homes, else None."""
    if job_kind is not None:
        return JOB_MODE.get(job_kind, "None")
    if state == State.HOMING:
        return "Setup"
    return "Processing" if state == State.READY else "None"


def active_alarms(status: dict) -> list[str]:
    """The alarms standing now: a fault or an e-stop, and the drift monitor's request
    for a check on the master."""
    out = []
    if status["state"] in (State.FAULTED.value, State.ESTOPPED.value):
        out.append(f"{status['state']}: {status['reason'] or 'no reason given'}")
    if status["needs_check"]:
        out.append(f"needs a check: {status['needs_check_reason'] or 'the station asked for a check on its master'}")
    return out


def _utc(text: str | None) -> datetime | None:
    return None if not text else datetime.fromisoformat(text)


_V = ua.VariantType
#: the variables of the last result and of each characteristic: name, type, job response key
_RESULT_FIELDS = (("ResultId", _V.String, "id"), ("PartNumber", _V.String, "part_number"),
                  ("Serial", _V.String, "serial"), ("OrderId", _V.String, "order_id"),
                  ("Result", _V.String, "result"), ("State", _V.String, "state"),
                  ("Reason", _V.String, "reason"), ("StartTime", _V.DateTime, "started_at"),
                  ("CreationTime", _V.DateTime, "finished_at"), ("MachineSeconds", _V.Double, "machine_s"))
_CHAR_FIELDS = (("Id", _V.String, "id"), ("Unit", _V.String, "unit"), ("Nominal", _V.Double, "nominal"),
                ("Lower", _V.Double, "lower_limit"), ("Upper", _V.Double, "upper_limit"),
                ("Measured", _V.Double, "measured"), ("Uncertainty", _V.Double, "uncertainty_k2"),
                ("Passed", _V.Boolean, "pass"))
_DEFAULTS = {_V.String: "", _V.Double: 0.0, _V.Boolean: False, _V.UInt32: 0, _V.Int32: 0,
             _V.DateTime: datetime(1601, 1, 1, tzinfo=timezone.utc), _V.LocalizedText: ua.LocalizedText("")}


# ---------------------------------------------------------------------- the server
class OpcUaServer:
    """The OPC UA server of one :class:`StationRuntime`: ``await start()``, ``await stop()``."""

    def __init__(self, rt: StationRuntime, endpoint: str, *, cert: str | Path | None = None,
                 key: str | Path | None = None, refresh_s: float = REFRESH_S):
        self.rt = rt
        self.endpoint = parse_endpoint(endpoint)
        if (cert is None) != (key is None):
            raise ValueError("OPC UA: a certificate needs its private key and a key its certificate")
        self.cert, self.key = cert, key
        self.refresh_s = refresh_s
        self.station_id = station_id(rt)
        self.users = TokenUserManager(rt.tokens.verify)
        self.server: Server | None = None
        self.idx = 0
        #: path -> (node id, variant type, value last written)
        self._vars: dict[str, list[Any]] = {}
        self._task: asyncio.Task | None = None
        self._started = time.monotonic()
        self._last_tick: float | None = None
        self._executing_s = 0.0
        #: inspections that ended complete since the server started (OperationCycleCounter)
        self.cycles = 0
        self._pending_result: str | None = None
        self._job_iid: str | None = None
        self._job_state: str | None = None
        self._char_ids: list[str] = []
        self._char_nodes: list[Node] = []
        self._alarms: list[str] | None = None
        self._events = None
        self._last_error: str | None = None
        #: refreshes begun and ended (a method waits for one that began after its change)
        self._refreshes_begun = 0
        self._refreshes_done = 0
        self._refreshed = asyncio.Event()

    # ------------------------------------------------------------------ life cycle
    async def start(self) -> None:
        url = self.endpoint.url
        check_endpoint_free(url)
        self.server = server = Server(iserver=_StationInternalServer(user_manager=self.users))
        await asyncio.wait_for(server.init(), timeout=SERVER_START_TIMEOUT_S)
        server.set_endpoint(url)
        server.set_server_name(f"Bore inspection station {self.station_id}")
        await server.set_application_uri(f"urn:bore-station:{self.station_id}")
        server.product_uri = NAMESPACE_URI
        await server.set_build_info(NAMESPACE_URI, MANUFACTURER, "bore-station", __version__, __version__,
                                    datetime.now(timezone.utc))
        server.allow_remote_admin(False)
        server.set_identity_tokens([ua.AnonymousIdentityToken, ua.UserNameIdentityToken])
        policies = [ua.SecurityPolicyType.NoSecurity]
        if self.cert is not None:
            await server.load_certificate(str(self.cert))
            await server.load_private_key(str(self.key))
            policies += [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
                         ua.SecurityPolicyType.Basic256Sha256_Sign]
        server.set_security_policy(policies, permission_ruleset=StationRuleset())
        self.idx = await server.register_namespace(NAMESPACE_URI)
        await self._build()
        self._pending_result = await self._last_finished()
        await self._refresh()
        try:
            await asyncio.wait_for(server.start(), timeout=SERVER_START_TIMEOUT_S)
        except (OSError, asyncio.TimeoutError) as exc:
            self.users.close()
            text = "timed out" if isinstance(exc, asyncio.TimeoutError) else (exc.strerror or str(exc))
            raise OpcUaStartError(f"cannot listen for OPC UA on {url}: {text}") from None
        self._task = asyncio.create_task(self._run(), name="opcua-refresh")
        log.info("OPC UA server at %s (station %s, security %s)", url, self.station_id,
                 "None and Basic256Sha256" if self.cert else "None")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(BaseException):
                await self._task
        if self.server is not None:
            try:
                await asyncio.wait_for(self.server.stop(), timeout=SERVER_STOP_TIMEOUT_S)
            except Exception:  # noqa: BLE001 - the station closes after us whatever happened here
                log.exception("stopping the OPC UA server failed")
        self.users.close()

    # ------------------------------------------------------------------ the address space
    def _nid(self, path: str) -> ua.NodeId:
        return ua.NodeId(path, self.idx)

    def _qn(self, name: str) -> ua.QualifiedName:
        return ua.QualifiedName(name, self.idx)

    async def _object(self, parent: Node, path: str, name: str) -> Node:
        return await parent.add_object(self._nid(f"{path}/{name}" if path else name), self._qn(name))

    async def _folder(self, parent: Node, path: str, name: str) -> Node:
        return await parent.add_folder(self._nid(f"{path}/{name}" if path else name), self._qn(name))

    async def _var(self, parent: Node, path: str, name: str, vtype: ua.VariantType, value: Any = None, *,
                   array: bool = False, datatype: int | None = None) -> Node:
        full = f"{path}/{name}"
        initial = value if value is not None else ([] if array else _DEFAULTS[vtype])
        node = await parent.add_variable(self._nid(full), self._qn(name), ua.Variant(initial, vtype),
                                         datatype=datatype)
        self._vars[full] = [node.nodeid, vtype, object()]  # written by the first refresh
        if value is not None:
            await self._write(full, value)
        return node

    async def _write(self, path: str, value: Any) -> None:
        """Write ``value`` (None: no value, status BadNoData) when it changed."""
        entry = self._vars[path]
        nodeid, vtype, last = entry
        if value == last and type(value) is type(last):
            return
        now = datetime.now(timezone.utc)
        if value is None:
            dv = ua.DataValue(ua.Variant(), StatusCode=ua.StatusCode(ua.StatusCodes.BadNoData),
                              SourceTimestamp=now, ServerTimestamp=now)
        else:
            dv = ua.DataValue(ua.Variant(value, vtype), SourceTimestamp=now, ServerTimestamp=now)
        await self.server.write_attribute_value(nodeid, dv)
        entry[2] = value

    async def _build(self) -> None:
        server, sid = self.server, self.station_id
        objects = server.nodes.objects
        machines = await self._folder(objects, "", "Machines")
        m = "Machines/BoreStation"
        machine = await machines.add_object(self._nid(m), self._qn("BoreStation"))
        await machine.write_attribute(ua.AttributeIds.DisplayName, ua.DataValue(ua.Variant(
            ua.LocalizedText(f"Bore station {sid}"))))
        self.machine = machine

        # OPC 40001-1 (via OPC 10000-100 DI): Identification
        ident = await self._object(machine, m, "Identification")
        p = f"{m}/Identification"
        await self._var(ident, p, "Manufacturer", _V.LocalizedText, ua.LocalizedText(MANUFACTURER))
        await self._var(ident, p, "Model", _V.LocalizedText, ua.LocalizedText(MODEL))
        await self._var(ident, p, "ProductInstanceUri", _V.String, f"urn:bore-station:{sid}")
        await self._var(ident, p, "SerialNumber", _V.String, sid)
        await self._var(ident, p, "AssetId", _V.String, sid)
        await self._var(ident, p, "SoftwareRevision", _V.String, __version__)
        await self._var(ident, p, "DeviceClass", _V.String, "bore inspection station")

        # OPC 40001-1: the building blocks (state machine and operation mode)
        blocks = await self._folder(machine, m, "MachineryBuildingBlocks")
        b = f"{m}/MachineryBuildingBlocks"
        await blocks.add_reference(ident.nodeid, ua.ObjectIds.Organizes)
        state = await self._object(blocks, b, "MachineryItemState")
        await self._var(state, f"{b}/MachineryItemState", "CurrentState", _V.LocalizedText)
        mode = await self._object(blocks, b, "MachineryOperationMode")
        await self._var(mode, f"{b}/MachineryOperationMode", "CurrentState", _V.LocalizedText)

        # OPC 40001-1: operation counters (under Monitoring)
        monitoring = await self._folder(machine, m, "Monitoring")
        counters = await self._object(monitoring, f"{m}/Monitoring", "OperationCounters")
        await blocks.add_reference(counters.nodeid, ua.ObjectIds.Organizes)
        c = f"{m}/Monitoring/OperationCounters"
        await self._var(counters, c, "PowerOnDuration", _V.Double, datatype=ua.ObjectIds.Duration)
        await self._var(counters, c, "OperationDuration", _V.Double, datatype=ua.ObjectIds.Duration)
        await self._var(counters, c, "OperationCycleCounter", _V.UInt32)

        # the station as REST shows it (GET /api/v1/station)
        st = await self._object(machine, m, "StationStatus")
        s = f"{m}/StationStatus"
        for name, vtype in (("State", _V.String), ("Reason", _V.String), ("Mode", _V.String),
                            ("Busy", _V.Boolean)):
            await self._var(st, s, name, vtype)

        alarms = await self._object(machine, m, "Alarms")
        a = f"{m}/Alarms"
        await self._var(alarms, a, "ActiveAlarms", _V.String, array=True)
        await self._var(alarms, a, "NeedsCheck", _V.Boolean)
        await self._var(alarms, a, "NeedsCheckReason", _V.String)
        await machine.set_event_notifier([ua.EventNotifier.SubscribeToEvents])
        self._events = await server.get_event_generator(ua.ObjectIds.BaseEventType, machine.nodeid)

        # OPC 40100: the vision system
        vision = await self._object(machine, m, "VisionSystem")
        v = f"{m}/VisionSystem"
        vsm = await self._object(vision, v, "VisionStateMachine")
        await self._var(vsm, f"{v}/VisionStateMachine", "CurrentState", _V.LocalizedText)
        job = await self._object(vision, v, "CurrentJob")
        j = f"{v}/CurrentJob"
        for name, vtype in (("Kind", _V.String), ("InspectionId", _V.String), ("PartNumber", _V.String),
                            ("Serial", _V.String), ("OrderId", _V.String), ("State", _V.String),
                            ("Running", _V.Boolean), ("ProgressDone", _V.Int32), ("ProgressTotal", _V.Int32)):
            await self._var(job, j, name, vtype)
        rm = await self._object(vision, v, "ResultManagement")
        results = await self._folder(rm, f"{v}/ResultManagement", "Results")
        last = await self._object(results, f"{v}/ResultManagement/Results", "LastResult")
        self._last_path = lr = f"{v}/ResultManagement/Results/LastResult"
        for name, vtype, _ in _RESULT_FIELDS:
            await self._var(last, lr, name, vtype)
        self._chars_folder = await self._folder(last, lr, "Characteristics")

        def arg(name: str, text: str) -> ua.Argument:
            return ua.Argument(Name=name, DataType=ua.NodeId(ua.ObjectIds.String), ValueRank=ua.ValueRank.Scalar,
                               Description=ua.LocalizedText(text))

        await vision.add_method(self._nid(f"{v}/StartJob"), self._qn("StartJob"), self._start_job,
                                [arg("PartNumber", "a part spec's part number"),
                                 arg("Serial", "the part's serial number"),
                                 arg("OrderId", "the production order (empty: none)")],
                                [arg("InspectionId", "the inspection started (GET /api/v1/inspections/{id})")])
        await vision.add_method(self._nid(f"{v}/Stop"), self._qn("Stop"), self._stop, [], [])
        await vision.add_method(self._nid(f"{v}/Abort"), self._qn("Abort"), self._abort, [], [])

    # ------------------------------------------------------------------ refreshing
    async def _run(self) -> None:
        hub = self.rt.hub
        queue = hub.subscribe()
        try:
            while True:
                try:
                    ev = await asyncio.wait_for(queue.get(), timeout=self.refresh_s)
                except asyncio.TimeoutError:
                    ev = None
                else:
                    while ev is not None:
                        self._on_event(ev)
                        ev = queue.get_nowait() if not queue.empty() else None
                    if hub.closed:  # the runtime is closing: we are being stopped
                        return
                try:
                    await self._refresh()
                    self._last_error = None
                except asyncio.CancelledError:
                    raise
                except Exception as exc:  # noqa: BLE001 - keep serving; say so once per kind of trouble
                    text = f"{type(exc).__name__}: {exc}"
                    if text != self._last_error:
                        log.exception("refreshing the OPC UA values failed")
                        self._last_error = text
        finally:
            hub.unsubscribe(queue)

    def _on_event(self, ev) -> None:
        d = ev.data
        if ev.kind == "job" and d.get("event") == "finished" and d.get("job") == "inspection":
            if d.get("state") == "complete":
                self.cycles += 1
            if d.get("inspection_id"):
                self._pending_result = d["inspection_id"]

    async def _last_finished(self) -> str | None:
        """This station's last finished inspection in the store (several stations may
        share it): LastResult shows it from the start, as after a restart the MES
        expects, not only once the next inspection ends. None when there is none, or the
        store does not answer in time (LastResult then fills with the next result)."""
        store = self.rt.store
        try:
            recent = await asyncio.wait_for(
                in_api_thread(lambda: store.list_inspections(station=store.station_id, limit=20)),
                timeout=IO_TIMEOUT_S)
        except Exception:  # noqa: BLE001 - a store in trouble leaves LastResult empty, the server starts
            log.exception("OPC UA: the last result could not be read from the store")
            return None
        return next((r.id for r in recent if r.state != "running"), None)

    async def _record(self, iid: str):
        return await asyncio.wait_for(self.rt.records.get(iid), timeout=IO_TIMEOUT_S)

    async def _refresh(self) -> None:
        self._refreshes_begun += 1
        begun = self._refreshes_begun
        try:
            await self._refresh_values()
        finally:
            self._refreshes_done = max(self._refreshes_done, begun)
            done, self._refreshed = self._refreshed, asyncio.Event()
            done.set()

    async def _next_refresh(self, timeout_s: float = 2.0) -> None:
        """Wait (at most ``timeout_s``) for a refresh begun after now: a method's caller
        then reads the job it started or stopped."""
        target = self._refreshes_begun + 1
        deadline = time.monotonic() + timeout_s
        while self._refreshes_done < target and self._task is not None and not self._task.done():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._refreshed.wait(), timeout=remaining)

    async def _refresh_values(self) -> None:
        rt = self.rt
        now = time.monotonic()
        m, v = "Machines/BoreStation", "Machines/BoreStation/VisionSystem"
        alive = rt.thread.alive and rt.session is not None
        if alive:
            status = rt.station_status()
            state = State(status["state"])
            job = status["job"]
            running_kind = job["kind"] if job and job["running"] else None
            item_state = MACHINERY_ITEM_STATE[state]
            vision_state = VISION_STATE[state]
            mode = operation_mode(state, running_kind)
        else:
            status, job, item_state, vision_state, mode = None, None, "NotAvailable", "Halted", "None"
        if self._last_tick is not None and item_state == "Executing":
            self._executing_s += now - self._last_tick
        self._last_tick = now

        w = self._write
        b = f"{m}/MachineryBuildingBlocks"
        await w(f"{b}/MachineryItemState/CurrentState", ua.LocalizedText(item_state))
        await w(f"{b}/MachineryOperationMode/CurrentState", ua.LocalizedText(mode))
        await w(f"{v}/VisionStateMachine/CurrentState", ua.LocalizedText(vision_state))
        c = f"{m}/Monitoring/OperationCounters"
        await w(f"{c}/PowerOnDuration", round((now - self._started) * 1000.0, -2))  # Duration: ms
        await w(f"{c}/OperationDuration", round(self._executing_s * 1000.0, -2))
        await w(f"{c}/OperationCycleCounter", self.cycles)
        if status is None:
            return
        s = f"{m}/StationStatus"
        await w(f"{s}/State", status["state"])
        await w(f"{s}/Reason", status["reason"] or "")
        await w(f"{s}/Mode", status["mode"])
        await w(f"{s}/Busy", bool(status["busy"]))
        alarms = active_alarms(status)
        a = f"{m}/Alarms"
        await w(f"{a}/ActiveAlarms", alarms)
        await w(f"{a}/NeedsCheck", bool(status["needs_check"]))
        await w(f"{a}/NeedsCheckReason", status["needs_check_reason"] or "")
        if self._alarms is not None and alarms != self._alarms:
            await self._alarm_event(alarms)
        self._alarms = alarms
        await self._refresh_job(status)
        if self._pending_result is not None:
            iid = self._pending_result
            await self._show_result(job_response(await self._record(iid)))
            if self._pending_result == iid:
                self._pending_result = None

    async def _refresh_job(self, status: dict) -> None:
        j = "Machines/BoreStation/VisionSystem/CurrentJob"
        job = status["job"]
        w = self._write
        await w(f"{j}/ProgressDone", int(status["progress"]["done"] or 0))
        await w(f"{j}/ProgressTotal", int(status["progress"]["total"] or 0))
        if job is None:
            return
        await w(f"{j}/Kind", job["kind"])
        await w(f"{j}/Running", bool(job["running"]))
        iid = job["inspection_id"]
        if iid is None:
            if job["kind"] == "home":
                for name in ("InspectionId", "PartNumber", "Serial", "OrderId"):
                    await w(f"{j}/{name}", "")
                await w(f"{j}/State", "running" if job["running"] else "ended")
            return
        # the record: once when the job appears, once more when it has ended
        if iid != self._job_iid or (not job["running"] and self._job_state == "running"):
            rec = await self._record(iid)
            self._job_iid, self._job_state = iid, rec.state
            await w(f"{j}/InspectionId", rec.id)
            await w(f"{j}/PartNumber", rec.part_number)
            await w(f"{j}/Serial", rec.serial)
            await w(f"{j}/OrderId", rec.order_id or "")
            await w(f"{j}/State", rec.state)

    async def _show_result(self, r: dict) -> None:
        lr = self._last_path
        for name, _, key in _RESULT_FIELDS:
            value = r.get(key)
            if key in ("started_at", "finished_at"):
                value = _utc(value)
            elif value is None and key in ("order_id", "result", "reason"):
                value = ""
            await self._write(f"{lr}/{name}", value)
        chars = r.get("characteristics") or []
        ids = [ch["id"] for ch in chars]
        if ids != self._char_ids:  # another part's characteristics: new child objects
            for node in self._char_nodes:
                await node.delete(recursive=True)
            for cid in self._char_ids:
                for name, _, _ in _CHAR_FIELDS:
                    self._vars.pop(f"{lr}/Characteristics/{cid}/{name}", None)
            self._char_nodes = []
            for cid in ids:
                obj = await self._object(self._chars_folder, f"{lr}/Characteristics", cid)
                for name, vtype, _ in _CHAR_FIELDS:
                    await self._var(obj, f"{lr}/Characteristics/{cid}", name, vtype)
                self._char_nodes.append(obj)
            self._char_ids = ids
        for ch in chars:
            for name, _, key in _CHAR_FIELDS:
                await self._write(f"{lr}/Characteristics/{ch['id']}/{name}", ch.get(key))

    async def _alarm_event(self, alarms: list[str]) -> None:
        ev = self._events
        ev.event.Severity = 700 if alarms else 100
        text = "; ".join(alarms) if alarms else "no active alarms"
        await ev.trigger(message=text)

    # ------------------------------------------------------------------ methods
    async def _caller(self, roles: frozenset[str], what: str) -> str | ua.StatusCode:
        """Who calls (for the audit log), or the status that refuses the call: no token
        session, a role not allowed, a token revoked or expired since the login."""
        user = _CALLER.get()
        if not isinstance(user, TokenUser):
            log.warning("OPC UA %s refused: not a token session", what)
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        if user.token_role not in roles:
            log.warning("OPC UA %s refused: role %r may not (it needs one of %s)", what, user.token_role,
                        ", ".join(sorted(roles)))
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        try:
            # the REST API's check: the slow hash once per token, then its revocation and
            # expiry (read at most every second)
            record = await asyncio.wait_for(known_token(self.rt, user.token), timeout=IO_TIMEOUT_S)
        except asyncio.TimeoutError:
            return ua.StatusCode(ua.StatusCodes.BadTimeout)
        if record is None or record.expired(utcnow()) or record.role not in roles:
            log.warning("OPC UA %s refused: the session's token is no longer valid", what)
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        # a method call is a write: it takes from the same bucket as the token's REST
        # writes (api/ratelimit.py), so OPC UA is no way around the limit
        wait_s = self.rt.write_limiter.take(record.id)
        if wait_s > 0:
            log.warning("OPC UA %s refused: too many writes with token %s (%s); retry after %.1f s", what,
                        record.id, self.rt.write_limiter.describe(), wait_s)
            return ua.StatusCode(ua.StatusCodes.BadTooManyOperations)
        return f"{record.name} (token {record.id}, {record.role}) over OPC UA"

    async def _start_job(self, parent, *args):
        who = await self._caller(START_ROLES, "StartJob")
        if isinstance(who, ua.StatusCode):
            return who
        if len(args) != 3:
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing if len(args) < 3
                                 else ua.StatusCodes.BadTooManyArguments)
        part_number, serial, order_id = (a.Value for a in args)
        rt = self.rt
        try:
            order = JobOrder(part_number=part_number, serial=serial, order_id=order_id or None)
            spec = await asyncio.wait_for(in_api_thread(load_by_number, order.part_number, rt.settings.parts_dir),
                                          timeout=IO_TIMEOUT_S)
        except (ValidationError, PartSpecError) as exc:
            log.warning("OPC UA StartJob refused: %s", str(exc).splitlines()[0])
            return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
        except asyncio.TimeoutError:
            return ua.StatusCode(ua.StatusCodes.BadTimeout)
        try:
            iid, _ = await asyncio.wait_for(rt.start_inspection(spec, order.serial, order.order_id, None),
                                            timeout=START_TIMEOUT_S)
        except Busy as exc:
            log.warning("OPC UA StartJob refused: %s", exc)
            return ua.StatusCode(ua.StatusCodes.BadInvalidState)
        except asyncio.TimeoutError:
            return ua.StatusCode(ua.StatusCodes.BadTimeout)
        except Exception:  # noqa: BLE001 - the caller gets a status, the log the cause
            log.exception("OPC UA StartJob failed")
            return ua.StatusCode(ua.StatusCodes.BadInternalError)
        what = f"ordered inspection {iid} of part {spec.part_number}, serial {order.serial!r}" + (
            f", order {order.order_id!r}" if order.order_id else "")
        try:
            await asyncio.wait_for(in_api_thread(rt.audit, who, what), timeout=IO_TIMEOUT_S)
        except Exception:  # noqa: BLE001 - the job runs either way (as over REST)
            log.exception("the audit entry of an OPC UA job order was not written")
        await self._next_refresh()
        return [ua.Variant(iid, _V.String)]

    async def _command(self, name: str) -> ua.StatusCode | list:
        who = await self._caller(STOP_ROLES, name)
        if isinstance(who, ua.StatusCode):
            return who
        try:
            await asyncio.wait_for(self.rt.command(name, who), timeout=IO_TIMEOUT_S)
        except (EngineStateError, Busy) as exc:
            log.warning("OPC UA %s refused: %s", name, exc)
            return ua.StatusCode(ua.StatusCodes.BadInvalidState)
        except asyncio.TimeoutError:
            return ua.StatusCode(ua.StatusCodes.BadTimeout)
        except Exception:  # noqa: BLE001
            log.exception("OPC UA %s failed", name)
            return ua.StatusCode(ua.StatusCodes.BadInternalError)
        await self._next_refresh()
        return []

    async def _stop(self, parent):
        return await self._command("stop")

    async def _abort(self, parent):
        return await self._command("abort")

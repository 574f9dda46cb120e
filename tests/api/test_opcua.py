"""The OPC UA server beside REST (api/opcua.py, docs/opcua.md), driven with the asyncua
client over 127.0.0.1 against a served simulated station: anonymous reads, refused
writes and calls, token sessions of the REST roles, a job started over OPC UA whose
last result matches the REST job response, Stop, and a revoked token."""

from __future__ import annotations

import asyncio
import socket
import subprocess
import time
from collections import Counter

import httpx
import pytest
from asyncua import Client, ua
from asyncua.ua.uaerrors import BadUserAccessDenied, UaStatusCodeError
from fastapi import HTTPException

from api import auth
from api.opcua import (MACHINERY_ITEM_STATE, NAMESPACE_URI, START_ROLES, STOP_ROLES, VISION_STATE, OpcUaStartError,
                       active_alarms, check_endpoint_free, operation_mode, parse_endpoint)
from station import __version__
from station.bench.served import station_command
from station.sequencer.engine import State
from station.store import Store
from station.store.tokens import TokenRepository
from tests.api.conftest import INSPECTION_TIMEOUT_S, PART, ROLES, start_server, stop_server, wait_done, wait_idle

#: every asyncua request and connect gives up after this (s)
CLIENT_TIMEOUT_S = 15.0
M = ("Machines", "BoreStation")
V = M + ("VisionSystem",)
LAST = V + ("ResultManagement", "Results", "LastResult")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """A served simulated station with its OPC UA server on a free loopback port; the
    port is free again once it has stopped."""
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    srv, server, thread = start_server(tmp_path_factory.mktemp("opcua-data"), opcua_endpoint=url)
    try:
        assert srv.app.state.opcua is not None
        yield srv, url
    finally:
        stop_server(server, thread)
        check_endpoint_free(url)  # the OPC UA server let go of its port


def client(url: str, token: str | None = None) -> Client:
    c = Client(url, timeout=CLIENT_TIMEOUT_S)
    if token is not None:
        c.set_user("test")
        c.set_password(token)
    return c


async def node(c: Client, *path: str):
    idx = await c.get_namespace_index(NAMESPACE_URI)
    return await c.nodes.objects.get_child([f"{idx}:{p}" for p in path])


async def value(c: Client, *path: str):
    return await (await node(c, *path)).read_value()


async def call(c: Client, method: str, *args: str):
    idx = await c.get_namespace_index(NAMESPACE_URI)
    return await (await node(c, *V)).call_method(f"{idx}:{method}", *args)


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, timeout=INSPECTION_TIMEOUT_S + 60))


# ---------------------------------------------------------------------- the mappings
def test_every_engine_state_maps_to_both_state_machines():
    assert set(MACHINERY_ITEM_STATE) == set(State) == set(VISION_STATE)
    assert set(MACHINERY_ITEM_STATE.values()) == {"NotExecuting", "Executing", "OutOfService"}
    assert set(VISION_STATE.values()) == {"Preoperational", "Operational", "Error", "Halted"}
    assert MACHINERY_ITEM_STATE[State.RUNNING] == "Executing" and VISION_STATE[State.FAULTED] == "Error"
    assert operation_mode(State.RUNNING, "inspection") == "Processing"
    assert operation_mode(State.RUNNING, "check") == "Maintenance"
    assert operation_mode(State.HOMING, None) == "Setup"
    assert operation_mode(State.READY, None) == "Processing"
    assert operation_mode(State.FAULTED, None) == "None"


def test_active_alarms_name_the_fault_and_the_check_the_station_needs():
    status = {"state": "faulted", "reason": "Z drive fault 0x21", "needs_check": True,
              "needs_check_reason": "grating residual drifting"}
    assert active_alarms(status) == ["faulted: Z drive fault 0x21", "needs a check: grating residual drifting"]
    assert active_alarms({"state": "ready", "reason": None, "needs_check": False, "needs_check_reason": None}) == []


def test_the_methods_roles_are_the_rest_routes_roles():
    """StartJob admits whom POST /job-orders admits, Stop/Abort whom POST /station/stop admits."""

    def admitted(dependency) -> set[str]:
        out = set()
        for role in ROLES:
            try:
                asyncio.run(dependency(principal=auth.Principal("t", role, 1)))
                out.add(role)
            except HTTPException as exc:
                assert exc.status_code == 403
        return out

    assert admitted(auth.job_orders) == START_ROLES
    assert admitted(auth.operator) == STOP_ROLES


@pytest.mark.parametrize("url, words", [("http://127.0.0.1:4840", "opc.tcp://"), ("opc.tcp://127.0.0.1", "no port"),
                                        ("opc.tcp://:4840", "no host"), ("opc.tcp://h:70000", "not a URL")])
def test_a_malformed_endpoint_is_refused_naming_it(url, words):
    with pytest.raises(ValueError) as err:
        parse_endpoint(url)
    assert url in str(err.value) and words in str(err.value)


def test_serve_fails_naming_the_endpoint_when_its_port_is_taken(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        url = f"opc.tcp://127.0.0.1:{taken.getsockname()[1]}"
        with pytest.raises(OpcUaStartError, match=url):
            check_endpoint_free(url)
        r = subprocess.run(station_command() + ["serve", "--data", str(tmp_path), "--port", str(free_port()),
                                                "--opcua", url], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"cannot listen for OPC UA on {url}" in r.stderr and "in use" in r.stderr


# ---------------------------------------------------------------------- over the wire
def test_anonymous_reads_the_machine_state_and_identification(served):
    srv, url = served
    with srv.client("admin") as c:
        wait_idle(c)
        rest = c.get("/api/v1/station").json()
    rt = srv.runtime
    station_id = rt.station.station_id

    async def main():
        async with client(url) as c:
            ident = M + ("Identification",)
            assert await value(c, *ident, "SoftwareRevision") == __version__
            assert await value(c, *ident, "AssetId") == station_id
            assert await value(c, *ident, "SerialNumber") == station_id
            assert await value(c, *ident, "ProductInstanceUri") == f"urn:bore-station:{station_id}"
            assert (await value(c, *ident, "Manufacturer")).Text
            item = await value(c, *M, "MachineryBuildingBlocks", "MachineryItemState", "CurrentState")
            assert item.Text == MACHINERY_ITEM_STATE[State(rest["state"])]
            vision = await value(c, *V, "VisionStateMachine", "CurrentState")
            assert vision.Text == VISION_STATE[State(rest["state"])]
            assert await value(c, *M, "StationStatus", "State") == rest["state"]
            assert await value(c, *M, "StationStatus", "Mode") == "simulated"
            assert await value(c, *M, "Alarms", "NeedsCheck") is rest["needs_check"]
            assert isinstance(await value(c, *M, "Alarms", "ActiveAlarms"), list)
            power_on = await value(c, *M, "Monitoring", "OperationCounters", "PowerOnDuration")
            assert power_on > 0
            await asyncio.sleep(1.2)
            assert await value(c, *M, "Monitoring", "OperationCounters", "PowerOnDuration") > power_on

    run(main())


def test_anonymous_may_neither_call_nor_write(served):
    srv, url = served

    async def main():
        async with client(url) as c:
            with pytest.raises(BadUserAccessDenied):
                await call(c, "StartJob", PART, "SN-OPCUA-ANON", "")
            with pytest.raises(BadUserAccessDenied):
                await call(c, "Stop")
            serial = await node(c, *M, "Identification", "SerialNumber")
            with pytest.raises(BadUserAccessDenied):
                await serial.write_value("forged")
            assert await serial.read_value() != "forged"

    run(main())
    with srv.client("admin") as c:
        assert c.get("/api/v1/inspections", params={"serial": "SN-OPCUA-ANON"}).json()["total"] == 0


def test_a_password_that_is_no_valid_token_opens_no_session(served):
    srv, url = served

    async def main():
        bad = srv.tokens["operator"][:-4] + "AAAA"
        with pytest.raises(UaStatusCodeError) as err:
            async with client(url, bad):
                pass
        assert err.value.code == ua.StatusCodes.BadUserAccessDenied

    run(main())


def test_roles_the_rest_routes_refuse_are_refused(served):
    srv, url = served

    async def main():
        async with client(url, srv.tokens["engineer"]) as c:
            with pytest.raises(BadUserAccessDenied):
                await call(c, "StartJob", PART, "SN-OPCUA-ENG", "")
            # a token session reads like anyone
            assert await value(c, *M, "StationStatus", "Mode") == "simulated"
        async with client(url, srv.tokens["mes"]) as c:  # the MES orders parts, it does not command the station
            with pytest.raises(BadUserAccessDenied):
                await call(c, "Stop")
            with pytest.raises(BadUserAccessDenied):
                await call(c, "Abort")

    run(main())
    with srv.client("admin") as c:
        assert c.get("/api/v1/inspections", params={"serial": "SN-OPCUA-ENG"}).json()["total"] == 0


def test_an_operator_starts_a_job_and_the_last_result_matches_rest(served):
    srv, url = served
    with srv.client("admin") as rest:
        wait_idle(rest)

    async def main():
        async with client(url, srv.tokens["operator"]) as c:
            cycles = await value(c, *M, "Monitoring", "OperationCounters", "OperationCycleCounter")
            iid = await call(c, "StartJob", PART, "SN-OPCUA-1", "PO-OPCUA")
            assert isinstance(iid, str) and iid
            # the method returns once the job shows
            assert await value(c, *V, "CurrentJob", "InspectionId") == iid
            assert await value(c, *V, "CurrentJob", "PartNumber") == PART
            assert await value(c, *V, "CurrentJob", "Serial") == "SN-OPCUA-1"
            assert await value(c, *V, "CurrentJob", "Kind") == "inspection"
            # a second order while it runs: the station is busy
            with pytest.raises(UaStatusCodeError) as err:
                await call(c, "StartJob", PART, "SN-OPCUA-2", "")
            assert err.value.code == ua.StatusCodes.BadInvalidState
            deadline = time.monotonic() + INSPECTION_TIMEOUT_S
            while await value(c, *LAST, "ResultId") != iid:
                assert time.monotonic() < deadline, "the last result never showed the inspection"
                await asyncio.sleep(0.25)
            last = {name: await value(c, *LAST, name) for name in
                    ("PartNumber", "Serial", "OrderId", "Result", "State", "StartTime", "CreationTime",
                     "MachineSeconds")}
            chars = {}
            for obj in await (await node(c, *LAST, "Characteristics")).get_children():
                fields = {}
                for var in await obj.get_children():
                    dv = await var.read_data_value(raise_on_bad_status=False)
                    fields[(await var.read_browse_name()).Name] = dv.Value.Value if dv.StatusCode.is_good() else None
                chars[(await obj.read_browse_name()).Name] = fields
            assert await value(c, *V, "CurrentJob", "State") == last["State"]
            assert await value(c, *M, "Monitoring", "OperationCounters", "OperationCycleCounter") == cycles + 1
            return iid, last, chars

    iid, last, chars = run(main())
    with srv.client("mes") as rest:
        done = wait_done(rest, iid)
    assert done["state"] == "complete" and done["result"] == "pass", done["reason"]
    assert last["State"] == done["state"] and last["Result"] == done["result"]
    assert (last["PartNumber"], last["Serial"], last["OrderId"]) == (PART, "SN-OPCUA-1", "PO-OPCUA")
    assert last["StartTime"].isoformat() == done["started_at"]
    assert last["CreationTime"].isoformat() == done["finished_at"]
    assert last["MachineSeconds"] == pytest.approx(done["machine_s"], rel=1e-12)
    assert len(done["characteristics"]) == 4
    assert set(chars) == {ch["id"] for ch in done["characteristics"]}
    for ch in done["characteristics"]:
        got = chars[ch["id"]]
        assert got["Id"] == ch["id"] and got["Unit"] == ch["unit"]
        assert got["Passed"] is ch["pass"]
        for name, key in (("Nominal", "nominal"), ("Lower", "lower_limit"), ("Upper", "upper_limit"),
                          ("Measured", "measured"), ("Uncertainty", "uncertainty_k2")):
            assert got[name] == ch[key], (ch["id"], name)
    # the order is in the audit log under the token's name, as a REST order is
    audit = [e.message for e in srv.runtime.store.events(kind="audit", limit=50, newest_first=True)]
    assert any(iid in m and "test operator" in m and "over OPC UA" in m for m in audit), audit


def test_stop_ends_the_running_job_and_is_refused_when_nothing_runs(served):
    srv, url = served
    with srv.client("admin") as rest:
        wait_idle(rest)

    async def main():
        async with client(url, srv.tokens["mes"]) as mes, client(url, srv.tokens["operator"]) as op:
            iid = await call(mes, "StartJob", PART, "SN-OPCUA-STOP", "")
            deadline = time.monotonic() + 60
            while await value(op, *M, "StationStatus", "State") != "running":
                assert time.monotonic() < deadline, "the job never ran"
                await asyncio.sleep(0.05)
            assert (await value(op, *M, "MachineryBuildingBlocks", "MachineryItemState",
                                "CurrentState")).Text == "Executing"
            assert (await value(op, *M, "MachineryBuildingBlocks", "MachineryOperationMode",
                                "CurrentState")).Text == "Processing"
            assert await call(op, "Stop") is None  # no output arguments
            return iid

    iid = run(main())
    with srv.client("admin") as rest:
        done = wait_done(rest, iid)
        wait_idle(rest)
    assert done["state"] != "complete" and done["result"] is None, done

    async def nothing_runs():
        async with client(url, srv.tokens["operator"]) as op:
            with pytest.raises(UaStatusCodeError) as err:
                await call(op, "Stop")
            assert err.value.code == ua.StatusCodes.BadInvalidState
            assert await value(op, *V, "CurrentJob", "Running") is False
            assert await value(op, *V, "CurrentJob", "State") == done["state"]

    run(nothing_runs())


def test_a_token_revoked_after_login_may_no_longer_call(served):
    srv, url = served
    with Store(data_dir=srv.data_dir) as store:
        record, token = TokenRepository(store).create("operator", name="opcua revoked")

    async def main():
        async with client(url, token) as c:
            with pytest.raises(UaStatusCodeError) as err:  # allowed, but nothing runs
                await call(c, "Stop")
            assert err.value.code == ua.StatusCodes.BadInvalidState
            with Store(data_dir=srv.data_dir) as store:
                TokenRepository(store).revoke(record.id)
            with pytest.raises(BadUserAccessDenied):
                await call(c, "Stop")

    run(main())


def test_with_a_certificate_a_token_session_runs_over_basic256sha256(tmp_path):
    """--opcua-cert/--opcua-key: the server offers Basic256Sha256 (signed and encrypted)
    beside None; a client with its own certificate logs in with a token over it."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    async def make(name: str, uri: str, use):
        key, cert = tmp_path / f"{name}-key.pem", tmp_path / f"{name}-cert.der"
        await setup_self_signed_certificate(key, cert, uri, "127.0.0.1", [use], {"commonName": name})
        return key, cert

    data = tmp_path / "data"
    data.mkdir()
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    skey, scert = run(make("server", "urn:bore-station:default", ExtendedKeyUsageOID.SERVER_AUTH))
    ckey, ccert = run(make("client", "urn:bore-station:test-client", ExtendedKeyUsageOID.CLIENT_AUTH))
    srv, server, thread = start_server(data, opcua_endpoint=url, opcua_cert=scert, opcua_key=skey)
    try:
        async def main():
            async with client(url) as plain:
                endpoints = await plain.get_endpoints()
            offered = {(e.SecurityPolicyUri.rsplit("#", 1)[-1], e.SecurityMode) for e in endpoints}
            assert ("None", ua.MessageSecurityMode.None_) in offered
            assert ("Basic256Sha256", ua.MessageSecurityMode.SignAndEncrypt) in offered
            secure = client(url, srv.tokens["operator"])
            secure.application_uri = "urn:bore-station:test-client"
            await secure.set_security_string(f"Basic256Sha256,SignAndEncrypt,{ccert},{ckey}")
            async with secure as c:
                assert c.security_policy.Mode == ua.MessageSecurityMode.SignAndEncrypt
                assert await value(c, *M, "Identification", "SoftwareRevision") == __version__
                with pytest.raises(UaStatusCodeError) as err:  # admitted; nothing runs to stop
                    await call(c, "Stop")
                assert err.value.code == ua.StatusCodes.BadInvalidState

        run(main())
    finally:
        stop_server(server, thread)
    check_endpoint_free(url)


def test_method_calls_count_against_the_tokens_write_limit(served):
    """A method call is a write: a flood of them from one token is refused with
    BadTooManyOperations once the token's bucket is empty, and the same token's REST
    writes then get 429 (one bucket for both faces); another token is unaffected."""
    srv, url = served
    with Store(data_dir=srv.data_dir) as store:
        _, flooder = TokenRepository(store).create("operator", name="opcua flood")
    limiter = srv.runtime.write_limiter
    burst = limiter.burst

    async def main():
        codes = Counter()
        async with client(url, flooder) as c:
            for _ in range(burst + 20):
                with pytest.raises(UaStatusCodeError) as err:
                    await call(c, "Stop")  # nothing runs: admitted calls answer BadInvalidState
                codes[err.value.code] += 1
        return codes

    t0 = time.monotonic()
    codes = run(main())
    elapsed = time.monotonic() - t0
    assert codes[ua.StatusCodes.BadTooManyOperations] >= 5
    # admitted: the burst and what refilled meanwhile, no more
    assert burst <= codes[ua.StatusCodes.BadInvalidState] <= burst + limiter.rate_per_s * elapsed + 1
    headers = {"Authorization": f"Bearer {flooder}"}
    with httpx.Client(base_url=srv.url, headers=headers, timeout=30.0) as rest:
        # the bucket refills at its rate meanwhile (a unit per 0.2 s): a few REST writes
        # empty it again, where a bucket of its own would admit a whole burst
        statuses = []
        for _ in range(10):
            r = rest.post("/api/v1/station/stop")
            statuses.append(r.status_code)
            if r.status_code == 429:
                break
        assert r.status_code == 429 and int(r.headers["Retry-After"]) >= 1, statuses
        assert len(statuses) < burst
    with srv.client("operator") as other:
        assert other.post("/api/v1/station/stop").status_code != 429


def test_the_last_result_is_there_from_the_start(tmp_path):
    """A station restarted after its last inspection: LastResult shows that inspection
    at once (read from the store, this station's own), not only after the next one."""
    from station.parts import load_part
    from station.store import Measurement

    spec = load_part(PART)
    data = tmp_path / "data"
    with Store(data_dir=data, station_id="station") as store:  # the default config's station id
        iid = store.begin_inspection(PART, serial="SN-BEFORE")
        store.finish(iid, "complete", "pass", measurements=[
            Measurement.of(c, c.nominal, passed=True, uncertainty_k2=0.001) for c in spec.characteristics()])
    with Store(data_dir=data, station_id="another-station") as store:  # a later one of another station
        other = store.begin_inspection(PART, serial="SN-ELSEWHERE")
        store.finish(other, "aborted")
    url = f"opc.tcp://127.0.0.1:{free_port()}"
    srv, server, thread = start_server(data, opcua_endpoint=url)
    try:
        async def main():
            async with client(url) as c:
                last = (*V, "ResultManagement", "Results", "LastResult")
                return (await value(c, *last, "ResultId"), await value(c, *last, "Serial"),
                        await value(c, *last, "Characteristics", "hole_1.diameter", "Measured"))

        rid, serial, d1 = run(main())
        assert (rid, serial) == (iid, "SN-BEFORE")
        assert d1 == pytest.approx(spec.characteristic("hole_1.diameter").nominal)
    finally:
        stop_server(server, thread)

// The operator panel: station state over Server-Sent Events, axes polled, job
// start and commands, the current part's verdict, results, alarms, plots.

import { api, ApiError, newIdempotencyKey, setCsrf, toLogin } from "./api.js";
import { linePlot } from "./plots.js";
import { surfaceLine, surfaceSection } from "./surface.js";

const $ = (id) => document.getElementById(id);
const AXES_PERIOD_MS = 500;
const ALARMS_PERIOD_MS = 5000;
const ACK_KEY = "bore-station.alarms-acknowledged";

const panel = {
  who: null,
  station: null, // GET /station
  current: null, // inspection id shown as the current part
  events: null, // EventSource
  resultsOffset: 0,
  thisStation: null, // this station's id (GET /stations); the results page may show others too
  view: "operation",
  busyClick: false,
};

// ------------------------------------------------------------------ formatting
function fmtNum(v, digits) {
  return v === null || v === undefined || !isFinite(v) ? "-" : Number(v).toFixed(digits);
}
function fmtTime(iso) {
  if (!iso) return "-";
  const d = new Date(iso);
  const today = new Date();
  const time = d.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit", second: "2-digit", hour12: false });
  return d.toDateString() === today.toDateString() ? time : `${d.toLocaleDateString()} ${time}`;
}
function td(text, cls) {
  const c = document.createElement("td");
  c.textContent = text;
  if (cls) c.className = cls;
  return c;
}
function row(cells, cls) {
  const r = document.createElement("tr");
  if (cls) r.className = cls;
  cells.forEach((c) => r.appendChild(c));
  return r;
}
function clear(node) {
  while (node.firstChild) node.removeChild(node.firstChild);
}
function say(id, text, isError = false) {
  const m = $(id);
  m.textContent = text || "";
  m.className = "message" + (isError && text ? " error" : "");
}
/** How an inspection's outcome reads: PASS, FAIL, or the state when it did not complete. */
function outcomeOf(rec) {
  if (rec.state === "running") return { text: "RUNNING", cls: "running" };
  if (rec.state === "complete") return rec.result === "pass" ? { text: "PASS", cls: "pass" } : { text: "FAIL", cls: "fail" };
  return { text: rec.state.toUpperCase(), cls: "other" };
}

/** A titled list (h2 + ul) appended to ``box``, each item's li filled by ``fill(li, item)``;
 * nothing at all for an empty list. Returns the ul (or null). */
function appendList(box, title, items, fill, cls = "") {
  if (!items || !items.length) return null;
  const h = document.createElement("h2");
  h.textContent = title;
  h.className = "list-title";
  box.appendChild(h);
  const ul = document.createElement("ul");
  if (cls) ul.className = cls;
  for (const item of items) {
    const li = document.createElement("li");
    fill(li, item);
    ul.appendChild(li);
  }
  box.appendChild(ul);
  return ul;
}

// ------------------------------------------------------------------ an inspection's findings and machine time
// how each finding kind reads; the abnormal ones (the part is not as the plan expects)
// are highlighted as warnings, in words as well as colour
const FINDING_KINDS = {
  unexpected_hole: { label: "WARNING: unexpected hole", warning: true },
  ambiguous_identity: { label: "WARNING: identity unclear", warning: true },
  datum: { label: "datum", warning: false },
};

function findingWhere(f) {
  const parts = [];
  const has = (v) => v !== null && v !== undefined;
  if (has(f.axial_mm)) parts.push(`axial ${fmtNum(f.axial_mm, 3)} mm`);
  if (has(f.angle_deg)) parts.push(`angle ${fmtNum(f.angle_deg, 2)} deg`);
  if (has(f.diameter_mm)) parts.push(`\u2300 ${fmtNum(f.diameter_mm, 3)} mm`);
  if (has(f.u_mm)) parts.push(`U ${fmtNum(f.u_mm, 4)} mm`);
  return parts.join(", ");
}

/** One finding of an inspection as a list item: kind, message, where. */
function findingItem(li, f) {
  const k = FINDING_KINDS[f.kind] || { label: f.kind, warning: false };
  li.className = `finding finding-${f.kind}` + (k.warning ? " warning" : "");
  const kind = document.createElement("span");
  kind.className = "finding-kind";
  kind.textContent = k.label;
  li.appendChild(kind);
  li.appendChild(document.createTextNode(` ${f.message}`));
  const where = findingWhere(f);
  if (where) {
    const w = document.createElement("span");
    w.className = "finding-where";
    w.textContent = ` (${where})`;
    li.appendChild(w);
  }
}

/** "machine time 7.1 s, 1.09 x the plan's lower bound (modelled)"; "" when unknown. */
function cycleText(rec) {
  if (rec.machine_s === null || rec.machine_s === undefined || !isFinite(rec.machine_s)) return "";
  const c = rec.cycle || {};
  let text = `machine time ${fmtNum(rec.machine_s, 1)} s`;
  if (c.ratio !== null && c.ratio !== undefined && isFinite(c.ratio)) text += `, ${fmtNum(c.ratio, 2)} x the plan's lower bound`;
  if (c.basis === "modelled") text += " (modelled)";
  return text;
}

/** The breakdown of the machine time (and of the lower bound), for a tooltip. */
function cycleTitle(rec) {
  const c = rec.cycle;
  if (!c || !c.breakdown) return "";
  const parts = (b) => Object.entries(b).map(([k, v]) => `${k.replace(/_s$/, "")} ${fmtNum(v, 2)} s`).join(", ");
  let t = (c.basis === "modelled" ? "modelled: the plan replayed at the axes' real speeds" : `${c.basis || "machine time"}`) +
    `; ${parts(c.breakdown)}`;
  if (c.lower_bound_breakdown) t += `\nlower bound ${fmtNum(c.lower_bound_s, 1)} s: ${parts(c.lower_bound_breakdown)}`;
  return t;
}

/** The findings list and the machine time line of an inspection, into ``box`` (cleared). */
function fillOutcomeExtras(box, rec) {
  clear(box);
  const line = cycleText(rec);
  if (line) {
    const d = document.createElement("div");
    d.className = "cycle";
    d.textContent = line;
    d.title = cycleTitle(rec);
    box.appendChild(d);
  }
  appendList(box, "Findings", rec.findings, findingItem, "findings");
}

// ------------------------------------------------------------------ station state
const ATTENTION = new Set(["paused", "stopping", "aborting", "homing"]);
const ABNORMAL = new Set(["faulted", "estopped"]);

function showStation(st) {
  panel.station = st;
  $("state").textContent = st.state.toUpperCase();
  $("state-reason").textContent = st.reason || (st.busy ? "working" : "\u00a0");
  const box = $("state-box");
  box.className = "status-box state" + (ABNORMAL.has(st.state) ? " abnormal" : ATTENTION.has(st.state) ? " attention" : "");
  $("mode").textContent = st.mode === "simulated" ? "simulated hardware" : st.mode || "";
  showProgress(st.progress, st.busy, st.state);
  if (st.state === "estopped") showEstop(true);
  showNeedsCheck(st);
  updateButtons();
}

// ------------------------------------------------------------------ station needs a check
const CHECK_ROLES = ["operator", "engineer", "admin"];
const DECIDE_ROLES = ["engineer", "admin"];
const hasRole = (roles) => Boolean(panel.who && roles.includes(panel.who.role));

/** The banner over every page while the station's charts ask for a check on the master. */
function showNeedsCheck(st) {
  if (st.needs_check === undefined) return; // an engine event's partial state: keep the last
  const banner = $("check-banner");
  banner.classList.toggle("hidden", !st.needs_check);
  $("check-text").textContent = st.needs_check ? `Station needs a check: ${st.needs_check_reason || "an alarm"}` : "";
  $("check-master").classList.toggle("hidden", !hasRole(CHECK_ROLES));
}

async function checkOnMaster() {
  panel.busyClick = true;
  updateButtons();
  $("check-message").textContent = "Starting the check ...";
  try {
    const chk = await api("POST", "/api/v1/checks", { json: { kind: "master" } });
    $("check-message").textContent = `Check on master ${chk.master_id} running (inspection ${chk.id.slice(0, 8)}).`;
    await showInspection(chk.id);
  } catch (err) {
    $("check-message").textContent = `Not started: ${err.message}`;
  } finally {
    panel.busyClick = false;
    refreshStationSoon();
    updateButtons();
  }
}

/** A check has ended (SSE "check"): say how, where the operator looks. */
function checkEnded(d) {
  const text = d.in_control
    ? `Check on master ${d.master_id}: in control, the station is within its stated U.`
    : `Check on master ${d.master_id}: OUT OF CONTROL` + (d.state !== "complete" ? ` (the inspection ${d.state})` : "") +
      (d.proposal_id ? `; a model proposal (${d.proposal_id}) awaits an engineer.` : ".");
  say("job-message", text, !d.in_control);
  $("check-message").textContent = text;
  refreshStationSoon();
  refreshAlarms().catch(() => {});
  if (hasRole(DECIDE_ROLES)) refreshProposals().catch(() => {});
}

function showProgress(p, running = true, state = "running") {
  if (!p) return;
  $("progress-text").textContent = running ? p.text || "\u00a0"
    : ["idle", "ready"].includes(state) ? "No job running: ready for the next part" : "No job running";
  const frac = p.total ? Math.min(1, Math.max(0, p.done / p.total)) : 0;
  $("progress-bar").style.width = `${(frac * 100).toFixed(1)}%`;
  $("progress-count").textContent = p.total ? `step ${p.done} of ${p.total}` : "\u00a0";
}

function updateButtons() {
  const st = panel.station;
  const state = st ? st.state : "unknown";
  const running = ["running", "paused", "stopping"].includes(state);
  const canWrite = panel.who && ["operator", "admin"].includes(panel.who.role);
  const set = (id, on) => { $(id).disabled = !on || !canWrite || panel.busyClick; };
  $("start").disabled = !(st && !st.busy && ["idle", "ready"].includes(state)) || panel.busyClick
    || !(panel.who && ["operator", "mes", "admin"].includes(panel.who.role));
  set("pause", state === "running");
  set("resume", state === "paused");
  set("stop", running);
  set("abort", running || state === "aborting");
  set("reset", st && !st.busy && ["faulted", "estopped", "idle", "ready"].includes(state));
  set("home", st && !st.busy && ["idle", "ready"].includes(state));
  $("check-master").disabled = !(st && !st.busy && ["idle", "ready"].includes(state)) || panel.busyClick
    || !hasRole(CHECK_ROLES);
}

async function refreshStation() {
  showStation(await api("GET", "/api/v1/station"));
  const job = panel.station.job;
  if (job && ["inspection", "check"].includes(job.kind) && job.inspection_id) {
    await showInspection(job.inspection_id);
  } else if (!panel.current) {
    const last = await api("GET", `/api/v1/inspections?${ownStation({ limit: "1" })}`);
    if (last.items.length) await showInspection(last.items[0].id);
  }
}

// ------------------------------------------------------------------ live events
function setLink(ok, text) {
  $("link").textContent = text;
  $("link-box").className = "status-box" + (ok ? "" : " abnormal");
}

function connectEvents() {
  if (panel.events) panel.events.close();
  const es = new EventSource("/api/v1/events");
  panel.events = es;
  es.addEventListener("open", () => {
    setLink(true, "live");
    // SSE does not replay what happened while disconnected: read the present first
    refreshStation().catch(() => {});
    refreshRecent().catch(() => {});
    refreshAlarms().catch(() => {});
  });
  es.addEventListener("error", () => {
    setLink(false, "LOST - reconnecting");
    // a 401 (session ended) also lands here: check, and go to the login page if so
    api("GET", "/api/v1/session").catch(() => {});
  });
  es.addEventListener("state", (ev) => {
    const d = JSON.parse(ev.data);
    if (d.progress !== undefined) {
      showStation(d); // the first event: a full snapshot
    } else if (panel.station) {
      showStation({ ...panel.station, state: d.state, reason: d.text || "" });
      refreshStationSoon();
    }
  });
  es.addEventListener("progress", (ev) => {
    const d = JSON.parse(ev.data);
    showProgress({ done: d.done, total: d.total, text: d.text });
  });
  es.addEventListener("note", (ev) => {
    const d = JSON.parse(ev.data);
    if (d.text) $("progress-text").textContent = d.text;
  });
  es.addEventListener("fault", () => { refreshAlarms().catch(() => {}); });
  es.addEventListener("alarm", () => {
    refreshStationSoon();
    refreshAlarms().catch(() => {});
  });
  es.addEventListener("check", (ev) => checkEnded(JSON.parse(ev.data)));
  es.addEventListener("proposal", () => {
    if (hasRole(DECIDE_ROLES)) refreshProposals().catch(() => {});
    refreshStationSoon();
  });
  es.addEventListener("retry", () => { refreshAlarms().catch(() => {}); });
  es.addEventListener("job", (ev) => {
    const d = JSON.parse(ev.data);
    if (d.event === "started" && d.inspection_id) {
      showInspection(d.inspection_id).catch(() => {});
    } else if (d.event === "finished") {
      if (d.inspection_id) showInspection(d.inspection_id).catch(() => {});
      refreshRecent().catch(() => {});
      refreshAlarms().catch(() => {});
      say("job-message", "");
      // the job's task ends just after this event: read the station again once it has
      setTimeout(refreshStationSoon, 1000);
    }
    refreshStationSoon();
  });
}

let stationTimer = null;
function refreshStationSoon() {
  clearTimeout(stationTimer);
  stationTimer = setTimeout(() => {
    api("GET", "/api/v1/station").then(showStation).catch(() => {});
  }, 150);
}

// ------------------------------------------------------------------ axes
function axisStateText(a) {
  if (!a) return { text: "-", cls: "" };
  if (a.error) return { text: "NO ANSWER", cls: "flag-abnormal" };
  if (a.estop) return { text: "E-STOP", cls: "flag-abnormal" };
  if (a.fault) return { text: `FAULT ${a.fault_code}`, cls: "flag-abnormal" };
  if (!a.enabled) return { text: "disabled", cls: "" };
  if (!a.homed) return { text: "not homed", cls: "flag-attention" };
  return { text: a.moving ? "moving" : "in position", cls: "" };
}

function showEstop(on) {
  $("estop").textContent = on ? "PRESSED" : "released";
  $("estop-box").className = "status-box" + (on ? " abnormal" : "");
}

async function refreshAxes() {
  const ax = await api("GET", "/api/v1/axes");
  for (const [name, key, digits] of [["Z", "z", 4], ["C", "c", 3]]) {
    const a = ax[name];
    $(`${key}-set`).textContent = a && a.setpoint !== null && a.setpoint !== undefined ? fmtNum(a.setpoint, digits) : "-";
    $(`${key}-pos`).textContent = a && !a.error ? fmtNum(a.position, digits) : "-";
    const s = axisStateText(a);
    const cell = $(`${key}-state`);
    cell.textContent = s.text;
    cell.className = s.cls;
  }
  const g = ax.grating;
  const gc = $("z-grating");
  if (!g) {
    gc.textContent = "n/a";
  } else if (g.error || !g.ok) {
    gc.textContent = "FAULT";
    gc.className = "num big flag-abnormal";
  } else {
    gc.textContent = fmtNum(g.position, 4);
    gc.className = "num big";
  }
  const estop = [ax.Z, ax.C].some((a) => a && a.estop) || (panel.station && panel.station.state === "estopped");
  showEstop(estop);
}

function pollAxes() {
  const tick = async () => {
    if (!document.hidden && panel.view === "operation") {
      try {
        await refreshAxes();
      } catch (err) {
        if (!(err instanceof ApiError) || err.status !== 401) setLink(false, "NO ANSWER");
      }
    }
    setTimeout(tick, AXES_PERIOD_MS);
  };
  tick();
}

// ------------------------------------------------------------------ current part
async function showInspection(id) {
  const rec = await api("GET", `/api/v1/inspections/${encodeURIComponent(id)}`);
  panel.current = id;
  const o = outcomeOf(rec);
  const v = $("verdict");
  v.className = `verdict ${o.cls}`;
  v.textContent = o.cls === "pass" ? "\u2713 PASS" : o.cls === "fail" ? "\u2717 FAIL" : o.text;
  const info = $("part-info");
  clear(info);
  const b = document.createElement("b");
  b.textContent = `${rec.part_number}  serial ${rec.serial || "-"}`;
  info.appendChild(b);
  info.appendChild(document.createTextNode(
    `  ${rec.order_id ? "order " + rec.order_id + "  " : ""}started ${fmtTime(rec.started_at)}` +
    (rec.reason && rec.state !== "complete" ? `  (${rec.reason})` : "")));
  fillChars($("chars").querySelector("tbody"), rec.characteristics || []);
  fillOutcomeExtras($("part-extras"), rec);
  if (rec.surface) {
    // the picture itself is on the results page (this card is narrow)
    const d = document.createElement("div");
    d.className = "surface-line";
    d.textContent = `${surfaceLine(rec.surface)} (the picture: Results)`;
    $("part-extras").appendChild(d);
  }
}

function fillChars(tbody, chars) {
  clear(tbody);
  for (const c of chars) {
    const digits = c.unit === "mm" ? 4 : 3;
    const failed = c.pass === false;
    tbody.appendChild(row([
      td(c.id),
      td(`${fmtNum(c.measured, digits)}`, "num measured"),
      td(fmtNum(c.nominal, digits), "num"),
      td(fmtNum(c.lower_limit, digits), "num"),
      td(fmtNum(c.upper_limit, digits), "num"),
      td(`\u00b1${fmtNum(c.uncertainty_k2, digits)}`, "num"),
      td(c.pass === null || c.pass === undefined ? "-" : failed ? "FAIL" : "ok", "verdict-cell"),
    ], failed ? "fail" : ""));
  }
}

// ------------------------------------------------------------------ job and commands
async function startJob() {
  const serial = $("serial").value.trim();
  const part = $("part").value;
  const order = $("order").value.trim();
  if (!part) return say("job-message", "Choose a part number.", true);
  if (!serial) return say("job-message", "Enter the part's serial number.", true);
  const body = { part_number: part, serial };
  if (order) body.order_id = order;
  const surface = $("surface-scan").value; // "": as the part spec says
  if (surface) body.surface = surface === "true";
  panel.busyClick = true;
  updateButtons();
  say("job-message", "Starting ...");
  try {
    const rec = await api("POST", "/api/v1/job-orders", { json: body, headers: { "Idempotency-Key": newIdempotencyKey() } });
    say("job-message", `Inspection started for serial ${rec.serial}.`);
    $("serial").value = "";
    await showInspection(rec.id);
  } catch (err) {
    say("job-message", `Not started: ${err.message}`, true);
  } finally {
    panel.busyClick = false;
    refreshStationSoon();
    updateButtons();
  }
}

async function command(name) {
  panel.busyClick = true;
  updateButtons();
  try {
    showStation(await api("POST", `/api/v1/station/${name}`));
    say("job-message", `${name[0].toUpperCase() + name.slice(1)} requested.`);
  } catch (err) {
    say("job-message", `${name}: ${err.message}`, true);
  } finally {
    panel.busyClick = false;
    updateButtons();
  }
}

async function loadParts() {
  const parts = await api("GET", "/api/v1/parts");
  const sel = $("part");
  clear(sel);
  for (const p of parts.items) {
    const o = document.createElement("option");
    o.value = p.part_number;
    o.textContent = p.part_number + (p.description ? ` - ${p.description}` : "");
    sel.appendChild(o);
  }
}

// ------------------------------------------------------------------ results
function resultCell(rec) {
  const o = outcomeOf(rec);
  return td(o.text, o.cls === "fail" ? "res-fail" : o.cls === "other" ? "res-other" : o.cls === "pass" ? "res-pass" : "");
}

// query of this station's own inspections: the operation page shows this station's
// parts even when other stations write the same database
function ownStation(params) {
  const q = new URLSearchParams(params);
  if (panel.thisStation) q.set("station", panel.thisStation);
  return q;
}

async function loadStations() {
  const data = await api("GET", "/api/v1/stations");
  panel.thisStation = data.this;
  const sel = $("filter-station");
  const chosen = sel.value;
  clear(sel);
  const all = document.createElement("option");
  all.value = "";
  all.textContent = "all";
  sel.appendChild(all);
  const ids = new Set(data.stations);
  if (data.this) ids.add(data.this);
  for (const id of [...ids].sort()) {
    const o = document.createElement("option");
    o.value = id;
    o.textContent = id === data.this ? `${id} (this station)` : id;
    sel.appendChild(o);
  }
  sel.value = [...ids].includes(chosen) ? chosen : "";
}

async function refreshRecent() {
  const data = await api("GET", `/api/v1/inspections?${ownStation({ limit: "8" })}`);
  const tbody = $("recent").querySelector("tbody");
  clear(tbody);
  for (const rec of data.items) {
    const r = row([td(fmtTime(rec.started_at)), td(rec.part_number), td(rec.serial || "-"), resultCell(rec)]);
    r.dataset.id = rec.id;
    if (rec.id === panel.current) r.className = "selected";
    r.addEventListener("click", () => showInspection(rec.id).then(refreshRecent).catch(() => {}));
    tbody.appendChild(r);
  }
}

async function refreshResults() {
  const q = new URLSearchParams({ limit: "50", offset: String(panel.resultsOffset) });
  if ($("filter-result").value) q.set("result", $("filter-result").value);
  if ($("filter-serial").value.trim()) q.set("serial", $("filter-serial").value.trim());
  if ($("filter-part").value.trim()) q.set("part_number", $("filter-part").value.trim());
  if ($("filter-station").value) q.set("station", $("filter-station").value);
  const data = await api("GET", `/api/v1/inspections?${q}`);
  const tbody = $("results").querySelector("tbody");
  clear(tbody);
  for (const rec of data.items) {
    const r = row([td(fmtTime(rec.started_at)), td(rec.station_id || "-"), td(rec.part_number), td(rec.serial || "-"), td(rec.order_id || "-"),
      td(rec.state), resultCell(rec)]);
    r.addEventListener("click", () => showResultDetail(rec.id).catch(() => {}));
    tbody.appendChild(r);
  }
  const last = Math.min(data.total, data.offset + data.items.length);
  $("results-count").textContent = data.total ? `${data.offset + 1} to ${last} of ${data.total}` : "no inspections";
  $("page-prev").disabled = data.offset === 0;
  $("page-next").disabled = last >= data.total;
}

async function showResultDetail(id) {
  const rec = await api("GET", `/api/v1/inspections/${encodeURIComponent(id)}`);
  const box = $("result-detail");
  clear(box);
  const h = document.createElement("h2");
  h.textContent = "Inspection";
  box.appendChild(h);
  const o = outcomeOf(rec);
  const v = document.createElement("div");
  v.className = `verdict ${o.cls}`;
  v.textContent = o.text;
  box.appendChild(v);
  const p = document.createElement("div");
  p.className = "part-info";
  p.textContent = `${rec.part_number}, serial ${rec.serial || "-"}, order ${rec.order_id || "-"}, ` +
    `station ${rec.station_id || "-"}; ` +
    `${fmtTime(rec.started_at)} to ${fmtTime(rec.finished_at)}` + (rec.reason ? `; ${rec.reason}` : "");
  box.appendChild(p);
  const t = $("chars").cloneNode(true);
  t.removeAttribute("id");
  fillChars(t.querySelector("tbody"), rec.characteristics || []);
  box.appendChild(t);
  const extras = document.createElement("div");
  extras.className = "outcome-extras";
  fillOutcomeExtras(extras, rec);
  box.appendChild(extras);
  if (rec.surface) box.appendChild(surfaceSection(rec.surface));
  if (rec.state !== "running") {
    const a = document.createElement("a");
    a.href = rec.links.qif;
    a.textContent = "QIF 3.0 results document";
    a.target = "_blank";
    a.rel = "noopener";
    box.appendChild(a);
  }
}

// ------------------------------------------------------------------ alarms
function acknowledged() {
  return Number(localStorage.getItem(ACK_KEY) || "0");
}

async function refreshAlarms() {
  const data = await api("GET", "/api/v1/alarms?limit=200");
  const fill = (tbody, items, full) => {
    clear(tbody);
    for (const e of items) {
      const cells = [td(fmtTime(e.at)), td(e.kind.toUpperCase(), "kind"), td(e.message)];
      if (full) cells.push(td(e.inspection_id ? e.inspection_id.slice(0, 8) : "-"));
      tbody.appendChild(row(cells, `kind-${e.kind}`));
    }
    if (!items.length) tbody.appendChild(row([td("No alarms.", "muted")]));
  };
  fill($("alarms").querySelector("tbody"), data.items, true);
  fill($("recent-alarms").querySelector("tbody"), data.items.slice(0, 5), false);
  const newest = data.items.length ? data.items[0].id : 0;
  if (panel.view === "alarms") localStorage.setItem(ACK_KEY, String(newest));
  const unack = data.items.filter((e) => e.id > acknowledged());
  const badge = $("alarm-badge");
  badge.textContent = String(unack.length);
  badge.className = "badge" + (unack.length ? "" : " hidden") + (unack.some((e) => e.kind === "fault") ? " fault" : "");
}

// ------------------------------------------------------------------ axis errors
async function refreshErrors() {
  const data = await api("GET", "/api/v1/models/active/curves");
  $("model-name").textContent = `Active model: ${data.model}` + (data.version ? ` (version ${data.version})` : " (built-in default)");
  const draw = (svgId, axis, names, unit) => {
    const ax = data.axes[axis];
    const series = [];
    for (const n of names) {
      const c = ax.curves[n];
      series.push({ name: `${n}${c.zero ? " (0)" : ""}`, values: c.values });
      if (c.values_down) series.push({ name: `${n} (-)`, values: c.values_down, dashed: true });
    }
    linePlot($(svgId), { x: ax.positions, series, xLabel: `${axis} / ${ax.unit}`, yLabel: unit,
      xTicks: axis === "C" ? [0, 60, 120, 180, 240, 300, 360] : undefined });
  };
  draw("plot-z-lin", "Z", ["EXZ", "EYZ", "EZZ"], "um");
  draw("plot-z-ang", "Z", ["EAZ", "EBZ", "ECZ"], "arcsec");
  draw("plot-c-lin", "C", ["EXC", "EYC", "EZC"], "um");
  draw("plot-c-ang", "C", ["EAC", "EBC", "ECC"], "arcsec");
  const box = $("comp-tables");
  clear(box);
  const names = Object.keys(data.compensation_tables);
  if (!names.length) box.textContent = "The active model has no tabulated error motions.";
  for (const name of names) {
    const t = data.compensation_tables[name];
    const card = document.createElement("div");
    card.className = "card";
    const h = document.createElement("h2");
    h.textContent = `${name} of ${t.axis} (${t.unit})` + (t.effects.length ? ` + ${t.effects.join(", ")}` : "");
    card.appendChild(h);
    const table = document.createElement("table");
    table.appendChild(row([td(`${t.axis} / ${t.position_unit}`), td("error", "num"), td("correction", "num")], "head"));
    t.target.forEach((x, i) => table.appendChild(row([td(fmtNum(x, 2)), td(fmtNum(t.deviation[i], 2), "num"),
      td(fmtNum(t.correction[i], 2), "num")])));
    card.appendChild(table);
    box.appendChild(card);
  }
}

// ------------------------------------------------------------------ discovery reports
async function refreshDiscovery() {
  const data = await api("GET", "/api/v1/reports/discovery");
  const tbody = $("discovery").querySelector("tbody");
  clear(tbody);
  for (const r of data.items) {
    const unexplained = r.verdict && r.verdict !== "explained";
    const tr = row([td(fmtTime(r.created_at)), td(r.created_by), td(r.axis ? r.axis.name : "-"),
      td(r.verdict || "-", unexplained ? "res-other" : ""), td(fmtNum(r.rms_before, 2), "num"),
      td(fmtNum(r.rms_after, 2), "num"), td(r.effects.join(", ") || "none")]);
    tr.addEventListener("click", () => showDiscovery(r.id).catch(() => {}));
    tbody.appendChild(tr);
  }
  if (!data.items.length) tbody.appendChild(row([td("No reports yet.", "muted")]));
}

async function showDiscovery(id) {
  const entry = await api("GET", `/api/v1/reports/discovery/${id}`);
  const r = entry.report;
  const box = $("discovery-detail");
  clear(box);
  const h = document.createElement("h2");
  h.textContent = `Report: ${entry.model_file} + ${entry.recording_file}`;
  box.appendChild(h);
  const p = document.createElement("div");
  p.className = "part-info";
  p.textContent = `Verdict: ${r.verdict}. RMS ${fmtNum(r.before.rms, 2)} before, ${fmtNum(r.after.rms, 2)} after ` +
    `(noise floor ${fmtNum(r.noise_floor, 2)}); residual white: ${r.after.white ? "yes" : "no"}. ` +
    `${r.recording ? r.recording.rows_used + " rows, " + r.recording.runs + " runs" : ""}`;
  box.appendChild(p);
  const plots = entry.plots || [];
  if (plots.length) {
    const pics = document.createElement("div");
    pics.className = "discovery-plots";
    for (const pl of plots) appendPicture(pics, pl.url, pl.view, `plot-${pl.name.replace(/\.png$/, "")}`);
    box.appendChild(pics);
  } else {
    const none = document.createElement("div");
    none.className = "muted no-plot";
    none.textContent = "No pictures kept with this report.";
    box.appendChild(none);
  }
  const t = document.createElement("table");
  t.className = "effects";
  t.appendChild(row([td("Effect"), td("Parameters (\u00b1 std. error)"), td("Why it happens")]));
  t.firstChild.querySelectorAll("td").forEach((c) => { c.style.fontWeight = "600"; });
  for (const e of r.effects) {
    const params = Object.entries(e.parameters).map(([k, v]) =>
      `${k} = ${fmtNum(v, 3)}` + (e.stderr && e.stderr[k] !== undefined ? ` \u00b1 ${fmtNum(e.stderr[k], 3)}` : "")).join(", ");
    t.appendChild(row([td(e.name), td(params), td(e.explanation || "")]));
  }
  if (!r.effects.length) t.appendChild(row([td("none found", "muted")]));
  box.appendChild(t);
  for (const [title, list, key] of [["Findings", r.findings, "description"], ["Ambiguities", r.ambiguities, "description"],
    ["Not analysed", r.not_analysed, "why"]]) {
    appendList(box, title, list, (li, f) => { li.textContent = f[key] || JSON.stringify(f); });
  }
}

async function runDiscovery(ev) {
  ev.preventDefault();
  const m = $("disc-model").files[0], rec = $("disc-recording").files[0];
  if (!m || !rec) return say("disc-message", "Choose an axis model and a recording.", true);
  const form = new FormData();
  form.append("model", m);
  form.append("recording", rec);
  say("disc-message", "Running discovery ...");
  try {
    await api("POST", "/api/v1/reports/discovery", { form });
    say("disc-message", "Report stored.");
    await refreshDiscovery();
  } catch (err) {
    say("disc-message", `Refused: ${err.message}`, true);
  }
}

// ------------------------------------------------------------------ model proposals (engineer)
const PROPOSAL_STATES = { proposed: "PROPOSED", approved: "APPROVED", rejected: "REJECTED" };

/** "installation.J.z_um" -> "um" (the unit is the key's suffix). */
function termUnit(term) {
  const key = term.split(".").pop();
  return key.includes("_") ? key.split("_").pop() : "";
}
function signed(v, digits) {
  return v === null || v === undefined || !isFinite(v) ? "-" : (v > 0 ? "+" : "") + Number(v).toFixed(digits);
}

/** A picture the API serves (a PNG of a proposal or of a discovery run) as a figure
 * with its caption, appended to ``box``. The panel's session cookie goes with the
 * image's request by itself (as with the camera's), so a plain <img> suffices; a
 * picture that does not load says so in words. */
function appendPicture(box, url, caption, cls) {
  const fig = document.createElement("figure");
  fig.className = `picture ${cls || ""}`.trim();
  const img = document.createElement("img");
  img.alt = caption;
  img.loading = "eager";
  const cap = document.createElement("figcaption");
  cap.textContent = caption;
  img.addEventListener("error", () => {
    fig.classList.add("missing");
    cap.textContent = `${caption}: the picture could not be loaded`;
  });
  img.src = url;
  fig.append(img, cap);
  box.appendChild(fig);
  return fig;
}

/** A small titled table (h3 + table) appended to ``box``. */
function miniTable(box, title, head, rows, cls) {
  const h = document.createElement("h3");
  h.textContent = title;
  box.appendChild(h);
  const t = document.createElement("table");
  t.className = `mini ${cls}`;
  const thead = document.createElement("thead");
  const hr = document.createElement("tr");
  for (const [text, num] of head) {
    const th = document.createElement("th");
    th.textContent = text;
    if (num) th.className = "num";
    hr.appendChild(th);
  }
  thead.appendChild(hr);
  t.appendChild(thead);
  const tbody = document.createElement("tbody");
  rows.forEach((cells) => tbody.appendChild(row(cells)));
  t.appendChild(tbody);
  box.appendChild(t);
}

function proposalCard(p) {
  const card = document.createElement("div");
  card.className = `card proposal state-${p.state}`;
  card.dataset.id = p.id;
  const h = document.createElement("h2");
  h.textContent = "Proposal ";
  const pid = document.createElement("span");
  pid.className = "proposal-id";
  pid.textContent = p.id;
  h.appendChild(pid);
  const st = document.createElement("span");
  st.className = "proposal-state";
  st.textContent = PROPOSAL_STATES[p.state] || p.state;
  h.appendChild(st);
  card.appendChild(h);
  const meta = document.createElement("div");
  meta.className = "part-info";
  meta.textContent = `made ${fmtTime(p.created_at)} on model ${p.base_version}`;
  card.appendChild(meta);
  const reason = document.createElement("div");
  reason.className = "proposal-reason";
  reason.textContent = `Why: ${p.reason}`;
  card.appendChild(reason);
  const ex = p.explanation || {};
  if (ex.kind || ex.description) {
    const what = document.createElement("div");
    what.className = "proposal-explanation";
    const kind = document.createElement("span");
    kind.className = "explanation-kind";
    kind.textContent = (ex.kind || "unknown").toUpperCase();
    what.append("What the checks over time say: ", kind);
    if (ex.description) what.append(` ${ex.description}`);
    card.appendChild(what);
  }
  if (p.plot_url) {
    appendPicture(card, p.plot_url, "Master checks before and after the change (bars: 2u)", "proposal-plot");
  } else {
    const none = document.createElement("div");
    none.className = "muted no-plot";
    none.textContent = "No picture: the proposal has no master checks over time to show.";
    card.appendChild(none);
  }
  miniTable(card, "Changes", [["Term"], ["Change", true], ["Why"]],
    p.changes.map((c) => [td(c.term), td(`${signed(c.delta, 3)} ${termUnit(c.term)}`, "num"), td(c.why || "")]),
    "changes");
  miniTable(card, "Expected change of each hole's measured position", [["Hole"], ["um", true]],
    Object.entries(p.expected_change_um).map(([hole, v]) => [td(hole), td(signed(v, 2), "num")]), "expected");
  miniTable(card, "Evidence: measured minus certified, per check", [["Characteristic"], ["um", true]],
    Object.entries(p.evidence).map(([cid, vs]) => [td(cid), td(vs.map((v) => signed(v, 2)).join(", "), "num")]),
    "evidence");
  const decision = document.createElement("div");
  decision.className = "decision";
  if (p.state === "proposed") {
    if (hasRole(DECIDE_ROLES)) {
      const note = document.createElement("input");
      note.className = "note";
      note.maxLength = 500;
      note.placeholder = "note (optional): why";
      note.setAttribute("aria-label", "note on the decision");
      const approve = document.createElement("button");
      approve.className = "cmd primary approve";
      approve.type = "button";
      approve.textContent = "Approve";
      approve.title = "The station uses the changed model from its next inspection";
      const reject = document.createElement("button");
      reject.className = "cmd reject";
      reject.type = "button";
      reject.textContent = "Reject";
      const msg = document.createElement("span");
      msg.className = "message";
      const decide = async (yes) => {
        approve.disabled = reject.disabled = true;
        msg.textContent = yes ? "Approving ..." : "Rejecting ...";
        try {
          await api("POST", `/api/v1/model-proposals/${encodeURIComponent(p.id)}/${yes ? "approve" : "reject"}`,
            { json: { note: note.value.trim() } });
          await refreshProposals();
        } catch (err) {
          msg.textContent = `Refused: ${err.message}`;
          msg.className = "message error";
          approve.disabled = reject.disabled = false;
        }
      };
      approve.addEventListener("click", () => decide(true));
      reject.addEventListener("click", () => decide(false));
      decision.append(note, approve, reject, msg);
    } else {
      decision.textContent = "Awaiting an engineer's decision.";
    }
  } else {
    decision.textContent = `${PROPOSAL_STATES[p.state] || p.state} by ${p.decided_by || "?"} at ${fmtTime(p.decided_at)}` +
      (p.decision_note ? `: ${p.decision_note}` : "");
  }
  card.appendChild(decision);
  return card;
}

async function refreshProposals() {
  const data = await api("GET", "/api/v1/model-proposals");
  $("model-version").textContent = `The station's model now: ${data.model_version}`;
  const box = $("proposals");
  clear(box);
  const items = [...data.items].reverse(); // newest first
  if (!items.length) {
    const none = document.createElement("div");
    none.className = "muted";
    none.textContent = "No model proposals.";
    box.appendChild(none);
  }
  items.forEach((p) => box.appendChild(proposalCard(p)));
  const open = items.filter((p) => p.state === "proposed").length;
  const badge = $("proposal-badge");
  badge.textContent = String(open);
  badge.className = "badge" + (open ? "" : " hidden");
}

// ------------------------------------------------------------------ views
const VIEWS = {
  operation: () => Promise.all([refreshRecent(), refreshAlarms()]),
  results: () => loadStations().catch(() => {}).then(refreshResults),
  alarms: refreshAlarms,
  errors: refreshErrors,
  discovery: refreshDiscovery,
  proposals: refreshProposals,
};

function showView(name) {
  panel.view = name;
  document.querySelectorAll("nav.tabs button").forEach((b) => b.setAttribute("aria-selected", String(b.dataset.view === name)));
  document.querySelectorAll("section.view").forEach((s) => s.classList.toggle("hidden", s.id !== `view-${name}`));
  if (location.hash !== `#${name}`) history.replaceState(null, "", `#${name}`);
  VIEWS[name]().catch((err) => console.warn(name, err));
}

// ------------------------------------------------------------------ start
async function main() {
  let who;
  try {
    who = await api("GET", "/api/v1/session");
  } catch {
    return toLogin();
  }
  panel.who = who;
  setCsrf(who.csrf_token || null);
  $("user-name").textContent = who.name;
  $("user-role").textContent = who.role;
  $("logout").addEventListener("click", async () => {
    try {
      await api("DELETE", "/api/v1/session");
    } finally {
      toLogin();
    }
  });
  document.querySelectorAll("nav.tabs button").forEach((b) => b.addEventListener("click", () => showView(b.dataset.view)));
  $("start").addEventListener("click", startJob);
  $("job-form").addEventListener("submit", (ev) => { ev.preventDefault(); startJob(); });
  document.querySelectorAll("button[data-cmd]").forEach((b) => b.addEventListener("click", () => command(b.dataset.cmd)));
  $("filter-apply").addEventListener("click", () => { panel.resultsOffset = 0; refreshResults().catch(() => {}); });
  $("page-prev").addEventListener("click", () => { panel.resultsOffset = Math.max(0, panel.resultsOffset - 50); refreshResults().catch(() => {}); });
  $("page-next").addEventListener("click", () => { panel.resultsOffset += 50; refreshResults().catch(() => {}); });
  $("discovery-form").addEventListener("submit", runDiscovery);
  $("check-master").addEventListener("click", checkOnMaster);
  $("tab-proposals").classList.toggle("hidden", !hasRole(DECIDE_ROLES));
  if (hasRole(DECIDE_ROLES)) refreshProposals().catch(() => {});
  updateButtons();
  await loadStations().catch(() => {});
  await loadParts().catch((err) => say("job-message", `Part list: ${err.message}`, true));
  await refreshStation().catch(() => {});
  connectEvents();
  pollAxes();
  setInterval(() => { if (!document.hidden) refreshAlarms().catch(() => {}); }, ALARMS_PERIOD_MS);
  const initial = (location.hash || "#operation").slice(1);
  const allowed = VIEWS[initial] && (initial !== "proposals" || hasRole(DECIDE_ROLES));
  showView(allowed ? initial : "operation");
  // last: an endless MJPEG stream must not hold up the page's load
  $("camera").addEventListener("error", () => { $("camera-note").textContent = "camera: no picture"; });
  $("camera").addEventListener("load", () => { $("camera-note").textContent = "live"; });
  $("camera").src = "/api/v1/camera.mjpg";
}

main();

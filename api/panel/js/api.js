// Calls to the station's REST API from the panel: the session cookie goes by itself,
// every write carries the session's CSRF token (X-CSRF-Token), a 401 sends the
// operator back to the login page.

let csrfToken = null;

export class ApiError extends Error {
  constructor(status, message) {
    super(message);
    this.status = status;
  }
}

export function setCsrf(token) {
  csrfToken = token;
}

export function detailText(body, status) {
  if (body && body.detail !== undefined) {
    const d = body.detail;
    if (typeof d === "string") return d;
    if (Array.isArray(d)) {
      return d.map((p) => {
        if (p.msg) return `${(p.loc || []).slice(1).join(".")}: ${p.msg}`;
        if (p.message) return `${p.field}: ${p.message}`;
        return JSON.stringify(p);
      }).join("; ");
    }
    return JSON.stringify(d);
  }
  return `HTTP ${status}`;
}

// once: a second assign while the first navigation is pending aborts it (a poll's 401
// right after "Log out" did, and the browser test waiting for the login page saw
// net::ERR_ABORTED under load)
let leaving = false;

export function toLogin() {
  if (leaving || location.pathname.endsWith("/login.html")) return;
  leaving = true;
  location.assign("/panel/login.html");
}

export async function api(method, path, { json, form, headers = {} } = {}) {
  const h = { Accept: "application/json", ...headers };
  let body;
  if (method !== "GET") h["X-CSRF-Token"] = csrfToken || "";
  if (json !== undefined) {
    h["Content-Type"] = "application/json";
    body = JSON.stringify(json);
  } else if (form !== undefined) {
    body = form; // FormData: the browser writes the multipart header
  }
  const r = await fetch(path, { method, headers: h, body, credentials: "same-origin", cache: "no-store" });
  let data = null;
  try {
    data = await r.json();
  } catch {
    data = null;
  }
  if (r.status === 401) {
    toLogin();
    throw new ApiError(401, detailText(data, 401));
  }
  if (!r.ok) throw new ApiError(r.status, detailText(data, r.status));
  return data;
}

/** A random key per click, so a double click or a retried request starts one job. */
export function newIdempotencyKey() {
  if (crypto.randomUUID) return `panel-${crypto.randomUUID()}`;
  const b = new Uint8Array(16);
  crypto.getRandomValues(b);
  return "panel-" + Array.from(b, (x) => x.toString(16).padStart(2, "0")).join("");
}

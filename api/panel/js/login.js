// The login page: POST /api/v1/session with the token; the server answers with the
// session cookie (HttpOnly) and the panel opens.

const form = document.getElementById("login-form");
const message = document.getElementById("login-message");
const input = document.getElementById("token");

async function alreadyLoggedIn() {
  const r = await fetch("/api/v1/session", { credentials: "same-origin", cache: "no-store" });
  if (r.ok) location.replace("/panel/");
}

form.addEventListener("submit", async (ev) => {
  ev.preventDefault();
  message.textContent = "Checking ...";
  message.className = "message";
  try {
    const r = await fetch("/api/v1/session", {
      method: "POST",
      credentials: "same-origin",
      headers: { "Content-Type": "application/json", Accept: "application/json" },
      body: JSON.stringify({ token: input.value.trim() }),
    });
    if (r.ok) {
      location.replace("/panel/");
      return;
    }
    const body = await r.json().catch(() => ({}));
    message.textContent = r.status === 401
      ? "This token is not valid (mistyped, unknown or revoked). Scan or paste it again."
      : `Login refused: ${body.detail || "HTTP " + r.status}`;
  } catch (err) {
    message.textContent = `The station does not answer: ${err.message}`;
  }
  message.className = "message error";
  input.select();
});

alreadyLoggedIn().catch(() => {});

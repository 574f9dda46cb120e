"""Browser sessions of the operator panel: a random id in an HttpOnly cookie, kept
server-side with a synchronizer CSRF token.

An operator logs in with an API token (``station token create --role operator
--name "A. Operator"``; a badge scanner can type it). The server then keeps a
session in memory:

* the cookie ``station_session`` carries 256 random bits (``secrets``), HttpOnly (no
  script reads it), ``SameSite=Strict`` (no other site's page sends it), ``Secure``
  when the panel is served over https, ``Path=/``; the server keeps only its SHA-256,
  so a memory dump of the table gives no usable cookie;
* every session has its own CSRF token (the synchronizer token pattern): the panel
  reads it from ``GET /api/v1/session`` (a same-origin read; no CORS is configured,
  so another site cannot read it) and sends it as ``X-CSRF-Token`` with every
  request that changes something; :func:`api.auth.authenticate` refuses a cookie
  write without it (403);
* a session ends after ``IDLE_S`` without a request, after ``ABSOLUTE_S`` in any
  case (a shift), at logout, when the server restarts (log in again), within
  ``RECHECK_S`` of its API token being revoked, and when its API token expires (at
  the token's ``expires_at``; within ``RECHECK_S`` when a rotation brings that
  forward).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
import time
from dataclasses import dataclass, field

SESSION_COOKIE = "station_session"
CSRF_HEADER = "X-CSRF-Token"
#: a session ends after this long without a request (the panel polls while open)
IDLE_S = 30 * 60.0
#: ... and this long after login whatever happens (about a shift)
ABSOLUTE_S = 12 * 3600.0
#: how often a session's API token is checked for revocation
RECHECK_S = 30.0
#: most sessions kept at once; the oldest go first
MAX_SESSIONS = 1000


def _key(session_id: str) -> str:
    return hashlib.sha256(session_id.encode()).hexdigest()


@dataclass
class BrowserSession:
    principal: object  # api.auth.Principal
    csrf_token: str
    created: float = field(default_factory=time.time)
    last_seen: float = field(default_factory=time.monotonic)
    checked: float = field(default_factory=time.monotonic)

    @property
    def token_expires(self) -> float | None:
        """Wall time (epoch s) when the session's API token ends (None: never)."""
        end = getattr(self.principal, "expires_at", None)
        return None if end is None else end.timestamp()

    @property
    def expires_at(self) -> float:
        """Wall time (epoch s) when the session ends at the latest: a shift after
        login, or its token's end if that comes first."""
        end = self.created + ABSOLUTE_S
        token_end = self.token_expires
        return end if token_end is None else min(end, token_end)

    def token_expired(self, wall: float | None = None) -> bool:
        end = self.token_expires
        return end is not None and (time.time() if wall is None else wall) >= end

    def csrf_ok(self, sent: str | None) -> bool:
        return bool(sent) and hmac.compare_digest(sent.encode(), self.csrf_token.encode())


class SessionStore:
    """The server's sessions by the hash of their cookie (thread-safe: routes run in
    the event loop, the bench and tests may call from threads)."""

    def __init__(self, idle_s: float = IDLE_S, absolute_s: float = ABSOLUTE_S):
        self.idle_s, self.absolute_s = idle_s, absolute_s
        self._sessions: dict[str, BrowserSession] = {}
        self._lock = threading.Lock()

    def create(self, principal) -> tuple[str, BrowserSession]:
        """A new session; returns the cookie value (never stored) and the session."""
        session_id = secrets.token_urlsafe(32)
        sess = BrowserSession(principal, secrets.token_urlsafe(32))
        with self._lock:
            self._expire()
            while len(self._sessions) >= MAX_SESSIONS:
                oldest = min(self._sessions, key=lambda k: self._sessions[k].last_seen)
                del self._sessions[oldest]
            self._sessions[_key(session_id)] = sess
        return session_id, sess

    def get(self, session_id: str | None) -> BrowserSession | None:
        """The live session of a cookie value (and it counts as activity), or None."""
        if not session_id:
            return None
        now = time.monotonic()
        with self._lock:
            sess = self._sessions.get(_key(session_id))
            if sess is None:
                return None
            if now - sess.last_seen > self.idle_s or time.time() - sess.created > self.absolute_s:
                del self._sessions[_key(session_id)]
                return None
            sess.last_seen = now
            return sess

    def drop(self, session_id: str | None) -> bool:
        if not session_id:
            return False
        with self._lock:
            return self._sessions.pop(_key(session_id), None) is not None

    def drop_token(self, token_id: int) -> None:
        """End every session opened with this API token (it was revoked)."""
        with self._lock:
            for k in [k for k, s in self._sessions.items() if s.principal.token_id == token_id]:
                del self._sessions[k]

    def _expire(self) -> None:
        now, wall = time.monotonic(), time.time()
        for k in [k for k, s in self._sessions.items()
                  if now - s.last_seen > self.idle_s or wall - s.created > self.absolute_s
                  or s.token_expired(wall)]:
            del self._sessions[k]

    def __len__(self) -> int:
        return len(self._sessions)


def read_token(store, token_id: int):
    """The API token ``token_id``'s stored record (revocation, expiry), or None."""
    from station.store.tokens import TokenRepository

    return TokenRepository(store).get(token_id)


def token_is_active(store, token_id: int) -> bool:
    """True while the API token ``token_id`` exists, is not revoked and has not expired."""
    record = read_token(store, token_id)
    return record is not None and record.active()

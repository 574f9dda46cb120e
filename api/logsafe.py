"""Secrets stay out of the logs.

The API takes its credentials only from headers (``Authorization``) and the panel's
cookie, which no log line carries; uvicorn's access log, though, writes every
request's path *with its query string*, so a client that puts a token into the URL by
mistake (``?token=...``, ``?access_token=...``) would leave it in the journal. The
filter here rewrites the access log's request target before it is written: values of
query parameters whose name says secret (token, key, secret, password, session, csrf,
auth) become ``<redacted>``, and anything shaped like an API token
(``st_<prefix>_<secret>``) anywhere in the target keeps only its public prefix. The
request itself is untouched (and such a token is refused anyway: 401).
"""

from __future__ import annotations

import logging
import re
from urllib.parse import unquote_plus

#: query parameter names whose values are secrets
SENSITIVE_NAME = re.compile(r"token|secret|passw|pwd|key|session|csrf|auth|cookie", re.IGNORECASE)
#: an API token's text (station/store/tokens.py): the prefix is public, the rest is not
TOKEN_TEXT = re.compile(r"(st_[0-9a-f]{16}_)[A-Za-z0-9_\-]+")
REDACTED = "<redacted>"


def redact_target(target: str) -> str:
    """A request target (path and query) fit for a log line."""
    path, sep, query = target.partition("?")
    path = TOKEN_TEXT.sub(r"\1" + REDACTED, path)
    if not sep:
        return path
    items = []
    for item in query.split("&"):
        name, eq, value = item.partition("=")
        if eq and SENSITIVE_NAME.search(unquote_plus(name)):
            value = REDACTED
        items.append(TOKEN_TEXT.sub(r"\1" + REDACTED, name + eq + value))
    return path + "?" + "&".join(items)


class RedactAccessLog(logging.Filter):
    """On ``uvicorn.access``: its records carry (client, method, target, http version,
    status) as arguments; the target is redacted."""

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        if isinstance(args, tuple) and len(args) == 5 and isinstance(args[2], str):
            record.args = (args[0], args[1], redact_target(args[2]), args[3], args[4])
        return True


def install() -> None:
    """Put the filter on uvicorn's access logger (once per process)."""
    logger = logging.getLogger("uvicorn.access")
    if not any(isinstance(f, RedactAccessLog) for f in logger.filters):
        logger.addFilter(RedactAccessLog())

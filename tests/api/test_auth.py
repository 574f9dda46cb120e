"""API tokens: revocation takes effect within a second; tokens are stored as salted hashes.

Who may call which endpoint (every route against every role, no token, bad tokens
and panel sessions with and without their CSRF token) is tested in
test_access_matrix.py; the rest of the security properties in test_security.py.
"""

from __future__ import annotations


def _status(api, token: str) -> int:
    with api.client(None) as c:
        return c.get("/api/v1/station", headers={"Authorization": f"Bearer {token}"}).status_code


def test_a_revoked_token_is_refused(api):
    from station.store.tokens import TokenRepository

    repo = TokenRepository(api.runtime.store)
    record, token = repo.create("operator", name="short-lived")
    assert _status(api, token) == 200
    repo.revoke(record.id)
    assert _status(api, token) == 401


def test_a_token_revoked_while_in_use_is_refused_within_the_check_interval(api):
    import time

    from api.auth import REVOCATION_CHECK_S
    from station.store.tokens import TokenRepository

    repo = TokenRepository(api.runtime.store)
    record, token = repo.create("operator", name="polling client")
    assert [_status(api, token) for _ in range(3)] == [200, 200, 200]  # verified, then kept
    revoked = time.monotonic()
    repo.revoke(record.id)  # as `station token revoke` does, behind the API's back
    while _status(api, token) != 401:
        assert time.monotonic() - revoked < REVOCATION_CHECK_S + 1.0, "the revoked token is still accepted"
        time.sleep(0.05)
    assert _status(api, token) == 401  # and stays refused


def test_tokens_are_stored_hashed(api):
    from tests.dbtools import rows as db_rows

    rows = db_rows(api.data_dir, "SELECT salt, token_hash, prefix FROM api_token")
    assert rows
    dump = repr(rows)
    for token in api.tokens.values():
        secret = token[len("st_") + 16 + 1:]  # the part after the public prefix
        assert token not in dump and secret not in dump
    assert len({salt for salt, _h, _p in rows}) == len(rows)  # a salt per token

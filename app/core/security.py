"""Tokens kept like passwords, and short-lived signed links.

- An API token is stored only as HMAC-SHA256(server key, token): the tokens table and every
  row's owner column hold that hash, so a copy of the database gives no usable token. Fixed
  tokens (TRYON_TOKENS) are compared in constant time.
- A job's results and viewer, and an uploaded garment's pictures, are opened with a link key,
  `<expiry>.<signature>` of "job:<id>" or "garment:<id>", valid for TRYON_LINK_SECONDS: links the
  page can put in <img src> and an iframe, never the API token.
- The server key is TRYON_SECRET, else a random key kept in DATA/secret.key (0600) so that
  tokens outlive a restart.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import time
from pathlib import Path


def load_key(secret: str | None, data_dir: Path) -> bytes:
    if secret:
        return secret.encode()
    path = Path(data_dir) / "secret.key"
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return path.read_bytes().strip()
    with os.fdopen(fd, "w") as f:
        f.write(secrets.token_hex(32))
    return path.read_bytes().strip()


class Keys:
    def __init__(self, key: bytes, fixed_tokens: list[str], link_seconds: float):
        self.key, self.link_seconds = key, link_seconds
        self.fixed = [t.encode() for t in fixed_tokens]

    def token_hash(self, token: str) -> str:
        return hmac.new(self.key, b"token:" + token.encode(), hashlib.sha256).hexdigest()

    def is_fixed(self, token: str) -> bool:
        t = token.encode()
        return any([hmac.compare_digest(t, f) for f in self.fixed])  # every one compared: no early exit

    def _sign(self, subject: str, expiry: int) -> str:
        return hmac.new(self.key, f"{subject}:{expiry}".encode(), hashlib.sha256).hexdigest()[:32]

    def link_key(self, rid: str, kind: str = "job") -> str:
        """A key that opens job `rid`'s results and viewer (kind "garment": an uploaded garment's
        pictures) until it expires."""
        expiry = int(time.time() + self.link_seconds)
        return f"{expiry}.{self._sign(f'{kind}:{rid}', expiry)}"

    def opens(self, key: str | None, rid: str, kind: str = "job") -> bool:
        expiry, _, sig = (key or "").partition(".")
        if not expiry.isdigit() or int(expiry) < time.time():
            return False
        return hmac.compare_digest(sig, self._sign(f"{kind}:{rid}", int(expiry)))


class RateLimit:
    """At most `per_minute` events per client address in any 60 s (kept in memory)."""

    def __init__(self, per_minute: int):
        import threading
        from collections import deque

        self.per_minute, self._new, self._lock = per_minute, deque, threading.Lock()
        self._seen: dict[str, object] = {}

    def allow(self, addr: str) -> bool:
        now = time.monotonic()
        with self._lock:
            if len(self._seen) > 100_000:  # forget idle addresses rather than grow without bound
                self._seen = {a: q for a, q in self._seen.items() if q and now - q[-1] < 60}
            q = self._seen.setdefault(addr, self._new())
            while q and now - q[0] >= 60:
                q.popleft()
            if len(q) >= self.per_minute:
                return False
            q.append(now)
            return True

"""A small load test: 50 concurrent clients create and poll try-ons against the service on
loopback (uvicorn, one worker), for a bounded time; no job may be lost. Prints p95 latency."""

from __future__ import annotations

import threading
import time

import httpx
import numpy as np
import pytest

from tests.test_page import server  # noqa: F401  (the uvicorn fixture)

CLIENTS = 50
DURATION = 45.0  # s of load, then everything left is cancelled


@pytest.fixture()
def server_env() -> dict[str, str]:
    # (fifty clients on one address: the default 10 tokens a minute per address left 40 of them
    # without a token, their threads dying unseen)
    return {"TRYON_TOKENS_PER_MINUTE": str(2 * CLIENTS)}


@pytest.mark.slow
def test_fifty_clients(server):  # noqa: F811
    url = server
    lat, lock = [], threading.Lock()
    accepted, refused, errors, started = [], [0], [], []
    t_end = time.time() + DURATION

    def call(c, method, path, **kw):
        t = time.perf_counter()
        r = c.request(method, path, **kw)
        with lock:
            lat.append(time.perf_counter() - t)
        return r

    def client(i):
        with httpx.Client(base_url=url, timeout=30) as c:
            r = call(c, "POST", "/api/tokens")
            if r.status_code != 201:
                errors.append((r.status_code, r.text))
                return
            h = {"Authorization": f"Bearer {r.json()['token']}"}
            with lock:
                started.append(i)
            jid = None
            while time.time() < t_end and jid is None:
                r = call(c, "POST", "/api/tryons", headers=h,
                         json={"body": "default:female", "garment": "skirt", "resolution_cm": 4})
                if r.status_code == 202:
                    jid = r.json()["id"]
                    with lock:
                        accepted.append((jid, h))
                elif r.status_code == 429:
                    with lock:
                        refused[0] += 1
                    time.sleep(min(2.0, float(r.headers.get("Retry-After", 1))))
                else:
                    errors.append((r.status_code, r.text))
                    return
            while jid and time.time() < t_end:
                s = call(c, "GET", f"/api/tryons/{jid}", headers=h).json()["status"]
                if s in ("done", "failed", "cancelled"):
                    return
                time.sleep(0.5)

    threads = [threading.Thread(target=client, args=(i,)) for i in range(CLIENTS)]
    t0 = time.time()
    for t in threads:
        t.start()
    for t in threads:
        t.join(DURATION + 60)
    assert not any(t.is_alive() for t in threads)
    assert errors == [], errors[:3]
    assert len(started) == CLIENTS, len(started)
    # every accepted job still exists, in a proper state; cancel what is left and see it stop
    lost, final = 0, {}
    with httpx.Client(base_url=url, timeout=30) as c:
        for jid, h in accepted:
            r = c.get(f"/api/tryons/{jid}", headers=h)
            if r.status_code != 200 or r.json()["status"] not in ("queued", "running", "done", "failed", "cancelled"):
                lost += 1
                continue
            if r.json()["status"] in ("queued", "running"):
                c.post(f"/api/tryons/{jid}/cancel", headers=h)
        deadline = time.time() + 30
        for jid, h in accepted:
            while True:
                s = c.get(f"/api/tryons/{jid}", headers=h).json()["status"]
                if s in ("done", "failed", "cancelled") or time.time() > deadline:
                    break
                time.sleep(0.3)
            final[s] = final.get(s, 0) + 1
    p95 = float(np.percentile(lat, 95)) * 1000
    print(f"\nload: {CLIENTS} clients, {time.time() - t0:.0f} s; {len(lat)} requests, p95 latency {p95:.0f} ms, "
          f"max {max(lat) * 1000:.0f} ms; accepted {len(accepted)}, 429 {refused[0]}; final {final}; lost {lost}")
    assert lost == 0
    assert final.get("done", 0) >= 1 and set(final) <= {"done", "cancelled"}, final
    assert p95 < 2000, p95

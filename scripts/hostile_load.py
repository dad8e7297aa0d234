"""The service under hostile load (issue 50), measured: a real service (uvicorn, one worker) while
attackers send node-cycle GLBs, an 8,000-edge pattern, a zip bomb, oversized bodies and 50
try-ons from one token, and an ordinary client keeps asking for its try-ons, the catalogue and a
default body. Prints the ordinary client's latency (p50/p95/max), every status code seen, and the
peak memory of the service's processes.

    .venv/bin/python scripts/hostile_load.py [--seconds 40]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from collections import Counter
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cycle_glb() -> bytes:
    from tests.fuzz.mutate import _glb, _glb_split
    from tests.test_gltf_anim import _skinned_bar

    doc, binary = _glb_split(_skinned_bar()[0])
    doc["nodes"][1]["children"] = [0]
    return _glb(doc, binary)


def _big_pattern(n: int = 8000) -> bytes:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 30 + 2 * np.sin(40 * a)
    verts = np.c_[r * np.cos(a), r * np.sin(a)].round(4).tolist()
    panel = {"vertices": verts, "edges": [{"endpoints": [i, (i + 1) % n]} for i in range(n)]}
    return json.dumps({"pattern": {"panels": {"p": panel}, "stitches": []}, "properties": {"units_in_meter": 100}}).encode()


def _zip_bomb(gib: float = 2.0) -> bytes:
    """A zip whose one member inflates to `gib` GiB of zeros (~2 MB compressed)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as z:
        with z.open("frame_000.obj", "w", force_zip64=True) as m:
            block = b"\0" * (64 << 20)
            for _ in range(int(gib * 16)):
                m.write(block)
        z.writestr("frame_001.obj", b"v 0 0 0\n")
    return buf.getvalue()


def _oversized(port: int, path: str, headers: dict, total: int, declared: bool) -> str:
    """Send a `total`-byte body, with its Content-Length or chunked, until the service answers;
    the status and how much was sent by then."""
    head = "".join(f"{k}: {v}\r\n" for k, v in headers.items())
    head += f"Content-Length: {total}\r\n" if declared else "Transfer-Encoding: chunked\r\n"
    s = socket.create_connection(("127.0.0.1", port), timeout=60)
    s.sendall(f"POST {path} HTTP/1.1\r\nHost: x\r\n{head}\r\n".encode())
    sent, block = 0, b"0," * (1 << 19)
    s.setblocking(False)
    answer = b""
    while sent < total:
        try:
            answer += s.recv(4096)
            if answer:
                break
        except BlockingIOError:
            pass
        try:
            sent += s.send(block if declared else b"%x\r\n%s\r\n" % (len(block), block))
        except (BlockingIOError, OSError):
            time.sleep(0.001)
    s.setblocking(True)
    while b"\r\n" not in answer:
        answer += s.recv(4096) or b"\r\n"
    s.close()
    return f"{answer.split()[1].decode()} after {sent >> 20} MB sent"


def _rss_mb(pid: int) -> float:
    """Resident memory of `pid` and its descendants (workers, fenced readers), MB."""
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        try:
            with open(f"/proc/{p}/status") as f:
                total += next(int(ln.split()[1]) for ln in f if ln.startswith("VmRSS:"))
            todo += [int(c) for t in os.listdir(f"/proc/{p}/task")
                     for c in open(f"/proc/{p}/task/{t}/children").read().split()]
        except (OSError, StopIteration):
            pass
    return total / 1024


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=40.0, help="how long the ordinary client keeps asking")
    ap.add_argument("--no-attack", action="store_true", help="the ordinary client alone (the baseline)")
    a = ap.parse_args()
    print("preparing the hostile inputs (the zip bomb takes a few seconds)...", flush=True)
    glb, pattern, bomb = _cycle_glb(), _big_pattern(), _zip_bomb()
    print(f"  node-cycle GLB {len(glb)} B, 8,000-edge pattern {len(pattern) >> 10} KB, zip bomb {len(bomb) >> 20} MB "
          "-> 2 GiB", flush=True)
    data = Path(tempfile.mkdtemp(prefix="tryon-hostile-"))
    port = _port()
    env = {**os.environ, "TRYON_DATA": str(data)}
    svc = subprocess.Popen([sys.executable, "-m", "uvicorn", "--factory", "app.main:create_app", "--port", str(port),
                            "--log-level", "warning"], cwd=ROOT, env=env)
    url = f"http://127.0.0.1:{port}"
    statuses, lat, peak, stop = Counter(), [], [0.0], threading.Event()
    try:
        for _ in range(300):
            try:
                httpx.get(url + "/api/garments", timeout=2)
                break
            except httpx.HTTPError:
                time.sleep(0.2)
        tok = lambda: {"Authorization": "Bearer " + httpx.post(url + "/api/tokens").json()["token"]}  # noqa: E731
        good, bad, other = tok(), tok(), [tok() for _ in range(4)]

        def hit(kind, method, path, headers, **kw):
            try:
                r = httpx.request(method, url + path, headers=headers, timeout=120, **kw)
                statuses[(kind, r.status_code)] += 1
            except httpx.HTTPError as e:
                statuses[(kind, type(e).__name__)] += 1

        def ordinary():
            k = 0
            while not stop.is_set():
                path, method, kw = [("/api/tryons", "GET", {}), ("/api/garments", "GET", {}),
                                    ("/api/bodies/default", "POST", {"json": {"preset": "male"}})][k % 3]
                t0 = time.perf_counter()
                r = httpx.request(method, url + path, headers=good, timeout=60, **kw)
                lat.append(time.perf_counter() - t0)
                statuses[("ordinary", r.status_code)] += 1
                k += 1
                time.sleep(0.05)

        def sampler():
            while not stop.is_set():
                peak[0] = max(peak[0], _rss_mb(svc.pid))
                time.sleep(0.2)

        attacks = [
            *[lambda: hit("node-cycle glb", "POST", "/api/bodies", bad, files={"file": ("w.glb", glb)})
              for _ in range(40)],
            lambda: hit("8000-edge pattern", "POST", "/api/garments", other[0], files={"file": ("p.json", pattern)}),
            lambda: hit("zip bomb", "POST", "/api/bodies", other[1], files={"file": ("w.zip", bomb)}),
            lambda: statuses.update({("300 MB upload", _oversized(port, "/api/bodies", {
                **other[2], "Content-Type": "multipart/form-data; boundary=x"}, 300 << 20, True)): 1}),
            lambda: statuses.update({("200 MB JSON, chunked", _oversized(port, "/api/tryons", {
                **other[3], "Content-Type": "application/json"}, 200 << 20, False)): 1}),
            *[lambda: hit("50 try-ons, one token", "POST", "/api/tryons", bad,
                          json={"body": "default:female", "garment": "skirt", "resolution_cm": 4}) for _ in range(50)],
        ]
        threads = [threading.Thread(target=f, daemon=True) for f in (ordinary, sampler)]
        for t in threads:
            t.start()
        time.sleep(2.0)  # the ordinary client's quiet baseline first
        workers = [threading.Thread(target=f, daemon=True) for f in ([] if a.no_attack else attacks)]
        for t in workers:
            t.start()
            time.sleep(0.02)
        t_end = time.time() + a.seconds
        while time.time() < t_end:
            time.sleep(0.5)
        hit("other token's try-on", "POST", "/api/tryons", good, json={"body": "default:male", "garment": "skirt"})
        stop.set()
        for t in workers:
            t.join(60)
    finally:
        svc.terminate()
        svc.wait(30)
    ms = np.array(lat) * 1000
    print(f"\nordinary client: {len(ms)} requests, p50 {np.percentile(ms, 50):.1f} ms, p95 {np.percentile(ms, 95):.1f} ms, "
          f"max {ms.max():.1f} ms")
    print(f"service processes' peak memory (API + workers + readers): {peak[0]:.0f} MB")
    print("status codes:")
    for (kind, code), n in sorted(statuses.items(), key=lambda kv: (kv[0][0], str(kv[0][1]))):
        print(f"  {kind:24s} {code!s:>6s} x {n}")
    fives = sum(n for (_, c), n in statuses.items() if isinstance(c, int) and c >= 500)
    print(f"5xx: {fives}")
    return 1 if fives else 0


if __name__ == "__main__":
    sys.exit(main())

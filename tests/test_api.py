"""The REST API (httpx through FastAPI's TestClient, a real SQLite file, real spawned workers)."""

from __future__ import annotations

import os
import time

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.core.config import Settings
from tests.samples import SAMPLE_BODY, SAMPLE_SKIRT, write_anim_zip, write_arms_lowered_scan

pytestmark = pytest.mark.integration  # (dresses, walks, or runs the service)


def _settings(tmp_path, **kw):
    return Settings(data_dir=tmp_path / "data", **kw)


@pytest.fixture()
def idle(tmp_path):
    """An app whose workers are not started: jobs stay queued (API-only tests)."""
    with TestClient(create_app(_settings(tmp_path, queue_max=3), start_workers=False)) as c:
        yield c


def token(c) -> dict:
    r = c.post("/api/tokens")
    assert r.status_code == 201
    return {"Authorization": f"Bearer {r.json()['token']}"}


def wait(c, h, jid, states=("done", "failed", "cancelled"), timeout=240):
    t0 = time.time()
    while time.time() - t0 < timeout:
        j = c.get(f"/api/tryons/{jid}", headers=h).json()
        if j["status"] in states:
            return j
        time.sleep(0.5)
    raise AssertionError(f"job {jid} still {j['status']} after {timeout} s: {j}")


def test_token_required(idle):
    r = idle.get("/api/bodies")
    assert r.status_code == 401 and "token" in r.json()["error"]
    r = idle.get("/api/bodies", headers={"Authorization": "Bearer nope"})
    assert r.status_code == 401


def test_default_body_and_errors(idle):
    h = token(idle)
    r = idle.post("/api/bodies/default", json={"preset": "female", "height": 1.72}, headers=h)
    assert r.status_code == 201 and r.json()["info"]["spec"] == "default:female,height=1.72"
    bid = r.json()["id"]
    assert idle.get(f"/api/bodies/{bid}", headers=h).status_code == 200
    r = idle.post("/api/bodies/default", json={"preset": "female", "height": 172}, headers=h)
    assert r.status_code == 422 and "centimetres" in r.json()["error"]
    r = idle.post("/api/bodies/default", json={"preset": "child"}, headers=h)
    assert r.status_code == 422 and "preset" in r.json()["error"]
    assert idle.delete(f"/api/bodies/{bid}", headers=h).status_code == 204
    assert idle.get(f"/api/bodies/{bid}", headers=h).status_code == 404


def test_upload_body_and_pattern(idle):
    h = token(idle)
    with open(SAMPLE_BODY, "rb") as f:
        r = idle.post("/api/bodies", files={"file": ("../../etc/passwd.obj", f)}, headers=h)
    assert r.status_code == 201, r.text
    b = r.json()
    assert 1.6 < b["info"]["height_m"] < 1.7
    stored = list((idle.app.state.settings.data_dir / "uploads").iterdir())
    assert [p.name for p in stored] == [f"body-{b['id']}.obj"]  # our name, not the client's path
    r = idle.post("/api/bodies", files={"file": ("x.obj", b"v 0 0 0\nnot a mesh")}, headers=h)
    assert r.status_code == 400 and "x.obj" in r.json()["error"]
    r = idle.post("/api/bodies", files={"file": ("x.exe", b"MZ")}, headers=h)
    assert r.status_code == 400 and ".obj" in r.json()["error"]
    with open(SAMPLE_SKIRT, "rb") as f:
        r = idle.post("/api/garments", files={"file": ("skirt.json", f)}, headers=h)
    assert r.status_code == 201 and r.json()["info"]["panels"] >= 2
    r = idle.post("/api/garments", files={"file": ("bad.json", b"{nope")}, headers=h)
    assert r.status_code == 400 and "JSON" in r.json()["error"]
    r = idle.post("/api/garments", files={"file": ("pieces.dxf", b"0\nSECTION\n")}, headers=h)
    assert r.status_code == 400 and "pieces.dxf" in r.json()["error"], r.text
    g = idle.get("/api/garments", headers=h).json()
    assert "dress" in [x["name"] for x in g["catalogue"]] and "M" in g["sizes"] and "silk" in g["fabrics"]
    assert g["sizes"][-1] == "auto"  # the smallest size that covers the body's girths
    assert len(g["uploaded"]) == 1


def test_upload_a_dxf_pattern_with_its_assembly(idle, tmp_path):
    """A DXF cutting pattern and its assembly file (stitches, placement): stored as uploaded, the
    assembly saying how it is sewn; its picture shows the pieces. A DXF whose pieces make no
    garment the inference knows, alone: 400 asking for its assembly. A damaged DXF or a bad
    assembly: a clear 400 naming the client's file; nothing is kept of a refused upload."""
    import json

    from engine.pattern.dxf import assembly_of, write_dxf
    from engine.pattern.io import load_pattern

    h = token(idle)
    spec = load_pattern(SAMPLE_SKIRT)
    write_dxf(spec, tmp_path / "skirt.dxf")
    asm = json.dumps(assembly_of(spec)).encode()
    dxf = (tmp_path / "skirt.dxf").read_bytes()
    r = idle.post("/api/garments", files={"file": ("My Skirt.dxf", dxf), "assembly": ("skirt-assembly.json", asm)},
                  headers=h)
    assert r.status_code == 201, r.text
    g = r.json()
    assert g["name"] == "My Skirt" and g["info"]["from"] == "dxf" and g["info"]["assembly"] == "yours"
    assert g["info"]["panels"] == len(spec.pattern.panels) and g["info"]["sizes"] == ["one size"]
    uploads = idle.app.state.settings.data_dir / "uploads"
    folder = uploads / f"garment-{g['id']}"
    assert [p.name for p in uploads.iterdir()] == [folder.name]
    assert (folder / "assembly.json").read_bytes() == asm and (folder / "pattern.dxf").read_bytes() == dxf
    assert idle.get(g["links"]["pattern_svg"]).text.startswith("<svg")
    assert idle.get(g["links"]["assembly"], headers=h).json()["stitches"] == json.loads(asm)["stitches"]
    bid = idle.post("/api/bodies/default", json={"preset": "female"}, headers=h).json()["id"]
    r = idle.post("/api/tryons", json={"body_id": bid, "garment": g["id"]}, headers=h)
    assert r.status_code == 202, r.text
    assert r.json()["request"]["garment"]["dxf"]["assembly"] == str(folder / "assembly.json")

    r = idle.post("/api/garments", files={"file": ("skirt.dxf", dxf)}, headers=h)
    assert r.status_code == 400 and "upload its assembly file" in r.json()["error"], r.text
    r = idle.post("/api/garments", files={"file": ("broken.dxf", b"0\nSECTION\n2\nENTITIES\n"),
                                          "assembly": ("a.json", asm)}, headers=h)
    assert r.status_code == 400 and "broken.dxf" in r.json()["error"] and "pattern.dxf" not in r.json()["error"], r.text
    r = idle.post("/api/garments", files={"file": ("skirt.dxf", dxf), "assembly": ("a.json", b'{"stitches": 3}')},
                  headers=h)
    assert r.status_code == 400 and "a.json" in r.json()["error"] and "invalid assembly" in r.json()["error"], r.text
    r = idle.post("/api/garments", files={"file": ("skirt.json", SAMPLE_SKIRT.read_bytes()),
                                          "assembly": ("a.json", asm)}, headers=h)
    assert r.status_code == 400 and "DXF" in r.json()["error"], r.text
    assert [p.name for p in uploads.iterdir()] == [folder.name]  # nothing left of the refused
    assert idle.delete(f"/api/garments/{g['id']}", headers=h).status_code == 204
    assert list(uploads.iterdir()) == []


def test_a_dxf_alone_gives_its_sizes_seams_and_pictures(idle):
    """A shop's DXF alone (leggings graded in 14 sizes, no assembly): its sizes in the file's
    order, pieces, the garment inferred and what the inference is unsure of, the fabric its
    pieces suggest, a signed link to the seam picture of any of its sizes (drawn in the fence
    when first asked for); a try-on takes its own size names or auto, and nothing else."""
    from tests.samples import DXF_SAMPLES

    h = token(idle)
    dxf = (DXF_SAMPLES / "ORILEGWB_AAMA.DXF").read_bytes()
    r = idle.post("/api/garments", files={"file": ("Leggings.DXF", dxf)}, headers=h)
    assert r.status_code == 201, r.text
    g = r.json()
    i = g["info"]
    assert i["sizes"] == [str(k) for k in range(26, 54, 2)] and i["size"] == "36" and i["units"] == "mm"
    assert [p["name"] for p in i["pieces"]] == ["ORILEG WB WB", "ORILEG WB LL"]
    assert i["garment"]["kind"] == "bottom" and i["garment"]["panels"] == ["leg_l", "leg_r", "waistband"]
    assert {"front rise", "back rise", "inseam (left)"} <= set(i["garment"]["seams"])
    assert i["garment"]["unsure"] == [] and i["assembly"] == "inferred"
    assert i["fabric"]["name"] == "stretch_knit" and "foot" in i["fabric"]["why"]
    assert idle.get(f"/api/garments/{g['id']}", headers=h).json()["info"] == i
    svg = idle.get(g["links"]["pattern_svg"])  # the link opens it without the token (an <img src>)
    assert svg.status_code == 200 and svg.headers["content-type"].startswith("image/svg+xml")
    assert "default-src 'none'" in svg.headers["content-security-policy"]
    root = svg.text
    assert "size 36 of 26, 28" in root and "front rise" in root and "Leggings.DXF" in root
    big = idle.get(g["links"]["pattern_svg"] + "&size=52")
    assert big.status_code == 200 and "size 52 of" in big.text
    r = idle.get(g["links"]["pattern_svg"] + "&size=99")
    assert r.status_code == 404 and "26, 28, 30" in r.json()["error"]
    assert idle.get(f"/api/garments/{g['id']}/pattern.svg").status_code == 401  # no key, no token
    assert idle.get(g["links"]["pattern_svg"].replace(g["id"], "0" * 16)).status_code == 401  # another's key
    other = token(idle)
    assert idle.get(f"/api/garments/{g['id']}/pattern.svg", headers=other).status_code == 404
    asm = idle.get(g["links"]["assembly"], headers=h).json()  # the inferred assembly, to correct
    assert set(asm["panels"]) == {"leg_l", "leg_r", "waistband"} and asm["tryon"]["fabric"] == "stretch_knit"

    bid = idle.post("/api/bodies/default", json={"preset": "female"}, headers=h).json()["id"]
    for size, want in (("40", "40"), ("auto", "auto"), ("AUTO", "auto"), (None, None)):
        r = idle.post("/api/tryons", json={"body_id": bid, "garment": g["id"], "size": size}, headers=h)
        assert r.status_code == 202 and r.json()["request"]["size"] == want, r.text
        idle.delete(f"/api/tryons/{r.json()['id']}", headers=h)
    r = idle.post("/api/tryons", json={"body_id": bid, "garment": g["id"], "size": "M"}, headers=h)
    assert r.status_code == 422 and "sizes are 26, 28" in r.json()["error"]
    r = idle.post("/api/tryons", json={"body_id": bid, "garment": g["id"], "assembly": "/etc/passwd"}, headers=h)
    assert r.status_code == 422 and "upload them with it" in r.json()["error"]


def test_upload_says_what_the_loader_and_the_measurements_found(idle, tmp_path):
    """A scan's notes come back with the upload: the loader's (units, axes) and the
    measurements' (arms held too close to the torso for tops), before anything is dressed."""
    h = token(idle)
    scan = write_arms_lowered_scan(tmp_path / "arms down.obj", 20.0)
    with open(scan, "rb") as f:
        r = idle.post("/api/bodies", files={"file": ("arms down.obj", f)}, headers=h)
    assert r.status_code == 201, r.text
    notes = r.json()["info"]["notes"]
    assert any(n.startswith("units: metres") for n in notes), notes
    assert any(n.startswith("the arms hang 5.4 cm from the torso") for n in notes), notes
    with open(SAMPLE_BODY, "rb") as f:  # its arms are 11.2 cm away: nothing to say about them
        notes = idle.post("/api/bodies", files={"file": ("me.obj", f)}, headers=h).json()["info"]["notes"]
    assert notes and not any("arms hang" in n for n in notes), notes


def test_upload_size_cap(tmp_path):
    with TestClient(create_app(_settings(tmp_path, max_upload_mb=1000 / 2 ** 20), start_workers=False)) as c:
        h = token(c)
        r = c.post("/api/bodies", files={"file": ("big.obj", b"v 0 0 0\n" * 500)}, headers=h)
        assert r.status_code == 413 and "MB" in r.json()["error"]
        assert not any((c.app.state.settings.data_dir / "uploads").iterdir())


def test_cross_token_access_is_404(idle):
    a, b = token(idle), token(idle)
    bid = idle.post("/api/bodies/default", json={"preset": "male"}, headers=a).json()["id"]
    jid = idle.post("/api/tryons", json={"body_id": bid, "garment": "skirt"}, headers=a).json()["id"]
    for url in (f"/api/bodies/{bid}", f"/api/tryons/{jid}", f"/api/tryons/{jid}/files/front.png"):
        assert idle.get(url, headers=b).status_code == 404, url
    assert idle.delete(f"/api/bodies/{bid}", headers=b).status_code == 404
    assert idle.post(f"/api/tryons/{jid}/cancel", headers=b).status_code == 404
    r = idle.post("/api/tryons", json={"body_id": bid, "garment": "skirt"}, headers=b)
    assert r.status_code == 404  # b cannot use a's body
    assert idle.get("/api/tryons", headers=b).json() == []


def test_tryon_validation(idle):
    h = token(idle)
    for body, words in [({"body": "default:female", "garment": "ballgown"}, "catalogue"),
                        ({"body": "default:female", "garment": "skirt", "size": "XXXL"}, "size"),
                        ({"body": "default:female", "garment": "skirt", "fabric": "tweed"}, "fabric"),
                        ({"garment": "skirt"}, "body"),
                        ({"body": "default:female", "garment": "skirt", "resolution_cm": 0.1}, "resolution"),
                        ({"body": "default:female", "garment": "skirt", "motion": "dance"}, "motion")]:
        r = idle.post("/api/tryons", json=body, headers=h)
        assert r.status_code in (404, 422), (body, r.status_code)
        assert words in r.json()["error"], (body, r.json())


def test_tryon_takes_auto_size(idle):
    """size auto (any case) is queued as such; the worker picks the size from the body."""
    h = token(idle)
    r = idle.post("/api/tryons", json={"body": "default:female", "garment": "dress", "size": "Auto"}, headers=h)
    assert r.status_code == 202, r.json()
    assert idle.get(f"/api/tryons/{r.json()['id']}", headers=h).json()["request"]["size"] == "auto"


def test_queue_full_is_429(idle):
    h = token(idle)
    for _ in range(3):
        assert idle.post("/api/tryons", json={"body": "default:female", "garment": "skirt"}, headers=h).status_code == 202
    r = idle.post("/api/tryons", json={"body": "default:female", "garment": "skirt"}, headers=h)
    assert r.status_code == 429 and int(r.headers["Retry-After"]) > 0


def test_cancel_and_delete_queued(idle):
    h = token(idle)
    jid = idle.post("/api/tryons", json={"body": "default:female", "garment": "skirt"}, headers=h).json()["id"]
    r = idle.post(f"/api/tryons/{jid}/cancel", headers=h)
    assert r.status_code == 202 and r.json()["status"] == "cancelled"
    assert idle.post(f"/api/tryons/{jid}/cancel", headers=h).status_code == 409
    assert idle.delete(f"/api/tryons/{jid}", headers=h).status_code == 204
    assert idle.get(f"/api/tryons/{jid}", headers=h).status_code == 404


def test_tryon_runs_to_the_end(tmp_path):
    """A real worker process dresses the default woman in a coarse skirt; the results download."""
    with TestClient(create_app(_settings(tmp_path))) as c:
        h = token(c)
        r = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt", "resolution_cm": 3},
                   headers=h)
        assert r.status_code == 202
        j = wait(c, h, r.json()["id"])
        assert j["status"] == "done", j
        assert j["report"]["cloth_vertices"] > 500 and j["report"]["penetration_mm"]["max"] <= 3.0
        png = c.get(j["files"]["front.png"], headers=h)
        assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
        glb = c.get(j["files"]["scene.glb"], headers=h)
        assert glb.content[:4] == b"glTF"
        # the skirt as cut for this body (M: the default size), to download
        spec = c.get(j["files"]["pattern.json"], headers=h).json()
        assert set(spec["pattern"]["panels"]) == {"front", "back"} and len(spec["pattern"]["stitches"]) == 4
        assert c.get(j["files"]["pattern.svg"], headers=h).text.startswith("<svg")
        assert c.get(f"/api/tryons/{j['id']}/files/..%2Fjobs.sqlite", headers=h).status_code == 404


def test_a_dxf_alone_is_tried_on_in_another_of_its_sizes(tmp_path):
    """A DXF uploaded alone, a try-on in one of its sizes that is not its default: a real worker
    dresses that size, in the fabric the pattern suggests."""
    from tests.samples import DXF_SAMPLES

    with TestClient(create_app(_settings(tmp_path))) as c:
        h = token(c)
        g = c.post("/api/garments", files={"file": ("Leggings.DXF", (DXF_SAMPLES / "ORILEGWB_AAMA.DXF").read_bytes())},
                   headers=h).json()
        r = c.post("/api/tryons", json={"body": "default:female", "garment": g["id"], "size": "40",
                                        "resolution_cm": 2}, headers=h)
        assert r.status_code == 202, r.text
        j = wait(c, h, r.json()["id"])
        assert j["status"] == "done", j
        rep = j["report"]
        assert rep["garment"] == "Leggings (size 40)" and rep["fabric"] == "stretch_knit", rep["garment"]
        assert rep["settled"] and rep["penetration_mm"]["max"] <= 2.0
        assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.01
        spec = c.get(j["files"]["pattern.json"], headers=h).json()  # the leggings as dressed
        assert list(spec["pattern"]["panels"]) == ["leg_l", "leg_r", "waistband"]


def test_animated_body_upload_moves_as_uploaded(tmp_path):
    """An uploaded animation (a zip of OBJ frames) is a body of its own kind; a walking try-on on
    it is dressed on the first frame and moves with the upload's frames, at the rate given."""
    from engine.body.default import default_body
    from engine.body.motion import WalkParams, walk_track

    body = default_body("female")
    tr = walk_track(body, WalkParams(), fps=15)
    zp = write_anim_zip(tmp_path / "walk.zip", [tr.vertices(i) for i in range(8)], body.faces)
    with TestClient(create_app(_settings(tmp_path))) as c:
        h = token(c)
        with open(zp, "rb") as f:
            r = c.post("/api/bodies", files={"file": ("my walk.zip", f)}, data={"fps": "15"}, headers=h)
        assert r.status_code == 201, r.text
        b = r.json()
        assert b["kind"] == "animation" and b["info"]["frames"] == 8 and b["info"]["fps"] == 15
        r = c.post("/api/bodies", files={"file": ("bad.zip", b"not a zip")}, headers=h)
        assert r.status_code == 400 and "bad.zip" in r.json()["error"]
        with open(zp, "rb") as f:
            r = c.post("/api/bodies", files={"file": ("w.zip", f)}, data={"fps": "0"}, headers=h)
        assert r.status_code == 422 and "fps" in r.json()["error"]
        r = c.post("/api/tryons", json={"body_id": b["id"], "garment": "skirt", "resolution_cm": 3,
                                        "motion": "walk", "seconds": 2.0}, headers=h)
        j = wait(c, h, r.json()["id"])
        assert j["status"] == "done", j
        rep = j["report"]
        assert rep["frames"] == 7 and rep["fps"] == 15  # the upload's 8 frames at its rate, not a 2 s walk
        assert any("animation ends" in line for line in rep["left_out"])
        glb = c.get(j["files"]["anim.glb"], headers=h)
        assert glb.status_code == 200 and glb.content[:4] == b"glTF"
        assert c.delete(f"/api/bodies/{b['id']}", headers=h).status_code == 204
        assert not list((c.app.state.settings.data_dir / "uploads").glob(f"body-{b['id']}*"))


def test_failed_tryon_reports_the_reason(tmp_path):
    with TestClient(create_app(_settings(tmp_path))) as c:
        h = token(c)
        r = c.post("/api/tryons", json={"body": "default:female,weight=1.0", "garment": "skirt", "size": "XS",
                                        "resolution_cm": 3}, headers=h)
        j = wait(c, h, r.json()["id"])
        assert j["status"] == "failed" and "too small" in j["error"], j
        assert "--size auto picks" in j["error"], j  # a heavier body than default:female's M
        assert "files" not in j


def test_worker_crash_fails_only_its_job(tmp_path):
    import os
    import signal

    with TestClient(create_app(_settings(tmp_path))) as c:
        h = token(c)
        first = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt", "resolution_cm": 3},
                       headers=h).json()["id"]
        second = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt", "resolution_cm": 3},
                        headers=h).json()["id"]
        j = wait(c, h, first, states=("running",))
        pid = c.app.state.db.one("SELECT worker_pid FROM jobs WHERE id=?", first)["worker_pid"]
        os.kill(pid, signal.SIGKILL)
        j = wait(c, h, first)
        assert j["status"] == "failed" and "stopped unexpectedly" in j["error"], j
        j2 = wait(c, h, second)  # the replacement worker runs the next one
        assert j2["status"] == "done", j2


def test_restart_requeues_running_and_keeps_queued(tmp_path):
    s = _settings(tmp_path)
    with TestClient(create_app(s)) as c:
        h = token(c)
        first = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt", "resolution_cm": 3},
                       headers=h).json()["id"]
        second = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt", "resolution_cm": 3},
                        headers=h).json()["id"]
        wait(c, h, first, states=("running",))
    # the service stopped (workers killed) while `first` ran and `second` waited
    with TestClient(create_app(s)) as c:
        j = wait(c, h, first)
        assert j["status"] == "done" and j["attempts"] == 2, j
        assert wait(c, h, second)["status"] == "done"


def test_viewer_relay_live_and_recording(tmp_path):
    """While a try-on runs, the viewer websocket at /viewer/{job} reaches the worker's viser
    server through the relay, with viser's subprotocol passed through; once done, the page
    plays the recording. Other tokens get nothing."""
    import viser

    with TestClient(create_app(_settings(tmp_path))) as c:
        h = token(c)
        other = token(c)["Authorization"][7:]
        tok = h["Authorization"][7:]
        jid = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt", "resolution_cm": 3,
                                          "motion": "walk", "seconds": 1.0}, headers=h).json()["id"]
        t0 = time.time()
        while time.time() - t0 < 120:
            j = c.get(f"/api/tryons/{jid}", headers=h).json()
            if j["status"] == "running" and j["viewer"]:
                break
            time.sleep(0.2)
        assert j["viewer"].startswith(f"/viewer/{jid}/?key="), j
        key = j["viewer"].split("key=")[1]
        page = c.get(j["viewer"])
        assert page.status_code == 200 and "<html" in page.text[:200].lower()
        assert tok not in page.headers.get("set-cookie", "")  # the cookie holds the job key, not the token
        c.cookies.clear()
        other_job = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt"},
                           headers={"Authorization": f"Bearer {other}"}).json()
        other_key = other_job["viewer"] or c.app.state.keys.link_key(other_job["id"])
        assert c.get(f"/viewer/{jid}/?key={other_key}").status_code == 401  # one job's key opens only it
        assert c.get(f"/viewer/{jid}/?token={tok}").status_code == 401  # never the API token in a URL
        proto = f"viser-v{viser.__version__}"
        with c.websocket_connect(f"/viewer/{jid}?key={key}", subprotocols=[proto]) as ws:
            assert ws.accepted_subprotocol == proto
            first = ws.receive_bytes()  # viser's messages (msgpack), relayed
            assert len(first) > 0
        j = wait(c, h, jid)
        assert j["status"] == "done", j
        r = c.get(j["viewer"], follow_redirects=False)
        assert r.status_code == 307 and "playbackPath" in r.headers["location"]
        rec = c.get(f"/viewer/{jid}/recording.viser?key={key}")
        assert rec.status_code == 200 and len(rec.content) > 10000  # body + cloth frames
        c.cookies.clear()
        assert c.get(f"/viewer/{jid}/recording.viser?key={other_key}").status_code == 401


def test_settings_tokens_and_listing(tmp_path):
    with TestClient(create_app(_settings(tmp_path, tokens=["shop-backend"]), start_workers=False)) as c:
        h = {"Authorization": "Bearer shop-backend"}
        assert c.get("/api/bodies", headers=h).json() == []
        b = c.post("/api/bodies/default", json={"preset": "male", "weight": 0.7}, headers=h).json()
        assert [x["id"] for x in c.get("/api/bodies", headers=h).json()] == [b["id"]]
        with open(SAMPLE_SKIRT, "rb") as f:
            g = c.post("/api/garments", files={"file": ("flare.json", f)}, headers=h).json()
        assert c.get(f"/api/garments/{g['id']}", headers=h).json()["name"] == "flare"
        j = c.post("/api/tryons", json={"body_id": b["id"], "garment": g["id"]}, headers=h)
        assert j.status_code == 202 and j.json()["request"]["garment"]["label"] == "flare"
        r = c.post("/api/tryons", json={"body_id": b["id"], "garment": g["id"], "size": "M"}, headers=h)
        assert r.status_code == 422 and "own size" in r.json()["error"]
        assert [x["id"] for x in c.get("/api/tryons", headers=h).json()] == [j.json()["id"]]
        key = c.app.state.keys.link_key(j.json()["id"])
        assert c.get(f"/viewer/{j.json()['id']}/?key={key}").status_code == 409  # queued: nothing yet
        assert c.delete(f"/api/garments/{g['id']}", headers=h).status_code == 204
        assert c.get(f"/api/garments/{g['id']}", headers=h).status_code == 404
        assert not any((c.app.state.settings.data_dir / "uploads").glob("pattern-*"))


def test_cancel_and_delete_running(tmp_path):
    with TestClient(create_app(_settings(tmp_path))) as c:
        h = token(c)
        a = c.post("/api/tryons", json={"body": "default:female", "garment": "dress", "resolution_cm": 2},
                   headers=h).json()["id"]
        b = c.post("/api/tryons", json={"body": "default:female", "garment": "dress", "resolution_cm": 2},
                   headers=h).json()["id"]
        wait(c, h, a, states=("running",))
        time.sleep(1.0)
        assert c.post(f"/api/tryons/{a}/cancel", headers=h).status_code == 202
        j = wait(c, h, a, timeout=30)
        assert j["status"] == "cancelled", j
        assert not (c.app.state.settings.data_dir / "jobs" / a).exists()
        wait(c, h, b, states=("running",))
        time.sleep(1.0)
        assert c.delete(f"/api/tryons/{b}", headers=h).status_code == 204
        assert c.get(f"/api/tryons/{b}", headers=h).status_code == 404
        t0 = time.time()  # the worker stops it and cleans up; it is free for the next one
        while c.app.state.db.one("SELECT COUNT(*) n FROM jobs")["n"] != 1 and time.time() - t0 < 5:
            time.sleep(0.2)
        c2 = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt", "resolution_cm": 4},
                    headers=h).json()["id"]
        assert wait(c, h, c2, timeout=120)["status"] == "done"
        assert not (c.app.state.settings.data_dir / "jobs" / b).exists()


def test_a_job_deleted_while_its_results_are_written_leaves_no_folder(tmp_path, monkeypatch):
    """The delete lands after the last progress check, while the worker writes its results (its
    mkdir makes the removed folder again): the worker removes it once it finds the job gone."""
    from app import crud
    from app.queue import worker
    from app.services import tryons

    settings = _settings(tmp_path)
    with TestClient(create_app(settings, start_workers=False)) as c:
        h = token(c)
        jid = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt"}, headers=h).json()["id"]
        db = c.app.state.db
        job = crud.claim(db, os.getpid(), 30.0)
        assert job["id"] == jid

        def run(req, out, progress, *_):
            tryons.delete(crud.get(db, "jobs", jid), settings, db)  # the user deletes it now
            out.mkdir(parents=True)
            (out / "garment.glb").write_bytes(b"x" * 100)
            return {"ok": True}

        monkeypatch.setattr(worker, "_run", run)
        worker.run_job(db, job, settings.data_dir)
        assert crud.get(db, "jobs", jid) is None
        assert not (settings.data_dir / "jobs" / jid).exists()


def test_a_try_on_past_the_dressing_time_limit_fails_and_says_so(tmp_path):
    """TRYON_DRESS_SECONDS: a try-on still dressing when its time is up stops there; the job fails
    with the limit's name and where it was, not a run that goes on for a quarter of an hour."""
    from app import crud
    from app.queue import worker

    settings = _settings(tmp_path)
    assert settings.dress_seconds == 300  # (the default a shop gets)
    with TestClient(create_app(settings, start_workers=False)) as c:
        h = token(c)
        jid = c.post("/api/tryons", json={"body": "default:female", "garment": "skirt"}, headers=h).json()["id"]
        db = c.app.state.db
        job = crud.claim(db, os.getpid(), 30.0)
        worker.run_job(db, job, settings.data_dir, 30.0, dress_seconds=1e-3)
        row = crud.get(db, "jobs", jid)
        assert row["status"] == "failed"
        assert "stopped after 0.001 s" in row["error"] and "TRYON_DRESS_SECONDS" in row["error"]
        assert "while still" in row["error"]
        assert not any((settings.data_dir / "jobs" / jid).glob("*/garment.glb"))  # (no half-written results)


def test_worker_warm_up_loads_the_engine_and_never_raises(monkeypatch, capsys):
    """A fresh worker, while no try-on waits, dresses a coarse skirt once (kernels, body, GL
    context); a failure there is reported and printed, never raised (the worker goes on)."""
    from app.queue.worker import warm_up

    r = warm_up()
    assert r["ok"] is True and r["seconds"] > 0

    def broken(*a, **k):
        raise RuntimeError("no GL here")

    monkeypatch.setattr("engine.scene.tryon.run_tryon", broken)
    r = warm_up()
    assert r["ok"] is False
    assert "no GL here" in capsys.readouterr().err


def test_settings_from_the_environment(monkeypatch, tmp_path):
    """Every TRYON_* variable lands in one Settings (the engine's too); the workers get them
    handed down, with the query helpers off when there is a worker per core (unless set)."""
    import os

    from app.core.db import DB
    from app.queue.supervisor import JobManager
    from engine.errors import InputError
    from engine.settings import read

    cores = os.cpu_count() or 1
    env = {"TRYON_DATA": str(tmp_path / "d"), "TRYON_TOKENS": "a, b,", "TRYON_MAX_UPLOAD_MB": "0.5",
           "TRYON_WORKERS": str(min(cores, 16)), "TRYON_MAX_TRIANGLES": "3e5", "TRYON_GL": "OSMesa"}
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    s = read(Settings)
    assert s.data_dir == tmp_path / "d" and s.db == tmp_path / "d" / "jobs.sqlite" and s.tokens == ["a", "b"]
    assert s.max_upload_bytes == 2 ** 19 and s.max_triangles == 300_000 and s.gl == "osmesa"
    manager = JobManager(s, DB(s.db))
    assert manager.worker_settings().query_helper is (cores > 16)
    monkeypatch.setenv("TRYON_QUERY_HELPER", "1")
    assert JobManager(read(Settings), manager.db).worker_settings().query_helper is True
    for name, value in (("TRYON_QUEUE_MAX", "lots"), ("TRYON_WORKERS", "99")):
        monkeypatch.setenv(name, value)
        with pytest.raises(InputError, match=f"{name}='{value}'"):
            read(Settings)


def test_a_job_says_its_own_time(tmp_path):
    """A try-on's `seconds` is the job's own, from its start to its end -- every size --size auto
    dressed and the walk; the report's wall_seconds are the last drape's (the page said "in 7.4 s"
    for a job that took 194 s); none while it runs."""
    import json

    from app.models import job_public

    row = {"id": "j1", "status": "running", "progress": 0.5, "stage": "walking", "message": "", "error": None,
           "attempts": 1, "request": json.dumps({"garment": "skirt"}), "report": None, "viewer_port": None,
           "started": 1000.0, "finished": None, "result": None}
    assert job_public(row, tmp_path, "k")["seconds"] is None
    row.update(status="done", finished=1194.0, report=json.dumps({"wall_seconds": {"total": 7.4}}))
    assert job_public(row, tmp_path, "k")["seconds"] == 194.0

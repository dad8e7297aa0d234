"""End to end in a real browser: Debian's chromium driven by Playwright, against the service
started as a user would (uvicorn, a real SQLite file, a spawned worker)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = "/usr/bin/chromium"
ROOT = Path(__file__).resolve().parents[1]
SHOTS = ROOT / "out" / "page"  # screenshots, to look at

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="Debian's chromium is not installed "
                                 "(scripts/setup.sh installs it)")]


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture()
def server_env() -> dict[str, str]:
    """Settings the service under test is started with (a test module may override this fixture)."""
    return {}


@pytest.fixture()
def server(tmp_path, server_env):
    port = _port()
    env = dict(os.environ, TRYON_DATA=str(tmp_path / "data"), **server_env)
    log = open(tmp_path / "server.log", "wb")  # a file, not a pipe: a full pipe would block the server
    p = subprocess.Popen([sys.executable, "-m", "uvicorn", "--factory", "app.main:create_app", "--host", "127.0.0.1",
                          "--port", str(port)], cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    t0 = time.time()
    while time.time() - t0 < 60:
        try:
            urllib.request.urlopen(url + "/web/index.html", timeout=1)
            break
        except OSError:
            if p.poll() is not None:
                raise AssertionError((tmp_path / "server.log").read_text()[-2000:])
            time.sleep(0.3)
    yield url
    p.terminate()
    try:
        p.wait(10)
    except subprocess.TimeoutExpired:
        p.kill()
    log.close()


@contextmanager
def _page(server: str):
    """The page in chromium, its catalogue loaded; yields (page, the page's script errors)."""
    from playwright.sync_api import sync_playwright

    SHOTS.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--enable-unsafe-swiftshader"])
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(server + "/")
        page.wait_for_selector("#garment option[value=dress]", state="attached")
        yield page, errors
        browser.close()


def _try_on(page) -> None:
    """Press Try on; wait for success or for a failure the page shows (the test then fails with
    its message at once instead of waiting out the timeout)."""
    page.click("#tryon")
    page.wait_for_function("(t => t.startsWith('Done') || t.startsWith('The try-on '))"
                           "(document.getElementById('status').textContent)", timeout=240_000)
    text = page.inner_text("#status")
    assert text.startswith("Done"), text


def _colour_share(img: np.ndarray, rgb, tol=40) -> float:
    d = np.abs(img[..., :3].astype(int) - np.array(rgb)).max(axis=-1)
    return float((d < tol).mean())


def test_page_dresses_the_default_avatar(server, tmp_path):
    from PIL import Image

    shots = SHOTS
    with _page(server) as (page, errors):
        page.select_option("#garment", "dress")
        page.select_option("#quality", "3")
        assert page.input_value("#size") == "auto"  # the page picks the shopper's size by default
        page.screenshot(path=str(shots / "1-form.png"))
        _try_on(page)
        assert "dress (M, women's chart, chosen from the body's girths)" in page.inner_text("#status")
        frame = page.frame_locator("#viewer")
        frame.locator("canvas").first.wait_for(timeout=60_000)
        time.sleep(6)  # the recording plays (the last frame is the draped dress)
        page.screenshot(path=str(shots / "2-done.png"))
        page.locator("#viewer").screenshot(path=str(tmp_path / "viewer.png"))
        shutil.copy(tmp_path / "viewer.png", shots / "3-viewer.png")
        link = page.locator("#download-scene-glb")
        assert link.count() == 1
        with page.expect_download() as d:
            link.click()
        glb = d.value.path()
        assert open(glb, "rb").read(4) == b"glTF"
        assert page.locator("#pattern-svg").count() == 1  # the dress as cut for this avatar
    img = np.asarray(Image.open(tmp_path / "viewer.png").convert("RGB"))
    # both meshes are on screen: skin-coloured body pixels and blue garment pixels (viser shades
    # them, so a generous tolerance around the base colours)
    body = _colour_share(img, (204, 173, 148), 60)
    cloth = _colour_share(img, (70, 110, 190), 60)
    assert body > 0.002 and cloth > 0.002, (body, cloth)
    assert errors == [], errors


def test_page_shows_what_was_found_in_a_scan_when_it_is_chosen(server, tmp_path):
    """Choosing a scan uploads it at once; the page shows its height and the notes of the loader
    and the measurements (here: arms held closer than tops need) before anything is dressed."""
    from tests.samples import write_arms_lowered_scan

    scan = write_arms_lowered_scan(tmp_path / "arms down.obj", 20.0)
    with _page(server) as (page, errors):
        page.set_input_files("#scan", str(scan))
        page.wait_for_selector("#bodynotes li", timeout=60_000)
        assert page.is_checked("input[name=bodykind][value=scan]")
        assert "arms down.obj: 165.0 cm tall" in page.inner_text("#bodyinfo")
        notes = page.inner_text("#bodynotes")
        assert "the arms hang 5.4 cm from the torso" in notes and "units: metres" in notes
        assert page.inner_text("#status").startswith("Body loaded")
        page.screenshot(path=str(SHOTS / "5-scan-notes.png"))
    assert errors == [], errors


def test_page_plays_an_uploaded_animation(server, tmp_path):
    """A user uploads a moving body (a zip of OBJ frames) through the page, at its frame rate,
    with Motion "walking": the result is the animation, played as uploaded."""
    from engine.body.default import default_body
    from engine.body.motion import WalkParams, walk_track
    from tests.samples import write_anim_zip

    body = default_body("male")
    tr = walk_track(body, WalkParams(), fps=15)
    zp = write_anim_zip(tmp_path / "my walk.zip", [tr.vertices(i) for i in range(8)], body.faces)
    with _page(server) as (page, errors):
        page.check("input[name=bodykind][value=scan]")
        page.set_input_files("#scan", str(zp))
        page.fill("#fps", "15")
        page.select_option("#garment", "skirt")
        page.select_option("#motion", "walk")
        page.select_option("#quality", "3")
        _try_on(page)
        page.wait_for_selector("#results img[alt='strip.png']")
        page.screenshot(path=str(SHOTS / "4-animation.png"))
        link = page.locator("#download-anim-glb")
        assert link.count() == 1
        with page.expect_download() as d:
            link.click()
        assert open(d.value.path(), "rb").read(4) == b"glTF"
    assert errors == [], errors


@pytest.mark.slow
def test_page_dresses_a_scan_with_the_arms_close_with_the_arms_turned_out(server, tmp_path):
    """A scan whose arms hang 2.4 cm from its torso, a shirt: the page says at upload that the
    arms will be turned out, and when it is done that they were (engine.scene.arms.clear_arms):
    the viewer shows the body in that pose."""
    from tests.samples import write_arms_lowered_scan

    scan = write_arms_lowered_scan(tmp_path / "arms30.obj", 30.0)
    with _page(server) as (page, errors):
        page.set_input_files("#scan", str(scan))
        page.wait_for_selector("#bodynotes li", timeout=60_000)
        assert "the arms are turned out that far for dressing and walking" in page.inner_text("#bodynotes")
        page.select_option("#garment", "shirt")
        page.select_option("#size", "M")
        page.select_option("#quality", "3")
        _try_on(page)
        text = page.inner_text("#status")
        assert "Note: the arms were turned" in text and "out from the body for dressing and walking" in text, text
        page.frame_locator("#viewer").locator("canvas").first.wait_for(timeout=60_000)
        time.sleep(8)  # the recording plays: sewing and the drape on the body with its arms turned out
        page.screenshot(path=str(SHOTS / "6-arms-turned-out.png"))
        page.locator("#viewer").screenshot(path=str(tmp_path / "viewer.png"))
    from PIL import Image

    img = np.asarray(Image.open(tmp_path / "viewer.png").convert("RGB"))
    body, cloth = _colour_share(img, (204, 173, 148), 60), _colour_share(img, (70, 110, 190), 60)
    assert body > 0.002 and cloth > 0.002, (body, cloth)
    assert errors == [], errors


def test_page_dresses_a_dxf_pattern_with_its_assembly(server, tmp_path):
    """A DXF whose pieces make no garment the inference knows: choosing it says so at once and
    asks for its assembly; with the assembly it is dressed like any other pattern."""
    import json

    from engine.pattern.dxf import assembly_of, write_dxf
    from engine.pattern.io import load_pattern
    from tests.samples import SAMPLE_SKIRT

    spec = load_pattern(SAMPLE_SKIRT)
    write_dxf(spec, tmp_path / "skirt.dxf")
    (tmp_path / "skirt-assembly.json").write_text(json.dumps(assembly_of(spec)))
    with _page(server) as (page, errors):
        assert page.is_hidden("#dxfparts")
        page.set_input_files("#pattern", str(tmp_path / "skirt.dxf"))
        assert page.is_visible("#assembly")
        page.wait_for_function("document.getElementById('status').textContent.includes('assembly')")
        page.set_input_files("#assembly", str(tmp_path / "skirt-assembly.json"))
        page.wait_for_selector("#dxfsvg[src]")  # read with its assembly: its pieces, edges numbered
        assert "from your assembly" in page.inner_text("#dxfinfo")
        page.select_option("#quality", "3")
        page.screenshot(path=str(SHOTS / "7-dxf-form.png"))
        _try_on(page)
        assert "skirt" in page.inner_text("#status")
        page.frame_locator("#viewer").locator("canvas").first.wait_for(timeout=60_000)
        time.sleep(6)  # the recording plays to the draped skirt
        page.screenshot(path=str(SHOTS / "8-dxf-done.png"))
    assert errors == [], errors


def test_page_dresses_a_dxf_alone_in_a_size_chosen_from_its_own(server, tmp_path):
    """A shop's DXF alone (leggings, 14 graded sizes): choosing it shows its pieces with the
    inferred seams numbered and coloured and fills the size chooser with the file's sizes (its
    sample size chosen); another size redraws the picture; Try on dresses that size, in the
    stretch knit the pattern suggests."""
    import shutil as sh

    from tests.samples import DXF_SAMPLES

    dxf = tmp_path / "Leggings.DXF"
    sh.copy(DXF_SAMPLES / "ORILEGWB_AAMA.DXF", dxf)
    with _page(server) as (page, errors):
        page.set_input_files("#pattern", str(dxf))
        page.wait_for_function("document.getElementById('dxfsvg').naturalWidth > 0", timeout=60_000)
        sizes = page.eval_on_selector_all("#size option", "os => os.map(o => o.value)")
        assert sizes == ["26", "28", "30", "32", "34", "36", "38", "40", "42", "44", "46", "48", "50", "52", "auto"]
        assert page.input_value("#size") == "36"
        info = page.inner_text("#dxfinfo")
        assert "Leggings.DXF: bottom, 2 pieces in 14 sizes" in info and "front rise" in info, info
        assert "stretch_knit" in info and "stretch_knit" in page.eval_on_selector("#fabric", "s => s.options[0].text")
        page.select_option("#size", "40")
        page.wait_for_function("document.getElementById('dxfsvg').src.endsWith('size=40') && "
                               "document.getElementById('dxfsvg').complete && "
                               "document.getElementById('dxfsvg').naturalWidth > 0", timeout=60_000)
        page.screenshot(path=str(SHOTS / "9-dxf-alone-form.png"))
        _try_on(page)
        text = page.inner_text("#status")
        assert "Done: Leggings (size 40) in stretch_knit" in text, text
        page.frame_locator("#viewer").locator("canvas").first.wait_for(timeout=60_000)
        time.sleep(6)  # the recording plays to the draped leggings
        page.screenshot(path=str(SHOTS / "10-dxf-alone-done.png"))
    assert errors == [], errors

"""The built-in catalogue: every garment in every size drafts a pattern that validates, and the
drafting choices that the drape quality depends on hold."""

from __future__ import annotations

import numpy as np
import pytest

from engine.body import resolve_body
from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.garment.catalogue import make_garment
from engine.pattern.catalogue import BUST_SHIFT, CATALOGUE, SIZES
from engine.pattern.validate import check


@pytest.fixture(scope="module", params=["default:female", "default:male"])
def body(request):
    return resolve_body(request.param)


@pytest.mark.parametrize("size", SIZES)
def test_every_garment_validates_in_every_size(body, size):
    for name in CATALOGUE:
        spec, place, label = make_garment(name, body, size)
        problems = check(spec, label)  # raises on errors
        assert not [p for p in problems if "error" in str(p)], problems
        assert callable(place) and size in label


def _width_below_armhole(spec, panel: str) -> float:
    """Panel width (cm) half-way down the panel, where both side seams are straight."""
    pts = geo.outline(spec.pattern.panels[panel], spec.scale) / spec.scale  # cm, closed polyline
    y = 0.5 * (pts[:, 1].max() + pts[:, 1].min())
    a, b = pts, np.roll(pts, -1, axis=0)
    cross = (a[:, 1] - y) * (b[:, 1] - y) < 0
    t = (y - a[cross, 1]) / (b[cross, 1] - a[cross, 1])
    xs = a[cross, 0] + t * (b[cross, 0] - a[cross, 0])
    return float(xs.max() - xs.min())


@pytest.mark.parametrize("garment", ["dress", "sleeveless-shirt", "shirt"])
def test_womens_bodice_front_is_fuller_than_the_back(garment):
    """Without a bust dart a flat front is stretched over the bust (measured: 8 % strain on the
    dress, the limit is 6 %), so a woman's front takes 2 x BUST_SHIFT cm from the back; a man's
    front and back are equal."""
    for body, shift in (("default:female", BUST_SHIFT), ("default:male", 0.0)):
        spec, _, _ = make_garment(garment, resolve_body(body), "M")
        front, back = _width_below_armhole(spec, "front"), _width_below_armhole(spec, "back")
        assert front - back == pytest.approx(4 * shift, abs=0.6), (body, front, back)


@pytest.mark.parametrize("garment, worst, p99", [("dress", 0.35, 0.16), ("skirt", 0.35, 0.16),
                                                 ("sleeveless-shirt", 0.35, 0.16), ("shirt", 0.6, 0.3)])
def test_placement_keeps_panels_near_their_flat_lengths(body, garment, worst, p99):
    """wrap_torso limits how fast the wrap's ellipses change with height, so the placed cloth is
    not stretched where the body's profile changes fast (under the bust, at the seat): before,
    structural springs started up to 70 % longer than flat and kicked the hem up in sewing.
    Sleeves: their axis is smooth enough at the elbow and ends straight at the wrist (the
    placed shirt's sleeves were stretched up to 185 %)."""
    from engine.cloth.fabrics import get_fabric
    from engine.cloth.model import STRUCTURAL, build_model
    from engine.garment.garment import build_garment

    spec, place, label = make_garment(garment, body, "M")
    g = build_garment(spec, h=0.015, place=place, source=label)
    m = build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric("cotton"), 0.015)
    x, (a, b) = g.positions, m.springs.T
    strain = (np.linalg.norm(x[a] - x[b], axis=1) / m.rest - 1)[m.kind == STRUCTURAL]
    assert strain.max() < worst, f"placed {garment} stretched {100 * strain.max():.0f} %"
    assert np.percentile(strain, 99) < p99


@pytest.mark.parametrize("garment", ["dress", "sleeveless-shirt"])
def test_straps_lean_in_over_the_shoulders(body, garment):
    """Above the armholes a sleeveless top's rows lean in toward the upper chest and the shoulder blades
    (wrap_torso, _lean_in): standing straight up from the bust, the shoulder seams' ends
    started 31-36 cm apart across the shoulders, and the seam pull swung the straps down
    about their base (the dress M fell off default:female at 3 of 8 cloth resolutions).
    Measured at M: 31-34 cm apart, 5-12 cm off the body; leaning, 19 cm apart, 1.3-5.7 cm off
    (not in it). The placed panels' strain is tested above. (The shirt's shoulders, held by its
    sleeve caps, stand as before: it sewed at every resolution, and leaning, the sample scan's
    L ended with one spring at the shoulder 6.5 % stretched, not 5.9 %.)"""
    from engine.collide.bvh import MeshBVH
    from engine.garment.garment import build_garment

    spec, place, label = make_garment(garment, body, "M")
    g = build_garment(spec, h=0.015, place=place, source=label)
    # the shoulder seams: the two front-back stitches highest up the flat panels
    fb = [k for k, n in enumerate(g.stitch_names) if n.startswith("front[") and "-back[" in n]
    top = sorted(fb, key=lambda k: -g.uv[g.seams[g.seam_id == k][:, 0], 1].mean())[:2]
    bvh = MeshBVH(body.vertices, body.faces)
    for k in top:
        pairs = g.seams[g.seam_id == k]
        gap = np.linalg.norm(g.positions[pairs[:, 0]] - g.positions[pairs[:, 1]], axis=1)
        assert gap.max() < 0.21, f"{g.stitch_names[k]} starts {100 * gap.max():.0f} cm open"
        d = bvh.signed_distance(g.positions[pairs.ravel()])
        assert d.min() > 0.0 and d.max() < 0.06, f"{g.stitch_names[k]}: {100 * d.min():.1f}-{100 * d.max():.1f} cm off"


def test_size_chart_follows_the_body_not_its_file_name(tmp_path):
    """The default bodies keep their own chart; a scan gets the men's chart by its waist-to-hip
    ratio, whatever its file is called (the service stores uploads as body-<id>)."""
    from engine.body import resolve_body
    from engine.body.types import Body
    from engine.pattern.catalogue import chart_of
    from tests.samples import SAMPLE_BODY

    male, female = resolve_body("default:male"), resolve_body("default:female")
    assert chart_of(male) == "men" and chart_of(female) == "women"
    for name in ("body-1234", "female_scan", "male_scan"):
        assert chart_of(Body(male.vertices, male.faces, name=name)) == "men", name
        assert chart_of(Body(female.vertices, female.faces, name=name)) == "women", name
    assert chart_of(resolve_body(str(SAMPLE_BODY))) == "women"  # the sample scan, a woman
    _, _, label = make_garment("skirt", Body(male.vertices, male.faces, name="body-1234"), "M")
    assert label == "skirt (M, men's chart)"


def test_auto_size_is_the_smallest_that_covers_the_body():
    """--size auto: the default bodies get M on their charts, the sample scan (hips 105 cm) L
    on the women's; a body scaled to a 30 % larger girth is beyond XXL, a clear error; the
    label says how the size was chosen."""
    from engine.body.measure import measure
    from engine.body.types import Body
    from engine.pattern.catalogue import FIT_GIRTHS, WOMEN, recommend_size
    from tests.samples import SAMPLE_BODY

    for name in ("default:female", "default:male"):
        body = resolve_body(name)
        assert {recommend_size(g, body) for g in CATALOGUE} == {"M"}, name
    scan = resolve_body(str(SAMPLE_BODY))
    m = measure(scan)
    for g in CATALOGUE:
        size = recommend_size(g, scan, m)
        assert size == "L", g
        # minimal: M (92/74/100) leaves the scan's hips (105 cm) beyond half a step (3 cm)
        assert 100 * m.hips > WOMEN["M"][2] + 3 and "hips" in FIT_GIRTHS[g]
    _, _, label = make_garment("dress", scan, "auto")
    assert label == "dress (L, women's chart, chosen from the body's girths)"
    big = Body(scan.vertices * [1.3, 1.0, 1.3], scan.faces, name="big")
    with pytest.raises(InputError, match="larger than the largest size, XXL"):
        recommend_size("skirt", big)
    with pytest.raises(InputError, match="choose one of XS, S, M, L, XL, XXL or auto"):
        make_garment("skirt", scan, "XXXL")


@pytest.mark.parametrize("garment, share", [("dress", 0.0), ("skirt", 0.0), ("sleeveless-shirt", 0.0),
                                            ("trousers", 0.0), ("shirt", 0.01)])
def test_placement_starts_clear_of_the_body(body, garment, share):
    """Panels start around the body without touching it (issue 3): no placed point inside the
    body (exact signed distance), but for under 1 % of the shirt where its sleeves meet the
    bodice under the arm. Before, 4-10 % of the dress's and sleeveless shirt's points started
    inside the shoulders (the straps, up to 5.8 cm deep) and the male hips."""
    from engine.collide.bvh import MeshBVH
    from engine.garment.garment import build_garment

    spec, place, label = make_garment(garment, body, "M")
    g = build_garment(spec, h=0.015, place=place, source=label)
    sd = MeshBVH(body.vertices, body.faces).signed_distance(g.positions)
    assert np.mean(sd < 0) <= share, f"{np.mean(sd < 0):.1%} of the placed {garment} inside the body"
    assert sd.min() > -0.01


def test_trousers_start_unstretched_round_the_ankles_and_at_their_own_heights(body):
    """The trousers' hem goes where its opening passes round the leg with room (measured on
    default:female: 6 cm up, where the foot is 31 cm round; at the old 3 cm, 47 cm, the 41 cm hem
    was wrapped round the foot stretched by up to 75 % with the leg seams 12 cm open, and on the
    first steps it sprang up to the calf and crumpled the legs). Every row is placed at its own
    height (before, rows squeezed toward the crotch started 58 % short and 74 % long)."""
    from engine.cloth.fabrics import get_fabric
    from engine.cloth.model import FLEXION, build_model
    from engine.garment.garment import build_garment
    from engine.pattern.catalogue import HEM_ROOM, _fit

    fit = _fit(body, "M")
    spec, place, label = make_garment("trousers", body, "M")
    g = build_garment(spec, h=0.015, place=place, source=label)
    x = g.positions
    assert np.abs(x[:, 1] - (fit.waist_h / 100 + g.uv[:, 1])).max() < 1e-9  # the panels' own heights
    hem_y = float(x[:, 1].min())
    ys, per = fit.ankle
    at_hem = float(np.interp(100 * hem_y, ys, per))
    opening = float(np.clip(40 + 0.1 * (fit.hips + 6 - 96), 40, 44))
    assert at_hem + HEM_ROOM <= opening + 0.5 and 100 * hem_y >= 3.0, (hem_y, at_hem, opening)
    low = x[g.seams.ravel(), 1].reshape(-1, 2).min(axis=1) < hem_y + 0.15
    assert np.linalg.norm(x[g.seams[low, 0]] - x[g.seams[low, 1]], axis=1).max() < 0.02  # leg seams start shut
    m = build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric("cotton"), 0.015)
    a, b = m.springs[:, 0], m.springs[:, 1]
    strain = np.linalg.norm(x[b] - x[a], axis=1) / m.rest - 1
    near = (np.minimum(x[a, 1], x[b, 1]) < hem_y + 0.15) & (m.kind != FLEXION)
    assert np.percentile(strain[near], 99) < 0.2 and strain[near].max() < 0.3, np.percentile(strain[near], [99, 100])


@pytest.mark.integration
def test_sleeves_go_on_a_scans_arms():
    """A scan has no skeleton: the shirt's sleeves are placed along the arms of the default
    skeleton fitted to it (engine.body.fit), around the scan's own arms -- before, sleeved
    garments were refused on every scan. Measured on the sample scan (arms out 45 degrees):
    sleeves 2.2-3.5 cm from the arm, reaching 58 cm out to the wrists."""
    from engine.collide.bvh import MeshBVH
    from engine.garment.garment import build_garment
    from tests.samples import SAMPLE_BODY

    scan = resolve_body(str(SAMPLE_BODY))
    assert scan.rig is None
    spec, place, label = make_garment("shirt", scan, "L")
    g = build_garment(spec, h=0.015, place=place, source=label)
    sd = MeshBVH(scan.vertices, scan.faces).signed_distance(g.positions)
    assert np.mean(sd < 0) <= 0.01 and sd.min() > -0.01
    names = list(spec.pattern.panels)
    for name, sign in (("sleeve_l", 1.0), ("sleeve_r", -1.0)):
        sel = g.panel == names.index(name)
        assert sd[sel].max() < 0.05, f"{name} up to {100 * sd[sel].max():.0f} cm off the arm"
        reach = (sign * g.positions[sel, 0]).max()
        assert reach > 0.5, f"{name} reaches only {100 * reach:.0f} cm out"


def test_an_arm_axis_ending_on_its_own_point_still_places_a_sleeve():
    """default:female as a scan with its arms lowered 30 degrees: the fitted skeleton's arm
    centre line ended on the very point it was extended to, and the shirt's placement died with
    numpy's "arange: cannot compute length". Repeated points are dropped; an axis with no length
    is a clear error."""
    from engine.errors import InputError
    from engine.garment.place import arm_path

    p = np.array([[0.15, 1.38, 0.0], [0.18, 1.1, 0.15], [0.25, 0.86, 0.17], [0.25, 0.86, 0.17]])
    path = arm_path(p)
    assert np.isfinite(path).all() and len(path) > 100
    with pytest.raises(InputError, match="arm's axis"):
        arm_path(np.repeat(p[:1], 3, axis=0))


@pytest.mark.integration
def test_auto_size_dresses_the_next_size_when_the_drape_refuses_one():
    """--size auto: the girths' size is dressed first; a drape that refuses it as too small
    (SimulationError marked too_small) makes the next larger size dressed, at most AUTO_TRIES
    more; other failures are not retried; the report lists the refused sizes. The drape here is
    a stand-in that refuses chosen sizes (a real refusal, the sample scan's L dress, takes a
    minute: tests/test_drape.py's slow test)."""
    from engine.errors import SimulationError
    from engine.scene.garments import AUTO_TRIES, dress_in_size

    body = resolve_body("default:female")  # auto picks M
    asked = []

    def drape_refusing(*refused, too_small=True, tight=()):
        def dress(spec, place, name):
            size = name.split("(")[1].split(",")[0]
            asked.append(size)
            if size in refused:
                e = SimulationError(f"{size} stretched 22 %")
                e.too_small = too_small
                raise e
            strain = 0.05 + 0.01 * (len(tight) - tight.index(size)) if size in tight else 0.058
            return size, {"garment": name, "tight": size in tight, "strain": {"max": strain}}
        return dress

    notes = []
    res, rep = dress_in_size("dress", body, "auto", drape_refusing("M"), note=lambda *a: notes.append(a))
    assert asked == ["M", "L"] and res == "L"
    assert rep["garment"] == "dress (L, women's chart, chosen by draping: M too small)"
    assert rep["sizes_tried"] == [{"size": "M", "verdict": "small", "error": "M stretched 22 %"}]
    assert notes == [("M", "M stretched 22 %", "L")]
    asked.clear()
    _, rep = dress_in_size("dress", body, "auto", drape_refusing())
    assert asked == ["M"] and rep["sizes_tried"] == []
    assert rep["garment"] == "dress (M, women's chart, chosen from the body's girths)"
    asked.clear()
    with pytest.raises(SimulationError, match=r"--size auto tried M, L, XL\)"):
        dress_in_size("dress", body, "auto", drape_refusing("M", "L", "XL", "XXL"))
    assert asked == list(SIZES[SIZES.index("M"):SIZES.index("M") + 1 + AUTO_TRIES])
    asked.clear()
    with pytest.raises(SimulationError, match="M stretched"):  # not a size problem: no retry
        dress_in_size("dress", body, "auto", drape_refusing("M", too_small=False))
    asked.clear()
    with pytest.raises(SimulationError, match="auto picks M"):  # an explicit size is dressed once
        dress_in_size("dress", body, "S", drape_refusing("S"))
    assert asked == ["S"]
    # a drape that ended tight (strain past the threshold + 1 %) is too small as well; when
    # every size is, the least stretched result comes back, its warnings say it is tight
    asked.clear()
    res, rep = dress_in_size("dress", body, "auto", drape_refusing("XL", tight=("M", "L")))
    assert asked == ["M", "L", "XL"] and res == "L" and rep["tight"]
    assert [t["size"] for t in rep["sizes_tried"]] == ["M", "XL"]
    assert rep["sizes_tried"][0]["error"] == "tight: stretched 7 %"
    assert rep["warnings"][-1].startswith("no size fits this body well: M too small (tight: stretched 7 %); "
                                          "L too small (tight: stretched 6 %); XL too small (XL stretched 22 %)")


def test_size_auto_goes_smaller_when_a_size_slides_down():
    """--size auto never returns a drape that slid down the body ("too large") when the size below
    fits: it dresses the next smaller one; when that is too small, neither fits and it says so
    (issue 48: a size auto chose slid 11 cm down, another ended tight). The drape here is a
    stand-in that slides or stretches in chosen sizes."""
    from engine.scene.garments import dress_in_size

    body = resolve_body("default:female")  # auto picks M
    asked = []

    def drape(slides=(), tight=()):
        def dress(spec, place, name):
            size = name.split("(")[1].split(",")[0]
            asked.append(size)
            warn = ["the garment slid 12 cm down the body from where it was placed: it may be too large for this "
                    "body (try a smaller size)"] if size in slides else []
            return size, {"garment": name, "tight": size in tight, "strain": {"max": 0.07 if size in tight else 0.05},
                          "warnings": warn}
        return dress

    res, rep = dress_in_size("skirt", body, "auto", drape(slides=("M",)))
    assert asked == ["M", "S"] and res == "S" and rep["warnings"] == []
    assert rep["garment"] == "skirt (S, women's chart, chosen by draping: M too large)"
    asked.clear()
    res, rep = dress_in_size("skirt", body, "auto", drape(slides=("M",), tight=("S",)))
    assert asked == ["M", "S"] and res == "S"
    assert rep["warnings"][-1].startswith("no size fits this body well: M too large (the garment slid 12 cm")
    asked.clear()
    res, rep = dress_in_size("skirt", body, "auto", drape(tight=("M",), slides=("L",)))  # up, then not down again
    assert asked == ["M", "L"] and res == "M" and rep["tight"]


@pytest.mark.integration
def test_shoulder_seams_open_with_the_arms_close_are_sewn_again_with_the_arms_raised(monkeypatch):
    """default:female as a scan with its arms lowered 20 degrees (5.4 cm from the torso 10 cm
    below the armpits, Measurements.arm_gap): a sewing failure beside the arms is dressed again in
    the same size with the arms raised (engine.scene.arms; tests/test_drape.py's slow tests dress
    such bodies for real), and --size auto goes on to larger sizes with them raised. When the
    arms cannot be raised, it ends at once and says why (its arms), not retried in larger sizes.
    The same failure lower down, or on the A-pose body, stays a size problem. The drape here is a
    stand-in that refuses every size. Such a body is sewn with friction (the A-pose body without)."""
    import engine.scene.arms as arms
    from engine.body.measure import ARM_GAP_OK, measure
    from engine.body.motion import _rot, pose_joints
    from engine.body.rig import skin
    from engine.body.types import Body
    from engine.errors import SimulationError
    from engine.scene.garments import dress_in_size
    from engine.scene.tryon import ARMS_CLOSE_SEW_FRICTION, sewing_friction

    a_pose = resolve_body("default:female")
    posed = skin(a_pose.vertices, a_pose.rig, pose_joints(a_pose.rig, {"upperarm01.L": _rot("z", -20.0),
                                                                       "upperarm01.R": _rot("z", 20.0)}))
    scan = Body(vertices=posed, faces=a_pose.faces, name="arms-down")
    m = measure(scan)
    assert 0.03 < m.arm_gap < ARM_GAP_OK and measure(a_pose).arm_gap > ARM_GAP_OK
    assert any("the arms hang" in n for n in m.notes)
    assert sewing_friction(scan)[0] == ARMS_CLOSE_SEW_FRICTION and sewing_friction(a_pose) == (0.0, None)
    asked = []

    def refusing(at):
        def dress(spec, place, name, lift=None):
            asked.append((name.split(" ")[1].strip("(,"), lift))
            e = SimulationError("sewing did not close within 4.0 s of simulated time; open seams: "
                                "front[1]-back[10] (15.4 cm). The garment may be too small for this "
                                "body (try a larger size) or the panels start too far apart")
            e.too_small, e.open_top = True, at
            raise e
        return dress

    with pytest.raises(SimulationError) as err:
        dress_in_size("dress", scan, "auto", refusing(m.armpit_height + 0.1))
    sizes = [s for s, _ in asked]
    lifts = [lift for _, lift in asked]
    assert sizes[:2] == [sizes[0]] * 2 and len(sizes) == 4 and len(set(sizes[1:])) == 3  # M, M raised, L, XL
    assert lifts[0] is None and all(lift is lifts[1] for lift in lifts[1:]) and lifts[1].degrees == 20.0
    msg = str(err.value)
    assert "dressed with the arms raised 20 degrees (they hang 5.4 cm from the torso" in msg
    assert "--size auto tried" in msg and err.value.too_small
    asked.clear()
    with pytest.raises(SimulationError, match="try a larger size.*arms raised 20 degrees"):  # an explicit size
        dress_in_size("dress", scan, "S", refusing(m.armpit_height + 0.1))
    assert [s for s, _ in asked] == ["S", "S"]
    asked.clear()
    with pytest.raises(SimulationError, match=r"--size auto tried"):  # open below the armpits: sizes
        dress_in_size("dress", scan, "auto", refusing(m.armpit_height - 0.25))
    assert len(asked) == 3 and all(lift is None for _, lift in asked)
    asked.clear()
    with pytest.raises(SimulationError, match=r"--size auto tried"):  # the A-pose: sizes
        dress_in_size("dress", a_pose, "auto", refusing(1.4))
    assert len(asked) == 3 and all(lift is None for _, lift in asked)
    # arms that cannot be raised (e.g. no skeleton fits): the reason, at once, in any size
    monkeypatch.setattr(arms, "lift_arms", lambda body: None)
    asked.clear()
    with pytest.raises(SimulationError) as err:
        dress_in_size("dress", scan, "auto", refusing(m.armpit_height + 0.1))
    assert len(asked) == 1 and not err.value.too_small
    msg = str(err.value)
    assert "arms hang close to its torso (5.4 cm away" in msg and "a larger size will not help" in msg
    assert "try a larger size" not in msg and msg.startswith("sewing did not close")
    asked.clear()
    with pytest.raises(SimulationError, match="arms hang close"):  # an explicit size: no size hint
        dress_in_size("dress", scan, "S", refusing(m.armpit_height + 0.1))


@pytest.mark.integration
def test_cloth_stretched_beside_close_arms_is_dressed_again_with_the_arms_raised(monkeypatch):
    """The same body (arms 5.4 cm from the torso). A drape refused as too small, or reported
    tight, whose most stretched cloth lies beside the arms is dressed again with the arms raised:
    the refused one gives the raised drape; of two tight ones the less stretched is kept (the
    other noted in the warnings). Stretched lower down (the hips) stays as it is. When the arms
    cannot be raised, the refusal says where and still suggests a larger size. Stand-in drapes."""
    import engine.scene.arms as arms
    from engine.body.measure import measure
    from engine.body.motion import _rot, pose_joints
    from engine.body.rig import skin
    from engine.body.types import Body
    from engine.errors import SimulationError
    from engine.scene.garments import dress_in_size

    a_pose = resolve_body("default:female")
    posed = skin(a_pose.vertices, a_pose.rig, pose_joints(a_pose.rig, {"upperarm01.L": _rot("z", -20.0),
                                                                       "upperarm01.R": _rot("z", 20.0)}))
    scan = Body(vertices=posed, faces=a_pose.faces, name="arms-down")
    m = measure(scan)
    shoulder, hips = m.armpit_height + 0.05, m.armpit_height - 0.4
    lift = arms.lift_arms(scan)  # fitting the skeleton takes seconds: once
    monkeypatch.setattr(arms, "lift_arms", lambda body: lift if body is scan else None)
    asked = []

    def drape(at_y, loaded_strain, raised_strain):
        def dress(spec, place, name, lift=None):
            asked.append(lift)
            strain = raised_strain if lift is not None else loaded_strain
            if strain > 0.15:
                e = SimulationError(f"the garment is too small for this body: after draping it is stretched "
                                    f"{100 * strain:.0f} % where cotton allows 5 %; try a larger size")
                e.too_small, e.stretched_at = True, np.array([0.15, at_y, 0.0])
                raise e
            return ("raised" if lift is not None else "loaded"), {
                "tight": strain > 0.06, "strain": {"max": strain, "at_m": [0.15, at_y, 0.0]}, "warnings": []}
        return dress

    res, rep = dress_in_size("shirt", scan, "M", drape(shoulder, 0.17, 0.059))  # refused -> raised
    assert res == "raised" and asked[0] is None and asked[1].degrees == 20.0 and len(asked) == 2
    asked.clear()
    res, rep = dress_in_size("shirt", scan, "M", drape(shoulder, 0.08, 0.062))  # tight -> the raised, less
    assert res == "raised" and len(asked) == 2
    asked.clear()
    res, rep = dress_in_size("shirt", scan, "M", drape(shoulder, 0.065, 0.09))  # ... or the loaded, noted
    assert res == "loaded" and len(asked) == 2
    assert "dressed with the arms raised 20 degrees" in rep["warnings"][0] and "9.0 %" in rep["warnings"][0]
    asked.clear()
    res, rep = dress_in_size("trousers", scan, "M", drape(hips, 0.08, 0.05))  # tight at the hips: kept
    assert res == "loaded" and asked == [None] and rep["warnings"] == []
    asked.clear()
    monkeypatch.setattr(arms, "lift_arms", lambda body: None)
    with pytest.raises(SimulationError) as err:
        dress_in_size("shirt", scan, "M", drape(shoulder, 0.17, 0.05))
    msg = str(err.value)
    assert "stretched 17 % where cotton allows 5 %, beside the arms" in msg and "arms hang close" in msg
    assert msg.endswith("or try a larger size") and err.value.too_small and asked == [None]


def test_armholes_go_deeper_round_thick_arms():
    """The underarm point sits SCYE x height below the shoulder, or ARMHOLE_PER_ARM_ROOT x the
    arm root's cut below the body's armpit when that is lower (thick arms). The default bodies
    keep their armholes (default:female's is 2 mm deeper since its shoulder point is the top of
    the surface, not of the vertices near it); the sample scan's and a heavy avatar's go deeper
    (their L and M sleeveless shirts were 13 and 32 % stretched round the armholes; the slow
    tests drape them)."""
    from engine.body.measure import measure
    from engine.pattern.catalogue import ARMHOLE_PER_ARM_ROOT, SCYE_MEN, SCYE_WOMEN, _fit
    from tests.samples import SAMPLE_BODY

    for spec, scye in (("default:female", SCYE_WOMEN), ("default:male", SCYE_MEN)):
        b = resolve_body(spec)
        m = measure(b)
        by_scye = 100 * (m.shoulder_height - scye * m.height)
        by_root = 100 * (m.armpit_height - ARMHOLE_PER_ARM_ROOT * m.arm_root)
        assert abs(_fit(b, "M").armpit_h - min(by_scye, by_root)) < 1e-9
        assert by_scye - _fit(b, "M").armpit_h < 0.3, spec
    for spec, deeper in ((str(SAMPLE_BODY), 1.7), ("default:female,gender=0.5,weight=1", 4.7)):
        b = resolve_body(spec)
        m = measure(b)
        f = _fit(b, "M")
        assert abs(f.armpit_h - 100 * (m.armpit_height - ARMHOLE_PER_ARM_ROOT * m.arm_root)) < 1e-9
        assert abs(100 * (m.shoulder_height - SCYE_WOMEN * m.height) - f.armpit_h - deeper) < 0.1, spec

"""engine.scene.girth: how far round a part too small for the body is, against the body where it
sits -- on a band wrapped round a cylinder whose sizes are known."""

from __future__ import annotations

import numpy as np

from engine.garment.garment import build_garment
from engine.pattern.spec import PatternSpec
from engine.scene.girth import girth_words, part_girths

WIDTH, DEPTH = 10.0, 6.0  # cm: each half of the band; the band is 20 cm round at rest


def _band():
    """A band of two rectangles sewn side to side, and a third panel sewn to neither."""
    rect = {"vertices": [[0, 0], [WIDTH, 0], [WIDTH, DEPTH], [0, DEPTH]],
            "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)]}
    spec = PatternSpec.model_validate({"pattern": {
        "panels": {"band_f": {**rect, "translation": [0, 0, 10]}, "band_b": {**rect, "translation": [0, 0, -10]},
                   "apart": {**rect, "translation": [40, 0, 0]}},
        "stitches": [[{"panel": "band_f", "edge": 1}, {"panel": "band_b", "edge": 3}],
                     [{"panel": "band_f", "edge": 3}, {"panel": "band_b", "edge": 1}]]}})
    return build_garment(spec, h=0.01)


def _limb(girth: float, sections: int = 128, rings: int = 41):
    """A tube `girth` m round (a 128-gon) and 0.4 m long, its axis along y, in small faces as a
    body's mesh has them: (vertices, faces)."""
    a = np.linspace(0, 2 * np.pi, sections, endpoint=False)
    y = np.linspace(-0.2, 0.2, rings)
    r = girth / (2 * sections * np.sin(np.pi / sections))  # (the polygon's perimeter is the girth)
    v = np.stack([np.repeat(r * np.cos(a)[None], rings, 0), np.repeat(y[:, None], sections, 1),
                  np.repeat(r * np.sin(a)[None], rings, 0)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(sections), indexing="ij")
    a0, a1 = i * sections + j, i * sections + (j + 1) % sections
    b0, b1 = a0 + sections, a1 + sections
    f = np.concatenate([np.stack([a0, b0, a1], -1).reshape(-1, 3), np.stack([a1, b0, b1], -1).reshape(-1, 3)])
    return v, f


def _wrapped(g, radius: float, gap: float):
    """The band wrapped round the y axis at `radius`, each half over pi - gap radians (its seams
    `gap` radians open), 'apart' laid flat far off."""
    x = np.zeros((len(g.positions), 3))
    for p, name in enumerate(g.panel_names):
        on = g.panel == p
        u, v = g.uv[on, 0], g.uv[on, 1]
        s = (u - u.min()) / (u.max() - u.min())
        if name == "apart":
            x[on] = np.c_[u + 1.0, v, np.zeros(on.sum())]
            continue
        a = (0.0 if name == "band_f" else np.pi) + gap / 2 + s * (np.pi - gap)
        x[on] = np.c_[radius * np.cos(a), v - v.mean(), radius * np.sin(a)]
    return x


def test_a_band_round_a_limb_reads_its_length_at_rest_against_the_limbs_girth():
    g = _band()
    bv, bf = _limb(0.30)
    x = _wrapped(g, 0.30 / (2 * np.pi) + 0.002, gap=0.3)  # (stretched round it, its seams 1.5 cm open)
    rings = part_girths(g, x, ["band_f", "band_b"], bv, bf)
    assert len(rings) == 1 and set(rings[0].panels) == {"band_f", "band_b"}, rings
    r = rings[0]
    assert abs(r.rest - 2 * WIDTH / 100) < 0.004, r  # (the open seams are left out: within a cloth edge)
    assert abs(r.girth - 0.30) < 0.003, r
    words = girth_words(rings, ("rib_knit", 0.4))
    assert words and f"{100 * r.rest:.1f} cm round (at rest) where the body is 30.0 cm round" in words, words
    assert "more than even rib_knit" in words, words
    assert "more than even" not in girth_words(rings, ("rib_knit", 0.8))
    # round a thinner limb, the same band (seams as open) reads the same length at rest
    thin = part_girths(g, x, ["band_f", "band_b"], *_limb(0.22))
    assert len(thin) == 1 and abs(thin[0].rest - r.rest) < 0.004 and abs(thin[0].girth - 0.22) < 0.003, thin
    # one half of it named: the other half of the band counts round the limb too
    half = part_girths(g, x, ["band_f"], bv, bf)
    assert len(half) == 1 and abs(half[0].rest - r.rest) < 0.004, half


def test_cloth_that_does_not_wrap_the_body_reads_no_girth():
    g = _band()
    bv, bf = _limb(0.30)
    x = _wrapped(g, 0.30 / (2 * np.pi) + 0.002, gap=0.3)
    assert part_girths(g, x, ["apart"], bv, bf) == []  # (far from the body)
    # a band wider round than the limb: no stretch to close, no words
    loose = part_girths(g, _wrapped(g, 0.30 / (2 * np.pi) + 0.002, gap=0.3), ["band_f", "band_b"], *_limb(0.15))
    assert girth_words(loose) is None


def test_the_sewing_error_says_it_in_centimetres_against_the_stretchiest_fabric():
    """engine.scene.drape._round_words, which a stall beside a part too small adds to its error."""
    from types import SimpleNamespace

    from engine.cloth.fabrics import FABRICS
    from engine.scene.drape import _round_words

    g = _band()
    bv, bf = _limb(0.60)  # (twice the band round: more than any fabric here stretches)
    x = _wrapped(g, 0.60 / (2 * np.pi) + 0.002, gap=0.3)
    job = SimpleNamespace(garment=g, body=SimpleNamespace(verts=bv, faces=bf))
    words = _round_words(job, x, ["band_f", "band_b"])
    top = max(FABRICS.values(), key=lambda f: f.strain_threshold)
    assert words and words.startswith("; at 'band_f' and 'band_b' the cloth is 20.0 cm round"), words
    assert f"more than even {top.name} does" in words, words
    assert _round_words(SimpleNamespace(garment=g, body=None), x, ["band_f"]) is None
    assert _round_words(job, x, []) is None


def test_a_held_top_far_wider_than_the_body_is_said_to_stand_off_it():
    """engine.scene.attach.stands_off: a skirt's top ('lower_interface', held as GarmentCode's
    simulator holds it) that ended 4 cm or more off the body stands off it (GarmentCode cuts some
    without a waistband far wider than the waist); one round the body does not."""
    from engine.collide.bvh import MeshBVH
    from types import SimpleNamespace

    from engine.cloth.config import Attachment
    from engine.scene.attach import stands_off

    rect = {"vertices": [[0, 0], [WIDTH, 0], [WIDTH, DEPTH], [0, DEPTH]],
            "edges": [{"endpoints": [0, 1]}, {"endpoints": [1, 2]},
                      {"endpoints": [2, 3], "label": "lower_interface"}, {"endpoints": [3, 0]}]}
    spec = PatternSpec.model_validate({"pattern": {
        "panels": {"band_f": {**rect, "translation": [0, 0, 10]}, "band_b": {**rect, "translation": [0, 0, -10]}},
        "stitches": [[{"panel": "band_f", "edge": 1}, {"panel": "band_b", "edge": 3}],
                     [{"panel": "band_f", "edge": 3}, {"panel": "band_b", "edge": 1}]]}})
    g = build_garment(spec, h=0.01)
    top = g.labelled["lower_interface"]
    held = Attachment(vertices=top, points=np.zeros((len(top), 3)), normals=np.tile([0.0, 1.0, 0.0], (len(top), 1)),
                      tau=np.full(len(top), 0.05), vmax=np.ones(len(top)))
    ident = np.arange(len(g.positions))
    thin = _limb(0.10)  # (the band is 40 cm round: 5 cm off this body all round)
    body = SimpleNamespace(vertices=thin[0], faces=thin[1])
    x = _wrapped(g, 0.40 / (2 * np.pi), gap=0.0)
    words = stands_off(g, body, x, ident, held, MeshBVH(*thin))
    assert words and "40 cm round where the body is 10 cm round, 5 cm off the body" in words, words
    fits = _limb(0.36)  # (under a centimetre off it)
    assert stands_off(g, SimpleNamespace(vertices=fits[0], faces=fits[1]), x, ident, held, MeshBVH(*fits)) is None
    assert stands_off(g, body, x, ident, None, MeshBVH(*thin)) is None  # (not held: it would fall, not stand off)


def _skirt_top(sewn_top: bool = False):
    """Two rectangles sewn side to side into a tube 20 cm round, their tops labelled
    'lower_interface' (a skirt with no waistband); sewn_top: a third panel sewn to the tops (a
    waistband)."""
    rect = {"vertices": [[0, 0], [WIDTH, 0], [WIDTH, DEPTH], [0, DEPTH]],
            "edges": [{"endpoints": [0, 1]}, {"endpoints": [1, 2]},
                      {"endpoints": [2, 3], "label": "lower_interface"}, {"endpoints": [3, 0]}]}
    band = {"vertices": [[0, 0], [2 * WIDTH, 0], [2 * WIDTH, 2], [0, 2]],
            "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)]}
    panels = {"band_f": {**rect, "translation": [0, 0, 10]}, "band_b": {**rect, "translation": [0, 0, -10]}}
    stitches = [[{"panel": "band_f", "edge": 1}, {"panel": "band_b", "edge": 3}],
                [{"panel": "band_f", "edge": 3}, {"panel": "band_b", "edge": 1}]]
    if sewn_top:
        panels["wb"] = {**band, "translation": [0, 10, 0]}
        stitches += [[{"panel": "wb", "edge": 0}, {"panel": "band_f", "edge": 2}]]
    return build_garment(PatternSpec.model_validate({"pattern": {"panels": panels, "stitches": stitches}}), h=0.01)


def test_a_held_top_far_wider_than_the_body_is_gathered_onto_an_elastic():
    """engine.scene.attach.top_elastic: a skirt's held top sewn to nothing and cut more than
    ELASTIC_PAST longer round than the body where it is held gets an elastic ELASTIC_EASE longer
    round than the body (its cloth read flat along the top: 20 cm); one cut to fit, or sewn to a
    waistband, gets none."""
    from types import SimpleNamespace

    from engine.scene.attach import ELASTIC_EASE, top_elastic

    g = _skirt_top()
    g.positions[:] = _wrapped(g, 0.20 / (2 * np.pi), gap=0.0)
    top = g.labelled["lower_interface"]
    y = float(np.median(g.positions[top, 1]))
    thin = _limb(0.12)
    body = SimpleNamespace(vertices=thin[0] + [0.0, y, 0.0], faces=thin[1])
    e = top_elastic(g, body, top)
    assert e is not None and abs(e.cloth - 0.20) < 1e-9 and abs(e.body - 0.12) < 0.003, e
    assert abs(e.factor * e.cloth - (1 + ELASTIC_EASE) * e.body) < 1e-9
    assert "cut 20 cm round with no waistband where the body is 12 cm round, is gathered onto an elastic 12 cm" \
        in e.note, e.note
    fits = _limb(0.19)  # (within ELASTIC_PAST of the top: cut to fit, no elastic)
    assert top_elastic(g, SimpleNamespace(vertices=fits[0] + [0.0, y, 0.0], faces=fits[1]), top) is None
    sewn = _skirt_top(sewn_top=True)  # (its top sewn to a band: the band holds it)
    assert top_elastic(sewn, body, sewn.labelled["lower_interface"]) is None
    # held on its elastic from below and from above (an elastic pulled in rides up a body that
    # narrows above it), both planes kept once its seams are welded
    from engine.cloth.welds import merge_map
    from engine.scene.attach import attachment, welded

    att, note = attachment(g, body)
    assert att.elastic is not None and "gathered onto an elastic" in note, note
    for a in (att, welded(att, merge_map(len(g.positions), g.seams.astype(np.int64)))):
        up, down = a.normals[:, 1] > 0.5, a.normals[:, 1] < -0.5
        assert up.sum() == down.sum() and set(a.vertices[up]) == set(a.vertices[down]), (up.sum(), down.sum())
        assert (a.points[down, 1] > a.points[up, 1]).all()


def test_an_elastic_shortens_the_edge_it_is_sewn_into_not_the_strain_measured_there():
    """engine.cloth.model.with_elastic: the springs between two of the edge's vertices rest at the
    elastic's share of their length, the strain limit still measures them from their full length
    (at it, 0 % strain), and every other spring is as it was."""
    from engine.cloth.fabrics import get_fabric
    from engine.cloth.model import FLEXION, build_model, spring_strains, with_elastic

    g = _skirt_top()
    model = build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric("cotton"), 0.01)
    top = g.labelled["lower_interface"]
    out = with_elastic(model, top, 0.6)
    on = np.isin(model.springs, top).all(axis=1)
    assert on.sum() == 2 * WIDTH  # (each half's top: 10 springs of 1 cm)
    np.testing.assert_allclose(out.rest[on], 0.6 * model.rest[on])
    np.testing.assert_array_equal(out.rest[~on], model.rest[~on])
    np.testing.assert_allclose(out.limit_rest, model.limit_rest)
    flat = np.c_[g.uv[:, 0], np.zeros(len(g.uv)), g.uv[:, 1]]  # (every spring at its full length)
    assert abs(spring_strains(out, flat)[1]).max() < 1e-9
    assert (out.kind[on] != FLEXION).all()

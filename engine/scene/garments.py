"""GARMENT arguments: a catalogue name or a pattern file -> (spec, placement, name)."""

from __future__ import annotations

import re
from pathlib import Path

from engine.body.types import Body
from engine.errors import InputError
from engine.pattern.io import load_pattern

PATTERN_SIZE_ADVICE = "a pattern has one size: grade it larger for this body"


def _roles_placement(spec, body: Body):
    """The placement of a pattern whose panels carry a DXF inference's roles (engine.garment.
    dxf_place), else None (the pattern's own, engine.garment.place.pattern_placement)."""
    from engine.garment.dxf_place import dxf_placement, has_roles

    return dxf_placement(spec, body)[0] if body is not None and has_roles(spec) else None


def is_dxf(arg: str) -> bool:
    return Path(arg).suffix.lower() == ".dxf"


def dxf_garment(path: Path, body: Body, size: str | None, units: str | None = None, assembly: str | None = None):
    """(spec, placement, display name) of a DXF cutting pattern in one of its sizes: its sample size
    (else its middle one) by default; `auto`: the smallest whose girth covers the body's with
    ease (engine.pattern.dxf_size). Its seams and placement are inferred, or as the assembly file
    at `assembly` says; units: the DXF's, where it does not say."""
    from engine.pattern.dxf import import_pattern, load_assembly
    from engine.pattern.dxf_read import read_pattern

    path = Path(path)
    pattern = read_pattern(path, units)
    asm = load_assembly(assembly) if assembly is not None else None
    how = ""
    if size == "auto":
        from engine.body.measure import measure
        from engine.pattern.dxf_size import recommend_size

        m = measure(body)
        size, why = recommend_size(pattern, {"chest": 100 * m.bust, "hips": 100 * m.hips})
        how = f", {why}"
    imp = import_pattern(path, size, assembly=asm, pattern=pattern)
    if imp.kind == "pieces" and asm is None:
        raise InputError(f"{path.name}: {'; '.join(imp.unsure)}")
    return imp.spec, _roles_placement(imp.spec, body), f"{path.name} (size {imp.size}{how})"


def dxf_sizes(path: Path, body: Body, units: str | None = None) -> tuple[list[str], int]:
    """--size auto on a DXF: (its sizes, the index of the one its girths recommend)."""
    from engine.body.measure import measure
    from engine.pattern.dxf_read import read_pattern
    from engine.pattern.dxf_size import recommend_size

    pattern = read_pattern(path, units)
    m = measure(body)
    first, _ = recommend_size(pattern, {"chest": 100 * m.bust, "hips": 100 * m.hips})
    return list(pattern.sizes), pattern.sizes.index(first)


def resolve_garment(arg: str, body: Body, size: str | None = "M", units: str | None = None,
                    assembly: str | None = None):
    """Returns (PatternSpec, placement function or None for the spec's own, display name).
    size: catalogue size; None means the default (M) for catalogue garments. units, assembly:
    a DXF's (dxf_garment)."""
    path = Path(arg)
    if is_dxf(arg):  # a cutting pattern: its seams inferred (or its assembly's), in one of its sizes
        return dxf_garment(path, body, size, units, assembly)
    if units is not None or assembly is not None:
        raise InputError(f"--units and --assembly go with a DXF pattern; '{path.name}' is not one (a GarmentCode "
                         "pattern has its own stitches and placement)")
    if path.suffix.lower() == ".json" or path.exists():
        if size is not None:
            raise InputError(f"--size {size} applies to catalogue garments; a pattern file ({path.name}) "
                             "has its own size: leave --size out")
        spec = load_pattern(path)
        return spec, _roles_placement(spec, body), path.name
    size = size or "M"
    from engine.garment.catalogue import make_garment
    from engine.pattern.catalogue import CATALOGUE

    if arg in CATALOGUE:
        return make_garment(arg, body, size)
    names = ", ".join(CATALOGUE)
    raise InputError(f"garment '{arg}' is neither a pattern file nor a catalogue garment ({names})")


def add_size_hint(err: Exception, arg: str, body: Body, size: str | None) -> None:
    """A catalogue garment that came out too small for the body (the drape marks such an error
    `too_small`: it could not be sewn, or ended stretched): add to the error's message the size
    --size auto picks for this body, when that is larger than the one asked for. For a pattern
    file the advice to try a larger size becomes one to grade the pattern larger."""
    from engine.pattern.catalogue import AUTO, CATALOGUE, SIZES, recommend_size

    if not getattr(err, "too_small", False):
        return
    if is_dxf(arg):  # a DXF has its graded sizes
        return
    if arg not in CATALOGUE:  # a pattern file has one size: "try a larger size" means grading it
        msg = str(err).replace("(try a larger size)", "(a pattern has one size: grade it larger)")
        msg = msg.replace("; try a larger size", f"; {PATTERN_SIZE_ADVICE}")
        err.args = (msg,) + tuple(err.args[1:])
        return
    size = size or "M"
    if size == AUTO:
        return
    try:
        best = recommend_size(arg, body)
    except InputError:
        return
    if SIZES.index(best) > SIZES.index(size):
        err.args = (f"{err} (for this body's girths --size auto picks {best})",) + tuple(err.args[1:])


AUTO_TRIES = 2  # --size auto: the recommended size and at most this many larger ones


def beside_the_arms(y: float, body: Body) -> bool:
    """On a body whose arms hang closer to the torso than ARM_GAP_OK, is height y beside the arms
    (above 15 cm under the armpits: over the shoulders, under the arms)?"""
    from engine.body.measure import ARM_GAP_BELOW, ARM_GAP_OK, measure

    m = measure(body)
    return bool(m.arm_gap < ARM_GAP_OK and y > m.armpit_height - ARM_GAP_BELOW - 0.05)


def arms_in_the_way(err: Exception, body: Body) -> bool:
    """A sewing failure whose open seams start beside the arms, or a drape refused as too small
    whose most stretched cloth lies beside them, on a body whose arms hang close to the torso
    (beside_the_arms): rewrite the error to say so and return True. A sewing failure is then
    marked not `too_small` (a larger size will not help; the scan's pose will); a stretched one
    may still be too small and keeps the size hint."""
    from engine.body.measure import ARM_GAP_BELOW, ARM_GAP_OK, measure

    top = getattr(err, "open_top", None)
    at = getattr(err, "stretched_at", None)
    y = top if top is not None else (float(at[1]) if at is not None else None)
    if y is None or not beside_the_arms(y, body):
        return False
    m = measure(body)
    pose = (f"This body's arms hang close to its torso ({100 * m.arm_gap:.1f} cm away {100 * ARM_GAP_BELOW:.0f} cm "
            f"below the armpits): the seams beside the arms are sewn reliably with the arms at least "
            f"{100 * ARM_GAP_OK:.0f} cm away there (an A-pose, arms about 45 degrees from the body)")
    if top is not None:
        head = re.split(r"\. (?:The garment may be too small|Beside them the cloth)", str(err))[0]
        err.args = (f"{head}. {pose}, and a larger size will not help. Scan the body in that pose, or try a "
                    "skirt or trousers",) + tuple(err.args[1:])
        err.too_small = False
    else:
        head = str(err).split("; try a larger size")[0]
        err.args = (f"{head}, beside the arms. {pose}. Scan the body in that pose, or try a larger size",) \
            + tuple(err.args[1:])
    return True


def dress_in_size(arg: str, body: Body, size: str | None, dress, note=None, dxf: dict | None = None):
    """Resolve GARMENT and dress the body with `dress(spec, place, name, **kw) -> (result, report)`
    (kw: `lift`, passed on to engine.scene.tryon.run_tryon). dxf: a DXF's `units` and `assembly`
    (resolve_garment).
    With --size auto on a catalogue garment, the size recommended from the body's girths comes
    first; if it comes out too small -- its drape refused it (seams that cannot close, cloth
    stretched past DrapeTuning.too_tight) or ended tight (report["tight"]) -- the next larger
    size is dressed, up to AUTO_TRIES more (a chart does not know a fuller bust); if it comes out
    too large (slid down the body), the next smaller (_dress_auto). The report's `sizes_tried`
    lists the sizes that did not fit and why; `note(size, why, next size)` is called before each
    retry. When no size fits, the closest result is returned with a warning naming each size
    tried and why, or the last refusal raised. Other sizes and pattern files are dressed
    once; a too-small error then names the size auto would pick (add_size_hint). Seams beside
    the arms that cannot close on a body whose arms hang close to its torso, or cloth beside
    them left too stretched (arms_in_the_way, beside_the_arms): the same size is dressed again
    with the arms raised and then lowered (engine.scene.arms),
    and so are the larger sizes --size auto goes on to; if the arms cannot be raised, the
    try-on ends with that reason, in any size."""
    from engine.errors import SimulationError
    from engine.pattern.catalogue import AUTO, CATALOGUE

    lifted = []  # the ArmLift, once the arms were found in the way

    def attempt(resolve, label=lambda name: name):
        """dress(*resolve(body)); with the arms raised when they are in the way: seams beside
        them that do not close, or cloth beside them left too stretched (refused, or tight: then
        the less stretched of the two drapes is kept)."""
        from engine.scene.arms import lift_arms

        loaded = None  # a tight drape as loaded, stretched beside the arms
        if not lifted:
            spec, place, name = resolve(body)
            try:
                loaded = dress(spec, place, label(name))
            except SimulationError as e:
                if not arms_in_the_way(e, body):
                    raise
                lift = lift_arms(body)
                if lift is None:
                    raise
                lifted.append(lift)
            else:
                at = loaded[1]["strain"].get("at_m")  # where it is most stretched
                if not (loaded[1].get("tight") and at is not None and beside_the_arms(at[1], body)):
                    return loaded
                lift = lift_arms(body)
                if lift is None:
                    return loaded
                lifted.append(lift)
        lift = lifted[0]
        spec, place, name = resolve(lift.raised)
        try:
            res = dress(spec, place, label(name), lift=lift)
        except SimulationError as e:
            if loaded is not None:
                loaded[1]["warnings"].append(f"{lift.describe()} failed ({e}): this is the drape as loaded")
                return loaded
            e.args = (f"{e} ({lift.describe()})",) + tuple(e.args[1:])
            raise
        if loaded is not None and loaded[1]["strain"]["max"] <= res[1]["strain"]["max"]:
            loaded[1]["warnings"].append(
                f"{lift.describe()} came out more stretched ({100 * res[1]['strain']['max']:.1f} %): this is the "
                "drape as loaded")
            return loaded
        return res

    dxf = dxf or {}
    if (arg not in CATALOGUE and not is_dxf(arg)) or size != AUTO:
        try:
            return attempt(lambda b: resolve_garment(arg, b, size, **dxf))
        except SimulationError as e:
            add_size_hint(e, arg, body, size)  # (only a too-small error; not the arms in the way)
            raise
    return _dress_auto(arg, body, attempt, note, dxf)


def _verdict(report: dict) -> str:
    """'fits', 'small' (ended tight) or 'large' (slid down the body) for a drape that ended."""
    if report.get("tight"):
        return "small"
    if any(w.startswith("the garment slid") for w in report.get("warnings", [])):
        return "large"
    return "fits"


def _auto_sizes(arg: str, body: Body, dxf: dict):
    """(the garment's sizes, smallest first; the index of the one the body's girths choose;
    make(arg, body, size) -> (spec, placement, name)): a DXF's own sizes, else the catalogue's."""
    from engine.garment.catalogue import make_garment
    from engine.pattern.catalogue import SIZES, recommend_size

    if is_dxf(arg):
        sizes, first = dxf_sizes(Path(arg), body, dxf.get("units"))

        def make(arg, b, s):
            return dxf_garment(Path(arg), b, s, **dxf)
        return sizes, first, make
    return list(SIZES), SIZES.index(recommend_size(arg, body)), make_garment


def _dress_auto(arg: str, body: Body, attempt, note=None, dxf: dict | None = None):
    """--size auto (dress_in_size): from the size the body's girths choose, one size larger while
    it comes out too small (refused, or tight) -- up to AUTO_TRIES larger --, one smaller while it
    comes out too large (slid down the body, or slid off it), never a size twice. A size that
    fits is returned; when none does, the drape that came closest (a tight one before one that
    slid) with a warning naming every size tried and why, or the last refusal raised."""
    from engine.errors import SimulationError

    sizes, first, make = _auto_sizes(arg, body, dxf or {})
    i = first
    tried: list[dict] = []
    ended: dict[str, tuple] = {}  # size -> (result, report, verdict, size) of drapes that ended
    error = None
    while True:
        s = sizes[i]
        how = "chosen from the body's girths" if not tried else \
            f"chosen by draping: {', '.join(t['size'] + ' too ' + t['verdict'] for t in tried)}"
        try:
            res, report = attempt(lambda b: make(arg, b, s), lambda name: name[:-1] + f", {how})")
        except SimulationError as e:
            verdict = {(True, False): "small", (False, True): "large"}.get(
                (getattr(e, "too_small", False), getattr(e, "too_large", False)))
            if verdict is None:
                raise
            why, error = str(e), e
        else:
            verdict = _verdict(report)
            report["sizes_tried"] = list(tried)
            if verdict == "fits":
                return res, report
            ended[s] = (res, report, verdict, s)
            why = (f"tight: stretched {100 * report['strain']['max']:.0f} %" if verdict == "small" else
                   next(w for w in report["warnings"] if w.startswith("the garment slid")))
        tried.append({"size": s, "verdict": verdict, "error": why})
        nxt = i + 1 if verdict == "small" else i - 1
        if not 0 <= nxt < len(sizes) or sizes[nxt] in {t["size"] for t in tried} or nxt > first + AUTO_TRIES:
            break
        if note is not None:
            note(s, why, sizes[nxt])
        i = nxt
    summary = "; ".join(f"{t['size']} too {t['verdict']} ({t['error']})" for t in tried)
    if not ended:
        error.args = (f"{error} (--size auto tried {', '.join(t['size'] for t in tried)})",) + tuple(error.args[1:])
        raise error
    tight = [v for v in ended.values() if v[2] == "small"]
    res, report, _, s = min(tight, key=lambda v: v[1]["strain"]["max"]) if tight else list(ended.values())[-1]
    report["sizes_tried"] = [t for t in tried if t["size"] != s]
    report.setdefault("warnings", []).append(f"no size fits this body well: {summary}")
    return res, report

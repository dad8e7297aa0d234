"""The `tryon` command. Every subcommand turns engine errors into one line on stderr and a
non-zero exit (2 for bad input, 3 for no OpenGL, 1 for an internal error)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from engine.errors import GLUnavailableError, TryonError
from engine.settings import EngineSettings, current, read, use

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Virtual try-on: bodies, collision maps, dressing (drape), walking (walk), evidence (bench).")
body_app = typer.Typer(no_args_is_help=True, help="Inspect bodies (scans or the default body).")
app.add_typer(body_app, name="body")

BODY_HELP = ("A mesh file (.obj .ply .stl .off .glb .gltf) or the default body: default:female, "
             "default:male, optionally with shape parameters, e.g. default:female,height=1.72,weight=0.6")
UP_HELP = "Up axis of a scan when detection is unsure: +x -x +y -y +z -z"
FRONT_HELP = "Axis the scan faces when detection is unsure: +x -x +y -y +z -z"


def _fail(msg: str, code: int) -> None:
    typer.echo(f"error: {msg}", err=True)
    raise typer.Exit(code)


@app.callback()
def _read_settings() -> None:
    # the TRYON_* settings (engine/settings.py), read once per command, before anything runs
    try:
        use(read(EngineSettings))
    except TryonError as e:
        _fail(str(e), 2)


def _run(fn):
    """Run a command body; engine errors become a one-line message and an exit code."""
    try:
        return fn()
    except GLUnavailableError as e:
        _fail(str(e), 3)
    except TryonError as e:
        _fail(str(e), 2)
    except (typer.Exit, typer.Abort):
        raise
    except KeyboardInterrupt:
        _fail("interrupted", 130)
    except Exception as e:  # a bug: say so in one line; TRYON_DEBUG=1 shows the traceback
        if current().debug:
            raise
        _fail(f"internal error ({type(e).__name__}: {e}); rerun with TRYON_DEBUG=1 for details", 1)


def _body(spec: str, up: Optional[str], front: Optional[str]):
    from engine.body import resolve_body

    body = resolve_body(spec, up=up, front=front)
    for line in body.notes:
        typer.echo(f"note: {line}", err=True)
    return body


def _dressable(spec: str, up: Optional[str], front: Optional[str]):
    """_body, with the arms turned out where they touch the torso or the hips (engine.scene.arms.clear_arms)."""
    from engine.scene.arms import clear_arms

    loaded = _body(spec, up, front)
    body = clear_arms(loaded)
    if body is not loaded:
        typer.echo(f"note: {body.notes[-1]}", err=True)
    return body


@body_app.command("info")
def body_info(
    body: str = typer.Argument(..., help=BODY_HELP),
    as_json: bool = typer.Option(False, "--json", help="Print the measurements as JSON (centimetres)."),
    up: Optional[str] = typer.Option(None, "--up", help=UP_HELP),
    front: Optional[str] = typer.Option(None, "--front", help=FRONT_HELP),
):
    """Measure a body: height, circumferences, widths, lengths and landmark heights (cm)."""

    def go():
        from engine.body.measure import measure

        b = _body(body, up, front)
        m = measure(b)
        if as_json:
            typer.echo(json.dumps(m.to_dict(), indent=2))
        else:
            typer.echo(m.to_text())

    _run(go)


@app.command("maps")
def maps_cmd(
    body: str = typer.Argument(..., help=BODY_HELP),
    out: Path = typer.Option(..., "--out", help="Directory for the map PNGs."),
    texel: float = typer.Option(0.005, "--texel", help="Texel size in metres (seed 003 §5.4: 0.5 cm)."),
    segments: Optional[str] = typer.Option(
        None, "--segments", help="Comma-separated segments to render (head,torso,left_arm,right_arm,left_leg,right_leg); "
        "default: the whole body in one map pair."),
    up: Optional[str] = typer.Option(None, "--up", help=UP_HELP),
    front: Optional[str] = typer.Option(None, "--front", help=FRONT_HELP),
):
    """Render the front/back depth, normal and velocity maps of a body and write them as PNGs."""

    def go():
        from engine.collide.maps import render_body_maps
        from engine.io.mapviz import save_map_pngs

        b = _body(body, up, front)
        segs = [s.strip() for s in segments.split(",")] if segments else None
        maps = render_body_maps(b, texel=texel, segments=segs)
        written = save_map_pngs(maps, out)
        for p in written:
            typer.echo(str(p))

    _run(go)


@app.command("render")
def render_cmd(
    body: str = typer.Argument(..., help=BODY_HELP),
    out: Path = typer.Option(..., "--out", help="PNG file to write."),
    size: int = typer.Option(800, "--size", help="Picture height in pixels."),
    view: str = typer.Option("front", "--view", help="front, side, back or three (all side by side)."),
    up: Optional[str] = typer.Option(None, "--up", help=UP_HELP),
    front: Optional[str] = typer.Option(None, "--front", help=FRONT_HELP),
):
    """Render a shaded picture of a body."""

    def go():
        from engine.io.render import render_body_png

        b = _body(body, up, front)
        render_body_png(b, out, size=size, view=view)
        typer.echo(str(out))

    _run(go)


def _size_note(size: str, why: str, other: str) -> None:
    typer.echo(f"note: size {size} did not fit ({why}); trying {other}", err=True)


def _progress_printer():
    """A one-line progress display on stderr (rich), returned with its context manager."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    prog = Progress(TextColumn("{task.fields[stage]:>8}"), BarColumn(), TextColumn("{task.fields[msg]}"),
                    TimeElapsedColumn(), transient=True, console=None, redirect_stdout=False)
    task = prog.add_task("tryon", total=1.0, stage="", msg="")

    def update(stage: str, fraction: float, message: str) -> None:
        prog.update(task, completed=max(0.0, min(1.0, fraction)), stage=stage, msg=message)

    return prog, update


TIME_LIMIT_HELP = ("Stop dressing after this many seconds of wall time (sewing and draping, every fabric "
                   "tried) and say where it was; default: no limit (the service's is TRYON_DRESS_SECONDS).")


def _limited(update, seconds: Optional[float]):
    """The progress display, stopping the dressing after `seconds` (None: no limit)."""
    from engine.scene.drape import time_limited

    if seconds is None:
        return update
    if not (seconds > 0 and seconds < float("inf")):
        _fail(f"--time-limit {seconds:g}: give a positive number of seconds", 2)
    return time_limited(update, seconds, "--time-limit")


# the request's fields by their options here (engine.scene.request.TryOnRequest)
OPTION_NAMES = {"resolution_cm": "--resolution", "texel_mm": "--texel", "dt_ms": "--dt",
                "reuse_maps": "--reuse-maps/--maps-every-frame", "walk_stiffness": "--walk-stiffness"}
DRESSING = ("garment", "size", "assembly", "units", "fabric", "resolution_cm", "texel_mm", "collision",
            "velocity_mode")
WALKING = ("seconds", "fps", "speed", "stride", "in_place", "walk_stiffness", "reuse_maps")


def request_options(fields: tuple[str, ...]):
    """A command whose options include these fields of TryOnRequest -- their types, defaults and
    help from the model -- handed to it as one TryOnRequest (its `request` parameter)."""
    import functools
    import inspect

    from engine.scene.request import TryOnRequest

    def option(name):
        f = TryOnRequest.model_fields[name]
        kind = {bool: bool, int: int, float: float}.get(f.annotation, str)  # (a Literal: checked by the model)
        if f.annotation in (float | None, str | None):
            kind = Optional[float] if f.annotation == float | None else Optional[str]
        flag = OPTION_NAMES.get(name, "--" + name.replace("_", "-"))
        default = ... if f.is_required() else f.default
        return inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, annotation=kind,
                                 default=typer.Option(default, flag,
                                                      help=f.description))

    def wrap(fn):
        own = [q for q in inspect.signature(fn).parameters.values() if q.name != "request"]
        params = own + [option(n) for n in fields]

        @functools.wraps(fn)
        def command(**kw):
            values = {n: kw.pop(n) for n in fields}
            values["motion"] = "walk" if "seconds" in fields else "none"
            names = {n: OPTION_NAMES.get(n, "--" + n.replace("_", "-")).split("/")[0] for n in fields}
            return fn(request=_run(lambda: TryOnRequest.of(names, **values)), **kw)

        command.__signature__ = inspect.Signature(params)
        command.__annotations__ = {q.name: q.annotation for q in params}
        return command

    return wrap


@app.command("drape")
@request_options(DRESSING + ("dt_ms", "force_dt"))
def drape_cmd(request, body: str = typer.Option(..., "--body", help=BODY_HELP),
              out: Path = typer.Option(Path("out/drape"), "--out", help="Output directory."),
              up: Optional[str] = typer.Option(None, "--up", help=UP_HELP),
              front: Optional[str] = typer.Option(None, "--front", help=FRONT_HELP),
              time_limit: Optional[float] = typer.Option(None, "--time-limit", help=TIME_LIMIT_HELP)):
    """Dress a standing body: mesh the pattern, place it, sew, drape; write scene.glb, garment.obj,
    front/side/back.png, report.json and the pattern dressed (pattern.json, pattern.svg)."""

    def go():
        from engine.errors import SimulationError
        from engine.scene.tryon import dress_request, write_outputs

        b = _dressable(body, up, front)
        prog, update = _progress_printer()
        with prog:
            try:
                res, report = dress_request(b, request, progress=_limited(update, time_limit), note=_size_note)
            except SimulationError as e:
                _failed_picture(out, b, e)
                raise
        (out / "failed.png").unlink(missing_ok=True)  # (an earlier failure's picture, not this drape's)
        for p in write_outputs(out, b, res, report):
            typer.echo(str(p))
        r = report
        typer.echo(f"{r['cloth_vertices']} cloth vertices, {r['iterations']} iterations, "
                   f"{r['ms_per_iteration']['total']:.2f} ms/iteration, {r['wall_seconds']['total']:.1f} s; "
                   f"penetration max {r['penetration_mm']['max']:.1f} mm p99 {r['penetration_mm']['p99']:.1f} mm; "
                   f"strain max {100 * r['strain']['max']:.1f} % (threshold {100 * r['strain']['threshold']:.0f} %); "
                   f"settled: {r['settled']}")
        for w in r["warnings"]:
            typer.echo(f"warning: {w}", err=True)

    _run(go)


def _failed_picture(out: Path, b, e) -> None:
    """A picture of the state a failed drape stopped in (failed.png), when the error carries it."""
    if getattr(e, "positions", None) is None:
        return
    from PIL import Image

    from engine.io.render import BODY_RGB, render_meshes

    out.mkdir(parents=True, exist_ok=True)
    img = render_meshes([(b.vertices, b.faces, BODY_RGB), (e.positions, e.triangles, (0.8, 0.3, 0.3))],
                        size=600, view="three")
    Image.fromarray(img).save(out / "failed.png")
    typer.echo(f"note: picture of the failed state: {out / 'failed.png'}", err=True)


@app.command("walk")
@request_options(DRESSING + WALKING)
def walk_cmd(request, body: str = typer.Option(..., "--body", help=BODY_HELP),
             out: Path = typer.Option(Path("out/walk"), "--out", help="Output directory."),
             up: Optional[str] = typer.Option(None, "--up", help=UP_HELP),
             front: Optional[str] = typer.Option(None, "--front", help=FRONT_HELP),
             time_limit: Optional[float] = typer.Option(None, "--time-limit", help=TIME_LIMIT_HELP)):
    """Dress a body (as `tryon drape`), then walk it: write anim.glb (plays in any glTF viewer),
    strip.png (frames side by side) and report.json. BODY may also be an animation: a .zip of OBJ
    frames (one mesh topology) played at --fps, or a .glb with a morph-target or skinned animation
    sampled at --fps; the garment is dressed on its first frame."""

    def go():
        from engine.scene.tryon import dress_request, write_pattern
        from engine.scene.walk import walk_cloth, walk_report, walking_body, write_walk_outputs

        track = None
        from engine.body.gltf_anim import has_animation

        if body.lower().endswith(".zip") or has_animation(body):  # an uploaded animation: its own motion
            from engine.body.animation import load_animation

            track = load_animation(Path(body), request.fps, up=up, front=front)
            b = track.body
            for line in track.notes:
                typer.echo(f"note: {line}", err=True)
        else:
            b = _dressable(body, up, front)
        walker = b if track is not None else walking_body(b)
        if walker is not b:  # a scan: the default body's skeleton and weights were fitted to it
            typer.echo(f"note: {walker.notes[-1]}", err=True)
        prog, update = _progress_printer()
        with prog:
            res, report = dress_request(b, request, progress=_limited(update, time_limit), note=_size_note)
            # (a scan is dressed as loaded and walks fitted: see engine.scene.walk.walking_body)
            w = walk_cloth(walker, res, request, progress=update, track=track)
        full = walk_report(report, w.report)
        for p in write_walk_outputs(out, walker, w, full) + write_pattern(out, res.spec):
            typer.echo(str(p))
        r = w.report
        typer.echo(f"{report['cloth_vertices']} cloth vertices; dressed in {report['wall_seconds']['total']:.1f} s; "
                   + (f"collision maps of the ramp and a walk cycle rendered in {r['map_prerender_seconds']:.1f} s; "
                      if r["map_prerender_seconds"] else "")
                   + f"walked {r['frames']} frames at {r['fps']:g} fps in {r['wall_seconds']['walking']:.1f} s "
                   f"(realtime factor {r['realtime_factor']:.2f}; {r['ms_per_frame']['total']:.0f} ms/frame); "
                   f"penetration max {r['penetration_mm']['max']:.1f} mm p99 {r['penetration_mm']['p99']:.1f} mm; "
                   f"strain max {100 * r['strain_max']:.1f} %")

    _run(go)


@app.command("bench")
def bench_cmd(
    quick: bool = typer.Option(False, "--quick", help="A reduced run (under two minutes)."),
    out: Path = typer.Option(Path("out/bench"), "--out", help="Output directory."),
):
    """Evidence: seed 003's Table 1 (image vs object space), error against run time (texel, time
    step, cloth edge), scaling, the stability map, a peer (Newton/Warp) when installed. Writes
    report.md, results.json and PNG plots."""

    def go():
        from engine.io.bench_report import write_bench
        from engine.scene.bench import run_bench

        res = run_bench(quick=quick, progress=lambda m: typer.echo(m, err=True))
        for p in write_bench(res, out):
            typer.echo(str(p))
        st = res["stability"]
        typer.echo(f"bench done in {res['total_seconds']:.0f} s; stability: {st['unstable']} unstable cell(s) "
                   f"of {len(st['cells'])}")

    _run(go)


@app.command("garments")
def garments_cmd():
    """List the catalogue garments (names for `tryon drape --garment`), with their sizes."""

    def go():
        from engine.pattern.catalogue import CATALOGUE, SIZES

        width = max(len(n) for n in CATALOGUE)
        for name, (_, description) in CATALOGUE.items():
            typer.echo(f"{name:<{width}}  {description}")
        typer.echo(f"sizes: {', '.join(SIZES)}, auto (--size; women's or men's chart from the body; auto: "
                   "the smallest size that covers the body's girths)")

    _run(go)


pattern_app = typer.Typer(no_args_is_help=True, help="Cutting patterns: import DXF pieces, export patterns to DXF.")
app.add_typer(pattern_app, name="pattern")


@pattern_app.command("import")
def pattern_import_cmd(
    dxf: Path = typer.Argument(..., help="A DXF cutting pattern as pattern CAD exports it (ASTM D6673 / AAMA: a block "
                               "per piece per graded size, the cut line on layer 1 in one or several parts; or "
                               "closed outlines in a plain drawing)."),
    size: Optional[str] = typer.Option(None, "--size", help="Which of the pattern's sizes (default: its sample size, "
                                       "else its middle one)."),
    assembly: Optional[Path] = typer.Option(None, "--assembly", help="An assembly file (JSON) to use instead of the "
                                            "inferred seams: the assembly.json an import writes, corrected (panels "
                                            "by piece and role; seams between spans of their outlines, corners "
                                            "numbered as in pattern.svg), or GarmentCode's kind (stitches by "
                                            "{panel, edge}, each panel's translation and rotation, copy_of)."),
    units: Optional[str] = typer.Option(None, "--units", help="mm, cm, m or in, when the DXF does not say."),
    out: Path = typer.Option(Path("out/pattern"), "--out", help="Directory for pattern.json, pattern.svg and "
                             "assembly.json."),
    as_json: bool = typer.Option(False, "--json", help="Print a summary as JSON: units, sizes, pieces (quantity; per "
                                 "size area cm^2, perimeter cm, notches, grain line), layers, the garment inferred."),
):
    """Read a DXF cutting pattern, every piece in every graded size, and turn one size into a
    GarmentCode specification: without --assembly the garment is inferred (which pieces, which
    seams, where each piece goes on the body). Writes pattern.json (for `tryon drape --garment`;
    drape also takes the DXF itself), pattern.svg (the panels, each seam in its own colour and
    numbered) and assembly.json (the inference, to correct and give back with --assembly)."""

    def go():
        from engine.pattern.dxf import import_pattern, load_assembly, summary
        from engine.pattern.io import save_pattern
        from engine.pattern.validate import check

        asm = load_assembly(assembly) if assembly is not None else None
        imp = import_pattern(dxf, size, units, asm)
        problems = check(imp.spec, dxf.name)  # errors raise; warnings come back
        out.mkdir(parents=True, exist_ok=True)
        written = [save_pattern(imp.spec, out / "pattern.json"), out / "pattern.svg"]
        (out / "pattern.svg").write_text(imp.svg())
        if imp.assembly is not None:
            (out / "assembly.json").write_text(json.dumps(imp.assembly, indent=1))
            written.append(out / "assembly.json")
        p = imp.pattern
        typer.echo(f"{dxf.name}: {len(p.pieces)} pieces x {len(p.sizes)} sizes ({', '.join(p.sizes)}); units "
                   f"{p.units_note}; size {imp.size}: {imp.kind}, {len(imp.spec.pattern.panels)} panels, "
                   f"{len(imp.spec.pattern.stitches)} stitches", err=True)
        for line in ([f"note: {n}" for n in p.notes + imp.notes] + [f"left out: {n}" for n in imp.left_out]
                     + [f"unsure: {n}" for n in imp.unsure] + [str(q) for q in problems]):
            typer.echo(line, err=True)
        if as_json:
            typer.echo(json.dumps(summary(p, imp), indent=1))
        else:
            for w in written:
                typer.echo(str(w))

    _run(go)


@pattern_app.command("export")
def pattern_export_cmd(
    garment: str = typer.Argument(..., help="A catalogue garment (cut for --body in --size) or a pattern file (.json)."),
    body: str = typer.Option("default:female", "--body", help=BODY_HELP),
    size: Optional[str] = typer.Option(None, "--size", help="Catalogue size: XS .. XXL or auto (default M)."),
    out: Path = typer.Option(Path("out/pattern"), "--out", help="Directory for pattern.dxf, assembly.json, pattern.svg."),
):
    """Write a pattern as a DXF for cutting (mm; ASTM/AAMA layers) with its assembly file, which
    `tryon pattern import` reads back as the same pattern."""

    def go():
        from engine.pattern.dxf import assembly_of, write_dxf
        from engine.pattern.io import pattern_to_svg
        from engine.scene.garments import resolve_garment

        is_file = garment.lower().endswith(".json") or Path(garment).exists()
        b = None if is_file else _body(body, None, None)
        spec, _, name = resolve_garment(garment, b, None if is_file else size)
        out.mkdir(parents=True, exist_ok=True)
        typer.echo(str(write_dxf(spec, out / "pattern.dxf")))
        (out / "assembly.json").write_text(json.dumps(assembly_of(spec), indent=2))
        typer.echo(str(out / "assembly.json"))
        (out / "pattern.svg").write_text(pattern_to_svg(spec, edge_numbers=True))
        typer.echo(str(out / "pattern.svg"))
        typer.echo(f"{name}: {len(spec.pattern.panels)} panels, {len(spec.pattern.stitches)} stitches", err=True)

    _run(go)


def main() -> None:
    app()


if __name__ == "__main__":
    main()

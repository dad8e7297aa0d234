"""GARMENT arguments: a catalogue name or a pattern file -> (spec, placement, name)."""

from __future__ import annotations

from pathlib import Path

from engine.body.types import Body
from engine.errors import InputError
from engine.pattern.io import load_pattern


def resolve_garment(arg: str, body: Body, size: str | None = "M"):
    """Returns (PatternSpec, placement function or None for the spec's own, display name).
    size: catalogue size; None means the default (M) for catalogue garments."""
    path = Path(arg)
    if path.suffix.lower() == ".json" or path.exists():
        if size is not None:
            raise InputError(f"--size {size} applies to catalogue garments; a pattern file ({path.name}) "
                             "has its own size: leave --size out")
        spec = load_pattern(path)
        return spec, None, path.name
    size = size or "M"
    from engine.pattern.catalogue import CATALOGUE, make_garment

    if arg in CATALOGUE:
        return make_garment(arg, body, size)
    names = ", ".join(CATALOGUE)
    raise InputError(f"garment '{arg}' is neither a pattern file nor a catalogue garment ({names})")


def add_size_hint(err: Exception, arg: str, body: Body, size: str | None) -> None:
    """A catalogue garment that came out too small for the body (the drape marks such an error
    `too_small`: it could not be sewn, or ended stretched): add to the error's message the size
    --size auto picks for this body, when that is larger than the one asked for."""
    from engine.pattern.catalogue import AUTO, CATALOGUE, SIZES, recommend_size

    size = size or "M"
    if arg not in CATALOGUE or size == AUTO or not getattr(err, "too_small", False):
        return
    try:
        best = recommend_size(arg, body)
    except InputError:
        return
    if SIZES.index(best) > SIZES.index(size):
        err.args = (f"{err} (for this body's girths --size auto picks {best})",) + tuple(err.args[1:])

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

"""GARMENT arguments: a catalogue name or a pattern file -> (spec, placement, name)."""

from __future__ import annotations

from pathlib import Path

from engine.body.types import Body
from engine.errors import InputError
from engine.pattern.io import load_pattern


def resolve_garment(arg: str, body: Body, size: str = "M"):
    """Returns (PatternSpec, placement function or None for the spec's own, display name)."""
    path = Path(arg)
    if path.suffix.lower() == ".json" or path.exists():
        spec = load_pattern(path)
        return spec, None, path.name
    try:
        from engine.pattern.catalogue import CATALOGUE, make_garment
    except ImportError:  # the catalogue is not built yet
        CATALOGUE, make_garment = {}, None
    if arg in CATALOGUE:
        return make_garment(arg, body, size)
    names = ", ".join(CATALOGUE) or "(none yet)"
    raise InputError(f"garment '{arg}' is neither a pattern file nor a catalogue garment ({names})")

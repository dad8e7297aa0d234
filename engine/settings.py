"""The engine's settings (TRYON_* environment variables), read once by an entry point.

    TRYON_GL              OpenGL backend: egl or osmesa            (EGL if it works, else OSMesa)
    TRYON_CACHE           cache directory (built default bodies)   (~/.cache/tryon)
    TRYON_MAX_TRIANGLES   refuse bodies with more triangles        (2,000,000)
    TRYON_QUERY_HELPER    0: no helper thread shares the collision queries   (1)
    TRYON_DEBUG           1: an internal error shows its traceback (the CLI)  (0)

An entry point (the `tryon` command, the service, each worker process) reads them once with
`EngineSettings()` and hands them to the engine with `use(settings)`; the engine asks
`current()`. A library caller that set none gets the environment's, read once on first use.
They are process-wide by nature: the GL backend is fixed when PyOpenGL is first imported.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, ValidationError, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from engine.errors import InputError


def _default_cache() -> Path:
    return Path.home() / ".cache" / "tryon"


class EngineSettings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="TRYON_", env_ignore_empty=True, extra="ignore", frozen=True)

    gl: Literal["egl", "osmesa"] | None = Field(None, description="force the OpenGL backend")
    cache: Path = Field(default_factory=_default_cache, description="cache directory (built default bodies)")
    max_triangles: int = Field(2_000_000, gt=0, description="refuse bodies with more triangles")
    query_helper: bool = Field(True, description="a helper thread shares the collision queries")
    debug: bool = Field(False, description="an internal error shows its traceback")

    @field_validator("gl", mode="before")
    @classmethod
    def _gl_lower(cls, v):
        return v.strip().lower() or None if isinstance(v, str) else v

    @field_validator("max_triangles", mode="before")
    @classmethod
    def _count(cls, v):
        # "2e6" is a count too
        try:
            return int(float(v)) if isinstance(v, str) else v
        except ValueError:
            return v


_current: EngineSettings | None = None


def use(settings: EngineSettings) -> EngineSettings:
    """Make `settings` the process's (entry points call this once, before the engine runs)."""
    global _current
    _current = settings
    return settings


def current() -> EngineSettings:
    """The settings an entry point gave; else the environment's, read now and kept."""
    global _current
    if _current is None:
        _current = read(EngineSettings)
    return _current


def read(cls: type[EngineSettings]) -> EngineSettings:
    """`cls()` from the environment; a bad value is an InputError that names the variable."""
    try:
        return cls()
    except ValidationError as e:
        raise InputError(describe(e)) from None


def describe(error) -> str:
    """A one-line message for a pydantic ValidationError raised while reading settings."""
    parts = []
    for e in error.errors():
        name = "_".join(str(x) for x in e.get("loc", ())).upper()
        name = name if name.startswith("TRYON_") else "TRYON_" + name  # aliased fields carry it
        parts.append(f"{name}={e.get('input')!r}: {e.get('msg')}")
    return "bad setting: " + "; ".join(parts) + " (fix or unset the environment variable)"

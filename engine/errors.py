"""Errors the engine raises for bad input. The CLI and the service turn them into a one-line
message and a non-zero exit / a JSON error; anything else escaping is a bug."""

import struct
import zipfile
import zlib


class TryonError(Exception):
    """Base class: the message says what is wrong and how to fix it."""


class InputError(TryonError):
    """A file or parameter the user gave cannot be used (broken mesh, absurd value, ...)."""


class GLUnavailableError(TryonError):
    """No headless OpenGL context (neither EGL nor OSMesa) could be created."""


class SimulationError(TryonError):
    """A simulation stage did not reach its goal (e.g. seams stayed open, energy blew up)."""


class TimeLimitError(TryonError):
    """A try-on ran past the wall-clock time it was given (engine.scene.drape.time_limited).
    Not a SimulationError: the fabric ladder does not take it for a garment that did not fit."""


# What malformed bytes make parsers and the libraries under them raise (trimesh, json, zipfile,
# struct, NumPy, SciPy): at a parser's public entry they become one InputError.
MALFORMED = (ValueError, TypeError, LookupError, AttributeError, ArithmeticError, RecursionError,
             UnicodeError, EOFError, OSError, MemoryError, AssertionError, struct.error, zipfile.BadZipFile,
             zipfile.LargeZipFile, zlib.error)


class reading:
    """`with reading(name, "an OBJ mesh"):` -- a malformed-input exception inside becomes an
    InputError that names the file and what it should have been; the project's own errors pass."""

    def __init__(self, name: str, what: str):
        self.name, self.what = name, what

    def __enter__(self):
        return self

    def __exit__(self, kind, e, tb):
        if kind is None or isinstance(e, TryonError) or not isinstance(e, MALFORMED):
            return False
        if isinstance(e, MemoryError):
            why = "it needs more memory than a file of its kind may take"
        elif isinstance(e, RecursionError):
            why = "it is nested too deeply"
        else:
            first = (str(e).splitlines() or [""])[0][:120]
            why = f"{type(e).__name__}: {first}" if first else type(e).__name__
        raise InputError(f"{self.name} could not be read as {self.what} ({why}): check the file") from None


def _file_name(*args, **kwargs) -> str:
    return str(args[0]).replace("\\", "/").rsplit("/", 1)[-1] if args else "the input"


def parser(what: str, name_of=_file_name):
    """Decorator for a parser's public entry: its body runs inside `reading(name, what)`; the name
    is the first argument's file name unless `name_of(*args, **kwargs)` says."""
    import functools

    def wrap(fn):
        @functools.wraps(fn)
        def run(*args, **kwargs):
            with reading(name_of(*args, **kwargs), what):
                return fn(*args, **kwargs)
        return run
    return wrap

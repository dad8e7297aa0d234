"""Errors the engine raises for bad input. The CLI and the service turn them into a one-line
message and a non-zero exit / a JSON error; anything else escaping is a bug."""


class TryonError(Exception):
    """Base class: the message says what is wrong and how to fix it."""


class InputError(TryonError):
    """A file or parameter the user gave cannot be used (broken mesh, absurd value, ...)."""


class GLUnavailableError(TryonError):
    """No headless OpenGL context (neither EGL nor OSMesa) could be created."""


class SimulationError(TryonError):
    """A simulation stage did not reach its goal (e.g. seams stayed open, energy blew up)."""

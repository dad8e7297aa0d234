"""Coverage-guided fuzzing of one parser with atheris (libFuzzer): the same targets and the same
verdicts as tests/fuzz/run.py, but atheris grows its inputs from the seeds by the code they reach.
An input that fails (an exception other than the project's TryonError, NaN/inf accepted, a
message of several lines) stops the run and is written as crash-<sha1> in the working folder.

    .venv/bin/python -m tests.fuzz.atheris_run obj -atheris_runs=20000 -max_total_time=300
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path


def main() -> None:
    import atheris

    with atheris.instrument_imports(include=["engine", "app"]):  # coverage of our readers, not the libraries'
        import engine.body.animation  # noqa: F401
        import engine.body.gltf_anim  # noqa: F401
        import engine.body.load  # noqa: F401
        import engine.pattern.dxf  # noqa: F401
        import engine.pattern.io  # noqa: F401
        import engine.pattern.validate  # noqa: F401
        from tests.fuzz.targets import TARGETS
    name, args = sys.argv[1], sys.argv[2:]
    target = TARGETS[name]
    corpus = Path(tempfile.mkdtemp(prefix=f"atheris-{name}-"))
    for k, s in enumerate(target.seeds()):
        (corpus / f"seed{k}").write_bytes(s)
    from engine.errors import TryonError

    def one(data: bytes) -> None:
        try:
            result = target.parse(data)
        except TryonError as e:
            if "\n" in str(e) or not str(e):
                raise AssertionError(f"a refusal of several lines or none: {e!r}") from None
            return
        if not target.finite(result):
            raise AssertionError("NaN or inf accepted")

    atheris.Setup([sys.argv[0], *args, str(corpus)], one)
    atheris.Fuzz()


if __name__ == "__main__":
    main()

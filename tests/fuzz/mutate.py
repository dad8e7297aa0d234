"""Hypothesis strategies that turn a valid seed into a malformed input: byte edits for any
format, number swaps for text formats (1e308, nan, -1, 2**32 ...), structure edits for JSON
(a value replaced by another type, huge or nested), and for GLB and zip containers edits of the
JSON chunk, the binary chunk, the members and their stated sizes."""

from __future__ import annotations

import io
import itertools
import json
import re
import struct
import zipfile

from hypothesis import strategies as st

NUMBERS = [b"1e308", b"-1e308", b"1e39", b"nan", b"inf", b"-inf", b"0", b"-1", b"4294967295", b"2147483648",
           b"99999999999999999999999", b"1e-320", b"3e9", b"-0"]
NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
EXTREME = [1e308, -1e308, float("nan"), float("inf"), 0, -1, 2 ** 32, 3_000_000_000, 10 ** 30, 1e-320, True, None,
           "", "x" * 1000, [], {}]

json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-(2 ** 64), 2 ** 64), st.floats(allow_nan=True, allow_infinity=True),
              st.text(max_size=20), st.sampled_from(EXTREME)),
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)),
    max_leaves=20)


@st.composite
def byte_edits(draw, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(draw(st.integers(1, 6))):
        op = draw(st.sampled_from(["flip", "insert", "delete", "dup", "truncate", "zero"]))
        i = draw(st.integers(0, max(len(b) - 1, 0)))
        n = draw(st.integers(1, 64))
        if op == "flip" and b:
            b[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "insert":
            b[i:i] = draw(st.binary(min_size=1, max_size=16))
        elif op == "delete":
            del b[i:i + n]
        elif op == "dup":
            b[i:i] = b[i:i + draw(st.integers(1, 4096))] * draw(st.integers(1, 8))
        elif op == "truncate":
            del b[i:]
        elif op == "zero":
            b[i:i + n] = bytes(len(b[i:i + n]))
    return bytes(b)


@st.composite
def number_edits(draw, data: bytes) -> bytes:
    spans = [m.span() for m in NUMBER.finditer(data[:200_000])]
    if not spans:
        return draw(byte_edits(data))
    b = data
    for _ in range(draw(st.integers(1, 8))):
        s, e = spans[draw(st.integers(0, len(spans) - 1))]
        b = b[:s] + draw(st.sampled_from(NUMBERS)) + b[e:]
        spans = [m.span() for m in NUMBER.finditer(b[:200_000])]
        if not spans:
            break
    return b


def _paths(obj, prefix=()):
    yield prefix
    if len(prefix) > 40:  # below a nest made by an earlier edit: nothing new to reach
        return
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, prefix + (i,))


@st.composite
def json_edits(draw, doc):
    doc = json.loads(json.dumps(doc))
    for _ in range(draw(st.integers(1, 4))):
        paths = list(itertools.islice((p for p in _paths(doc) if p), 100_000))
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        op = draw(st.sampled_from(["replace", "replace", "delete", "nest", "grow"]))
        if op == "replace":
            parent[path[-1]] = draw(json_values)
        elif op == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif op == "nest":
            v = parent[path[-1]]
            for _ in range(draw(st.sampled_from([2, 50, 5000]))):
                v = [v]
            parent[path[-1]] = v
        elif op == "grow" and isinstance(parent[path[-1]], list) and parent[path[-1]]:
            n = draw(st.sampled_from([2, 100, 3000]))
            if len(_dumps(parent[path[-1]])) * n < 20_000_000:  # the input, not the mutator, should be big
                # copies, not n references to one list: a later edit inside must not multiply again
                try:
                    parent[path[-1]] = json.loads(_dumps(parent[path[-1]] * n))
                except RecursionError:  # a deep nest from an earlier edit: left as it is
                    pass
    return doc


def _dumps(doc) -> bytes:
    try:
        return json.dumps(doc).encode()
    except (RecursionError, ValueError):
        return b"[" * 100_000


@st.composite
def json_inputs(draw, data: bytes) -> bytes:
    if draw(st.booleans()):
        return _dumps(draw(json_edits(json.loads(data))))
    return draw(st.one_of(byte_edits(data), number_edits(data)))


def _glb_split(data: bytes):
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + jlen])
    rest = data[20 + jlen:]
    return doc, rest[8:]


def _glb(doc, binary: bytes) -> bytes:
    js = _dumps(doc)
    js += b" " * ((-len(js)) % 4)
    binary += b"\0" * ((-len(binary)) % 4)
    out = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(out)) + out


@st.composite
def glb_inputs(draw, data: bytes) -> bytes:
    doc, binary = _glb_split(data)
    how = draw(st.sampled_from(["json", "json", "binary", "bytes", "cycle"]))
    if how == "json":
        return _glb(draw(json_edits(doc)), binary)
    if how == "binary":
        return _glb(doc, draw(byte_edits(binary)))
    if how == "cycle" and doc.get("nodes"):  # a node hierarchy that loops back
        n = len(doc["nodes"])
        i, j = draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))
        doc["nodes"][i].setdefault("children", []).append(j)
        doc["nodes"][j].setdefault("children", []).append(i)
        return _glb(doc, binary)
    return draw(byte_edits(data))


@st.composite
def zip_inputs(draw, data: bytes) -> bytes:
    how = draw(st.sampled_from(["member", "member", "bytes", "bomb", "names"]))
    if how == "bytes":
        return draw(byte_edits(data))
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        members = [(n, z.read(n)) for n in z.namelist()]
    if how == "member":
        k = draw(st.integers(0, len(members) - 1))
        members[k] = (members[k][0], draw(st.one_of(byte_edits(members[k][1]), number_edits(members[k][1]))))
    elif how == "bomb":  # one member that inflates far more than OBJ text does
        members.append(("frame_999.obj", b"v 0 0 0\n" + b"\0" * draw(st.sampled_from([10 ** 6, 5 * 10 ** 7]))))
    else:
        members = [(draw(st.sampled_from(["../x.obj", "/abs.obj", "a/" * 100 + "b.obj", "f.OBJ", "x.txt"])), b)
                   for _, b in members]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for n, b in members:
            z.writestr(n, b)
    return buf.getvalue()


def inputs(kind: str, data: bytes):
    """The strategy of malformed inputs grown from seed `data`."""
    return {"text": lambda d: st.one_of(byte_edits(d), number_edits(d)), "binary": byte_edits,
            "json": json_inputs, "glb": glb_inputs, "zip": zip_inputs}[kind](data)

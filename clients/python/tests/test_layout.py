"""The Python payloads cannot drift from the Rust ones: ``ipc/CONTRACT.md``'s layout, codes and
constants tables are generated from the Rust types (and checked by ``cargo test -p herb-ipc
--test contract_doc``); here every Python structure is compared with them, field by field
(name, order, type, offset, size), as a whole (size, alignment, iceoryx2 type name), and every
code and constant.
"""

import ctypes
import re
from pathlib import Path

import iceoryx2 as iox2
import pytest

from herb_client import payloads as p

CONTRACT = Path(__file__).resolve().parents[3] / "ipc" / "CONTRACT.md"

_SCALARS = {
    ctypes.c_uint16: "u16",
    ctypes.c_uint32: "u32",
    ctypes.c_uint64: "u64",
    ctypes.c_float: "f32",
    ctypes.c_double: "f64",
}


def block(name: str) -> list[list[str]]:
    """The rows of the generated table ``name`` (cells stripped of backticks)."""
    text = CONTRACT.read_text()
    m = re.search(rf"<!-- {name}:begin -->\n(.*?)<!-- {name}:end -->", text, re.S)
    assert m, f"CONTRACT.md has no {name} block"
    rows = []
    for line in m.group(1).splitlines():
        if not line.startswith("|") or line.startswith("| ---"):
            continue
        cells = [c.strip().strip("`") for c in line.strip("|").split("|")]
        rows.append(cells)
    return rows[1:]  # without the heading


def rust_name(t) -> str:
    """The contract's type name of a ctypes field type."""
    if t in _SCALARS:
        return _SCALARS[t]
    if issubclass(t, ctypes.Array):
        return f"[{rust_name(t._type_)}; {t._length_}]"
    return t.__name__


def layouts() -> dict:
    out: dict = {}
    for payload, field, ty, offset, size, meaning in block("layout"):
        entry = out.setdefault(payload, {"fields": []})
        if field == "(whole)":
            entry["align"] = int(ty.removeprefix("align "))
            entry["size"] = int(size)
            entry["type_name"] = re.search(r"type name `?([\w:]+)", meaning).group(1)
        else:
            entry["fields"].append((field, ty, int(offset), int(size)))
    return out


def test_every_payload_has_the_contracts_layout_and_type_name():
    table = layouts()
    assert set(table) == set(p.PAYLOADS), "the same payloads on both sides"
    for name, want in table.items():
        cls = p.PAYLOADS[name]
        got = [
            (f, rust_name(t), getattr(cls, f).offset, getattr(cls, f).size)
            for f, t in cls._fields_
        ]
        assert got == want["fields"], name
        assert ctypes.sizeof(cls) == want["size"], name
        assert ctypes.alignment(cls) == want["align"], name
        assert cls.type_name() == want["type_name"], name
        # What iceoryx2 registers for it.
        assert iox2.get_type_name(cls) == want["type_name"], name


def test_every_code_is_the_contracts():
    rows = block("codes")
    tables: dict = {}
    for enum_name, member, code in rows:
        tables.setdefault(enum_name, {})[int(code)] = member
    assert tables.pop("SimBound") == dict(enumerate(p.SimBound))
    assert set(tables) == set(p.CODES)
    for enum_name, members in tables.items():
        ours = {m.value: p.code_name(m) for m in p.CODES[enum_name]}
        assert ours == members, enum_name


def test_the_constants_are_the_contracts():
    rows = dict((k, v) for k, v in block("constants"))
    assert int(rows["PROTOCOL_VERSION"]) == p.PROTOCOL_VERSION
    assert int(rows["DOF"]) == p.DOF
    assert int(rows["HEIGHTMAP_MAX_CELLS"]) == p.HEIGHTMAP_MAX_CELLS
    assert int(rows["MAX_JOB_OBJECTS"]) == p.MAX_JOB_OBJECTS
    assert int(rows["NO_OBJECT"].split()[0]) == p.NO_OBJECT


def test_a_field_out_of_place_is_caught(monkeypatch):
    """The check is not vacuous: a structure with two fields swapped fails it."""

    class PackJobReply(ctypes.Structure):
        _fields_ = [
            ("header", p.Header),
            ("job_id", ctypes.c_uint64),
            ("reason", ctypes.c_uint32),
            ("accepted", ctypes.c_uint32),
            ("detail", ctypes.c_uint32),
            ("reserved", ctypes.c_uint32),
        ]

        @classmethod
        def type_name(cls):
            return "herb::v1::PackJobReply"

    monkeypatch.setitem(p.PAYLOADS, "PackJobReply", PackJobReply)
    with pytest.raises(AssertionError, match="PackJobReply"):
        test_every_payload_has_the_contracts_layout_and_type_name()


def test_a_service_of_another_wire_version_is_named_with_both_versions():
    """A ``status`` service created with wire version 1's ``Status`` (144 bytes, type name
    ``herb::v1::Status``), as an older herbd creates it: the client says both versions at once
    instead of retrying until its timeout."""
    import os

    from herb_client import Herb, WireVersionMismatch

    class Status(ctypes.Structure):  # wire version 1's layout: the header and 120 bytes
        _fields_ = [("header", p.Header), ("fields", ctypes.c_uint64 * 15)]

        @classmethod
        def type_name(cls) -> str:
            return "herb::v1::Status"

    assert ctypes.sizeof(Status) == 144
    prefix = f"pyversion{os.getpid()}"
    iox2.set_log_level(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    old = (
        node.service_builder(iox2.ServiceName.new(f"{prefix}/status"))
        .publish_subscribe(Status)
        .history_size(1)
        .subscriber_max_buffer_size(256)
        .max_publishers(4)
        .open_or_create()
    )
    with pytest.raises(WireVersionMismatch) as e:
        Herb(prefix, timeout_s=5.0)
    assert (e.value.ours, e.value.theirs) == (p.PROTOCOL_VERSION, 1)
    assert "herb::v1::Status" in str(e.value) and "version 2" in str(e.value)
    del old

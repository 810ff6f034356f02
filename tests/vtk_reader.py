"""A reader of VTK XML files with raw appended data (the layout pyevtk writes), written from the
VTK file-format specification independently of the writer: the tests read back what a run wrote.

A file is its XML header, then `<AppendedData encoding="raw">_` and the binary blocks; each
DataArray's `offset` points at a block: a UInt64 byte count (header_type="UInt64"), then the
values (byte_order="LittleEndian").
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

_TYPES = {"Float64": "<f8", "Float32": "<f4", "Int64": "<i8", "Int32": "<i4", "UInt8": "u1",
          "Int8": "i1", "UInt64": "<u8"}


def read_vtk(path) -> dict:
    """{"kind": the dataset element, "Points"/"Coordinates"/"PointData"/"CellData"/"FieldData":
    name -> array ((n, k) for k components)} of a .vtu/.vtr/.vts file."""
    raw = Path(path).read_bytes()
    mark = b'<AppendedData encoding="raw">'
    head, _, tail = raw.partition(mark)
    assert tail, f"{path}: no raw appended data"
    data = tail[tail.index(b"_") + 1:]
    root = ET.fromstring(head + b"</VTKFile>")
    assert root.get("header_type") == "UInt64" and root.get("byte_order") == "LittleEndian"
    out: dict = {"kind": root.get("type")}
    for parent in root.iter():
        for arr in parent.findall("DataArray"):
            off = int(arr.get("offset"))
            n = int(np.frombuffer(data[off:off + 8], "<u8")[0])
            values = np.frombuffer(data[off + 8:off + 8 + n], _TYPES[arr.get("type")])
            k = int(arr.get("NumberOfComponents", "1"))
            out.setdefault(parent.tag, {})[arr.get("Name")] = (values.reshape(-1, k) if k > 1
                                                               else values)
    return out


def read_pvd(path) -> list[tuple[float, str]]:
    """The (time, file) entries of a ParaView collection, in file order."""
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]

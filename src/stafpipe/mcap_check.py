"""Integrity of an MCAP file, record by record, and recovery of every intact chunk.

An MCAP file (the MCAP specification, mcap.dev) is: magic, Header, the data section (Schema, Channel, Chunk,
MessageIndex, ... records), DataEnd (CRC-32 of the data section), the summary section, Footer (CRC-32 of the summary
section), magic. Every chunk carries the CRC-32 of its records. `check` verifies all four (magic, chunk, data section,
summary), so a flipped byte anywhere is found; `intact_records` walks the data section chunk by chunk and steps over a
damaged chunk (or a damaged record length) to the next chunk whose CRC holds, so nothing intact after a damage is lost.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, McapRecord, Message, Schema
from mcap.stream_reader import breakup_chunk

MAGIC = b"\x89MCAP0\r\n"
_FOOTER = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, summary_crc
_OPCODES = {int(o) for o in Opcode}


BLOCK = 1 << 20
"""Bytes read at a time where a file is scanned or its CRC computed: memory stays bounded for a log of any size."""


class FileView:
    """A file's bytes, read only where they are asked for, with the parts of the `bytes` interface the scan uses
    (len, an index, a slice, find): `check` walks a log of any size in memory bounded by its largest record. The
    last block read is kept, so that the many short reads and searches of a resync over a damaged stretch cost what
    they cost on `bytes`."""

    def __init__(self, f: BinaryIO) -> None:
        self.f = f
        self.size = os.fstat(f.fileno()).st_size
        self._start, self._block = 0, b""

    def __len__(self) -> int:
        return self.size

    def _cover(self, start: int, stop: int) -> int:
        """Keep bytes start..stop in the block; their offset in it."""
        if not (self._start <= start and stop <= self._start + len(self._block)):
            self._start = start - start % BLOCK
            self.f.seek(self._start)
            self._block = self.f.read(max(stop, self._start + 2 * BLOCK) - self._start)
        return start - self._start

    def _read(self, start: int, stop: int) -> bytes:
        at = self._cover(start, stop)
        return self._block[at : at + stop - start]

    def __getitem__(self, key: int | slice) -> Any:
        if isinstance(key, slice):
            start, stop, _ = key.indices(self.size)
            if stop - start > BLOCK:  # a chunk or a whole record: read it alone, keep the block
                self.f.seek(start)
                return self.f.read(stop - start)
            return self._read(start, max(start, stop))
        index = key + self.size if key < 0 else key
        if not 0 <= index < self.size:
            raise IndexError(key)
        return self._read(index, index + 1)[0]

    def find(self, sub: bytes, start: int = 0) -> int:
        pos = max(start, 0)
        while pos < self.size:
            stop = min(pos + BLOCK + len(sub) - 1, self.size)
            at = self._cover(pos, stop)
            found = self._block.find(sub, at, at + stop - pos)
            if found >= 0:
                return self._start + found
            pos += BLOCK
        return -1


Data = bytes | FileView


def crc_of(data: Data, start: int, end: int) -> int:
    """CRC-32 of data[start:end], read a block at a time."""
    crc = 0
    for pos in range(start, end, BLOCK):
        crc = zlib.crc32(data[pos : min(pos + BLOCK, end)], crc)
    return crc


def _unpack(fmt: str, data: Data, offset: int) -> tuple[Any, ...]:
    return struct.unpack(fmt, data[offset : offset + struct.calcsize(fmt)])


@dataclass
class Damage:
    offset: int
    """Byte offset in the file where the damaged part starts."""
    what: str

    def __str__(self) -> str:
        return f"byte {self.offset}: {self.what}"


@dataclass
class Scan:
    """What `intact_records` found in the data section."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    chunks: int = 0
    damaged: list[Damage] = field(default_factory=list)
    data_end: int | None = None
    """Offset of the DataEnd record, if one was reached."""


def _record_at(data: Data, pos: int) -> tuple[int, int] | None:
    """(opcode, end offset) of a record that starts at `pos` and fits the file, or None."""
    if pos + 9 > len(data):
        return None
    op = data[pos]
    end = pos + 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    return (op, end) if op in _OPCODES and end <= len(data) else None


def _unreadable(data: Data, pos: int) -> str:
    if pos + 9 > len(data) or (
        data[pos] in _OPCODES and pos + 9 + int.from_bytes(data[pos + 1 : pos + 9], "little") > len(data)
    ):
        return "a record runs past the end of the file (truncated)"
    return f"unknown record opcode {data[pos]}"


def _definition(data: Data, pos: int, end: int) -> Schema | Channel:
    """The Schema or Channel record at `pos` (outside chunks: no CRC of its own, the data section's covers it)."""
    kind = Schema if data[pos] == Opcode.SCHEMA else Channel
    return kind.read(ReadDataStream(io.BytesIO(data[pos + 9 : end])))


def _footer(data: Data) -> tuple[int, int, int] | None:
    """(offset of the Footer record, summary_start, summary_crc), or None where the file has no Footer there."""
    footer = len(data) - 8 - _FOOTER
    if footer < 8 or data[-8:] != MAGIC or data[footer] != Opcode.FOOTER:
        return None
    summary_start, _, summary_crc = _unpack("<QQI", data, footer + 9)
    return footer, summary_start, summary_crc


def _chunk_records(data: Data, pos: int, end: int) -> list[McapRecord] | None:
    """The records of the chunk at `pos`, or None where it does not parse or fails its CRC."""
    try:
        chunk = Chunk.read(ReadDataStream(io.BytesIO(data[pos + 9 : end])))
        return breakup_chunk(chunk, validate_crc=True)
    except Exception:  # noqa: BLE001 - a damaged chunk fails in many ways (CRC, decompression, lengths)
        return None


def _resync(data: Data, start: int) -> int | None:
    """The first offset >= start where an intact chunk or a DataEnd record begins (lengths and CRCs must hold)."""
    candidates = (bytes([Opcode.CHUNK]), bytes([Opcode.DATA_END]))
    pos = start
    while True:
        found = [q for q in (data.find(c, pos) for c in candidates) if q >= 0]
        if not found:
            return None
        q = min(found)
        rec = _record_at(data, q)
        if rec is not None:
            op, end = rec
            follows = data[end : end + 1]  # a DataEnd is followed by the summary's first record or the Footer
            if op == Opcode.DATA_END and end - q == 9 + 4 and (not follows or follows[0] in _OPCODES):
                return q
            if op == Opcode.CHUNK and _chunk_records(data, q, end) is not None:
                return q
        pos = q + 1


def intact_records(data: Data, keep_messages: bool = True) -> Scan:
    """Every schema, channel and message of the data section that lies in an intact chunk (or outside chunks); with
    `keep_messages` false, the messages are checked and dropped (a check of a large log keeps none in memory)."""
    scan = Scan()
    if data[:8] != MAGIC:
        scan.damaged.append(Damage(0, "not the MCAP magic"))
    pos = 8
    while pos < len(data):
        rec = _record_at(data, pos)
        records: list[McapRecord] | None = None
        if rec is not None and rec[0] == Opcode.CHUNK:
            records = _chunk_records(data, pos, rec[1])
        if rec is None or (rec[0] == Opcode.CHUNK and records is None):
            scan.damaged.append(Damage(pos, "chunk fails its CRC or does not parse" if rec else _unreadable(data, pos)))
            nxt = _resync(data, pos + 1)
            if nxt is None:
                break
            pos = nxt
            continue
        op, end = rec
        if op == Opcode.DATA_END:
            scan.data_end = pos
            _summary_definitions(data, end, scan)
            break
        if op == Opcode.CHUNK:
            scan.chunks += 1
        elif op in (Opcode.SCHEMA, Opcode.CHANNEL):
            try:
                records = [_definition(data, pos, end)]
            except Exception:  # noqa: BLE001 - a damaged record fails in many ways
                scan.damaged.append(Damage(pos, "a schema or channel record does not parse"))
        for r in records or []:
            if isinstance(r, Schema):
                scan.schemas[r.id] = r
            elif isinstance(r, Channel):
                scan.channels[r.id] = r
            elif isinstance(r, Message) and keep_messages:
                scan.messages.append(r)
        pos = end
    return scan


def seal_data_crc(f: BinaryIO) -> None:
    """Write the data section's CRC into the DataEnd record of a finished MCAP file open for update (the ROS 2
    writer leaves it 0, "not computed", so a flipped byte between chunks would go unseen)."""
    data = FileView(f)
    found = _footer(data)
    if found is None:
        raise ValueError("no Footer record at the end")
    footer, summary_start, _ = found
    data_end = (summary_start or footer) - 13
    if data_end < 8 or data[data_end] != Opcode.DATA_END:
        raise ValueError("no DataEnd record before the summary")
    crc = crc_of(data, 0, data_end)
    f.seek(data_end + 9)
    f.write(struct.pack("<I", crc))


def _summary_definitions(data: Data, pos: int, scan: Scan) -> None:
    """Schemas and channels repeated in the summary section (the writer repeats them), for those whose chunk is
    damaged; a damaged summary is reported by `check`, not here."""
    while (rec := _record_at(data, pos)) is not None and rec[0] != Opcode.FOOTER:
        op, end = rec
        if op in (Opcode.SCHEMA, Opcode.CHANNEL):
            try:
                record = _definition(data, pos, end)
            except Exception:  # noqa: BLE001
                return
            if isinstance(record, Schema):
                scan.schemas.setdefault(record.id, record)
            else:
                scan.channels.setdefault(record.id, record)
        pos = end


def check(data: Data, scan: Scan | None = None) -> list[Damage]:
    """Every damage in an MCAP file's bytes: magic, chunk CRCs, the data section's and the summary's CRC (`scan`:
    `intact_records(data)` if the caller has it already)."""
    scan = scan if scan is not None else intact_records(data, keep_messages=False)
    damage = list(scan.damaged)
    if scan.data_end is None:
        damage.append(Damage(len(data), "no DataEnd record: the file is truncated"))
    else:
        (length, crc) = _unpack("<QI", data, scan.data_end + 1)
        if length != 4:
            damage.append(Damage(scan.data_end, "the DataEnd record's length is wrong"))
        elif crc != 0 and crc != crc_of(data, 0, scan.data_end):
            damage.append(Damage(scan.data_end, "the data section's CRC does not match"))
    if len(data) < 8 + _FOOTER or data[-8:] != MAGIC:
        damage.append(Damage(max(0, len(data) - 8), "no closing MCAP magic: the file is truncated or damaged"))
        return damage
    found = _footer(data)
    if found is None:
        damage.append(Damage(len(data) - 8 - _FOOTER, "no Footer record"))
        return damage
    footer, summary_start, summary_crc = found
    if summary_start > footer or (summary_start and summary_start < (scan.data_end or 0)):
        damage.append(Damage(footer, "the Footer's summary offset is out of range"))
    elif summary_crc != 0 and summary_crc != crc_of(data, summary_start or footer, len(data) - 8 - 4):
        damage.append(Damage(summary_start or footer, "the summary section's CRC does not match"))
    return damage

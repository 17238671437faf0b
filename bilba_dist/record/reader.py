"""Reading planning logs back: every message decoded, with one clear error for a bad file."""

import io
import json
import struct
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from jsonschema import Draft202012Validator
from jsonschema.exceptions import best_match
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer

from bilba_dist.errors import BilbaError
from bilba_dist.files import PathArg, read_bytes
from bilba_dist.record.schemas import TOPICS

MAGIC = b"\x89MCAP0\r\n"
#: Top-level records that hold no schema, channel or message (indexes, statistics...).
_OTHER_RECORDS = {o.value for o in Opcode} - {
    Opcode.CHUNK,
    Opcode.SCHEMA,
    Opcode.CHANNEL,
    Opcode.MESSAGE,
}


@dataclass
class Log:
    path: Path
    #: Every message in file order: (topic, log time [ns], data).
    records: list[tuple[str, int, bytes]] = field(default_factory=list)
    _decoded: dict[str, list[Any]] = field(default_factory=dict, repr=False)

    @cached_property
    def messages(self) -> dict[str, list[bytes]]:
        """The messages by topic, in file order (a topic with none: an empty list)."""
        by_topic: dict[str, list[bytes]] = defaultdict(list)
        for topic, _, data in self.records:
            by_topic[topic].append(data)
        return by_topic

    def json(self, topic: str) -> list[dict[str, Any]]:
        """The messages of ``topic``, decoded (each once)."""
        if topic not in self._decoded:
            self._decoded[topic] = [
                self._decode(topic, k, data) for k, data in enumerate(self.messages.get(topic, []))
            ]
        return self._decoded[topic]

    def _decode(self, topic: str, k: int, data: bytes) -> Any:
        """Message ``k`` of ``topic``; one BilbaError line when it is not JSON."""
        try:
            return json.loads(data)
        except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
            raise BilbaError(
                f"{self.path}: message {k} on {topic} is not JSON ({exc}); "
                "not a log as bilba writes it"
            ) from None

    def check(self) -> None:
        """Raise one BilbaError line for the first message of a bilba topic that does not
        match the topic's schema (bilba_dist.record.schemas). Checking costs more than
        reading (2.7x on a puzzle log), so readers index messages unchecked and call this
        only when one fails on a message's shape (`reading`)."""
        for topic, schema in TOPICS.items():
            validator = Draft202012Validator(schema)
            for k, message in enumerate(self.json(topic)):
                error = best_match(validator.iter_errors(message))
                if error is not None:
                    where = "/".join(map(str, error.absolute_path)) or "the message"
                    raise BilbaError(
                        f"{self.path}: message {k} on {topic}, at {where}: "
                        f"{error.message[:200]}; not a log as bilba writes it"
                    )

    @property
    def metadata(self) -> dict[str, Any]:
        (first,) = self.json("/metadata")[:1] or [{}]
        return first


@contextmanager
def reading(log: Log) -> Iterator[Log]:
    """Read ``log`` inside: where a reader fails on a message's shape (a key missing, a
    number where a list is), name the message that does not match its schema in one
    BilbaError line; when every message matches, the failure is a bug and is raised as is."""
    try:
        yield log
    except (KeyError, IndexError, TypeError, ValueError):  # a BilbaError is none of these
        log.check()
        raise


def _open(path: Path) -> bytes:
    data = read_bytes(path, "planning log (MCAP)")
    if not data:
        raise BilbaError(f"{path}: empty file, not an MCAP log")
    if not data.startswith(MAGIC):
        raise BilbaError(f"{path}: not an MCAP file")
    return data


def read_log(path: PathArg) -> Log:
    """Every message of a complete log, CRCs checked."""
    path = Path(path)
    data = io.BytesIO(_open(path))  # a corrupt length then reads to the end, not 2**62 bytes
    log = Log(path)
    try:
        for _, channel, message in make_reader(data, validate_crcs=True).iter_messages():
            log.records.append((channel.topic, message.log_time, message.data))
    except (McapError, ValueError, EOFError, KeyError, OSError, struct.error) as exc:
        raise BilbaError(
            f"{path}: truncated or corrupt MCAP ({type(exc).__name__}); "
            "`bilba logs recover` rewrites what is readable"
        ) from None
    if "/metadata" not in log.messages:
        raise BilbaError(f"{path}: an MCAP file, but not a bilba planning log (no /metadata)")
    return log


def _u64(data: bytes, at: int) -> int:
    return int.from_bytes(data[at : at + 8], "little")


def _parsed(opcode: int, body: bytes, strict: bool = False) -> list[Any] | None:
    """The schemas, channels and messages in one top-level record's content ``body`` ([] for
    a record of another kind), or None when it does not parse to exactly its length, or a
    chunk's checksum does not match (``strict``: a chunk must carry one — for a chunk found
    by scanning, not by the length of the record before it)."""
    readers: dict[int, Callable[[ReadDataStream], Any]] = {
        Opcode.CHUNK: Chunk.read,
        Opcode.SCHEMA: Schema.read,
        Opcode.CHANNEL: Channel.read,
        Opcode.MESSAGE: lambda stream: Message.read(stream, len(body)),
    }
    if opcode not in readers:
        return [] if opcode in _OTHER_RECORDS else None
    stream = ReadDataStream(io.BytesIO(body))
    try:
        record = readers[opcode](stream)
        if stream.count != len(body):
            return None
        if isinstance(record, Chunk):
            if strict and not record.uncompressed_crc:
                return None
            return breakup_chunk(record, validate_crc=True)
        return [record]
    except Exception:  # whatever the damage, the record is not readable
        return None


def _next_chunk(data: bytes, start: int) -> tuple[int, list[Any]] | None:
    """The end and the records of the first chunk from ``start`` on whose lengths agree with
    each other and whose checksum matches: where reading resumes after damage."""
    at = data.find(Opcode.CHUNK.to_bytes(1, "little"), start)
    while at != -1 and at + 9 + 40 <= len(data):
        end = at + 9 + _u64(data, at + 1)
        name = int.from_bytes(data[at + 37 : at + 41], "little")  # the compression's name
        if end <= len(data) and at + 49 + name + _u64(data, at + 41 + name) == end:
            records = _parsed(Opcode.CHUNK, data[at + 9 : end], strict=True)
            if records is not None:
                return end, records
        at = data.find(Opcode.CHUNK.to_bytes(1, "little"), at + 1)
    return None


def _readable_records(data: bytes) -> Iterator[Any]:
    """The schemas, channels and messages of every readable record of an MCAP file, in
    order (the summary's schemas and channels too: a finished file repeats them there).
    After a record that does not read (a bad checksum or length, a file cut short inside
    it), reading resumes at the next chunk that reads with a matching checksum."""
    at = len(MAGIC)
    while at + 9 <= len(data) and data[at] != Opcode.FOOTER:
        end = at + 9 + _u64(data, at + 1)
        records = _parsed(data[at], data[at + 9 : end]) if end <= len(data) else None
        if records is None:
            found = _next_chunk(data, at + 1)
            if found is None:
                return
            end, records = found
        yield from records
        at = end


def recover(path: Path, out: Path) -> int:
    """Rewrite every readable message of a damaged or truncated log into a valid file at
    ``out`` (`_readable_records`: a damaged chunk loses its own messages, not the later
    ones); return the number of messages kept. A log whose header (the first chunk: the
    topics and /metadata) is damaged has nothing usable: one BilbaError line, nothing
    written."""
    data = _open(path)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    for record in _readable_records(data):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message):
            messages.append(record)
    topics = {c.id: c.topic for c in channels.values() if c.schema_id in schemas}
    if not any(topics.get(m.channel_id) == "/metadata" for m in messages):
        raise BilbaError(f"{path}: the log's header is damaged; nothing to recover")
    with out.open("wb") as f:
        writer = Writer(f, compression=CompressionType.NONE)  # chunked: indexed readers see all
        writer.start(profile="bilba", library="bilba_dist recover")
        schema_ids = {
            sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in schemas.items()
        }
        channel_ids = {
            cid: writer.register_channel(
                c.topic, c.message_encoding, schema_ids[c.schema_id], dict(c.metadata)
            )
            for cid, c in channels.items()
            if cid in topics
        }
        kept = 0
        for m in messages:
            if m.channel_id in channel_ids:
                writer.add_message(
                    channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence
                )
                kept += 1
        writer.finish()
    return kept

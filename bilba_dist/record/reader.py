"""Reading planning logs back: every message decoded, with one clear error for a bad file."""

import io
import json
import struct
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from jsonschema import Draft202012Validator
from jsonschema.exceptions import best_match
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from bilba_dist.errors import BilbaError
from bilba_dist.files import PathArg, read_bytes
from bilba_dist.record.schemas import TOPICS

MAGIC = b"\x89MCAP0\r\n"


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


def recover(path: Path, out: Path) -> int:
    """Rewrite every complete record of a (possibly truncated) log into a valid file at
    ``out``; return the number of messages kept. Nothing readable (a log damaged in its
    first chunk) is one BilbaError line, and nothing is written."""
    from mcap.records import Channel, Message, Schema

    data = _open(path)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    try:
        for record in StreamReader(io.BytesIO(data), skip_magic=False, validate_crcs=True).records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                messages.append(record)
    except Exception:
        pass
    if not any(m.channel_id in channels for m in messages):
        raise BilbaError(f"{path}: no complete message before the damage; nothing to recover")
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
            if c.schema_id in schema_ids
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

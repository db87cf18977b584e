"""Read and write MCAP bags the way rosbag2 does, without rosbag2 or rclpy.

Bags are MCAP files with profile ``ros2``, schemas encoded as ``ros2msg`` (the message
definition with its dependencies concatenated, as rosbag2 stores them), messages encoded as
``cdr`` and channels carrying ``offered_qos_profiles`` metadata, so ``ros2 bag play``,
Foxglove and the ``mcap`` / ``rosbags`` readers open what we write, and we open what
``ros2 bag record -s mcap`` writes.

Messages are written from plain objects or dicts (``mcap_ros2``'s dynamic CDR encoder) and
read back as raw CDR bytes (for replay, published as they are) or decoded objects whose
attributes mirror the ROS message fields.

Integrity: every chunk is written with the CRC of its uncompressed records (and the data
section with its own CRC); readers verify chunk CRCs wherever a bag has them, so flipped
bytes in a message payload are an error naming the file, not a wrong cell later.  A bag
is written to a temporary file in the target directory and renamed over the target only
when it is closed without an error, so a failed or interrupted run never leaves a stub.
"""
from __future__ import annotations

import contextlib
import os
import pathlib
import struct
import sys
import tempfile
from dataclasses import dataclass
from typing import Any, Iterable, Iterator

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Chunk, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, get_chunk_data_stream
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2._dynamic import DecoderFunction, EncoderFunction, generate_dynamic, serialize_dynamic

from tactile_sl_common import signals

MCAP_MAGIC = b"\x89MCAP0\r\n"
CDR_HEADER_STAMP_OFFSET = 4  # after the 4-byte CDR encapsulation header

# rosbag2's QoS metadata (YAML list) for a sensor-data style publisher: best effort, keep last.
SENSOR_DATA_QOS_YAML = (
    "- history: 1\n  depth: 5\n  reliability: 2\n  durability: 2\n"
    "  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  avoid_ros_namespace_conventions: false"
)
RELIABLE_QOS_YAML = SENSOR_DATA_QOS_YAML.replace("reliability: 2", "reliability: 1").replace(
    "depth: 5", "depth: 10"
)


class BagError(Exception):
    """A bag that cannot be read or written as asked; the message names the file."""


@dataclass(frozen=True)
class TopicInfo:
    """What a bag says about one of its topics."""

    name: str
    schema_name: str
    message_count: int


@dataclass(frozen=True)
class RawMessage:
    """One message as stored: CDR bytes plus where and when it was logged."""

    topic: str
    schema_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


# --------------------------------------------------------------------------- definitions


def _ament_prefixes() -> list[pathlib.Path]:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [pathlib.Path(p) for p in prefixes]


def _find_msg_file(schema_name: str) -> pathlib.Path:
    package, _, type_name = _split_type(schema_name)
    for prefix in _ament_prefixes():
        path = prefix / "share" / package / "msg" / f"{type_name}.msg"
        if path.is_file():
            return path
    raise BagError(
        f"message definition {schema_name} not found under AMENT_PREFIX_PATH "
        "(source env.sh or a ROS 2 setup file)"
    )


def _split_type(schema_name: str) -> tuple[str, str, str]:
    parts = schema_name.split("/")
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    raise BagError(f"not a ROS message type name: {schema_name!r}")


_BUILTIN_TYPES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring", "time", "duration",
}


def _field_types(definition: str, package: str) -> list[str]:
    """Non-builtin field types named in a .msg definition, as pkg/Type (constants are builtin)."""
    found = []
    for line in definition.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        type_token = line.split()[0]
        base = type_token.split("[", 1)[0].split("<=", 1)[0]
        if base in _BUILTIN_TYPES:
            continue
        found.append(base if "/" in base else f"{package}/{base}")
    return found


def message_definition(schema_name: str) -> str:
    """The ros2msg schema text rosbag2 stores: the definition, then each dependency once."""
    root_pkg, _, root_type = _split_type(schema_name)
    text = _find_msg_file(schema_name).read_text()
    parts = [text.rstrip("\n")]
    seen = {f"{root_pkg}/{root_type}"}
    queue = _field_types(text, root_pkg)
    while queue:
        dep = queue.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        dep_text = _find_msg_file(dep).read_text()
        parts.append("=" * 80 + f"\nMSG: {dep}\n" + dep_text.rstrip("\n"))
        queue.extend(_field_types(dep_text, dep.split("/")[0]))
    return "\n".join(parts) + "\n"


# --------------------------------------------------------------------------- writing


class BagWriter:
    """Write a rosbag2-compatible MCAP file (``with BagWriter(path) as bag: bag.write(...)``).

    The bag goes to a temporary file next to ``path``; :meth:`close` renames it onto
    ``path``, :meth:`abort` (and leaving the ``with`` block by an exception) removes it.
    No temporary file outlives a Ctrl-C or SIGTERM, wherever it comes: while the writer is
    being made the signals wait (main thread), and a writer dropped unclosed (an exception
    between its making and the ``with`` block) removes its file too.
    """

    _closed = True      # until the writer is whole: nothing for __del__ to remove

    def __init__(self, path: str | os.PathLike, compression: str = "zstd") -> None:
        self.path = pathlib.Path(path)
        kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                 "none": CompressionType.NONE}
        if compression not in kinds:
            raise BagError(f"{self.path}: unknown compression {compression!r}")
        self._schemas: dict[str, tuple[int, EncoderFunction]] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        fd = tmp = None
        try:
            with signals.held(swap_handlers=True):
                self.path.parent.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp",
                                           dir=self.path.parent)
                self._tmp = pathlib.Path(tmp)
                self._file = os.fdopen(fd, "wb")
                self._writer = McapWriter(self._file, compression=kinds[compression],
                                          enable_crcs=True, enable_data_crcs=True)
                self._writer.start(profile="ros2", library="tactile-sl")
                self._closed = False
        except BaseException as exc:      # a signal held back above is raised here, too
            self._closed = True
            if tmp is not None:
                with contextlib.suppress(OSError, ValueError):
                    if getattr(self, "_file", None) is not None:
                        self._file.close()
                    elif fd is not None:
                        os.close(fd)
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            if isinstance(exc, OSError):
                raise BagError(f"cannot write {self.path}: {exc.strerror or exc}") from None
            raise

    def _schema(self, schema_name: str) -> tuple[int, EncoderFunction]:
        if schema_name not in self._schemas:
            definition = message_definition(schema_name)
            schema_id = self._writer.register_schema(schema_name, "ros2msg", definition.encode())
            encoder = serialize_dynamic(schema_name, definition)[schema_name]
            self._schemas[schema_name] = (schema_id, encoder)
        return self._schemas[schema_name]

    def _channel(self, topic: str, schema_name: str, qos_yaml: str) -> int:
        if topic not in self._channels:
            schema_id, _ = self._schema(schema_name)
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema_id,
                metadata={"offered_qos_profiles": qos_yaml},
            )
            self._sequence[topic] = 0
        return self._channels[topic]

    def write(self, topic: str, schema_name: str, message: Any, log_time_ns: int,
              qos_yaml: str = SENSOR_DATA_QOS_YAML) -> None:
        """Encode ``message`` (object or dict with the ROS fields) and append it."""
        _, encoder = self._schema(schema_name)
        self.write_raw(topic, schema_name, encoder(message), log_time_ns, qos_yaml)

    def write_raw(self, topic: str, schema_name: str, cdr: bytes, log_time_ns: int,
                  qos_yaml: str = SENSOR_DATA_QOS_YAML) -> None:
        """Append an already CDR-encoded message."""
        channel = self._channel(topic, schema_name, qos_yaml)
        self._sequence[topic] += 1
        self._writer.add_message(channel_id=channel, log_time=int(log_time_ns),
                                 publish_time=int(log_time_ns),
                                 sequence=self._sequence[topic], data=bytes(cdr))

    def close(self) -> None:
        """Finish the file and move it onto the target path."""
        if not self._closed:
            self._closed = True
            try:
                self._writer.finish()
                self._file.close()
                umask = os.umask(0)
                os.umask(umask)
                os.chmod(self._tmp, 0o666 & ~umask)
                os.replace(self._tmp, self.path)
            except OSError as exc:
                self._discard()
                raise BagError(f"cannot write {self.path}: {exc.strerror or exc}") from None
            except BaseException:
                self._discard()
                raise

    def abort(self) -> None:
        """Drop what was written; the target path is left as it was."""
        if not self._closed:
            self._closed = True
            self._discard()

    def _discard(self) -> None:
        try:
            self._file.close()
        except (OSError, ValueError):
            pass
        try:
            self._tmp.unlink()
        except OSError:
            pass

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:
        """A writer dropped without :meth:`close` leaves no temporary file behind."""
        try:
            self.abort()
        except Exception:     # at interpreter exit the modules may be gone; nothing to do
            pass


# --------------------------------------------------------------------------- reading


class BagReader:
    """Open an MCAP bag, checking up front that it is whole and readable.

    A missing file, a file that is not MCAP, a truncated recording (no footer / summary) and
    corrupt records all raise :class:`BagError` naming the file and the problem.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = pathlib.Path(path)
        if self.path.is_dir():  # a rosbag2 bag directory: use its single .mcap file
            files = sorted(self.path.glob("*.mcap"))
            if len(files) != 1:
                raise BagError(f"{self.path}: expected exactly one .mcap file in the bag "
                               f"directory, found {len(files)}")
            self.path = files[0]
        if not self.path.is_file():
            raise BagError(f"{self.path}: no such bag file")
        with open(self.path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - len(MCAP_MAGIC)))
            tail = f.read()
        if head != MCAP_MAGIC:
            raise BagError(f"{self.path}: not an MCAP file (bad magic bytes)")
        if tail != MCAP_MAGIC:
            raise BagError(f"{self.path}: truncated MCAP file (no closing magic; "
                           f"the recording was cut off after {size} bytes)")
        try:
            with open(self.path, "rb") as f:
                summary = make_reader(f).get_summary()
        except (McapError, struct.error, ValueError, EOFError) as exc:
            raise BagError(f"{self.path}: corrupt MCAP file ({exc})") from exc
        if summary is None:
            raise BagError(f"{self.path}: MCAP file without a summary section; "
                           "re-write it with `mcap recover`")
        self._summary = summary
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        self.topics: dict[str, TopicInfo] = {}
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            if channel.message_encoding != "cdr" or schema is None:
                continue
            self.topics[channel.topic] = TopicInfo(
                channel.topic, schema.name, int(counts.get(channel_id, 0)))
        self._decoders: dict[int, DecoderFunction] = {}

    def topics_of_type(self, schema_name: str) -> list[str]:
        return sorted(t.name for t in self.topics.values() if t.schema_name == schema_name)

    def require_topics(self, names: Iterable[str]) -> None:
        """Raise a BagError listing every expected topic the bag does not carry."""
        missing = [n for n in names if n not in self.topics]
        if missing:
            have = ", ".join(sorted(self.topics)) or "none"
            raise BagError(f"{self.path}: missing topic(s) {', '.join(missing)} "
                           f"(the bag has: {have})")

    def raw_messages(self, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
        """Messages in log-time order as raw CDR bytes."""
        wanted = set(topics) if topics is not None else None
        try:
            with open(self.path, "rb") as f:
                reader = make_reader(f, validate_crcs=True)
                for schema, channel, message in reader.iter_messages(
                        topics=list(wanted) if wanted is not None else None,
                        log_time_order=True):
                    yield RawMessage(channel.topic, schema.name if schema else "",
                                     message.log_time, message.publish_time, message.data)
        except CRCValidationError as exc:
            raise BagError(f"{self.path}: corrupt MCAP data: a chunk fails its CRC check "
                           f"({exc})") from exc
        except (McapError, struct.error, ValueError, EOFError) as exc:
            raise BagError(f"{self.path}: corrupt MCAP data ({exc})") from exc

    def verify(self) -> int:
        """Check every chunk against its CRC (where the bag has one); returns chunks checked.

        Raises :class:`BagError` naming the file and the chunk's offset on a mismatch.
        """
        checked = 0
        try:
            with open(self.path, "rb") as f:
                for record in StreamReader(f, skip_magic=False, emit_chunks=True).records:
                    if isinstance(record, Chunk):
                        get_chunk_data_stream(record, validate_crc=True)
                        checked += int(record.uncompressed_crc != 0)
        except CRCValidationError as exc:
            raise BagError(f"{self.path}: corrupt MCAP data: a chunk fails its CRC check "
                           f"({exc})") from exc
        except (McapError, struct.error, ValueError, EOFError) as exc:
            raise BagError(f"{self.path}: corrupt MCAP data ({exc})") from exc
        return checked

    def decoder(self, schema: Schema) -> DecoderFunction:
        if schema.id not in self._decoders:
            if schema.encoding != "ros2msg":
                raise BagError(f"{self.path}: schema {schema.name} is encoded as "
                               f"{schema.encoding!r}; only ros2msg is supported")
            self._decoders[schema.id] = generate_dynamic(schema.name, schema.data.decode())[
                schema.name]
        return self._decoders[schema.id]

    def messages(self, topics: Iterable[str] | None = None,
                 strict: bool = False) -> Iterator[tuple[RawMessage, Any]]:
        """Messages in log-time order, each with its decoded form.

        A message that cannot be deserialised is skipped with a warning on stderr naming
        its topic and time (its stereo frame is then incomplete and left out);
        ``strict=True`` raises :class:`BagError` instead.
        """
        by_name = {s.name: s for s in self._summary.schemas.values()}
        for raw in self.raw_messages(topics):
            decode = self.decoder(by_name[raw.schema_name])
            try:
                decoded = decode(raw.data)
            except Exception as exc:  # the dynamic decoder raises assorted errors on bad CDR
                text = (f"{self.path}: cannot decode a {raw.schema_name} message on "
                        f"{raw.topic} at {raw.log_time_ns // 1_000_000_000}."
                        f"{raw.log_time_ns % 1_000_000_000:09d} s ({exc})")
                if strict:
                    raise BagError(text) from exc
                print(f"warning: {text}; message skipped", file=sys.stderr)
                continue
            yield raw, decoded


# --------------------------------------------------------------------------- CDR helpers


def restamp_cdr(cdr: bytes, sec: int, nanosec: int) -> bytes:
    """Replace the header stamp of a CDR message whose first field is std_msgs/Header."""
    if len(cdr) < CDR_HEADER_STAMP_OFFSET + 8:
        raise ValueError("CDR message too short to carry a header stamp")
    little = cdr[1] & 1  # encapsulation kind: odd = little endian
    fmt = "<iI" if little else ">iI"
    out = bytearray(cdr)
    struct.pack_into(fmt, out, CDR_HEADER_STAMP_OFFSET, int(sec), int(nanosec))
    return bytes(out)


def header_stamp_of_cdr(cdr: bytes) -> tuple[int, int]:
    """(sec, nanosec) of a CDR message whose first field is std_msgs/Header."""
    little = cdr[1] & 1
    return struct.unpack_from("<iI" if little else ">iI", cdr, CDR_HEADER_STAMP_OFFSET)


def stamp_to_ns(sec: int, nanosec: int) -> int:
    return int(sec) * 1_000_000_000 + int(nanosec)


def ns_to_stamp(ns: int) -> tuple[int, int]:
    return int(ns // 1_000_000_000), int(ns % 1_000_000_000)


"""Reading RGB-D recordings: what `ros2 bag record` writes from the RealSense ROS 2 driver,
and what `hsp record` writes. The one reader `hsp parse` uses.

Reads a bare ``.mcap`` file, a rosbag2 directory (``metadata.yaml``) in MCAP or SQLite
storage, uncompressed or compressed per message or per file, split or not, and a ROS 1
``.bag``. MCAP data goes through hsp's own chunk-by-chunk scan, which keeps what survives
damage (a truncated file keeps the complete chunks before the break; a chunk failing its
CRC is skipped; both are reported as warnings); everything else through the maintained
``rosbags`` reader, keeping the messages read before a break.

Finds colour, aligned depth and camera info by message type and by the driver's topic
names (both ``/camera/camera/...`` of realsense-ros ≥ 4.55 and the older ``/camera/...``),
pairs colour and depth on ``header.stamp``, decodes ``rgb8``/``bgr8``/``rgba8``/``bgra8``,
``16UC1``/``mono16`` (mm) and ``32FC1`` (m), honouring ``step`` and ``is_bigendian``.
Ground-truth topics (``/hsp/ground_truth/*``) are never read here.
"""

from __future__ import annotations

import logging
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zstandard
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from hsp.errors import HspError
from hsp.geometry import compose
from hsp.recording.messages import GROUND_TRUTH_PREFIX

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROS1_MAGIC = b"#ROSBAG V2.0"
SQLITE_MAGIC = b"SQLite format 3\x00"
_FOREIGN_MAGIC = {b"PK\x03\x04": "a zip archive; unpack it first", b"\x89PNG": "a PNG image"}
RECORDING_SUFFIXES = (".mcap", ".bag")
IMAGE_SCHEMA = "sensor_msgs/msg/Image"
INFO_SCHEMA = "sensor_msgs/msg/CameraInfo"
TF_SCHEMA = "tf2_msgs/msg/TFMessage"
COLOR_ENCODINGS = {"rgb8": (3, [0, 1, 2]), "bgr8": (3, [2, 1, 0]), "rgba8": (4, [0, 1, 2]), "bgra8": (4, [2, 1, 0])}
DEPTH_ENCODINGS = {"16UC1": np.uint16, "mono16": np.uint16, "32FC1": np.float32}


@dataclass(frozen=True)
class ReadOptions:
    """Overrides for recordings that do not follow the driver's names."""

    color_topic: str | None = None
    depth_topic: str | None = None
    info_topic: str | None = None
    intrinsics: tuple[float, float, float, float] | None = None
    """(fx, fy, cx, cy) in pixels, when the recording has no CameraInfo."""
    camera_pose: tuple[float, ...] | None = None
    """(x, y, z, qx, qy, qz, qw): the colour camera's optical frame in the table frame (z = 0
    on the table top, z up), overriding ``/tf_static`` and the fitted plane."""


@dataclass
class ReadReport:
    color_messages: int = 0
    depth_messages: int = 0
    paired: int = 0
    paired_nearest: int = 0
    skipped_chunks: int = 0
    skipped_messages: int = 0
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)

    def warn(self, text: str) -> None:
        self.warnings.append(text)
        log.warning(text)


@dataclass
class Recording:
    """Paired RGB-D frames of one recording; depth in metres, 0 = no reading."""

    path: Path
    rgb: np.ndarray
    """(T, H, W, 3) uint8."""
    depth: np.ndarray
    """(T, H, W) float32 metres."""
    stamps_ns: np.ndarray
    """(T,) int64 colour ``header.stamp``."""
    K: np.ndarray
    """(3, 3) colour intrinsics."""
    frame_id: str
    T_world_cam: np.ndarray | None
    """Camera pose from ``/tf_static`` (7,), when a chain to the image frame exists: in the
    frame of its root, which may be the camera's own (see :mod:`hsp.perception.table`)."""
    tf_root: str
    """The root frame of that chain."""
    topics: dict[str, str]
    report: ReadReport


def is_bag_directory(path: Path) -> bool:
    return path.is_dir() and (path / "metadata.yaml").is_file()


def recording_name(path: Path, root: Path) -> str:
    """How a dataset names the recording ``path`` found in ``root`` (:func:`find_recordings`):
    its path relative to the folder, or its own name when ``root`` is the recording."""
    path, root = Path(path), Path(root)
    return path.resolve().name if path == root else path.relative_to(root).as_posix()


def _cut_short_bag(path: Path) -> bool:
    """A rosbag2 directory cut short before ``metadata.yaml`` was written: files named as
    rosbag2 writers name them (``DIR_0.db3``, ``DIR_0.mcap``, ``DIR.mcap.zstd``), no metadata."""
    pattern = re.compile(rf"{re.escape(path.name)}(_\d+)?\.(db3|mcap)(\.zstd)?")
    return (path.is_dir() and not is_bag_directory(path)
            and any(pattern.fullmatch(f.name) for f in path.iterdir()))


def find_recordings(path: Path) -> list[Path]:
    """The recordings ``path`` names: one rosbag2 directory, ``.mcap`` file or ROS 1 ``.bag``
    file, or a folder of them (sorted)."""
    path = Path(path)
    if not path.exists():
        raise HspError(f"{path}: recordings not found")
    if path.is_file():
        if is_bag_directory(path.parent):
            raise HspError(f"{path}: one file of the rosbag2 bag {path.parent}; name the bag directory "
                           "(a split or compressed bag is read whole)")
        return [path]
    if is_bag_directory(path) or _cut_short_bag(path):
        return [path]  # the check says what to do with one cut short
    found = sorted(p for p in path.iterdir() if (p.is_file() and p.suffix in RECORDING_SUFFIXES)
                   or is_bag_directory(p) or _cut_short_bag(p))  # the check reports those cut short
    if found:
        return found
    if any(path.glob("*.db3")):
        raise HspError(f"{path}: a rosbag2 directory without metadata.yaml (a recording that was cut short?); "
                       "restore it with `ros2 bag reindex DIR`")
    names = ", ".join(sorted(p.name for p in path.iterdir())[:8]) or "nothing"
    raise HspError(f"{path}: no recordings (.mcap or .bag files, rosbag2 directories with metadata.yaml); "
                   f"found: {names}")


def _magic(path: Path) -> bytes:
    with open(path, "rb") as f:
        head = f.read(16)
    if not head:
        raise HspError(f"{path}: empty file")
    return head


def _check_mcap(path: Path) -> None:
    head = _magic(path)
    if head.startswith(MCAP_MAGIC):
        return
    for magic, what in _FOREIGN_MAGIC.items():
        if head.startswith(magic):
            raise HspError(f"{path}: not MCAP but {what}")
    raise HspError(f"{path}: not an MCAP file (magic bytes {head[:8]!r})")


def _scan(path: Path, report: ReadReport) -> tuple[dict[int, Schema], dict[int, Channel], list[Message]]:
    """All schemas, channels and messages that survive: chunks are CRC-checked one by one."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []

    def take(records: list) -> None:
        for r in records:
            if isinstance(r, Schema):
                schemas[r.id] = r
            elif isinstance(r, Channel):
                channels[r.id] = r
            elif isinstance(r, Message):
                messages.append(r)

    with open(path, "rb") as f:
        reader = StreamReader(f, emit_chunks=True)
        try:
            for record in reader.records:
                if isinstance(record, Chunk):
                    try:
                        take(breakup_chunk(record, validate_crc=True))
                    except (McapError, ValueError, zstandard.ZstdError, RuntimeError) as e:  # lz4 raises RuntimeError
                        report.skipped_chunks += 1
                        report.warn(f"{path}: skipped a corrupt chunk at log time {record.message_start_time} ({e})")
                else:
                    take([record])
        except (McapError, EOFError, ValueError, OSError) as e:
            report.truncated = True
            report.warn(f"{path}: truncated or damaged after {len(messages)} messages ({type(e).__name__}); keeping them")
    return schemas, channels, messages


@dataclass
class _Messages:
    """The messages of one recording that hsp reads (images, camera info, ``/tf_static``), decoded."""

    types: dict[str, str]
    """Every topic's message type, e.g. ``sensor_msgs/msg/Image``."""
    messages: list[tuple[str, int, object]]
    """(topic, log time in ns, message), in the order stored."""


Choose = Callable[[dict[str, str]], set[str]]
"""Given every topic's message type, the topics to decode."""


def _read_mcap(files: list[Path], path: Path, report: ReadReport, compressed_messages: bool,
               choose: Choose) -> _Messages:
    """MCAP files (a bare ``.mcap`` or the files of a rosbag2 MCAP bag) with hsp's own scan,
    which keeps what survives damage. ``compressed_messages``: rosbag2's per-message zstd."""
    out = _Messages({}, [])
    unzip = zstandard.ZstdDecompressor()
    bad = 0
    scanned = []
    for f in files:
        _check_mcap(f)
        schemas, channels, messages = _scan(f, report)
        out.types |= {ch.topic: schemas[ch.schema_id].name for ch in channels.values() if ch.schema_id in schemas}
        scanned.append((f, schemas, channels, messages))
    wanted = choose(out.types)
    while scanned:
        f, schemas, channels, messages = scanned.pop(0)  # each file's raw messages go once decoded
        factory, decoders = DecoderFactory(), {}  # it caches by schema id, which each file of a split bag numbers anew
        for m in messages:
            ch = channels.get(m.channel_id)
            if ch is None or ch.topic not in wanted or ch.schema_id not in schemas:
                continue
            schema = schemas[ch.schema_id]
            if ch.id not in decoders:
                decoders[ch.id] = factory.decoder_for(ch.message_encoding, schema)
                if decoders[ch.id] is None:
                    raise HspError(f"{path}: cannot decode {ch.topic} ({ch.message_encoding}, {schema.encoding})")
            try:
                data = unzip.decompress(m.data) if compressed_messages else m.data
                out.messages.append((ch.topic, m.log_time, decoders[ch.id](data)))
            except (zstandard.ZstdError, ValueError, IndexError, EOFError, struct.error) as e:
                bad += 1
                if bad == 1:
                    report.warn(f"{f}: skipped a message of {ch.topic} that does not decode ({type(e).__name__})")
    report.skipped_messages += bad
    return out


def _read_rosbags(path: Path, report: ReadReport, choose: Choose) -> _Messages:
    """A rosbag2 directory in SQLite storage or compressed per file, or a ROS 1 bag, through
    the ``rosbags`` reader; messages before a break are kept."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out = _Messages({}, [])
    # Any failure of the third-party reader on this file is a fault of the file: one line naming it.
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as e:  # noqa: BLE001
        raise HspError(f"{path}: cannot read the bag ({_first_line(e)})") from None
    try:
        out.types = {c.topic: c.msgtype for c in reader.connections}
        topics = choose(out.types)
        wanted = [c for c in reader.connections if c.topic in topics]
        try:
            for c, t, raw in reader.messages(connections=wanted):
                out.messages.append((c.topic, t, reader.deserialize(raw, c.msgtype)))
        except Exception as e:  # noqa: BLE001
            report.truncated = True
            report.warn(f"{path}: damaged after {len(out.messages)} messages ({_first_line(e)}); keeping them")
    finally:
        reader.close()
    return out


def _first_line(e: BaseException) -> str:
    text = str(e).strip()
    return f"{type(e).__name__}: {text.splitlines()[0]}" if text else type(e).__name__


def _read_messages(path: Path, report: ReadReport, choose: Choose) -> _Messages:
    """The messages of the topics ``choose`` picks from every topic's type, decoded; dispatch
    on what ``path`` is (see the module docstring)."""
    if not path.exists():
        raise HspError(f"{path}: no such file or directory")
    if path.is_dir():
        if not is_bag_directory(path):
            raise HspError(f"{path}: a directory without metadata.yaml is not a rosbag2 bag "
                           "(name the .mcap files, or restore it with `ros2 bag reindex`)")
        meta = _bag_metadata(path)
        storage, mode = meta.get("storage_identifier"), str(meta.get("compression_mode") or "").lower()
        if storage == "mcap" and mode != "file":
            files = [path / Path(f).name for f in meta.get("relative_file_paths") or []]
            if missing := [f.name for f in files if not f.is_file()]:
                raise HspError(f"{path}: metadata.yaml lists files that are missing: {missing}")
            if mode == "message" and meta.get("compression_format") != "zstd":
                raise HspError(f"{path}: compression {meta.get('compression_format')!r} is not supported (zstd is)")
            return _read_mcap(files, path, report, mode == "message", choose)
        return _read_rosbags(path, report, choose)
    head = _magic(path)
    if head.startswith(ROS1_MAGIC):
        if path.suffix != ".bag":
            raise HspError(f"{path}: a ROS 1 bag without the .bag suffix; rename it to {path.stem}.bag")
        return _read_rosbags(path, report, choose)
    if head.startswith(SQLITE_MAGIC):
        raise HspError(f"{path}: a rosbag2 SQLite file; name its bag directory (with metadata.yaml), not the .db3")
    return _read_mcap([path], path, report, False, choose)


def _bag_metadata(path: Path) -> dict:
    import yaml

    try:
        meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        if not isinstance(meta, dict):
            raise TypeError("not a mapping")
    except (yaml.YAMLError, KeyError, TypeError, OSError) as e:
        raise HspError(f"{path / 'metadata.yaml'}: not rosbag2 metadata ({_first_line(e)})") from None
    return meta


def _pick(types: dict[str, str], msgtype: str, prefer: list[str], override: str | None, what: str, path: Path,
          report: ReadReport) -> str | None:
    cands = sorted(t for t, ty in types.items() if ty == msgtype and not t.startswith(GROUND_TRUTH_PREFIX))
    if override is not None:
        if override in cands:
            return override
        raise HspError(f"{path}: no {msgtype} topic {override!r} (found: {', '.join(cands) or 'none'})")
    for suffix in prefer:
        hits = [t for t in cands if t.endswith(suffix)]
        if hits:
            if len(hits) > 1:
                report.warn(f"{path}: several {what} topics {hits}; using {hits[0]}")
            return hits[0]
    return None


def _image(msg: object, path: Path) -> tuple[str, np.ndarray]:
    h, w, step, enc = msg.height, msg.width, msg.step, msg.encoding  # type: ignore[attr-defined]
    data = np.frombuffer(msg.data, np.uint8)  # type: ignore[attr-defined]
    if data.size < h * step:
        raise HspError(f"{path}: image of {data.size} bytes is shorter than height × step = {h * step}")
    rows = data[: h * step].reshape(h, step)
    if enc in COLOR_ENCODINGS:
        ch, order = COLOR_ENCODINGS[enc]
        return "color", rows[:, : w * ch].reshape(h, w, ch)[:, :, order]
    if enc in DEPTH_ENCODINGS:
        dtype = np.dtype(DEPTH_ENCODINGS[enc]).newbyteorder(">" if msg.is_bigendian else "<")  # type: ignore[attr-defined]
        px = rows[:, : w * dtype.itemsize].copy().view(dtype).reshape(h, w)
        if enc == "32FC1":
            return "depth", np.nan_to_num(px.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        return "depth", px.astype(np.float32) / 1000.0
    raise HspError(f"{path}: unsupported image encoding {enc!r} (colour: {sorted(COLOR_ENCODINGS)}, depth: {sorted(DEPTH_ENCODINGS)})")


def _check_intrinsics(K: np.ndarray, shape: tuple[int, int], path: Path, source: str) -> None:
    """A pinhole camera of an image ``shape (H, W)``: focal lengths > 0, principal point inside."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (np.all(np.isfinite(K)) and fx > 0 and fy > 0 and 0 < cx < shape[1] and 0 < cy < shape[0]):
        raise HspError(f"{path}: intrinsics from {source} (fx {fx:g}, fy {fy:g}, cx {cx:g}, cy {cy:g}) are not "
                       f"those of a {shape[1]}x{shape[0]} camera; is the camera calibrated? "
                       "(--intrinsics fx,fy,cx,cy overrides)")


def _tf_pose(tf: object) -> np.ndarray:
    t, r = tf.transform.translation, tf.transform.rotation  # type: ignore[attr-defined]
    return np.array([t.x, t.y, t.z, r.x, r.y, r.z, r.w])


def _camera_pose(static: dict[str, tuple[str, np.ndarray]], frame: str) -> tuple[np.ndarray | None, str]:
    """Compose ``/tf_static`` from its root down to ``frame``: the pose and the root's name;
    ``(None, "")`` if ``frame`` is absent."""
    if frame not in static:
        return None, ""
    chain, node = [], frame
    while node in static and len(chain) < 32:
        parent, T = static[node]
        chain.append(T)
        node = parent
    pose = chain[-1]
    for T in reversed(chain[:-1]):
        pose = compose(pose, T)
    return pose, node


def _topics(types: dict[str, str], options: ReadOptions, path: Path, report: ReadReport) -> dict[str, str | None]:
    """The colour, aligned depth and camera info topics among ``types`` (topic → message type)."""
    if not types:
        raise HspError(f"{path}: no readable messages")
    color = _pick(types, IMAGE_SCHEMA, ["/color/image_raw", "/color/image_rect_raw", "/color/image"],
                  options.color_topic, "colour", path, report)
    depth = _pick(types, IMAGE_SCHEMA, ["aligned_depth_to_color/image_raw", "depth/image_rect_raw", "depth/image_raw"],
                  options.depth_topic, "depth", path, report)
    if color is None or depth is None:
        images = sorted(t for t, ty in types.items() if ty == IMAGE_SCHEMA)
        missing = "colour" if color is None else "depth"
        raise HspError(f"{path}: no {missing} image topic; Image topics: {images or 'none'}; "
                       f"all topics: {sorted(types)}"
                       " (name them with --color-topic/--depth-topic)")
    if "aligned_depth_to_color" not in depth and options.depth_topic is None:
        if not any("aligned_depth_to_color" in t for t in types):
            report.warn(f"{path}: depth topic {depth} is not the aligned one; it must be registered to colour")
    info = _pick(types, INFO_SCHEMA, ["/color/camera_info", "camera_info"], options.info_topic, "camera info", path,
                 report)
    return {"color": color, "depth": depth, "info": info}


def read_recording(path: Path, options: ReadOptions = ReadOptions()) -> Recording:
    """Read and pair the RGB-D frames of one recording (see module docstring)."""
    path = Path(path)
    report = ReadReport()
    topics: dict[str, str | None] = {}

    def choose(types: dict[str, str]) -> set[str]:
        topics.update(_topics(types, options, path, report))
        return {t for t in topics.values() if t} | {"/tf_static"}

    bag = _read_messages(path, report, choose)
    color, depth, info = topics["color"], topics["depth"], topics["info"]

    colour_frames: dict[int, np.ndarray] = {}
    depth_frames: dict[int, np.ndarray] = {}
    colour_log_times: list[int] = []
    K = None
    info_size = None
    frame_id = ""
    static: dict[str, tuple[str, np.ndarray]] = {}
    for topic, log_time, msg in bag.messages:
        if topic == color or topic == depth:
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec  # type: ignore[attr-defined]
            kind, img = _image(msg, path)
            if topic == color:
                if kind != "color":
                    raise HspError(f"{path}: colour topic {color} carries {msg.encoding!r}")  # type: ignore[attr-defined]
                colour_frames[stamp] = img
                colour_log_times.append(log_time)
                frame_id = msg.header.frame_id  # type: ignore[attr-defined]
            else:
                if kind != "depth":
                    raise HspError(f"{path}: depth topic {depth} carries {msg.encoding!r}")  # type: ignore[attr-defined]
                depth_frames[stamp] = img
        elif topic == info and K is None:
            k = msg.k if hasattr(msg, "k") else msg.K  # type: ignore[attr-defined]  # ROS 1 spells it K
            K = np.asarray(k, float).reshape(3, 3)
            info_size = (msg.height, msg.width)  # type: ignore[attr-defined]
        elif topic == "/tf_static" and bag.types[topic] == TF_SCHEMA:
            for tf in msg.transforms:  # type: ignore[attr-defined]
                static[tf.child_frame_id] = (tf.header.frame_id, _tf_pose(tf))
    report.color_messages, report.depth_messages = len(colour_frames), len(depth_frames)
    if not colour_frames or not depth_frames:
        raise HspError(f"{path}: no usable frames ({len(colour_frames)} colour, {len(depth_frames)} depth)")

    c_shape = next(iter(colour_frames.values())).shape[:2]
    d_shape = next(iter(depth_frames.values())).shape
    if c_shape != d_shape:
        raise HspError(f"{path}: depth {d_shape[1]}x{d_shape[0]} differs from colour {c_shape[1]}x{c_shape[0]}; "
                       "record the aligned depth (realsense-ros: align_depth.enable:=true)")
    if options.intrinsics is not None:
        fx, fy, cx, cy = options.intrinsics
        K, info = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]), "--intrinsics"
    elif K is None:
        raise HspError(f"{path}: no CameraInfo topic and no intrinsics given (pass --intrinsics fx,fy,cx,cy)")
    elif info_size != c_shape and info_size != (0, 0):
        raise HspError(f"{path}: camera info is for {info_size[1]}x{info_size[0]}, images are {c_shape[1]}x{c_shape[0]}")
    _check_intrinsics(K, c_shape, path, info)

    c_stamps = np.array(sorted(colour_frames), dtype=np.int64)
    d_stamps = np.array(sorted(depth_frames), dtype=np.int64)
    pairs = [(s, s) for s in c_stamps if s in depth_frames]
    report.paired = len(pairs)
    if len(pairs) < len(c_stamps) and len(c_stamps) > 1:
        half = np.median(np.diff(c_stamps)) / 2
        used = {d for _, d in pairs}
        for s in c_stamps:
            if s in depth_frames:
                continue
            j = int(np.clip(np.searchsorted(d_stamps, s), 1, len(d_stamps) - 1))
            near = min((d_stamps[j - 1], d_stamps[j]), key=lambda d: abs(d - s))
            if abs(near - s) <= half and near not in used and near not in colour_frames:
                pairs.append((s, near))
                used.add(near)
                report.paired_nearest += 1
        pairs.sort()
    if len(pairs) < 0.5 * len(c_stamps):
        offsets = np.abs(c_stamps[:, None] - d_stamps[None, :]).min(axis=1)
        raise HspError(f"{path}: only {len(pairs)} of {len(c_stamps)} colour frames pair with depth "
                       f"(median stamp offset {np.median(offsets) / 1e6:.1f} ms)")
    if len(pairs) < len(c_stamps) or len(pairs) < len(d_stamps):
        report.warn(f"{path}: {len(c_stamps) - len(pairs)} colour and {len(d_stamps) - len(pairs)} depth frames left unpaired")
    if np.any(np.diff(colour_log_times) < 0):
        report.warn(f"{path}: colour messages are not in time order; sorted by header.stamp")

    depth_arr = np.stack([depth_frames[d] for _, d in pairs])
    T_world_cam, tf_root = _camera_pose(static, frame_id)
    valid = depth_arr[depth_arr > 0]
    if valid.size and not 0.1 <= float(np.median(valid)) <= 10.0:
        report.warn(f"{path}: median depth {np.median(valid):.3f} m is outside 0.1–10 m; is the depth unit millimetres?")
    return Recording(
        path=path,
        rgb=np.stack([colour_frames[c] for c, _ in pairs]),
        depth=depth_arr,
        stamps_ns=np.array([c for c, _ in pairs], dtype=np.int64),
        K=K,
        frame_id=frame_id,
        T_world_cam=T_world_cam,
        tf_root=tf_root,
        topics={"color": color, "depth": depth, "info": info or ""},
        report=report,
    )

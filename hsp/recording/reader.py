"""Reading RGB-D recordings: what `ros2 bag record` writes from the RealSense ROS 2 driver,
and what `hsp record` writes. The one reader `hsp parse` uses.

Accepts an ``.mcap`` file or a rosbag2 directory (``metadata.yaml`` + ``*.mcap``). Finds
colour, aligned depth and camera info by schema and by the driver's topic names (both
``/camera/camera/...`` of realsense-ros ≥ 4.55 and the older ``/camera/...``), pairs colour
and depth on ``header.stamp``, decodes ``rgb8``/``bgr8``/``rgba8``/``bgra8``,
``16UC1``/``mono16`` (mm) and ``32FC1`` (m), honouring ``step`` and ``is_bigendian``.

Damaged files lose only what is damaged: a truncated file keeps the complete chunks before
the break; a chunk failing its CRC is skipped. Both are reported as warnings. Ground-truth
topics (``/hsp/ground_truth/*``) are never read here.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from hsp.errors import HspError
from hsp.geometry import compose
from hsp.recording.messages import GROUND_TRUTH_PREFIX

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOREIGN_MAGIC = {
    b"SQLite format 3\x00": "a rosbag2 SQLite (.db3) file; convert it with `ros2 bag convert` to the mcap storage",
    b"#ROSBAG V2.0": "a ROS 1 bag; convert it to ROS 2 MCAP (e.g. `rosbags-convert --dst-storage mcap`)",
    b"PK\x03\x04": "a zip archive; unpack it first",
}
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


@dataclass
class ReadReport:
    color_messages: int = 0
    depth_messages: int = 0
    paired: int = 0
    paired_nearest: int = 0
    skipped_chunks: int = 0
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
    """Camera pose from ``/tf_static`` (7,), when a chain to the image frame exists."""
    topics: dict[str, str]
    report: ReadReport


def _mcap_files(path: Path) -> list[Path]:
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if not files:
            found = ", ".join(sorted(p.name for p in path.iterdir())[:8]) or "nothing"
            raise HspError(f"{path}: a directory without .mcap files (found: {found})")
        return files
    if not path.is_file():
        raise HspError(f"{path}: no such file or directory")
    return [path]


def _check_magic(path: Path) -> None:
    with open(path, "rb") as f:
        head = f.read(16)
    if not head:
        raise HspError(f"{path}: empty file")
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
                    except (McapError, ValueError) as e:
                        report.skipped_chunks += 1
                        report.warn(f"{path}: skipped a corrupt chunk at log time {record.message_start_time} ({e})")
                else:
                    take([record])
        except (McapError, EOFError, ValueError, OSError) as e:
            report.truncated = True
            report.warn(f"{path}: truncated or damaged after {len(messages)} messages ({type(e).__name__}); keeping them")
    return schemas, channels, messages


def _pick(channels: dict[int, Channel], schemas: dict[int, Schema], schema: str, prefer: list[str], override: str | None,
          what: str, path: Path, report: ReadReport) -> Channel | None:
    cands = [c for c in channels.values() if c.schema_id in schemas and schemas[c.schema_id].name == schema
             and not c.topic.startswith(GROUND_TRUTH_PREFIX)]
    if override is not None:
        for c in cands:
            if c.topic == override:
                return c
        raise HspError(f"{path}: no {schema} topic {override!r} (found: {', '.join(sorted(c.topic for c in cands)) or 'none'})")
    for suffix in prefer:
        hits = [c for c in cands if c.topic.endswith(suffix)]
        if hits:
            if len(hits) > 1:
                report.warn(f"{path}: several {what} topics {[c.topic for c in hits]}; using {hits[0].topic}")
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


def _tf_pose(tf: object) -> np.ndarray:
    t, r = tf.transform.translation, tf.transform.rotation  # type: ignore[attr-defined]
    return np.array([t.x, t.y, t.z, r.x, r.y, r.z, r.w])


def _camera_pose(static: dict[str, tuple[str, np.ndarray]], frame: str) -> np.ndarray | None:
    """Compose ``/tf_static`` from its root down to ``frame``; None if ``frame`` is absent."""
    if frame not in static:
        return None
    chain, node = [], frame
    while node in static and len(chain) < 32:
        parent, T = static[node]
        chain.append(T)
        node = parent
    pose = chain[-1]
    for T in reversed(chain[:-1]):
        pose = compose(pose, T)
    return pose


def read_recording(path: Path, options: ReadOptions = ReadOptions()) -> Recording:
    """Read and pair the RGB-D frames of one recording (see module docstring)."""
    path = Path(path)
    report = ReadReport()
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    for f in _mcap_files(path):
        _check_magic(f)
        s, c, m = _scan(f, report)
        schemas.update(s)
        channels.update(c)
        messages += m
    if not messages:
        raise HspError(f"{path}: no readable messages")

    color = _pick(channels, schemas, IMAGE_SCHEMA, ["/color/image_raw", "/color/image_rect_raw", "/color/image"],
                  options.color_topic, "colour", path, report)
    depth = _pick(channels, schemas, IMAGE_SCHEMA, ["aligned_depth_to_color/image_raw", "depth/image_rect_raw", "depth/image_raw"],
                  options.depth_topic, "depth", path, report)
    if color is None or depth is None:
        images = sorted(c.topic for c in channels.values() if schemas.get(c.schema_id) and schemas[c.schema_id].name == IMAGE_SCHEMA)
        others = sorted({c.topic for c in channels.values()})
        missing = "colour" if color is None else "depth"
        raise HspError(f"{path}: no {missing} image topic; Image topics: {images or 'none'}; all topics: {others}"
                       " (name them with --color-topic/--depth-topic)")
    if "aligned_depth_to_color" not in depth.topic and options.depth_topic is None:
        aligned = [c.topic for c in channels.values() if "aligned_depth_to_color" in c.topic]
        if not aligned:
            report.warn(f"{path}: depth topic {depth.topic} is not the aligned one; it must be registered to colour")
    info = _pick(channels, schemas, INFO_SCHEMA, ["/color/camera_info", "camera_info"], options.info_topic, "camera info", path, report)

    factory = DecoderFactory()
    decoders = {}

    def decode(m: Message) -> object:
        ch = channels[m.channel_id]
        if ch.id not in decoders:
            decoders[ch.id] = factory.decoder_for(ch.message_encoding, schemas[ch.schema_id])
            if decoders[ch.id] is None:
                raise HspError(f"{path}: cannot decode {ch.topic} ({ch.message_encoding}, {schemas[ch.schema_id].encoding})")
        return decoders[ch.id](m.data)

    colour_frames: dict[int, np.ndarray] = {}
    depth_frames: dict[int, np.ndarray] = {}
    K = None
    info_size = None
    frame_id = ""
    static: dict[str, tuple[str, np.ndarray]] = {}
    for m in messages:
        cid = m.channel_id
        if cid == color.id or cid == depth.id:
            msg = decode(m)
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec  # type: ignore[attr-defined]
            kind, img = _image(msg, path)
            if cid == color.id:
                if kind != "color":
                    raise HspError(f"{path}: colour topic {color.topic} carries {msg.encoding!r}")  # type: ignore[attr-defined]
                colour_frames[stamp] = img
                frame_id = msg.header.frame_id  # type: ignore[attr-defined]
            else:
                if kind != "depth":
                    raise HspError(f"{path}: depth topic {depth.topic} carries {msg.encoding!r}")  # type: ignore[attr-defined]
                depth_frames[stamp] = img
        elif info is not None and cid == info.id and K is None:
            msg = decode(m)
            K = np.asarray(msg.k, float).reshape(3, 3)  # type: ignore[attr-defined]
            info_size = (msg.height, msg.width)  # type: ignore[attr-defined]
        elif schemas.get(channels[cid].schema_id) is not None and schemas[channels[cid].schema_id].name == TF_SCHEMA \
                and channels[cid].topic == "/tf_static":
            for tf in decode(m).transforms:  # type: ignore[attr-defined]
                static[tf.child_frame_id] = (tf.header.frame_id, _tf_pose(tf))
    report.color_messages, report.depth_messages = len(colour_frames), len(depth_frames)
    if not colour_frames or not depth_frames:
        raise HspError(f"{path}: no usable frames ({len(colour_frames)} colour, {len(depth_frames)} depth)")

    c_shape = next(iter(colour_frames.values())).shape[:2]
    d_shape = next(iter(depth_frames.values())).shape
    if c_shape != d_shape:
        raise HspError(f"{path}: depth {d_shape[1]}x{d_shape[0]} differs from colour {c_shape[1]}x{c_shape[0]}; "
                       "record the aligned depth (realsense-ros: align_depth.enable:=true)")
    if K is None:
        if options.intrinsics is None:
            raise HspError(f"{path}: no CameraInfo topic and no intrinsics given (pass --intrinsics fx,fy,cx,cy)")
        fx, fy, cx, cy = options.intrinsics
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    elif info_size != c_shape and info_size != (0, 0):
        raise HspError(f"{path}: camera info is for {info_size[1]}x{info_size[0]}, images are {c_shape[1]}x{c_shape[0]}")

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
    if np.any(np.diff([m.log_time for m in messages if m.channel_id == color.id]) < 0):
        report.warn(f"{path}: colour messages are not in time order; sorted by header.stamp")

    depth_arr = np.stack([depth_frames[d] for _, d in pairs])
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
        T_world_cam=_camera_pose(static, frame_id),
        topics={"color": color.topic, "depth": depth.topic, "info": info.topic if info else ""},
        report=report,
    )

"""Images of a bag for ``kinfw detect``.

:func:`write_bag_images` writes the images of a ``sensor_msgs/Image`` or
``CompressedImage`` topic that the joint states place (the same drop rules) into a
folder, with the joint values per image in the CSV that ``kinfw detect --joints`` reads.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from kinfw.measurements._bag_align import BagAlignment, align_stamps
from kinfw.measurements._bag_read import bag_messages, open_bag, read_joint_states, stamp_ns
from kinfw.observations import DatasetError

if TYPE_CHECKING:
    from kinfw.model import Robot

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
#: The files :func:`write_bag_images` writes beside the images: the joint values per
#: image in the CSV that ``kinfw detect --joints`` reads, and the stamps.
IMAGE_JOINTS_CSV = "joints.csv"
IMAGE_STAMPS_JSON = "images.json"
#: ``sensor_msgs/Image`` encodings read: numpy type, channels, OpenCV conversion to the
#: channel order ``cv2.imwrite`` expects (BGR, BGRA) or None.
_ENCODINGS: dict[str, tuple[str, int, str | None]] = {
    "mono8": ("uint8", 1, None),
    "8UC1": ("uint8", 1, None),
    "mono16": ("uint16", 1, None),
    "16UC1": ("uint16", 1, None),
    "bgr8": ("uint8", 3, None),
    "8UC3": ("uint8", 3, None),
    "rgb8": ("uint8", 3, "COLOR_RGB2BGR"),
    "bgra8": ("uint8", 4, None),
    "rgba8": ("uint8", 4, "COLOR_RGBA2BGRA"),
}


@dataclass(frozen=True, slots=True)
class BagImages:
    """The images of a bag written by :func:`write_bag_images`.

    Attributes
    ----------
    directory : Path
        Where the images, :data:`IMAGE_JOINTS_CSV` and :data:`IMAGE_STAMPS_JSON` are.
    files : tuple of str
        The image files' names in ``directory``, in time order.
    t_s : ndarray, shape (k,)
        Their stamps, seconds from the bag's first message.
    joint_names : tuple of str
        The joints, in the URDF's order.
    qs : ndarray, shape (k, len(joint_names))
        Joint values interpolated at each image's stamp minus the offset, rad or m.
    alignment : BagAlignment
        Which images were kept (indices in the topic's time order) and why the others
        were dropped.
    """

    directory: Path
    files: tuple[str, ...]
    t_s: NDArray[np.float64]
    joint_names: tuple[str, ...]
    qs: NDArray[np.float64]
    alignment: BagAlignment


def write_bag_images(
    path: str | Path,
    directory: str | Path,
    *,
    robot: Robot,
    images: str,
    joint_states: str = "/joint_states",
    offset_s: float = 0.0,
    max_gap_s: float | None = 0.05,
    max_interpolation_error: float | None = 1e-3,
    still_speed: float | None = None,
) -> BagImages:
    """Write the images of a bag that the joint states place, for ``kinfw detect``.

    Parameters
    ----------
    path : str or Path
        The bag (as for :func:`read_bag`).
    directory : str or Path
        Folder to write (created): ``image_00000.png``, ... (``.jpg`` for JPEG
        ``CompressedImage`` data, copied as recorded), :data:`IMAGE_JOINTS_CSV` (a
        header ``image, JOINT...`` and one row per image: ``kinfw detect --joints``)
        and :data:`IMAGE_STAMPS_JSON` (the bag, topic, offset, joint names, and per
        image its file, stamp and joint values; the dropped counts).
    robot : Robot
        The URDF robot (which joints are read).
    images : str, keyword-only
        A ``sensor_msgs/Image`` (encodings mono8, mono16, bgr8, rgb8, bgra8, rgba8,
        8UC1, 8UC3, 16UC1) or ``sensor_msgs/CompressedImage`` topic.
    joint_states, offset_s, max_gap_s, max_interpolation_error, still_speed
        As for :func:`read_bag` and :func:`measurements_from_bag`; ``still_speed``
        keeps the images taken while the robot stood (no motion blur, no timing error).

    Returns
    -------
    BagImages

    Raises
    ------
    DatasetError
        As :func:`read_bag`; an unsupported encoding (naming it and those read); no
        image within the joint states' time range, or every image dropped.
    """
    import cv2

    from kinfw.files import json_text, write_text_atomic

    path, directory = Path(path), Path(directory)
    expected = (IMAGE, COMPRESSED_IMAGE)
    with open_bag(path) as (reader, topics, t0_ns):
        joints = read_joint_states(reader, path, topics, joint_states, robot, t0_ns)
        stamps = []  # a first pass for the stamps: the images are written by the second
        for record_ns, msg in bag_messages(reader, path, topics, images, expected):
            stamps.append((stamp_ns(msg, record_ns) - t0_ns) * 1e-9)
            if not hasattr(msg, "format") and msg.encoding not in _ENCODINGS:
                raise DatasetError(
                    f"{path}: {images}: image encoding {msg.encoding!r} is not read; expected "
                    f"one of {list(_ENCODINGS)} (or a CompressedImage topic)"
                )
        if not stamps:
            raise DatasetError(f"{path}: topic {images!r} has no messages")
        order = np.argsort(stamps, kind="stable")
        t_s = np.asarray(stamps)[order]
        qs, alignment = align_stamps(
            path,
            images,
            joints,
            t_s,
            offset_s,
            max_gap_s=max_gap_s,
            max_interpolation_error=max_interpolation_error,
            still_speed=still_speed,
        )
        rank = {int(order[k]): i for i, k in enumerate(alignment.kept)}  # message -> file
        files = [""] * len(rank)
        directory.mkdir(parents=True, exist_ok=True)
        for m, (_, msg) in enumerate(bag_messages(reader, path, topics, images, expected)):
            if m in rank:
                data, suffix = _image_file(path, images, msg, cv2)
                files[rank[m]] = f"image_{rank[m]:05d}{suffix}"
                (directory / files[rank[m]]).write_bytes(data)
    qs = qs[alignment.kept]
    rows = [",".join(["image", *joints.names])]
    rows += [",".join([f, *map(repr, q)]) for f, q in zip(files, qs.tolist(), strict=True)]
    write_text_atomic(directory / IMAGE_JOINTS_CSV, "\n".join(rows) + "\n")
    record = {
        "bag": str(path),
        "topic": images,
        "t0_ns": t0_ns,
        "offset_s": float(offset_s),
        "joint_names": list(joints.names),
        "images": [
            {"file": f, "t_s": float(t), "q": q}
            for f, t, q in zip(files, t_s[alignment.kept], qs.tolist(), strict=True)
        ],
        "dropped": alignment.dropped,
    }
    write_text_atomic(directory / IMAGE_STAMPS_JSON, json_text(record) + "\n")
    return BagImages(directory, tuple(files), t_s[alignment.kept], joints.names, qs, alignment)


def _image_file(path: Path, topic: str, msg: Any, cv2: Any) -> tuple[bytes, str]:
    """The bytes of an image file and its suffix: a ``CompressedImage``'s data as
    recorded, an ``Image`` (encoding checked by the caller) encoded as PNG (lossless,
    16 bits kept)."""
    if hasattr(msg, "format"):  # CompressedImage
        return bytes(msg.data), ".png" if "png" in msg.format.lower() else ".jpg"
    dtype_name, channels, conversion = _ENCODINGS[msg.encoding]
    dtype = np.dtype(dtype_name).newbyteorder(">" if msg.is_bigendian else "<")
    row_bytes = msg.width * channels * dtype.itemsize
    rows = np.asarray(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)[:, :row_bytes]
    pixels = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="))
    shape = (msg.height, msg.width) if channels == 1 else (msg.height, msg.width, channels)
    pixels = pixels.reshape(shape)
    if conversion is not None:
        pixels = cv2.cvtColor(pixels, getattr(cv2, conversion))
    ok, png = cv2.imencode(".png", pixels)
    if not ok:
        raise DatasetError(f"{path}: {topic}: an image could not be encoded as PNG")
    return png.tobytes(), ".png"

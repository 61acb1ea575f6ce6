"""Reading a URDF's text: the XML checks, the joints as written, Pinocchio's model.

The standard library's XML parser reads the structure (:func:`check_urdf_xml`,
:func:`parse_joints`) and refuses, with a message naming the file, what urdfdom (the C++
parser under Pinocchio) would only print on the process's stderr;
:func:`pinocchio_model` builds the Pinocchio model with that stderr captured, so its
messages become the :class:`RobotModelError`. :class:`kinfw.model.Robot` is built from
these.
"""

from __future__ import annotations

import contextlib
import difflib
import io
import logging
import os
import re
import sys
import tempfile
import threading
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

logger = logging.getLogger("kinfw.model")  # urdfdom's messages, logged as the robot's


MOVABLE_TYPES = ("revolute", "continuous", "prismatic")


_NATIVE_STDERR_LOCK = threading.Lock()


#: The "at line N in file.cpp" that ends each of urdfdom's stderr messages.
_URDFDOM_LINE = re.compile(r"\s*at line \d+ in \S+\s*")


class RobotModelError(ValueError):
    """The URDF cannot be used as asked (bad XML, unsupported joint on a needed path...)."""


@dataclass(frozen=True, slots=True)
class JointInfo:
    """One URDF joint as written in the file.

    Attributes
    ----------
    name, type, parent, child : str
        URDF joint name, type, parent link and child link.
    parent_T_child : ndarray, shape (4, 4)
        The joint's ``<origin>`` (pose of the child link in the parent link at q = 0).
    axis : ndarray, shape (3,)
        Unit joint axis in the child link frame (the URDF value, normalised).
    lower, upper : float
        Limits in rad or m; ``-inf`` / ``inf`` when the URDF gives none.
    mimic : str or None
        Name of the joint this one mimics.
    """

    name: str
    type: str
    parent: str
    child: str
    parent_T_child: NDArray[np.float64]
    axis: NDArray[np.float64]
    lower: float
    upper: float
    mimic: str | None

    @property
    def is_movable(self) -> bool:
        """True for revolute, continuous and prismatic joints (one scalar joint value)."""
        return self.type in MOVABLE_TYPES

    @property
    def is_revolute(self) -> bool:
        """True for revolute and continuous joints."""
        return self.type in ("revolute", "continuous")


#: The xacro XML namespace. Declaring it does not make a document xacro: xacro's output
#: keeps the declaration (example-robot-data's ``panda.urdf``); see :func:`is_xacro`.
XACRO_NAMESPACE = "http://www.ros.org/wiki/xacro"

#: A xacro substitution, ``$(arg x)`` or ``${expression}``.
_SUBSTITUTION = re.compile(r"\$[({]")


def is_xacro(text: str, source: str) -> bool:
    """True when ``text`` needs xacro: ``source`` is a ``.xacro`` file, or the document has
    an element or attribute in the xacro namespace, or a ``$(...)`` / ``${...}``
    substitution in an attribute or text (comments do not count). A document that only
    declares the namespace, as xacro's own output does, is a plain URDF; one that is not
    well-formed XML is left to the URDF checks, which name the parse error."""
    if source.endswith(".xacro"):
        return True
    if XACRO_NAMESPACE not in text:
        return False
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return False
    namespace = f"{{{XACRO_NAMESPACE}}}"
    for element in root.iter():
        if element.tag.startswith(namespace):
            return True
        if any(k.startswith(namespace) for k in element.attrib):
            return True
        words = [*element.attrib.values(), element.text or "", element.tail or ""]
        if any(_SUBSTITUTION.search(w) for w in words):
            return True
    return False


def xml_text(urdf: str | Path, xacro_args: Mapping[str, str] | None = None) -> tuple[str, str]:
    """Return (xml_text, source) for a path or an XML string; a xacro document (a
    ``.xacro`` file, or one with xacro elements or substitutions: :func:`is_xacro`) is
    expanded first (:func:`expand_xacro`, with ``xacro_args``)."""
    if not str(urdf).strip():  # Path("") is ".", read as a directory
        raise RobotModelError("an empty URDF argument: expected a file name or a URDF's XML text")
    if isinstance(urdf, Path) or not str(urdf).lstrip().startswith("<"):
        path = Path(urdf)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise RobotModelError(f"{path}: cannot read URDF ({exc.strerror})") from None
        source = str(path)
    else:
        text, source = str(urdf), "<urdf string>"
    if is_xacro(text, source):
        return expand_xacro(text, source, xacro_args or {}), source
    if xacro_args:
        raise RobotModelError(
            f"{source}: xacro arguments given ({', '.join(xacro_args)}) for a plain URDF "
            "(no xacro element or substitution, not a .xacro file)"
        )
    return text, source


def expand_xacro(text: str, source: str, xacro_args: Mapping[str, str]) -> str:
    """The URDF a xacro document describes, with the ``xacro_args`` (``<xacro:arg>``
    values, as ``name:=value`` on xacro's command line), by the ``xacro`` package (the
    ``ros`` extra). Includes are relative to ``source``'s folder; ``$(find PKG)`` needs
    the package on ``ROS_PACKAGE_PATH`` or in an ament index.

    Raises
    ------
    RobotModelError
        The xacro package is missing, or xacro refuses the document (its message, and
        the file).
    """
    try:
        import xacro
    except ImportError:
        raise RobotModelError(
            f"{source}: a xacro file; reading it needs the xacro package (pip install 'kinfw[ros]')"
        ) from None
    path = Path(source)
    try:
        with captured_native_stderr():  # xacro's own warnings, printed on stderr
            if path.is_file():  # includes relative to the file
                doc = xacro.process_file(str(path), mappings=dict(xacro_args))
            else:
                doc = xacro.parse(text)
                xacro.process_doc(doc, mappings=dict(xacro_args))
    except Exception as exc:  # xacro raises XacroException and plain errors alike
        raise RobotModelError(f"{source}: xacro: {' '.join(str(exc).split())}") from None
    return doc.toxml()


def check_urdf_xml(xml: str, source: str) -> ET.Element:
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise RobotModelError(f"{source}: not well-formed XML ({exc})") from None
    if root.tag != "robot":
        raise RobotModelError(
            f"{source}: not a URDF (the root element is <{root.tag}>, expected <robot>)"
        )
    _check_links_and_joints(root, source)
    return root


def _check_links_and_joints(root: ET.Element, source: str) -> None:
    """Check what urdfdom would refuse with a message on the C++ stderr: unnamed or
    repeated links and joints, and joints whose parent or child link is not declared."""
    links: list[str] = []
    for k, link in enumerate(root.findall("link")):
        name = link.get("name")
        if not name:
            raise RobotModelError(f"{source}: <link> number {k + 1} has no name")
        if name in links:
            raise RobotModelError(f"{source}: link {name!r} is declared twice")
        links.append(name)
    known = set(links)
    joints: set[str] = set()
    parent_joint: dict[str, str] = {}
    for k, joint in enumerate(root.findall("joint")):
        name = joint.get("name")
        if not name:
            raise RobotModelError(f"{source}: <joint> number {k + 1} has no name")
        if name in joints:
            raise RobotModelError(f"{source}: joint {name!r} is declared twice")
        joints.add(name)
        for role in ("parent", "child"):
            element = joint.find(role)
            link = None if element is None else element.get("link")
            if not link:
                raise RobotModelError(f"{source}: joint {name!r} has no <{role} link=...>")
            if link not in known:
                close = difflib.get_close_matches(link, links, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise RobotModelError(
                    f"{source}: joint {name!r}: its {role} link {link!r} is not a <link> of "
                    f"the URDF (links: {', '.join(links)}){hint}"
                )
        child = joint.find("child").get("link")
        if child in parent_joint:
            raise RobotModelError(
                f"{source}: link {child!r} is the child of two joints, "
                f"{parent_joint[child]!r} and {name!r}"
            )
        parent_joint[child] = name


@contextlib.contextmanager
def captured_native_stderr() -> Iterator[io.StringIO]:
    """Redirect file descriptor 2 (where urdfdom's C++ code prints) to a buffer.

    Yields a buffer filled with what was printed once the block ends. Falls back to
    capturing nothing when descriptor 2 cannot be duplicated.
    """
    buffer = io.StringIO()
    with _NATIVE_STDERR_LOCK:  # one redirection at a time, or threads restore it wrongly
        try:
            saved = os.dup(2)
        except OSError:
            yield buffer
            return
        try:
            with tempfile.TemporaryFile(mode="w+b") as tmp:
                with contextlib.suppress(OSError, ValueError):
                    sys.stderr.flush()
                os.dup2(tmp.fileno(), 2)
                try:
                    yield buffer
                finally:
                    os.dup2(saved, 2)
                    tmp.seek(0)
                    buffer.write(tmp.read().decode("utf-8", "replace"))
        finally:
            os.close(saved)


def pinocchio_model(urdf_xml: str, source: str) -> pin.Model:
    """Pinocchio's model of a URDF text, urdfdom's stderr captured: its messages make the
    :class:`RobotModelError` when the model cannot be built (and are logged at debug level
    otherwise)."""
    model, error = None, None
    with captured_native_stderr() as native:
        try:
            model = pin.buildModelFromXML(urdf_xml)
        except Exception as exc:  # Pinocchio raises ValueError/RuntimeError
            error = exc
    said = " ".join(native.getvalue().split())
    if model is None:  # urdfdom's own lines say why; Pinocchio's only that it failed
        lines = [
            m.strip().removeprefix("Error:").strip()
            for m in _URDFDOM_LINE.sub("\n", said).splitlines()
        ]
        why = "; ".join(m for m in lines if m) or str(error)
        raise RobotModelError(f"{source}: Pinocchio cannot load this URDF ({why})")
    if said:
        logger.debug("%s: urdfdom printed: %s", source, said)
    return model


def up_vector(text: str | None, source: str) -> NDArray[np.float64] | None:
    if text is None:
        return None
    try:
        up = np.array([float(v) for v in text.split()])
    except ValueError:
        up = np.zeros(0)
    if up.shape != (3,) or not np.linalg.norm(up) > 0:
        raise RobotModelError(
            f"{source}: <kinfw up={text!r}>: expected three numbers, not all zero"
        )
    return up / np.linalg.norm(up)


def _floats(
    element: ET.Element | None, key: str, n: int, default: list[float], where: str
) -> list[float]:
    """``n`` numbers of attribute ``key`` of ``element`` (``default`` when absent)."""
    text = None if element is None else element.get(key)
    if text is None:
        return default
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != n or not all(np.isfinite(values)):
        raise RobotModelError(f"{where}: {key}={text!r}: expected {n} finite numbers")
    return values


def parse_joints(
    root: ET.Element, source: str
) -> tuple[tuple[JointInfo, ...], tuple[str, ...], str]:
    """Joints (document order), links and the root link of a checked ``<robot>`` element
    (:func:`check_urdf_xml`). Origins follow URDF: ``rpy`` is fixed-axis roll, pitch, yaw,
    ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`pinocchio.rpy.rpyToMatrix`)."""
    joints = []
    for element in root.findall("joint"):
        name, kind = element.get("name"), element.get("type")
        where = f"{source}: joint {name!r}"
        if kind not in (*MOVABLE_TYPES, "fixed", "floating", "planar"):
            raise RobotModelError(f"{where}: unknown type {kind!r}")
        origin = element.find("origin")
        parent_T_child = np.eye(4)
        parent_T_child[:3, 3] = _floats(origin, "xyz", 3, [0.0, 0.0, 0.0], f"{where} <origin>")
        parent_T_child[:3, :3] = pin.rpy.rpyToMatrix(
            np.array(_floats(origin, "rpy", 3, [0.0, 0.0, 0.0], f"{where} <origin>"))
        )
        axis = np.array(_floats(element.find("axis"), "xyz", 3, [1.0, 0.0, 0.0], f"{where} <axis>"))
        norm = np.linalg.norm(axis)
        if kind in MOVABLE_TYPES and not norm > 0.0:
            raise RobotModelError(f"{source}: joint {name!r} has a zero axis")
        limit = element.find("limit")
        lower = _floats(limit, "lower", 1, [-np.inf], f"{where} <limit>")[0]
        upper = _floats(limit, "upper", 1, [np.inf], f"{where} <limit>")[0]
        if kind == "continuous":
            lower, upper = -np.inf, np.inf
        mimic = element.find("mimic")
        joints.append(
            JointInfo(
                name=name,
                type=kind,
                parent=element.find("parent").get("link"),
                child=element.find("child").get("link"),
                parent_T_child=parent_T_child,
                axis=axis / norm if norm > 0 else axis,
                lower=lower,
                upper=upper,
                mimic=None if mimic is None else mimic.get("joint"),
            )
        )
    links = tuple(link.get("name") for link in root.findall("link"))
    children = {j.child for j in joints}
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise RobotModelError(f"{source}: expected one root link, found {roots}")
    return tuple(joints), links, roots[0]

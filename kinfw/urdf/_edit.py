"""Edit a URDF's text: new joint origins and axes, and link frames shifted in place.

:func:`edit_urdf` changes exactly the elements it is asked to and keeps everything else
(comments, ``<transmission>``, ``<gazebo>``, ``<calibration>``, meshes, attribute order,
whitespace) as lxml parsed it. A link frame shifted by ``old_T_new`` has its visuals,
collisions, inertials and child joints re-expressed so that nothing attached moves. The
calibrated export (:mod:`kinfw.urdf`) is built on it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from types import MappingProxyType

import numpy as np
import pinocchio as pin
from lxml import etree
from numpy.typing import ArrayLike, NDArray

from kinfw.geometry import check_transform, inverse_transform

SAME_TOL = 1e-12
"""An origin or axis within this of the file's value (max abs entry) keeps its text."""

_EMPTY: Mapping[str, ArrayLike] = MappingProxyType({})
_GEOMETRY_TAGS = ("visual", "collision", "inertial")
# Text around the root element that lxml would not reproduce byte for byte.
_PROLOG = re.compile(
    r"(?:\s|<\?(?:(?!\?>).)*\?>|<!--(?:(?!-->).)*-->|<!DOCTYPE(?:[^\[>]|\[.*?\])*>)*", re.S
)
_EPILOG = re.compile(r"(?:\s|<\?(?:(?!\?>).)*\?>|<!--(?:(?!-->).)*-->)*\Z", re.S)


class ExportError(ValueError):
    """The URDF cannot be edited or cannot represent the calibrated model as asked."""


def edit_urdf(
    urdf_xml: str,
    *,
    joint_origins: Mapping[str, ArrayLike] = _EMPTY,
    joint_axes: Mapping[str, ArrayLike] = _EMPTY,
    link_shifts: Mapping[str, ArrayLike] = _EMPTY,
) -> str:
    """Return ``urdf_xml`` with new joint origins, joint axes and re-expressed links.

    Parameters
    ----------
    urdf_xml : str
        URDF text.
    joint_origins : mapping of str to array_like, shape (4, 4)
        New ``<origin>`` of each named joint: ``parent_T_child`` at q = 0, metres.
    joint_axes : mapping of str to array_like, shape (3,)
        New unit ``<axis>`` of each named joint, in its child link frame.
    link_shifts : mapping of str to array_like, shape (4, 4)
        Per link, ``old_T_new``: the link frame moves to ``old_T_new`` (in the old link
        frame). Every ``<visual>``, ``<collision>`` and ``<inertial>`` origin of the link
        becomes ``new_T_x = inv(old_T_new) @ old_T_x`` (the geometry stays put), and so
        does the origin of each joint whose parent is the link, unless that joint is in
        ``joint_origins``.

    Returns
    -------
    str
        The edited URDF. Only the changed ``xyz`` / ``rpy`` attributes differ (written with
        ``repr(float(x))``, so they read back exactly); an origin or axis whose new value
        is within ``SAME_TOL`` of the current one keeps its text, and when nothing changes
        ``urdf_xml`` itself is returned. Text before and after the root element (XML
        declaration, comments) is kept verbatim; inside it, lxml keeps comments, unknown
        tags and attribute order. Missing ``<origin>`` / ``<axis>`` elements are created.

    Raises
    ------
    ExportError
        For XML that is not a URDF, unknown joint or link names (all are named), a
        transform that is not rigid, an axis that is not unit, or a rotation whose rpy
        does not reproduce it to ``SAME_TOL``.
    """
    robot_elem = _parse(urdf_xml)
    joints = _named_children(robot_elem, "joint")
    links = _named_children(robot_elem, "link")
    _check_known("joint", [*joint_origins, *joint_axes], joints)
    _check_known("link", list(link_shifts), links)
    changed = False
    for name, parent_T_child in joint_origins.items():
        parent_T_child = check_transform(parent_T_child, name=f"joint_origins[{name!r}]")
        changed |= _set_origin(joints[name], parent_T_child, f"joint {name!r}")
    for name, axis in joint_axes.items():
        changed |= _set_axis(joints[name], _check_unit(axis, f"joint_axes[{name!r}]"))
    for name, old_T_new in link_shifts.items():
        new_T_old = inverse_transform(check_transform(old_T_new, name=f"link_shifts[{name!r}]"))
        for elem in _shifted_elements(links[name], joints, name, skip=joint_origins):
            changed |= _set_origin(elem, new_T_old @ _origin_transform(elem), _describe(elem))
    return _serialize(robot_elem, urdf_xml) if changed else urdf_xml


def add_fixed_links(urdf_xml: str, links: Mapping[str, tuple[str, ArrayLike]]) -> str:
    """Return ``urdf_xml`` with new links, each on a new fixed joint to an existing link.

    Parameters
    ----------
    urdf_xml : str
        URDF text.
    links : mapping of str to (str, array_like of shape (4, 4))
        Per new link name: its parent link (one of the URDF's, or a link added before it
        in ``links``) and the new joint's origin ``parent_T_link``, metres. The joint is
        named ``f"{name}_joint"``.

    Returns
    -------
    str
        The URDF with ``<link name="NAME"/>`` and ``<joint name="NAME_joint"
        type="fixed">`` appended at the end of ``<robot>``, in the order of ``links``;
        every other element and the text around the root element kept as in
        :func:`edit_urdf`. ``urdf_xml`` itself when ``links`` is empty.

    Raises
    ------
    ExportError
        For a name that is already a link or joint, an unknown parent (the links are
        listed) or a transform that is not rigid.
    """
    if not links:
        return urdf_xml
    robot_elem = _parse(urdf_xml)
    known_links = _named_children(robot_elem, "link")
    known_joints = _named_children(robot_elem, "joint")
    indent = (robot_elem.text or "\n  ") if not (robot_elem.text or "").strip() else "\n  "
    last = robot_elem[-1] if len(robot_elem) else None
    for name, (parent, parent_T_link) in links.items():
        parent_T_link = check_transform(parent_T_link, name=f"links[{name!r}]")
        joint_name = f"{name}_joint"
        if name in known_links or name in known_joints or joint_name in known_joints:
            raise ExportError(
                f"link {name!r}: the URDF already has a link or joint {name!r} or "
                f"{joint_name!r}; choose another name"
            )
        if parent not in known_links:
            raise ExportError(
                f"link {name!r}: its parent {parent!r} is not a link of the URDF; links are "
                f"{list(known_links)}"
            )
        link = etree.Element("link", name=name)
        joint = etree.Element("joint", name=joint_name, type="fixed")
        for tag, value in (("parent", parent), ("child", name)):
            etree.SubElement(joint, tag, link=value)
        joint.append(etree.Element("origin", xyz="0 0 0", rpy="0 0 0"))
        _set_origin(joint, parent_T_link, f"joint {joint_name!r}")
        for elem in (link, joint):
            if last is not None:
                elem.tail, last.tail = last.tail, indent
            robot_elem.append(elem)
            last = elem
        known_links[name], known_joints[joint_name] = link, joint
    return _serialize(robot_elem, urdf_xml)


def _parse(urdf_xml: str) -> etree._Element:
    parser = etree.XMLParser(remove_comments=False, strip_cdata=False, encoding="utf-8")
    try:
        robot_elem = etree.fromstring(urdf_xml.encode("utf-8"), parser)
    except etree.XMLSyntaxError as exc:
        raise ExportError(f"urdf_xml: not well-formed XML ({exc})") from None
    if robot_elem.tag != "robot":
        raise ExportError(f"urdf_xml: root element is <{robot_elem.tag}>, expected <robot>")
    return robot_elem


def _serialize(robot_elem: etree._Element, original: str) -> str:
    """The edited root element between the original's untouched prolog and epilog."""
    prolog = _PROLOG.match(original).group(0)
    epilog = _EPILOG.search(original, len(prolog)).group(0)
    return prolog + etree.tostring(robot_elem, encoding="unicode", with_tail=False) + epilog


def _named_children(robot_elem: etree._Element, tag: str) -> dict[str, etree._Element]:
    # Direct children only: <transmission> and <gazebo> hold <joint> tags of their own.
    return {e.get("name"): e for e in robot_elem.findall(tag)}


def _check_known(kind: str, names: list[str], known: Mapping[str, object]) -> None:
    unknown = sorted({n for n in names if n not in known})
    if unknown:
        raise ExportError(f"unknown {kind} name(s) {unknown}; the URDF has {list(known)}")


def _check_unit(axis: ArrayLike, name: str) -> NDArray[np.float64]:
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis) if axis.shape == (3,) else np.nan
    if not abs(norm - 1.0) <= 1e-6:
        raise ExportError(f"{name}: expected a unit 3-vector, got {axis.tolist()}")
    return axis / norm


def _shifted_elements(
    link: etree._Element,
    joints: Mapping[str, etree._Element],
    link_name: str,
    skip: Mapping[str, object],
) -> Iterator[etree._Element]:
    """The link's visuals, collisions, inertials and its child joints not in ``skip``."""
    yield from (e for e in link if e.tag in _GEOMETRY_TAGS)
    for name, joint in joints.items():
        parent = joint.find("parent")
        if name not in skip and parent is not None and parent.get("link") == link_name:
            yield joint


def _describe(elem: etree._Element) -> str:
    owner = elem if elem.tag == "joint" else elem.getparent()
    return f"{owner.tag} {owner.get('name')!r}" + ("" if owner is elem else f" <{elem.tag}>")


def _floats(
    elem: etree._Element | None, attr: str, default: tuple[float, ...]
) -> NDArray[np.float64]:
    text = None if elem is None else elem.get(attr)
    if text is None:
        return np.array(default)
    try:
        values = np.array([float(v) for v in text.split()])
    except ValueError:
        values = np.array([])
    if values.shape != (3,):
        raise ExportError(
            f"{_describe(elem.getparent())}: <{elem.tag} {attr}={text!r}> is not three numbers"
        )
    return values


def _origin_transform(elem: etree._Element) -> NDArray[np.float64]:
    """``parent_T_elem`` of an element's ``<origin>`` (identity when it has none)."""
    origin = elem.find("origin")
    out = np.eye(4)
    out[:3, :3] = pin.rpy.rpyToMatrix(_floats(origin, "rpy", (0.0, 0.0, 0.0)))
    out[:3, 3] = _floats(origin, "xyz", (0.0, 0.0, 0.0))
    return out


def _format(values: ArrayLike) -> str:
    return " ".join(repr(float(v)) for v in np.asarray(values))


def rpy_from_matrix(a_R_b: NDArray[np.float64], what: str) -> NDArray[np.float64]:
    """URDF roll, pitch, yaw (rad) of ``a_R_b``, checked to reproduce it to ``SAME_TOL``.

    ``pin.rpy.matrixToRpy`` stays exact at pitch = +-pi/2, where roll and yaw are not
    unique (it returns one valid pair); the check is what guarantees the round trip.
    """
    rpy = pin.rpy.matrixToRpy(a_R_b)
    error = np.abs(pin.rpy.rpyToMatrix(rpy) - a_R_b).max()
    if not error <= SAME_TOL:
        raise ExportError(
            f"{what}: rpy {rpy.tolist()} reproduce the rotation only to "
            f"{error:.3g} (> {SAME_TOL:g}); is the matrix orthonormal?"
        )
    return rpy


def _child(elem: etree._Element, tag: str) -> etree._Element:
    """``elem``'s ``<tag>`` child, created first in ``elem`` with its indentation if missing."""
    found = elem.find(tag)
    if found is not None:
        return found
    new = etree.Element(tag)
    elem.insert(0, new)
    if elem.text is not None and not elem.text.strip():
        new.tail = elem.text
    return new


def _set_origin(elem: etree._Element, a_T_b: NDArray[np.float64], what: str) -> bool:
    """Write ``a_T_b`` into ``elem``'s ``<origin>``; True if the text changed."""
    current = _origin_transform(elem)
    new_xyz = np.abs(a_T_b[:3, 3] - current[:3, 3]).max() > SAME_TOL
    new_rpy = np.abs(a_T_b[:3, :3] - current[:3, :3]).max() > SAME_TOL
    if new_xyz:
        _child(elem, "origin").set("xyz", _format(a_T_b[:3, 3]))
    if new_rpy:
        _child(elem, "origin").set("rpy", _format(rpy_from_matrix(a_T_b[:3, :3], what)))
    return bool(new_xyz or new_rpy)


def _set_axis(joint: etree._Element, axis: NDArray[np.float64]) -> bool:
    """Write a unit ``axis`` into the joint's ``<axis>``; True if the text changed."""
    current = _floats(joint.find("axis"), "xyz", (1.0, 0.0, 0.0))
    norm = np.linalg.norm(current)
    if norm > 0.0 and np.abs(axis - current / norm).max() <= SAME_TOL:
        return False
    _child(joint, "axis").set("xyz", _format(axis))
    return True
